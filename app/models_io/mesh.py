"""Meshes (OBJ, STL, PLY, glTF/GLB) through trimesh: read as feature-edge B-Reps, write surfaces.

Reading merges duplicate vertices (an STL is a triangle soup) and reduces the triangles to their
feature edges with ``core.mesh_features.brep_from_mesh``: a triangulated planar face adds no
false edge. A curved region keeps its triangles as faces whose sides are not edges; the overlay
draws its silhouette at each pose (``core.silhouette``, ``BRep.wireframe``): a
cylinder's two side lines, a sphere's outline. A glTF scene's meshes are placed by their node
transforms and merged into one model. Bad input raises ``MeshError`` naming the file (and, for
OBJ, the line) and the problem; a mesh that gives nothing to draw (no sharp edge and no curved
region with an outline, e.g. each triangle given twice) loads with a ``MeshWarning`` naming the file.
Materials and textures are not read (only the geometry is kept): an OBJ's ``mtllib``, a PLY's
``TextureFile`` and a glTF's images are never opened.

Limits, so that a careless or hostile file is refused before trimesh allocates anything (reading
a 10^6-triangle mesh takes 20 s and 1.2 GB; at the limit it takes 3.5 s and 0.3 GB):

* at most ``max_faces`` triangles (default ``MAX_MESH_FACES``, 200,000: a detailed CAD part)
  and ``3 * max_faces`` vertices (a triangle soup's three corners per triangle);
* at most 64 MB (``MAX_MESH_BYTES``; more in proportion when ``max_faces`` is raised): the file
  and a glTF's buffer files (each reference counted), checked first, from the file system;
* the counts are taken before reading: OBJ, on the text as trimesh reads it (continuation lines
  joined, every line starting with ``f`` a face, a polygon of n vertices n - 2 triangles, a record
  at most 1 MB, at most ``MAX_OBJ_MATERIALS`` ``usemtl`` groups: trimesh's time grows as their
  square); STL, the binary header's count, which must match the file's size, or an ASCII file's
  ``vertex`` lines; PLY, the header's elements, which must match the bytes that follow (binary)
  or the lines (ASCII); glTF/GLB, the accessors, which must fit in their buffers, the meshes'
  triangles, each placed node counted, at most ``max_faces / 20`` primitives and nodes (trimesh
  spends 0.4 ms and 12 KB on each) and a JSON of at most 10 values a triangle.

``read_mesh(path, max_faces=N)`` raises them (``mcit db import --max-faces N``); a refusal is one
line that names the file, what it holds, the limit and how to raise it. A file whose header
declares more than its bytes hold is refused as such, whatever the limits.

Writing tessellates the model (``BRep.triangles``: faces fan-triangulated, cylinders and cones
with ``n_circle`` sides) and exports the surface; ``.gltf`` embeds its buffer so the file stands
alone. The edges are not written (these formats carry surfaces): reading the file back recovers
the polyhedral edges through the dihedral-angle threshold, and a cylinder comes back as two rim
polylines and a smooth side drawn by its silhouettes.
"""

from __future__ import annotations

import json
import re
import stat
import struct
import warnings
from dataclasses import dataclass
from itertools import islice
from pathlib import Path

import numpy as np

from app.models_io.files import resolve_file
from core.brep import BRep
from core.mesh_features import brep_from_mesh

__all__ = [
    "MeshError",
    "MeshWarning",
    "MESH_SUFFIXES",
    "MAX_MESH_FACES",
    "MAX_MESH_BYTES",
    "MAX_OBJ_MATERIALS",
    "read_mesh",
    "write_mesh",
]

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".gltf", ".glb")

MAX_MESH_FACES = 200_000  # triangles; a 10^6-triangle mesh reads in 20 s and 1.2 GB, this in 3.5 s and 0.3 GB
MAX_MESH_BYTES = 64 * 2**20  # per MAX_MESH_FACES triangles allowed: an ASCII STL of 200,000 facets fits
_MAX_OBJ_RECORD = 2**20  # bytes in one OBJ record (a line and its continuations): bounds the split into tokens
_MAX_PLY_HEADER = 2**16  # bytes of a PLY header
_PLY_EXTRA_LINES = 16  # lines after an ASCII PLY's declared rows (trimesh makes an array of every line)


class MeshError(ValueError):
    """A mesh file that cannot be read; the message names the file and the problem."""


class MeshWarning(UserWarning):
    """A mesh that loads but that the overlay cannot show; the message names the file."""


@dataclass(frozen=True)
class _Limits:
    """What one mesh file may hold, from the triangle limit the caller chose."""

    faces: int

    @property
    def vertices(self) -> int:
        return 3 * self.faces

    @property
    def bytes(self) -> int:
        return max(MAX_MESH_BYTES, -(-self.faces * MAX_MESH_BYTES // MAX_MESH_FACES))

    @property
    def json_values(self) -> int:
        """Values in a glTF's JSON (10 a triangle: a 10,000-part assembly holds about 1.3 million);
        Python spends 30 to 200 bytes on each."""
        return 10 * self.faces

    @property
    def parts(self) -> int:
        """glTF primitives, nodes and links between nodes: trimesh spends 0.4 ms and 12 KB on each."""
        return max(100, self.faces // 20)

    def refuse(self, where: str, holds: str) -> MeshError:
        return MeshError(
            f"{where}: {holds}, beyond mcit's limits for one mesh ({self.faces:,} triangles, "
            f"{self.vertices:,} vertices, {self.bytes / 2**20:g} MB); simplify the mesh in "
            "its CAD program, or raise the limits with `mcit db import --max-faces N`"
        )


def _unreadable(path: Path, why: str) -> MeshError:
    return MeshError(f"{path}: cannot read the mesh: {why}")


def _count(path: Path, needles: tuple[bytes, ...], lower: bool = False) -> list[int]:
    """How many times each needle occurs in the file's bytes (lowered first if ``lower``), streamed in
    4 MB chunks. A needle must not overlap itself (``b"vertex"`` does not)."""
    counts = [0] * len(needles)
    keep = max(map(len, needles)) - 1
    tail = b""
    with open(path, "rb") as fh:
        while chunk := fh.read(2**22):
            buf = tail + (chunk.lower() if lower else chunk)
            for k, needle in enumerate(needles):
                counts[k] += buf.count(needle) - tail.count(needle)  # those inside the tail were counted before
            tail = buf[len(buf) - keep :]
    return counts


def _file_size(path: Path, limits: _Limits, what: str = "the file") -> int:
    """The size of a regular file, refused beyond the byte limit (read from the file system, nothing parsed)."""
    st = path.stat()
    if not stat.S_ISREG(st.st_mode):
        raise _unreadable(path, f"{what} is not a regular file")
    if st.st_size > limits.bytes:
        raise limits.refuse(str(path), f"{what} holds {st.st_size:,} bytes ({st.st_size / 2**20:,.1f} MB)")
    return st.st_size


# --- OBJ -----------------------------------------------------------------------------------------

# a line that trimesh reads as a vertex ("v " at the start of a line) or a face (any line starting with "f":
# trimesh splits its face chunks at "^f", so "f1 2 3" is a face too); indented ones too, as a superset
_OBJ_RECORD = re.compile(r"^[ \t]*(?:v[ \t]|f)[^\n]*", re.M)
_OBJ_CONTINUATION = "\\\n"
# characters that str.splitlines breaks at besides "\n": trimesh's fallback for uneven vertex rows makes a
# vertex of each piece, so one "v" line holding them could make any number of vertices
_OBJ_ODD_BREAKS = "\r\x0b\x0c\x1c\x1d\x1e\x85\u2028\u2029"
MAX_OBJ_MATERIALS = 1_000  # usemtl lines: trimesh makes a mesh for each, in time growing as their square


def _obj_text(path: Path, data: bytes) -> tuple[str, str, int]:
    """The OBJ's text as trimesh's loader sees it: decoded as it decodes it, stripped, CRLF made LF, a
    backslash-newline removed (the line continues), a newline added at each end; with the text before the
    continuations were removed and the newlines stripped from its start (for line numbers)."""
    from trimesh.util import decode_text

    try:
        text = decode_text(data)
    except Exception as exc:  # charset detection failed: trimesh could not read it either
        raise _unreadable(path, f"its text encoding is unknown ({type(exc).__name__})") from None
    stripped = text.strip()
    lead = text[: len(text) - len(text.lstrip())].count("\n")
    joined = stripped.replace("\r\n", "\n")
    return "\n" + joined.replace(_OBJ_CONTINUATION, "") + "\n", joined, lead


def _obj_line(text: str, joined: str, lead: int, pos: int) -> int:
    """The file's line number of position ``pos`` in trimesh's text (each removed continuation had a newline)."""
    removed = 0
    for k, match in enumerate(re.finditer(re.escape(_OBJ_CONTINUATION), joined)):
        if match.start() - 2 * k + 1 >= pos:  # its place in the text ("\n" added before it)
            break
        removed += 1
    return lead + text.count("\n", 0, pos) + removed


def _check_obj(path: Path, limits: _Limits) -> None:
    """Bound an OBJ's counts in the text trimesh reads (``_obj_text``): its ``v``/``vn``/``vt`` lines, its
    face lines (any line starting with ``f``) and its ``usemtl`` groups; then check its vertices and
    faces, so an error names its line, counting the triangles as trimesh makes them (a polygon of n
    vertices makes n - 2). Only the v and f records are split, so a file of comments costs no Python
    loop per line."""
    text, joined, lead = _obj_text(path, path.read_bytes())
    keys = {
        "v": ("vertices (v lines)", limits.vertices),
        "vn": ("normals (vn lines)", limits.vertices),
        "vt": ("texture coordinates (vt lines)", limits.vertices),
    }
    for key, (what, limit) in keys.items():
        n = text.count(f"\n{key} ") + text.count(f"\n{key}\t")
        if n > limit:
            raise limits.refuse(str(path), f"the file holds {n:,} {what}")
    n = text.count("\nf")
    if n > limits.faces:
        raise limits.refuse(str(path), f"the file holds {n:,} faces (f lines)")
    n = text.count("usemtl")  # trimesh splits its faces at every "usemtl ", wherever it is
    if n > MAX_OBJ_MATERIALS:
        raise MeshError(
            f"{path}: the file holds {n:,} material groups (usemtl), beyond mcit's limit of {MAX_OBJ_MATERIALS:,} "
            "(trimesh builds a mesh for each, in time growing as their square); merge the materials in its CAD program"
        )
    odd = [c for c in _OBJ_ODD_BREAKS if c in text]
    if odd:
        pos = min(text.index(c) for c in odd)
        raise MeshError(
            f"{path}:{_obj_line(text, joined, lead, pos)}: a line break other than LF or CRLF "
            f"({odd[0]!r}), which trimesh reads inconsistently; save the file with LF or CRLF line ends"
        )
    n_vertices = 0
    n_triangles = 0
    for match in _OBJ_RECORD.finditer(text):
        if match.end() - match.start() > _MAX_OBJ_RECORD:
            number = _obj_line(text, joined, lead, match.start())
            raise _unreadable(
                path, f"line {number} is longer than {_MAX_OBJ_RECORD // 2**20} MB (with the lines it continues)"
            )
        record = match.group().lstrip(" \t")
        body = record[1:]  # after the v or f
        if record[0] == "v":
            tokens = body.split("#", 1)[0].split()
            try:
                xyz = [float(t) for t in tokens[:3]]
            except ValueError:
                raise MeshError(
                    f"{path}:{_obj_line(text, joined, lead, match.start())}: vertex coordinates must be numbers, "
                    f"got {record.strip()!r}"
                ) from None
            if len(xyz) < 3 or not np.all(np.isfinite(xyz)):
                raise MeshError(
                    f"{path}:{_obj_line(text, joined, lead, match.start())}: a vertex needs 3 finite coordinates, "
                    f"got {record.strip()!r}"
                )
            n_vertices += 1
            if n_vertices > limits.vertices:
                raise limits.refuse(
                    f"{path}:{_obj_line(text, joined, lead, match.start())}",
                    f"the file holds more than {limits.vertices:,} vertices",
                )
        else:
            # trimesh splits the whole line (a comment too) at white space: count its triangles from all of it
            tokens = body.split("#", 1)[0].split()
            if len(tokens) < 3:
                raise MeshError(
                    f"{path}:{_obj_line(text, joined, lead, match.start())}: a face needs at least 3 vertices, "
                    f"got {record.strip()!r}"
                )
            n_triangles += max(len(body.split()), len(tokens)) - 2
            if n_triangles > limits.faces:
                raise limits.refuse(
                    f"{path}:{_obj_line(text, joined, lead, match.start())}",
                    f"the faces up to this line make {n_triangles:,} triangles (a polygon of n vertices makes n - 2)",
                )
            for ref in tokens:
                try:
                    i = int(ref.split("/")[0])
                except ValueError:
                    raise MeshError(
                        f"{path}:{_obj_line(text, joined, lead, match.start())}: face vertex {ref!r} is not an index"
                    ) from None
                if i == 0 or i > n_vertices or -i > n_vertices:
                    raise MeshError(
                        f"{path}:{_obj_line(text, joined, lead, match.start())}: face vertex index {i} refers to "
                        f"no vertex (1..{n_vertices} defined so far)"
                    )


# --- STL -----------------------------------------------------------------------------------------


def _check_stl(path: Path, limits: _Limits, size: int) -> None:
    """Binary STL: the header's triangle count, which must agree with the file's size (trimesh reads
    any other file as ASCII). ASCII STL (``solid`` first): its ``vertex`` lines, three a triangle."""
    with open(path, "rb") as fh:
        head = fh.read(84)
    if len(head) == 84:
        n = struct.unpack_from("<I", head, 80)[0]
        if size == 84 + 50 * n:
            if n > limits.faces:
                raise limits.refuse(str(path), f"the binary STL holds {n:,} triangles")
            return
    if not head.lstrip().lower().startswith(b"solid"):
        if len(head) < 84:
            raise _unreadable(
                path, f"{size} bytes: too short for a binary STL (84 bytes of header) and not an ASCII STL"
            )
        raise MeshError(
            f"{path}: the binary STL's header declares {n:,} triangles, which take {84 + 50 * n:,} bytes, "
            f"but the file holds {size:,}: it is truncated or not an STL file"
        )
    n_vertex, n_facet = _count(path, (b"vertex", b"endfacet"), lower=True)
    n = max(-(-n_vertex // 3), n_facet)
    if n > limits.faces:
        raise limits.refuse(str(path), f"the ASCII STL holds {n:,} triangles")


# --- PLY -----------------------------------------------------------------------------------------

_PLY_TYPES = {
    "char": 1,
    "uchar": 1,
    "int8": 1,
    "uint8": 1,
    "short": 2,
    "ushort": 2,
    "int16": 2,
    "uint16": 2,
    "int": 4,
    "uint": 4,
    "int32": 4,
    "uint32": 4,
    "float": 4,
    "float32": 4,
    "float16": 2,
    "int64": 8,
    "uint64": 8,
    "double": 8,
    "float64": 8,
}
_PLY_STRUCT = {
    "uchar": "B",
    "uint8": "B",
    "ushort": "H",
    "uint16": "H",
    "uint": "I",
    "uint32": "I",
    "uint64": "Q",
    "char": "b",
    "int8": "b",
    "short": "h",
    "int16": "h",
    "int": "i",
    "int32": "i",
    "int64": "q",
}
_PLY_TEXT = bytes(range(32, 127)) + b"\t\n\r"
_TOKEN = re.compile(rb"\S+")


@dataclass
class _PlyElement:
    name: str
    count: int
    properties: list  # (name, type) for a scalar, (name, (count type, item type)) for a list


def _ply_header(path: Path) -> tuple[str, list[_PlyElement], int]:
    """(format, elements, offset of the data) from a PLY header, which must end within 64 KB."""
    with open(path, "rb") as fh:
        head = fh.read(_MAX_PLY_HEADER)
    end = re.search(rb"^end_header[ \t\r]*\n", head, re.M)
    if not head.startswith(b"ply") or end is None:
        raise _unreadable(path, "no PLY header (a first line 'ply' and an 'end_header' line within 64 KB)")
    fmt, elements = None, []
    for raw in head[: end.start()].decode("ascii", "replace").splitlines()[1:]:
        tokens = raw.split()
        if not tokens or tokens[0] in ("comment", "obj_info"):
            continue
        if tokens[0] == "format" and len(tokens) >= 2:
            fmt = tokens[1]
        elif tokens[0] == "element" and len(tokens) == 3 and tokens[2].isdigit():
            elements.append(_PlyElement(tokens[1], int(tokens[2]), []))
        elif tokens[0] == "property" and elements and len(tokens) == 3 and tokens[1] in _PLY_TYPES:
            elements[-1].properties.append((tokens[2], tokens[1]))
        elif (
            tokens[0] == "property"
            and elements
            and len(tokens) == 5
            and tokens[1] == "list"
            and tokens[2] in _PLY_STRUCT
            and tokens[3] in _PLY_TYPES
        ):
            elements[-1].properties.append((tokens[4], (tokens[2], tokens[3])))
        else:
            raise _unreadable(
                path, f"the PLY header line {raw.strip()[:80]!r} is not an element, property, format or comment"
            )
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _unreadable(path, "the PLY header names no format among ascii, binary_little_endian, binary_big_endian")
    return fmt, elements, end.end()


def _face_list(element: _PlyElement) -> int | None:
    """Index among the face element's properties of its vertex-index list (as trimesh picks it)."""
    lists = [k for k, (name, kind) in enumerate(element.properties) if isinstance(kind, tuple)]
    named = [k for k in lists if element.properties[k][0] in ("vertex_indices", "vertex_index")]
    return (named or lists or [None])[0]


def _check_ply(path: Path, limits: _Limits, size: int) -> None:
    """The header's element counts against the limits, then against the bytes (binary: every list as
    long as its first row, as trimesh reads it) or the lines (ASCII) that follow; the triangles are
    counted from the faces' vertex lists (a polygon of n vertices makes n - 2)."""
    fmt, elements, start = _ply_header(path)
    for el in elements:
        limit = limits.faces if el.name == "face" else limits.vertices
        if el.count > limit:
            raise limits.refuse(str(path), f"the PLY header declares {el.count:,} {el.name} elements")
    declared = ", ".join(f"{el.count:,} {el.name}" for el in elements)
    face = next((el for el in elements if el.name == "face"), None)
    index = _face_list(face) if face is not None else None
    triangles = 0
    if fmt != "ascii":
        order = "<" if fmt == "binary_little_endian" else ">"
        offset = start
        with open(path, "rb") as fh:
            for el in elements:
                row = 0
                for k, (name, kind) in enumerate(el.properties):
                    if not isinstance(kind, tuple):
                        row += _PLY_TYPES[kind]
                        continue
                    n = 0
                    if el.count:
                        fh.seek(offset + row)
                        blob = fh.read(_PLY_TYPES[kind[0]])
                        if len(blob) < _PLY_TYPES[kind[0]]:
                            raise MeshError(
                                f"{path}: the PLY header declares {declared}, but the file ends inside "
                                f"the first {el.name}: it is truncated or its header is wrong"
                            )
                        n = struct.unpack(order + _PLY_STRUCT[kind[0]], blob)[0]
                        if n < 0:
                            raise _unreadable(path, f"the first {el.name}'s {name} has {n} items")
                    if el is face and k == index:
                        triangles = el.count * max(n - 2, 1)
                    row += _PLY_TYPES[kind[0]] + n * _PLY_TYPES[kind[1]]
                offset += el.count * row
        if offset != size:
            raise MeshError(
                f"{path}: the PLY header declares {declared}, which take {offset - start:,} bytes "
                f"(every list as long as the first), but {size - start:,} follow the header: "
                f"it is truncated or its header is wrong"
            )
    else:
        with open(path, "rb") as fh:
            fh.seek(start)
            body = fh.read()
        if body.translate(None, _PLY_TEXT):
            raise _unreadable(path, "the ASCII PLY's data holds bytes that are not text")
        n_lines = (
            body.count(b"\n")
            + body.count(b"\r")
            - body.count(b"\r\n")
            + (not body.endswith((b"\n", b"\r")) and bool(body))
        )
        rows = sum(el.count for el in elements)
        if n_lines < rows:
            raise MeshError(
                f"{path}: the PLY header declares {declared} ({rows:,} lines), but {n_lines:,} lines "
                f"follow the header: it is truncated or its header is wrong"
            )
        if n_lines > rows + _PLY_EXTRA_LINES:
            raise MeshError(
                f"{path}: {n_lines:,} lines follow the PLY header, which declares {declared} "
                f"({rows:,} lines): its header is wrong"
            )
        if face is not None and index is not None:
            first = sum(el.count for el in elements[: elements.index(face)])
            for number, line in enumerate(islice(body.splitlines(), first, first + face.count), start=1):
                tokens = _TOKEN.finditer(line)
                try:
                    for k, (_name, kind) in enumerate(face.properties):
                        n = 1 if not isinstance(kind, tuple) else int(next(tokens).group())
                        if k == index:
                            break
                        for _ in islice(tokens, n):
                            pass
                except (StopIteration, ValueError):
                    raise _unreadable(path, f"face {number} does not hold its properties") from None
                triangles += max(n - 2, 1)
                if triangles > limits.faces:
                    break
    if triangles > limits.faces:
        raise limits.refuse(
            str(path),
            f"the PLY's {face.count:,} faces make at least {triangles:,} triangles "
            f"(a polygon of n vertices makes n - 2)",
        )


# --- glTF / GLB ----------------------------------------------------------------------------------

_GLTF_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_GLTF_TYPE_SIZE = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}
_GLB_JSON, _GLB_BIN = 0x4E4F534A, 0x004E4942
_MAX_GLB_CHUNKS = 64  # the format has a JSON chunk and a binary one; trimesh walks every chunk header


def _gltf_json(path: Path, size: int) -> tuple[bytes, list[int]]:
    """(the JSON text, the lengths of the BIN chunks in order) of a .gltf or .glb file, each GLB
    chunk's declared length checked against the file's size."""
    if path.suffix.lower() == ".gltf":
        return path.read_bytes(), []
    with open(path, "rb") as fh:
        head = fh.read(20)
        if len(head) < 20 or head[:4] != b"glTF":
            raise _unreadable(path, "no GLB header (the magic 'glTF', a version, a length and a JSON chunk)")
        json_length, json_type = struct.unpack_from("<II", head, 12)
        if json_type != _GLB_JSON or 20 + json_length > size:
            raise MeshError(
                f"{path}: the GLB's first chunk declares {json_length:,} bytes of JSON, but the file holds "
                f"{size:,} bytes: it is truncated or not a GLB file"
            )
        text = fh.read(json_length)
        chunks, offset, n_chunks = [], 20 + json_length, 0
        while offset + 8 <= size:
            fh.seek(offset)
            length, kind = struct.unpack("<II", fh.read(8))
            if offset + 8 + length > size:
                raise MeshError(
                    f"{path}: a GLB chunk at byte {offset:,} declares {length:,} bytes, past the file's "
                    f"end at {size:,}: it is truncated or its header is wrong"
                )
            if kind == _GLB_BIN:
                chunks.append(length)
            offset += 8 + length
            n_chunks += 1
            if n_chunks > _MAX_GLB_CHUNKS:
                raise _unreadable(
                    path, f"the GLB holds more than {_MAX_GLB_CHUNKS} chunks (a JSON and a binary one expected)"
                )
    return text, chunks


def _gltf_external(path: Path, uri: str) -> Path:
    """The file a relative buffer URI names, as trimesh's resolver finds it (inside the glTF's folder)."""
    folder = path.parent
    for candidate in (uri.strip(), uri.strip().lstrip("/"), Path(uri).name):
        target = (folder / candidate.strip()).resolve()
        if target.is_relative_to(folder) and target.exists():
            return target
    raise _unreadable(path, f"its buffer file {uri[:80]!r} is not in {folder}")


def _nat(value, path: Path, what: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise _unreadable(path, f"{what} must be a whole number ≥ 0, got {str(value)[:40]!r}")
    return value


def _items(tree: dict, key: str, path: Path, limit: int, limits: _Limits) -> list:
    items = tree.get(key, [])
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise _unreadable(path, f"the glTF's {key!r} is not a list of objects")
    if len(items) > limit:
        raise limits.refuse(str(path), f"the glTF holds {len(items):,} {key}")
    return items


def _check_gltf(path: Path, limits: _Limits, size: int) -> None:
    """A glTF's buffers (a .gltf's files counted towards the bytes), buffer views and accessors, which
    must fit in one another; then the triangles and vertices of every mesh read, and of every mesh
    placed by a node of the scene trimesh shows (a mesh placed twice counted twice)."""
    text, chunks = _gltf_json(path, size)
    n_values = sum(text.count(c) for c in b",:[{") + 1  # a base64 data URI holds none of these
    if n_values > limits.json_values:
        raise limits.refuse(
            str(path),
            f"the glTF's JSON holds {n_values:,} values (counted by its commas, colons "
            f"and brackets), more than {limits.json_values:,}",
        )
    try:
        tree = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise _unreadable(path, f"its JSON does not parse ({str(exc)[:80]})") from None
    if not isinstance(tree, dict):
        raise _unreadable(path, "its JSON is not an object")
    buffers = _items(tree, "buffers", path, limits.faces, limits)
    views = _items(tree, "bufferViews", path, limits.faces, limits)
    accessors = _items(tree, "accessors", path, limits.faces, limits)
    meshes = _items(tree, "meshes", path, limits.parts, limits)
    nodes = _items(tree, "nodes", path, limits.parts, limits)

    held = _gltf_buffers(path, limits, buffers, chunks, size)
    view_bytes = _gltf_views(path, views, held)
    counts = _gltf_accessors(path, limits, accessors, views, view_bytes)
    mesh_size = _gltf_mesh_sizes(path, limits, meshes, counts)
    read = [sum(t for t, _ in mesh_size), sum(v for _, v in mesh_size)]
    placed = _gltf_placed(path, limits, tree, nodes, mesh_size)
    for (triangles, vertices), how in ((read, "its meshes hold"), (placed, "its scene places at least")):
        if triangles > limits.faces or vertices > limits.vertices:
            raise limits.refuse(str(path), f"{how} {triangles:,} triangles and {vertices:,} vertices")


def _gltf_buffers(path: Path, limits: _Limits, buffers: list, chunks: list, size: int) -> list[int]:
    """The bytes each buffer holds; a .gltf's buffer files counted towards the file's bytes."""
    held, total = [], size
    for b, buffer in enumerate(buffers):  # trimesh reads a buffer's uri if it has one, else the next BIN chunk
        uri = buffer.get("uri")
        if uri is None:
            held.append(chunks.pop(0) if chunks else 0)
        elif not isinstance(uri, str):
            raise _unreadable(path, f"buffer {b}'s uri is not a string")
        elif "base64," in uri:
            held.append(len(uri) * 3 // 4)
        else:
            external = _gltf_external(path, uri)
            total += _file_size(external, limits, f"its buffer file {external}")
            held.append(external.stat().st_size)
            if total > limits.bytes:
                raise limits.refuse(
                    str(path), f"the file and its buffer files hold {total:,} bytes ({total / 2**20:,.1f} MB)"
                )

    return held


def _gltf_views(path: Path, views: list, held: list[int]) -> list[int]:
    """Each buffer view's length, once it is checked to end inside its buffer."""
    view_bytes = []
    for v, view in enumerate(views):
        b = _nat(view.get("buffer"), path, f"buffer view {v}'s buffer")
        length = _nat(view.get("byteLength"), path, f"buffer view {v}'s byteLength")
        end = _nat(view.get("byteOffset", 0), path, f"buffer view {v}'s byteOffset") + length
        if b >= len(held) or end > held[b]:
            raise MeshError(
                f"{path}: the glTF's buffer view {v} ends at byte {end:,} of buffer {b}, which holds "
                f"{held[b] if b < len(held) else 0:,} bytes: the file is truncated or its JSON is wrong"
            )
        view_bytes.append(length)

    return view_bytes


def _gltf_accessors(path: Path, limits: _Limits, accessors: list, views: list, view_bytes: list[int]) -> list[int]:
    """Each accessor's count, once its items are checked to fit in its buffer view (or, without one,
    counted as the zeros trimesh would make)."""
    counts, placeholders = [], 0
    for a, accessor in enumerate(accessors):
        count = _nat(accessor.get("count"), path, f"accessor {a}'s count")
        item = _GLTF_COMPONENT_BYTES.get(accessor.get("componentType"), 0) * _GLTF_TYPE_SIZE.get(
            accessor.get("type"), 0
        )
        if not item:
            raise _unreadable(path, f"accessor {a} has no known componentType and type")
        if "bufferView" not in accessor:  # trimesh fills it with zeros; one with data is a view of its buffer
            placeholders += count
            if placeholders > limits.vertices:
                raise limits.refuse(str(path), f"the glTF's accessors without data declare {placeholders:,} items")
        elif count:
            v = _nat(accessor["bufferView"], path, f"accessor {a}'s bufferView")
            if v >= len(views):
                raise _unreadable(path, f"accessor {a} names buffer view {v}, which does not exist")
            stride = _nat(views[v].get("byteStride", item), path, f"buffer view {v}'s byteStride")
            if stride < item:  # overlapping items: trimesh's copy would outgrow the buffer
                raise _unreadable(
                    path, f"buffer view {v}'s byteStride {stride} is shorter than accessor {a}'s items ({item} bytes)"
                )
            need = _nat(accessor.get("byteOffset", 0), path, f"accessor {a}'s byteOffset") + (count - 1) * stride + item
            if need > view_bytes[v]:
                raise MeshError(
                    f"{path}: the glTF's accessor {a} declares {count:,} items, which take {need:,} bytes, "
                    f"but its buffer view {v} holds {view_bytes[v]:,}: the file is truncated or its JSON is wrong"
                )
        counts.append(count)

    return counts


def _gltf_mesh_sizes(path: Path, limits: _Limits, meshes: list, counts: list[int]) -> list[tuple[int, int]]:
    """(triangles, vertices) of each mesh, from its primitives' accessors."""

    def count_of(index, what: str) -> int:
        if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < len(counts):
            raise _unreadable(path, f"{what} names no accessor")
        return counts[index]

    mesh_size, n_primitives = [], 0  # (triangles, vertices) of each mesh
    for m, mesh in enumerate(meshes):
        primitives = mesh.get("primitives", [])
        n_primitives += len(primitives) if isinstance(primitives, list) else 0
        if n_primitives > limits.parts:
            raise limits.refuse(str(path), f"the glTF's meshes hold more than {limits.parts:,} primitives")
        triangles = vertices = 0
        for p, primitive in enumerate(primitives):
            if not isinstance(primitive, dict) or not isinstance(primitive.get("attributes"), dict):
                raise _unreadable(path, f"mesh {m}'s primitive {p} has no attributes")
            n_vertices = count_of(primitive["attributes"].get("POSITION"), f"mesh {m}'s primitive {p}'s POSITION")
            n_corners = (
                count_of(primitive["indices"], f"mesh {m}'s primitive {p}'s indices")
                if "indices" in primitive
                else n_vertices
            )
            mode = primitive.get("mode", 4)
            triangles += n_corners // 3 if mode == 4 else max(n_corners - 2, 0) if mode == 5 else 0
            vertices += n_vertices
        mesh_size.append((triangles, vertices))
    return mesh_size


def _gltf_placed(path: Path, limits: _Limits, tree: dict, nodes: list, mesh_size: list) -> list[int]:
    """[triangles, vertices] that the chosen scene places (each mesh once per link that reaches it), the
    walk stopped once beyond the limits."""
    # trimesh walks the nodes from the chosen scene's roots, each (parent, child) link once, and places
    # a mesh at each link (a node reached twice makes a DAG, not the tree the format asks for)
    scenes = tree.get("scenes") if isinstance(tree.get("scenes"), list) else []
    chosen = tree.get("scene", 0)
    scene = scenes[chosen] if isinstance(chosen, int) and 0 <= chosen < len(scenes) else {}
    roots = scene.get("nodes", []) if isinstance(scene, dict) else []
    roots = roots if isinstance(roots, list) else []
    children = [n.get("children", []) if isinstance(n.get("children", []), list) else [] for n in nodes]
    n_links = len(roots) + sum(map(len, children))
    if n_links > limits.parts:
        raise limits.refuse(str(path), f"the glTF's scene links {n_links:,} nodes")
    placed = [0, 0]
    stack, seen = [(None, r) for r in roots], set()
    while stack and placed[0] <= limits.faces and placed[1] <= limits.vertices:
        link = stack.pop()
        if link in seen:
            continue
        seen.add(link)
        n = link[1]
        if isinstance(n, bool) or not isinstance(n, int) or not 0 <= n < len(nodes):
            raise _unreadable(path, f"the scene names node {str(n)[:20]}, which does not exist")
        if "mesh" in nodes[n]:
            m = nodes[n]["mesh"]
            if isinstance(m, bool) or not isinstance(m, int) or not 0 <= m < len(mesh_size):
                raise _unreadable(path, f"node {n} names mesh {str(m)[:20]}, which does not exist")
            placed[0] += mesh_size[m][0]
            placed[1] += mesh_size[m][1]
        stack.extend((n, c) for c in children[n])
    return placed


def _check_limits(path: Path, suffix: str, limits: _Limits) -> None:
    """Refuse a mesh file beyond ``limits`` (or whose header lies) before trimesh reads it."""
    size = _file_size(path, limits)
    if suffix == ".obj":
        _check_obj(path, limits)
    elif suffix == ".stl":
        _check_stl(path, limits, size)
    elif suffix == ".ply":
        _check_ply(path, limits, size)
    else:
        _check_gltf(path, limits, size)


def read_mesh(path: str | Path, angle_deg: float = 30.0, *, max_faces: int = MAX_MESH_FACES) -> BRep:
    """Read a mesh file into a feature-edge ``BRep`` (object frame = the file's frame, metres).

    Parameters
    ----------
    path : an ``.obj``, ``.stl``, ``.ply``, ``.gltf`` or ``.glb`` file.
    angle_deg : dihedral angle from which an edge between two triangles is drawn.
    max_faces : the most triangles the file may hold; it also sets the vertex limit (3 per triangle)
        and the byte limit (64 MB per 200,000 triangles, never less than 64 MB).
    """
    import trimesh

    if isinstance(max_faces, bool) or not isinstance(max_faces, (int, np.integer)) or max_faces < 1:
        raise ValueError(f"max_faces must be a whole number ≥ 1, got {max_faces!r}")
    limits = _Limits(int(max_faces))
    path = resolve_file(Path(path), MeshError)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unknown mesh type {suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.is_file():
        raise MeshError(f"{path}: no such file")
    _check_limits(path, suffix, limits)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False, skip_materials=True)
    except Exception as exc:  # trimesh raises many types for bad files
        raise MeshError(f"{path}: cannot read the mesh: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: the file holds no triangles")
    if len(mesh.faces) > limits.faces or len(mesh.vertices) > limits.vertices:  # the checks above bound trimesh's
        raise limits.refuse(
            str(path), f"trimesh read {len(mesh.faces):,} triangles and {len(mesh.vertices):,} vertices"
        )
    V = np.asarray(mesh.vertices, dtype=float)
    if not np.all(np.isfinite(V)):
        raise MeshError(f"{path}: the mesh has non-finite vertex coordinates")
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    try:
        model = brep_from_mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), angle_deg=angle_deg)
    except ValueError as exc:
        raise MeshError(f"{path}: {exc}") from None
    if not len(model.edges) and not len(model.polyhedron.smooth_sides()):
        warnings.warn(
            MeshWarning(
                f"{path}: this mesh gives nothing to draw on the overlay (no sharp edge and no curved surface with an "
                "outline, e.g. each triangle given twice); export the "
                "object again from its CAD program as a closed surface"
            ),
            stacklevel=2,
        )
    return model


def write_mesh(model: BRep, path: str | Path, n_circle: int = 48) -> None:
    """Write a model's surface (triangles, object frame, metres) as OBJ, STL, PLY, glTF or GLB."""
    import trimesh
    from trimesh.exchange.gltf import export_gltf

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"{path}: unknown mesh type {suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    V, T = model.triangles(n_circle)
    if len(T) == 0:
        raise ValueError(f"{path}: the model has no surface to export (edges or circles only); export it as .cao")
    mesh = trimesh.Trimesh(V, T, process=False)
    if suffix == ".gltf":
        files = export_gltf(trimesh.Scene(mesh), embed_buffers=True)
        ((name, data),) = files.items()
        path.write_bytes(data)
    else:
        mesh.export(str(path))
