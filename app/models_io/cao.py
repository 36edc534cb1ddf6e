"""ViSP ``.cao`` CAD models: read into a ``BRep``, write a ``BRep`` back.

The format (ViSP's ``vpMbTracker::loadCAOModel``), plain text, ``#`` starts a comment::

    V1                                  # or V2: points carry two extra integers (ignored)
    load("other.cao", t=[0.1; 0; 0], tu=[0; 0; 90deg])   # optional includes, any number
    N                                   # points, then N lines "X Y Z" (metres)
    L                                   # lines, then L lines "i j"
    FL                                  # faces from lines, "n l1 ... ln"
    FP                                  # faces from points, "n p1 ... pn" (CCW seen from outside)
    C                                   # cylinders, "i j radius" (axis between points i and j)
    K                                   # circles, "radius centre p1 p2" (p1, p2 span its plane)

Each record is one line; what follows its numbers is a comment, except ``name=…``,
``useLod=…``, ``minLineLengthThreshold=…`` and ``minPolygonAreaThreshold=…`` (ViSP's options),
which are checked and kept by record: ``read_cao_options`` returns them with the model
(``CaoOptions``) and ``write_cao(..., options=)`` writes them back (mcit itself draws every edge).
The cylinder and circle blocks may be absent (old files).
``load(path, t=[x; y; z], tu=[θux; θuy; θuz])`` includes a model whose points map into this file's
frame by ``X = R(θu) X_included + t`` (θu in radians, or with a ``deg``/``rad`` suffix); a
relative path is relative to the including file. ViSP ≥ 3.7 also takes ``R=[r11; r12; …; r33]``
(the rotation row by row) instead of ``tu``: accepted within 1e-3 of a rotation and made exact
(nearest rotation), so that a matrix written with four digits neither shears nor scales the model.
A file may hold only ``load()`` lines (ViSP ≥ 3.7).

Reading into a ``BRep``: the vertices are the points that lines and faces use (points that only
define a cylinder's axis or a circle are not vertices); the edges are every face's sides and
every line, each once; faces from lines are chained into vertex loops. Bad input raises
``CaoError`` naming the file, the line and the problem. A circle whose centre and two points are
on one line has no plane: ViSP parses it, mcit leaves it out with a ``CaoWarning`` naming its line
and loads the rest (a face without area, by contrast, is refused: see the limits).

``read_init`` reads a ViSP ``.init`` file (the model points a user clicks: a count, then ``X Y Z``
per line), with the same ``load()`` lines first (ViSP ≥ 3.7) and the same limits; ``read_init_pixels``
also the points' pixels when the file gives them after the points, as ViSP's ``initFromPoints`` reads
them (a count, then ``i j``: the row, then the column, of each point).

Limits, so that a careless or hostile file is refused at once, never hangs the reader or
exhausts memory, and so that whatever loads can also be exported and read back:

* includes nest at most 8 levels deep (``MAX_INCLUDE_DEPTH``); one model reads at most 256 files
  (``MAX_FILES``; every include counts, a file included twice counts twice) and 64 MB of text in
  all (``MAX_TOTAL_BYTES``, repeats counted too, so the model itself stays bounded); a cyclic
  include is refused. A file that includes the next one twice, 16 levels deep, is refused after
  reading 9 files.
* every count (points, lines, faces, a face's points, cylinders, circles) is checked against the
  lines or numbers left in the file before anything is allocated.
* one model holds at most what a mesh file may (``MAX_COUNTS``, from ``mesh.MAX_MESH_FACES``): 600,000
  points, 600,000 lines, 200,000 faces, 600,000 points or lines in all the faces' lists, 200,000
  cylinders and 200,000 circles, every file read counted (includes and repeats too), each count
  checked when it is read, before its records are.
* coordinates, radii and include translations are finite and within ±1e6 m (``MAX_COORD_M``,
  1000 km; a model placed by its includes too, and a circle's rim and a cylinder's side, so that
  what is read is written back readable); a line's ends, two points of a face or a
  cylinder's axis ends closer than 1 nm (``MIN_LENGTH_M``) are refused as coincident; a face
  whose area is below 1e-9 of its size squared (its points on one line, or folded over itself)
  is refused.

Error messages say ``file:line`` and what was expected; they never quote the file's text (the
named file may not be a model at all, e.g. a system file named in a ``load()``).

Writing: every face becomes a face from points, the edges that are no face's side become lines,
cylinders and circles get their defining points appended. A cone (two radii) has no ``.cao``
form: writing one raises ``ValueError``. A mesh's curved region (triangles whose sides are not
edges, drawn by its silhouette: ``core.silhouette``) is written as its triangles, so the surface
reads back, in mcit and in ViSP, with the same vertices and faces; but a ``.cao`` face's sides are
always edges (the format cannot say that a side is smooth), so the read-back model draws every
triangle of the curved region: keep the mesh file (OBJ, glTF) for the silhouettes.
"""

from __future__ import annotations

import re
import stat
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO

import numpy as np
from scipy.spatial import cKDTree

from app.models_io.files import resolve_file
from app.models_io.mesh import MAX_MESH_FACES
from app.names import NAME_RULE, check_object_name
from core.brep import BRep, Circle, Revolution
from core.transforms import exp_so3, make_T

__all__ = [
    "CaoError",
    "CaoWarning",
    "CaoOptions",
    "read_cao",
    "read_cao_options",
    "read_init",
    "read_init_pixels",
    "write_cao",
    "cao_text",
    "concat_breps",
    "MAX_INCLUDE_DEPTH",
    "MAX_FILES",
    "MAX_TOTAL_BYTES",
    "MAX_COORD_M",
    "MIN_LENGTH_M",
]

_PARAM = re.compile(r"(name|useLod|minLineLengthThreshold|minPolygonAreaThreshold)=(\"[^\"]*\"|\S+)")
# what one model may hold (every file read, includes and repeats counted), as a mesh file may (mesh.py):
# a .cao of 999,996 faces took 10 min and 854 MB to read, one face of 10^6 points 3 min and 1.2 GB
MAX_COUNTS = {
    "points": 3 * MAX_MESH_FACES,  # 600,000: a mesh's vertex limit
    "lines": 3 * MAX_MESH_FACES,  # 600,000: every side of every triangle once
    "faces": MAX_MESH_FACES,  # 200,000, from lines and from points together
    "face indices": 3 * MAX_MESH_FACES,  # 600,000 points or lines in all the faces' lists
    "cylinders": MAX_MESH_FACES,
    "circles": MAX_MESH_FACES,
}
_SHORT_LINE = 2**16  # a face line this short is split to say how few numbers it holds
MAX_INCLUDE_DEPTH = 8  # levels of load() below the file named
MAX_FILES = 256  # files read for one model, every include counted (repeats too)
MAX_TOTAL_BYTES = 64 * 1024 * 1024  # text read for one model, repeats counted
MAX_COORD_M = 1e6  # |coordinate|, radius, include translation (metres)
MIN_LENGTH_M = 1e-9  # points closer than this are the same point
_MIN_AREA_RATIO = 1e-9  # a face's area / its size² below this has no area
_ROTATION_TOL = 1e-3  # R=[...]: largest |RᵀR − I| accepted (then made exactly a rotation)
_MIN_SINE = 1e-6  # a circle's two points seen from its centre at less than this sine: no plane


class CaoError(ValueError):
    """A malformed ``.cao`` file; the message is ``file:line: problem``."""


class CaoWarning(UserWarning):
    """Something in a ``.cao`` file that ViSP accepts but mcit cannot use; the model still loads."""


@dataclass(frozen=True)
class CaoOptions:
    """ViSP's per-record options (``name=… useLod=… minLineLengthThreshold=… minPolygonAreaThreshold=…``).

    Each value is the options' text as read (``"name=door useLod=true"``), keyed by the record of the
    ``BRep`` it belongs to: ``edges`` by sorted vertex pair, ``faces``, ``cylinders`` (``solids``) and
    ``circles`` by index. ``read_cao_options`` returns them; ``cao_text``/``write_cao`` write them back.
    """

    edges: dict = field(default_factory=dict)
    faces: dict = field(default_factory=dict)
    cylinders: dict = field(default_factory=dict)
    circles: dict = field(default_factory=dict)

    def to_json(self) -> dict:
        """JSON-ready (an edge's key "a-b"), for the database's history of an import."""
        return {
            "edges": {f"{a}-{b}": v for (a, b), v in self.edges.items()},
            "faces": {str(k): v for k, v in self.faces.items()},
            "cylinders": {str(k): v for k, v in self.cylinders.items()},
            "circles": {str(k): v for k, v in self.circles.items()},
        }

    @staticmethod
    def from_json(d: dict) -> CaoOptions:
        """Inverse of ``to_json``; ValueError on a malformed description."""
        try:
            edges = {tuple(int(i) for i in k.split("-")): str(v) for k, v in d.get("edges", {}).items()}
            return CaoOptions(
                edges,
                *({int(k): str(v) for k, v in d.get(part, {}).items()} for part in ("faces", "cylinders", "circles")),
            )
        except (AttributeError, TypeError, ValueError) as exc:
            raise ValueError(f"malformed .cao options: {exc}") from None

    def __bool__(self) -> bool:
        return bool(self.edges or self.faces or self.cylinders or self.circles)

    @staticmethod
    def concat(models: list[BRep], options: list[CaoOptions]) -> CaoOptions:
        """The options of ``concat_breps(models)``: each model's keys shifted like its records."""
        out = CaoOptions()
        nv = nf = ns = nc = 0
        for m, o in zip(models, options):
            out.edges.update({(a + nv, b + nv): v for (a, b), v in o.edges.items()})
            out.faces.update({k + nf: v for k, v in o.faces.items()})
            out.cylinders.update({k + ns: v for k, v in o.cylinders.items()})
            out.circles.update({k + nc: v for k, v in o.circles.items()})
            nv, nf, ns, nc = nv + len(m.vertices), nf + len(m.faces), ns + len(m.solids), nc + len(m.circles)
        return out


def _limits() -> str:
    return (
        f"mcit reads at most {MAX_INCLUDE_DEPTH} levels of includes, {MAX_FILES} files (every include counts) "
        f"and {MAX_TOTAL_BYTES / 2**20:g} MB in all for one model"
    )


def _resolved(path: Path, where: str | None = None) -> Path:
    """``path`` absolute, its symbolic links followed; CaoError for a loop of them (``resolve_file``)."""
    return resolve_file(path, CaoError, where)


class _Lines:
    """The file's meaningful lines with their numbers (comments and blank lines dropped)."""

    def __init__(self, path: Path, text: str):
        self.path = path
        self.items: list[tuple[int, str]] = []
        number = 0
        for number, raw in enumerate(text.splitlines(), start=1):
            line = raw.split("#", 1)[0].strip()
            if line:
                self.items.append((number, line))
        self.pos = 0
        self.last_line = number

    def error(self, number: int, problem: str) -> CaoError:
        return CaoError(f"{self.path}:{number}: {problem}")

    def peek(self) -> tuple[int, str] | None:
        return self.items[self.pos] if self.pos < len(self.items) else None

    def left(self) -> int:
        """How many meaningful lines are still to be read."""
        return len(self.items) - self.pos

    def next(self, what: str) -> tuple[int, str]:
        item = self.peek()
        if item is None:
            raise CaoError(f"{self.path}:{self.last_line}: the file ends where {what} was expected")
        self.pos += 1
        return item


def _numbers(lines: _Lines, number: int, line: str, count: int, kinds: str, what: str) -> tuple[list, str]:
    """The first ``count`` whitespace tokens as numbers and the rest of the line.

    kinds: 'i' (int) or 'f' (float, finite) per token; the last kind repeats for the tokens beyond.
    The number of tokens is checked before anything is converted or allocated.
    """
    tokens = line.split(None, count)
    if len(tokens) < count:
        raise lines.error(number, f"{what}: expected {count} numbers, got {len(tokens)}")
    out = []
    for k, tok in enumerate(tokens[:count]):
        kind = kinds[min(k, len(kinds) - 1)]
        try:
            v = int(tok) if kind == "i" else float(tok)
        except ValueError:
            expected = "an integer" if kind == "i" else "a number"
            raise lines.error(number, f"{what}: value {k + 1} is not {expected}") from None
        if kind == "f" and not np.isfinite(v):
            raise lines.error(number, f"{what}: value {k + 1} is not finite")
        out.append(v)
    rest = tokens[count] if len(tokens) > count else ""
    return out, rest


def _check_params(lines: _Lines, number: int, rest: str) -> str:
    """The record's ViSP options (``name=… useLod=… min…Threshold=…``), checked, as ``key=value`` words."""
    found = _PARAM.findall(rest)
    for key, raw in found:
        value = raw.strip('"')
        if key == "name":
            try:
                check_object_name(value)
            except ValueError:  # the value is not quoted: the file may not be a model at all
                raise lines.error(number, f"name= must be {NAME_RULE}") from None
        if key == "useLod" and value.lower() not in ("true", "false", "1", "0"):
            raise lines.error(number, "useLod= must be true, false, 1 or 0")
        if key.startswith("min"):
            try:
                float(value)
            except ValueError:
                raise lines.error(number, f"{key}= must be a number") from None
    return " ".join(f"{key}={raw}" for key, raw in found)


def _count(lines: _Lines, what: str, reading: _Reading, kind: str | None = None) -> int:
    """A block's count, refused before anything is allocated when the file cannot hold that many records
    or when the model would hold more than ``MAX_COUNTS[kind]`` (``what`` when not given)."""
    number, line = lines.next(f"the number of {what}")
    (n,), _ = _numbers(lines, number, line, 1, "i", f"number of {what}")
    if n < 0:
        raise lines.error(number, f"the number of {what} is negative")
    if n > lines.left():
        raise lines.error(
            number, f"the number of {what} is more than the {lines.left()} lines left in the file (one line each)"
        )
    reading.add(lines, number, kind or what, n, what)
    return n


def _over_limit(lines: _Lines, number: int, kind: str, total: int, what: str) -> CaoError:
    return lines.error(
        number,
        f"the {what} make the model hold {total:,} {kind}, more than {MAX_COUNTS[kind]:,}, mcit's limit for one "
        f"model (as for a mesh file, includes counted); simplify the model in its CAD program",
    )


def _index(lines: _Lines, number: int, i: int, n: int, what: str) -> int:
    if not 0 <= i < n:
        raise lines.error(number, f"{what} index {i} out of range 0..{n - 1}")
    return i


def _within(lines: _Lines, number: int, values, what: str) -> None:
    if not np.all(np.abs(np.asarray(values, dtype=float)) <= MAX_COORD_M):
        raise lines.error(number, f"{what} is beyond ±{MAX_COORD_M:g} m (coordinates are metres)")


def _parse_vector(lines: _Lines, number: int, text: str, key: str, angles: bool) -> np.ndarray:
    parts = [p.strip() for p in text.split(";")]
    if len(parts) != 3:
        raise lines.error(number, f"load(): {key}=[...] needs 3 values separated by ';', got {len(parts)}")
    out = []
    for k, p in enumerate(parts):
        scale = 1.0
        if angles and p.endswith("deg"):
            p, scale = p[:-3], np.pi / 180.0
        elif angles and p.endswith("rad"):
            p = p[:-3]
        try:
            v = float(p) * scale
        except ValueError:
            raise lines.error(number, f"load(): value {k + 1} of {key}=[...] is not a number") from None
        if not np.isfinite(v) or abs(v) > MAX_COORD_M:
            raise lines.error(number, f"load(): value {k + 1} of {key}=[...] is not finite or beyond ±{MAX_COORD_M:g}")
        out.append(v)
    return np.array(out)


def _parse_rotation(lines: _Lines, number: int, text: str) -> np.ndarray:
    """R=[r11; r12; r13; r21; …; r33] (row by row, ViSP ≥ 3.7) → the nearest rotation, refused when far from one."""
    parts = [p.strip() for p in text.split(";")]
    if len(parts) != 9:
        raise lines.error(number, f"load(): R=[...] needs 9 values separated by ';' (row by row), got {len(parts)}")
    try:
        R = np.array([float(p) for p in parts]).reshape(3, 3)
    except ValueError:
        raise lines.error(number, "load(): a value of R=[...] is not a number") from None
    if not np.all(np.isfinite(R)) or np.abs(R.T @ R - np.eye(3)).max() > _ROTATION_TOL or np.linalg.det(R) <= 0:
        raise lines.error(
            number, f"load(): R=[...] is not a rotation (orthonormal rows, determinant +1, to {_ROTATION_TOL:g})"
        )
    U, _, Vt = np.linalg.svd(R)
    return U @ Vt


def _parse_load(lines: _Lines, number: int, line: str) -> tuple[Path, np.ndarray]:
    """``load("file", t=[x; y; z], tu=[a; b; c] or R=[9 values])`` → the included file and T_this_included."""
    m = re.fullmatch(r'load\s*\(\s*"([^"]+)"\s*((?:,[^)]*)?)\).*', line)
    if not m:
        raise lines.error(
            number,
            'malformed include; expected load("file.cao", t=[x; y; z], tu=[a; b; c]) or R=[9 values] instead of tu',
        )
    target = Path(m.group(1))
    if not target.is_absolute():
        target = lines.path.parent / target
    t = np.zeros(3)
    R = None
    seen = set()
    for param in (p.strip() for p in m.group(2).split(",")[1:]):
        pm = re.fullmatch(r"(t|tu|R)\s*=\s*\[([^\]]*)\]", param)
        if not pm:
            raise lines.error(number, "load(): unknown parameter; use t=[x; y; z] and tu=[a; b; c] or R=[9 values]")
        key = pm.group(1)
        if key in seen or (key != "t" and ({"tu", "R"} & seen)):
            raise lines.error(number, "load(): give t= once and one rotation, tu= or R=")
        seen.add(key)
        if key == "t":
            t = _parse_vector(lines, number, pm.group(2), "t", angles=False)
        elif key == "tu":
            R = exp_so3(_parse_vector(lines, number, pm.group(2), "tu", angles=True))
        else:
            R = _parse_rotation(lines, number, pm.group(2))
    return _resolved(target, f"{lines.path}:{number}"), make_T(np.eye(3) if R is None else R, t)


def _chain(lines: _Lines, number: int, segments: list[tuple[int, int]]) -> list[int]:
    """Vertex loop from a face's lines, in the given order; CaoError when they do not close."""
    if len(segments) < 3:
        raise lines.error(number, f"a face needs at least 3 lines, got {len(segments)}")
    a, b = segments[0]
    c, d = segments[1]
    loop = [b, a] if a in (c, d) and b not in (c, d) else [a, b]
    for k, (c, d) in enumerate(segments[1:], start=2):
        if c == loop[-1]:
            loop.append(d)
        elif d == loop[-1]:
            loop.append(c)
        else:
            raise lines.error(
                number,
                f"line {k} of the face does not continue from point {loop[-1]}: the face's lines must form a loop",
            )
    if loop[-1] != loop[0]:
        raise lines.error(number, f"the face's lines do not close: they end at point {loop[-1]}, not {loop[0]}")
    loop.pop()
    if len(set(loop)) != len(loop):
        raise lines.error(number, "the face's lines visit a point twice")
    return loop


def _check_face(lines: _Lines, number: int, k: int, P: np.ndarray, loop: list[int]) -> None:
    """Refuse a face with two points at the same place or without area (collinear, or folded flat)."""
    Q = P[loop] - P[loop].mean(axis=0)
    pairs = cKDTree(Q).query_pairs(MIN_LENGTH_M)
    if pairs:
        a, b = min(pairs)
        raise lines.error(number, f"face {k}: its points {loop[a]} and {loop[b]} are at the same place")
    twice_area = np.linalg.norm(np.cross(Q, np.roll(Q, -1, axis=0)).sum(axis=0))
    size = np.linalg.norm(np.ptp(Q, axis=0))
    if twice_area <= 2 * _MIN_AREA_RATIO * size**2:
        raise lines.error(number, f"face {k} has no area: its points are on one line, or it folds over itself")


def concat_breps(models: list[BRep]) -> BRep:
    """One model holding several (vertex indices shifted); they share one frame."""
    Vs, Es, Fs, solids, circles = [], [], [], [], []
    offset = 0
    for m in models:
        Vs.append(m.vertices)
        Es.append(m.edges + offset)
        Fs += [tuple(v + offset for v in f) for f in m.faces]
        solids += list(m.solids)
        circles += list(m.circles)
        offset += len(m.vertices)
    return BRep(np.vstack(Vs).reshape(-1, 3), np.vstack(Es).reshape(-1, 2), tuple(Fs), tuple(solids), tuple(circles))


def _reach_m(model: BRep) -> float:
    """The largest |coordinate| the reader checks in a model's written form: its points, and each
    cylinder's axis ends and circle's centre plus their radius (``_within`` at each record)."""
    values = [0.0]
    for rec in (p.cao_part() for p in model.parts):
        P = np.abs(np.asarray(rec.points, dtype=float).reshape(-1, 3)).max(axis=1)
        values += P.tolist()
        values += [max(P[i], P[j]) + r for i, j, r in rec.cylinders]
        values += [P[c] + r for r, c, _, _ in rec.circles]
    return float(max(values))


class _Reading:
    """What one ``read_cao`` has read so far: files and bytes (includes counted, repeats too), files parsed.

    A file included again is not parsed again, but it counts again with everything it includes,
    so that the limits bound the model that is built, not only the reading.
    """

    def __init__(self, parse=None, what: str = "a .cao model"):
        self.files = 0
        self.bytes = 0
        self.parsed: dict[Path, tuple[BRep | None, int, int, dict]] = {}  # model, files, bytes, counts
        self.parse = parse or _parse  # (path, text, stack, reading) → the file's content
        self.options: dict[Path, CaoOptions] = {}  # each parsed file's ViSP options, by record of its model
        self.what = what
        self.counts = dict.fromkeys(MAX_COUNTS, 0)  # what the model holds so far, includes and repeats counted
        self.image_points: dict[Path, np.ndarray] = {}  # an .init's pixels (ViSP's initFromPoints), by file

    def add(self, lines: _Lines, number: int, kind: str, n: int, what: str) -> None:
        """Count ``n`` more ``kind`` in the model, refused beyond ``MAX_COUNTS`` (before they are read)."""
        self.counts[kind] += n
        if self.counts[kind] > MAX_COUNTS[kind]:
            raise _over_limit(lines, number, kind, self.counts[kind], what)

    def read(self, path: Path, where: str, stack: tuple[Path, ...]) -> BRep | None:
        """Parse ``path`` (``where``: the file, or the ``file:line`` of the load() naming it), within the limits."""
        if len(stack) > MAX_INCLUDE_DEPTH + 1:
            raise CaoError(f"{where}: includes are nested more than {MAX_INCLUDE_DEPTH} levels deep; {_limits()}")
        if path in self.parsed:
            model, files, size, counts = self.parsed[path]
            self._add(files, size, where)
            for kind, n in counts.items():  # the file again: what it holds counts again
                self.counts[kind] += n
                if self.counts[kind] > MAX_COUNTS[kind]:
                    raise CaoError(
                        f"{where}: the model holds {self.counts[kind]:,} {kind} with this include, more than "
                        f"{MAX_COUNTS[kind]:,}, mcit's limit for one model (as for a mesh file, includes counted)"
                    )
            return model
        files0, bytes0, counts0 = self.files, self.bytes, dict(self.counts)
        try:
            st = path.stat()
            if not stat.S_ISREG(st.st_mode):
                raise CaoError(f"{where}: {path} is not a regular file")
            self._add(1, st.st_size, where)
            with open(path, "rb") as fh:
                data = fh.read(st.st_size + 1)
        except OSError as exc:
            what = "it" if where == str(path) else str(path)  # the file itself: its name said once
            hint = "; check the path" if isinstance(exc, FileNotFoundError) else ""
            raise CaoError(f"{where}: cannot read {what}: {exc.strerror or type(exc).__name__}{hint}") from None
        if len(data) != st.st_size:
            raise CaoError(f"{where}: {path} changed while it was read; read it again when it is complete")
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise CaoError(f"{path}:1: not {self.what} (not a text file)") from None
        model = self.parse(path, text, stack, self)
        counts = {kind: n - counts0[kind] for kind, n in self.counts.items()}
        self.parsed[path] = (model, self.files - files0, self.bytes - bytes0, counts)
        return model

    def _add(self, files: int, size: int, where: str) -> None:
        self.files += files
        self.bytes += size
        if self.files > MAX_FILES:
            raise CaoError(f"{where}: the model includes more than {MAX_FILES} files; {_limits()}")
        if self.bytes > MAX_TOTAL_BYTES:
            raise CaoError(
                f"{where}: the model's files hold more than {MAX_TOTAL_BYTES / 2**20:g} MB of text; {_limits()}"
            )


def _parse(path: Path, text: str, stack: tuple[Path, ...], reading: _Reading) -> BRep | None:
    lines = _Lines(path, text)
    number, head = lines.next("the version line 'V1'")
    m = re.fullmatch(r"V(\d{1,6})(\s.*)?", head)
    if not m:
        # Not recognised as a .cao: say nothing of what the file holds (it may be any file).
        raise lines.error(number, "not a .cao model: the first line must be the version 'V1' (or V2)")
    version = int(m.group(1))
    if version not in (1, 2):
        raise lines.error(number, f"unsupported .cao version V{version}; mcit reads V1 and V2")
    parts: list[BRep] = []
    part_options: list[CaoOptions] = []
    n_loads = 0
    while (item := lines.peek()) is not None and item[1][:1] in ("l", "L"):
        number, line = lines.next("load(...)")
        n_loads += 1
        target, sub, T = _read_include(lines, number, line, path, stack, reading)
        if sub is not None:
            placed = sub.transformed(T)
            if _reach_m(placed) > MAX_COORD_M:
                raise lines.error(
                    number, f"the included model, placed by its t= and rotation, reaches beyond ±{MAX_COORD_M:g} m"
                )
            parts.append(placed)
            part_options.append(reading.options.get(target, CaoOptions()))
    if lines.peek() is None and n_loads:  # a file of load() lines only (ViSP ≥ 3.7 reads it too)
        reading.options[path] = CaoOptions.concat(parts, part_options)
        return concat_breps(parts) if parts else None
    n_points = _count(lines, "points", reading)
    n_num = 5 if version == 2 else 3
    P = np.zeros((n_points, 3))
    for k in range(n_points):
        number, line = lines.next(f"point {k} of {n_points}")
        values, _ = _numbers(lines, number, line, n_num, "fffii"[:n_num], f"point {k}")
        _within(lines, number, values[:3], f"point {k}")
        P[k] = values[:3]
    n_lines = _count(lines, "lines", reading)
    segs: list[tuple[int, int]] = []
    seg_options: list[str] = []
    loop_options: list[str] = []
    cylinder_options: list[str] = []
    circle_options: list[str] = []
    for k in range(n_lines):
        number, line = lines.next(f"line {k} of {n_lines}")
        (i, j), rest = _numbers(lines, number, line, 2, "ii", f"line {k}")
        i, j = _index(lines, number, i, n_points, "point"), _index(lines, number, j, n_points, "point")
        if i == j:
            raise lines.error(number, f"line {k} joins point {i} to itself")
        if np.linalg.norm(P[i] - P[j]) <= MIN_LENGTH_M:
            raise lines.error(number, f"line {k}: its points {i} and {j} are at the same place")
        seg_options.append(_check_params(lines, number, rest))
        segs.append((i, j))
    loops: list[list[int]] = []
    for what, by_lines in (("faces from lines", True), ("faces from points", False)):
        n_faces = _count(lines, what, reading, "faces")
        for k in range(n_faces):
            number, line = lines.next(f"face {k} of the {what}")
            (n,), _ = _numbers(lines, number, line, 1, "i", f"face {k}")
            if n < 3:
                raise lines.error(
                    number, f"face {k} has {n} {'lines' if by_lines else 'points'}; a face needs at least 3"
                )
            over = reading.counts["face indices"] + n > MAX_COUNTS["face indices"]
            if over and len(line) > _SHORT_LINE:  # refused before its numbers are split
                raise _over_limit(
                    lines,
                    number,
                    "face indices",
                    reading.counts["face indices"] + n,
                    f"{'lines' if by_lines else 'points'} of face {k}",
                )
            values, rest = _numbers(lines, number, line, n + 1, "i", f"face {k}")  # a short line: few numbers
            reading.add(lines, number, "face indices", n, f"{'lines' if by_lines else 'points'} of face {k}")
            options = _check_params(lines, number, rest)
            if by_lines:
                idx = [_index(lines, number, i, n_lines, "line") for i in values[1:]]
                loop = _chain(lines, number, [segs[i] for i in idx])
            else:
                loop = [_index(lines, number, i, n_points, "point") for i in values[1:]]
                if len(set(loop)) != len(loop):
                    raise lines.error(number, f"face {k} lists a point twice")
            _check_face(lines, number, k, P, loop)
            loops.append(loop)
            loop_options.append(options)
    solids: list[Revolution] = []
    circles: list[Circle] = []
    dropped_circles = 0
    if lines.peek() is not None:
        for k in range(_count(lines, "cylinders", reading)):
            number, line = lines.next(f"cylinder {k}")
            (i, j, r), rest = _numbers(lines, number, line, 3, "iif", f"cylinder {k}")
            i, j = _index(lines, number, i, n_points, "point"), _index(lines, number, j, n_points, "point")
            options = _check_params(lines, number, rest)
            if r <= 0:
                raise lines.error(number, f"cylinder {k}: radius must be positive, got {r}")
            _within(lines, number, r, f"cylinder {k}: the radius")
            # its written form (axis ends, rim) must read back: the rim within the limit too
            _within(
                lines,
                number,
                max(np.abs(P[i]).max(), np.abs(P[j]).max()) + r,
                f"cylinder {k}: its side (axis end and radius)",
            )
            if np.linalg.norm(P[i] - P[j]) <= MIN_LENGTH_M:
                raise lines.error(
                    number,
                    f"cylinder {k}: needs two distinct axis endpoints (points {i} and {j} are at the same place)",
                )
            solids.append(Revolution(P[i], P[j], r, r))
            cylinder_options.append(options)
    if lines.peek() is not None:
        for k in range(_count(lines, "circles", reading)):
            number, line = lines.next(f"circle {k}")
            (r, c, i, j), rest = _numbers(lines, number, line, 4, "fiii", f"circle {k}")
            c, i, j = (_index(lines, number, v, n_points, "point") for v in (c, i, j))
            options = _check_params(lines, number, rest)
            _within(lines, number, r, f"circle {k}: the radius")
            if r <= 0:
                raise lines.error(number, f"circle {k}: radius must be positive, got {r}")
            u, v = P[i] - P[c], P[j] - P[c]
            normal = np.cross(u, v)
            if (
                np.linalg.norm(normal) <= _MIN_SINE * np.linalg.norm(u) * np.linalg.norm(v)
                or min(np.linalg.norm(u), np.linalg.norm(v)) <= MIN_LENGTH_M
            ):
                # ViSP parses such a circle; its plane is unknown, so there is nothing true to draw.
                warnings.warn(
                    CaoWarning(
                        f"{path}:{number}: circle {k} is left out: its centre "
                        "and two points are on one line, so its plane is unknown"
                    ),
                    stacklevel=2,
                )
                dropped_circles += 1
                continue
            # its written form (centre and two rim points) must read back: the rim within the limit too
            _within(lines, number, np.abs(P[c]).max() + r, f"circle {k}: its rim (centre and radius)")
            circles.append(Circle(P[c], normal, r))
            circle_options.append(options)
    if (item := lines.peek()) is not None:
        raise lines.error(item[0], "unexpected content after the last block (circles)")
    used = sorted({v for loop in loops for v in loop} | {v for s in segs for v in s})
    if not used and not solids and not circles and not parts and not dropped_circles:
        raise CaoError(f"{path}:{lines.last_line}: the model has no lines, faces, cylinders or circles")
    remap = {old: new for new, old in enumerate(used)}
    edges: dict[tuple[int, int], None] = {}
    for loop in loops:
        for a, b in zip(loop, loop[1:] + loop[:1]):
            edges.setdefault((min(remap[a], remap[b]), max(remap[a], remap[b])), None)
    for a, b in segs:
        edges.setdefault((min(remap[a], remap[b]), max(remap[a], remap[b])), None)
    if used or solids or circles:
        parts.append(
            BRep(
                P[used].reshape(-1, 3),
                np.array(list(edges), dtype=np.int64).reshape(-1, 2),
                tuple(tuple(remap[v] for v in loop) for loop in loops),
                tuple(solids),
                tuple(circles),
            )
        )
        part_options.append(
            CaoOptions(
                {(min(remap[a], remap[b]), max(remap[a], remap[b])): o for (a, b), o in zip(segs, seg_options) if o},
                {k: o for k, o in enumerate(loop_options) if o},
                {k: o for k, o in enumerate(cylinder_options) if o},
                {k: o for k, o in enumerate(circle_options) if o},
            )
        )
    reading.options[path] = CaoOptions.concat(parts, part_options)
    return concat_breps(parts) if parts else None


def read_cao(path: str | Path) -> BRep:
    """Read a ViSP ``.cao`` model (with its ``load(...)`` includes) into a ``BRep`` in its frame.

    Raises
    ------
    CaoError (a ValueError) naming the file, the line and the problem; also for a model beyond
    the limits in the module docstring (includes, counts, coordinates, degenerate geometry).
    """
    return read_cao_options(path)[0]


def read_cao_options(path: str | Path) -> tuple[BRep, CaoOptions]:
    """``read_cao`` and the file's ViSP options (``name=``, LOD), for ``write_cao(..., options=)``."""
    path = _resolved(Path(path))
    reading = _Reading()
    model = reading.read(path, str(path), (path,))
    if model is None:
        raise CaoError(
            f"{path}: the model has nothing mcit can draw (its only circles have no plane, or its includes are empty)"
        )
    return model, reading.options.get(path, CaoOptions())


def _read_include(lines, number: int, line: str, path: Path, stack: tuple[Path, ...], reading):
    """One ``load(...)`` line of a ``.cao`` or ``.init``: (the included file, what reading it gave —
    None when it holds nothing —, its placement T (4, 4)), after the cycle and existence checks;
    CaoError naming path:number otherwise."""
    target, T = _parse_load(lines, number, line)
    if target in stack:
        raise lines.error(number, f"cyclic include: {target} is already being read")
    if not target.exists():
        raise lines.error(number, f"included file not found: {target}")
    return target, reading.read(target, f"{path}:{number}", stack + (target,)), T


def _parse_init(path: Path, text: str, stack: tuple[Path, ...], reading: _Reading) -> np.ndarray | None:
    lines = _Lines(path, text)
    parts: list[np.ndarray] = []
    while (item := lines.peek()) is not None and item[1][:1] in ("l", "L"):
        number, line = lines.next("load(...)")
        _, sub, T = _read_include(lines, number, line, path, stack, reading)
        if sub is not None:
            placed = sub @ T[:3, :3].T + T[:3, 3]
            if np.abs(placed).max() > MAX_COORD_M:
                raise lines.error(
                    number, f"the included points, placed by its t= and rotation, reach beyond ±{MAX_COORD_M:g} m"
                )
            parts.append(placed)
    if lines.peek() is not None:
        n = _count(lines, "points", reading)
        P = np.zeros((n, 3))
        for k in range(n):
            number, line = lines.next(f"point {k} of {n}")
            values, _ = _numbers(lines, number, line, 3, "f", f"point {k}")
            _within(lines, number, values, f"point {k}")
            P[k] = values
        parts.append(P)
        if lines.peek() is not None:  # ViSP's initFromPoints: the points' pixels follow them
            reading.image_points[path] = _image_points(lines, reading, sum(len(p) for p in parts))
    elif not parts:
        raise CaoError(f"{path}:{lines.last_line}: the file ends where the number of points was expected")
    return np.vstack(parts) if parts else None


def _image_points(lines: _Lines, reading: _Reading, n_points: int) -> np.ndarray:
    """The pixels of an .init's points as ViSP's ``initFromPoints`` reads them: a count (the number of
    points), then ``i j`` per line — the row, then the column (v, u) — returned as (N, 2) ``uv``."""
    number = lines.peek()[0]
    n = _count(lines, "image points", reading, kind="points")
    if n != n_points:
        raise lines.error(
            number, f"{n} image points for the file's {n_points} model points; give one pixel (row column) per point"
        )
    uv = np.zeros((n, 2))
    for k in range(n):
        number, line = lines.next(f"image point {k} of {n}")
        (i, j), _ = _numbers(lines, number, line, 2, "f", f"image point {k} (row column)")
        uv[k] = (j, i)
    if lines.peek() is not None:
        raise lines.error(lines.peek()[0], "more lines after the image points; an .init file ends with them")
    return uv


def read_init(path: str | Path) -> np.ndarray:
    """Model points (N, 3), metres, object frame, from a ViSP ``.init`` file (the points a user clicks).

    A count, then ``X Y Z`` per line (``#`` comments), as ViSP has always read it; and, as ViSP ≥ 3.7
    reads it, ``load("other.init", t=[x; y; z], tu=[a; b; c])`` (or ``R=[9 values]``) lines first,
    whose points, placed as in a ``.cao``, come before this file's own; a file may hold only
    ``load()`` lines. The include limits of the module docstring apply. CaoError names file:line.
    """
    return read_init_pixels(path)[0]


def read_init_pixels(path: str | Path) -> tuple[np.ndarray, np.ndarray | None]:
    """(X_obj (N, 3) metres, uv (N, 2) pixels or None) of a ViSP ``.init`` file: its model points
    (``read_init``) and, when the file gives them after the points as ViSP's
    ``vpMbTracker::initFromPoints`` reads them (a count, then ``i j`` — row, column — per point), their
    pixels as ``uv`` (u = j, v = i); None when the file holds the model points only."""
    path = _resolved(Path(path))
    reading = _Reading(_parse_init, "a ViSP .init file")
    P = reading.read(path, str(path), (path,))
    if P is None or len(P) == 0:
        raise CaoError(f"{path}: the file holds no points")
    return P, reading.image_points.get(path)


def _fmt(x: float) -> str:
    return repr(float(x))


def cao_text(model: BRep, comment: str = "", options: CaoOptions | None = None) -> str:
    """The ``.cao`` (V1) text of a model (each primitive's ``cao_part``, in the model's order); see the
    module docstring. ValueError for a primitive the format has no form for (a cone, a sphere).

    options : the ViSP options of the model's records (``read_cao_options``), written after each
    record's numbers. A line's options are written when the edge is written as a line (an edge
    that is a face's side is written by the face, as ViSP draws it once).
    """
    options = options or CaoOptions()

    def tail(text: str | None) -> str:
        return f" {text}" if text else ""

    records = [p.cao_part() for p in model.parts]  # ValueError for a primitive the format has no form for
    points, lines, faces, cylinders, circles = [], [], [], [], []
    for rec in records:
        k = len(points)
        points += [tuple(p) for p in np.asarray(rec.points, dtype=float).reshape(-1, 3).tolist()]
        lines += [(a + k, b + k) for a, b in np.asarray(rec.lines, dtype=np.int64).reshape(-1, 2).tolist()]
        faces += [tuple(v + k for v in f) for f in rec.faces]
        cylinders += [(i + k, j + k, r) for i, j, r in rec.cylinders]
        circles += [(r, c + k, i + k, j + k) for r, c, i, j in rec.circles]
    out = ["V1"]
    if comment:
        out += [f"# {line}" for line in comment.splitlines()]
    out += ["# 3D points", str(len(points))]
    out += [" ".join(_fmt(x) for x in p) for p in points]
    out += ["# 3D lines", str(len(lines))] + [
        f"{a} {b}" + tail(options.edges.get((min(a, b), max(a, b)))) for a, b in lines
    ]
    out += ["# Faces from 3D lines", "0"]
    out += ["# Faces from 3D points", str(len(faces))]
    out += [" ".join(str(v) for v in (len(f),) + tuple(f)) + tail(options.faces.get(k)) for k, f in enumerate(faces)]
    out += ["# 3D cylinders", str(len(cylinders))] + [
        f"{i} {j} {_fmt(r)}" + tail(options.cylinders.get(k)) for k, (i, j, r) in enumerate(cylinders)
    ]
    out += ["# 3D circles", str(len(circles))] + [
        f"{_fmt(r)} {c} {i} {j}" + tail(options.circles.get(k)) for k, (r, c, i, j) in enumerate(circles)
    ]
    return "\n".join(out) + "\n"


def write_cao(model: BRep, path: str | Path | IO[str], comment: str = "", options: CaoOptions | None = None) -> None:
    """Write a model as a ViSP ``.cao`` file (see ``cao_text``)."""
    text = cao_text(model, comment, options)
    if hasattr(path, "write"):
        path.write(text)
    else:
        Path(path).write_text(text)
