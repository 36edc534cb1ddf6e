"""Mesh bombs: OBJ, STL, PLY and glTF/GLB files too big for the interface, or whose headers lie, are
refused in one line naming the file, what it holds, the limit and ``--max-faces``, before trimesh
allocates anything; a file at the limit loads, and ``--max-faces`` raises the limit."""

from __future__ import annotations

import base64
import json
import struct
import time
from pathlib import Path

import numpy as np
import pytest
import trimesh

from app.cli import main
from app.db import Database
from app.models_io import MAX_MESH_BYTES, MAX_MESH_FACES, MeshError, load_model, read_mesh
from app.models_io import mesh as mesh_module
from app.scene import SceneError, load_scene, scenes_dir


def _surface(n_faces: int) -> tuple[np.ndarray, np.ndarray]:
    """A wavy strip of exactly ``n_faces`` triangles, every vertex used: vertices (n_faces + 2, 3)
    metres, faces (n_faces, 3)."""
    k = n_faces // 2 + 2
    x = np.repeat(np.arange(k) * 0.01, 2)
    y = np.tile([0.0, 0.05], k)
    z = 0.01 * np.sin(7.0 * x + 40.0 * y)
    i = np.arange(k - 1) * 2
    F = np.stack([np.c_[i, i + 2, i + 1], np.c_[i + 1, i + 2, i + 3]], axis=1).reshape(-1, 3)
    return np.c_[x, y, z][: n_faces + 2], F[:n_faces]


def _obj(path: Path, V, F) -> Path:
    path.write_text(
        "".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V)
        + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in F)
    )
    return path


def _stl_binary(path: Path, V, F, count: int | None = None) -> Path:
    records = np.zeros(len(F), dtype=[("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    records["corners"] = V[F]
    count = len(F) if count is None else count
    path.write_bytes(b"binary stl".ljust(80, b" ") + struct.pack("<I", count) + records.tobytes())
    return path


def _stl_ascii(path: Path, V, F) -> Path:
    facets = "".join(
        "facet normal 0 0 1\nouter loop\n"
        + "".join(f"vertex {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V[f])
        + "endloop\nendfacet\n"
        for f in F
    )
    path.write_text(f"solid strip\n{facets}endsolid strip\n")
    return path


def _ply(path: Path, V, F, ascii: bool, n_vertices: int | None = None, n_faces: int | None = None) -> Path:
    header = (
        f"ply\nformat {'ascii' if ascii else 'binary_little_endian'} 1.0\ncomment mesh bomb test\n"
        f"element vertex {len(V) if n_vertices is None else n_vertices}\nproperty float x\nproperty float y\n"
        f"property float z\nelement face {len(F) if n_faces is None else n_faces}\n"
        f"property list uchar int vertex_indices\nend_header\n"
    ).encode()
    if ascii:
        data = "".join(f"{x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in V) + "".join(f"3 {a} {b} {c}\n" for a, b, c in F)
        path.write_bytes(header + data.encode())
    else:
        faces = np.zeros(len(F), dtype=[("n", "u1"), ("i", "<i4", 3)])
        faces["n"], faces["i"] = 3, F
        path.write_bytes(header + V.astype("<f4").tobytes() + faces.tobytes())
    return path


def _gltf_tree(V, F, n_nodes: int = 1, **accessor_counts) -> tuple[dict, bytes]:
    """A glTF tree (one mesh placed by ``n_nodes`` nodes) and its binary buffer."""
    binary = V.astype("<f4").tobytes() + F.astype("<u4").tobytes()
    tree = {
        "asset": {"version": "2.0"},
        "buffers": [{"byteLength": len(binary)}],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 12 * len(V)},
            {"buffer": 0, "byteOffset": 12 * len(V), "byteLength": 12 * len(F)},
        ],
        "accessors": [
            {
                "bufferView": 0,
                "componentType": 5126,
                "count": accessor_counts.get("vertices", len(V)),
                "type": "VEC3",
                "min": V.min(0).tolist(),
                "max": V.max(0).tolist(),
            },
            {
                "bufferView": 1,
                "componentType": 5125,
                "count": accessor_counts.get("indices", 3 * len(F)),
                "type": "SCALAR",
            },
        ],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "nodes": [{"mesh": 0, "translation": [0.0, 0.0, 0.1 * i]} for i in range(n_nodes)],
        "scenes": [{"nodes": list(range(n_nodes))}],
        "scene": 0,
    }
    return tree, binary


def _glb(path: Path, tree: dict, binary: bytes) -> Path:
    text = json.dumps(tree).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    path.write_bytes(
        struct.pack("<4sII", b"glTF", 2, 28 + len(text) + len(binary))
        + struct.pack("<I4s", len(text), b"JSON")
        + text
        + struct.pack("<I4s", len(binary), b"BIN\0")
        + binary
    )
    return path


def _gltf(path: Path, tree: dict, binary: bytes) -> Path:
    tree["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
    path.write_text(json.dumps(tree))
    return path


WRITERS = {
    "obj": lambda p, V, F: _obj(p.with_suffix(".obj"), V, F),
    "stl-binary": lambda p, V, F: _stl_binary(p.with_suffix(".stl"), V, F),
    "stl-ascii": lambda p, V, F: _stl_ascii(p.with_suffix(".stl"), V, F),
    "ply-binary": lambda p, V, F: _ply(p.with_suffix(".ply"), V, F, ascii=False),
    "ply-ascii": lambda p, V, F: _ply(p.with_suffix(".ply"), V, F, ascii=True),
    "glb": lambda p, V, F: _glb(p.with_suffix(".glb"), *_gltf_tree(V, F)),
    "gltf": lambda p, V, F: _gltf(p.with_suffix(".gltf"), *_gltf_tree(V, F)),
}


@pytest.fixture
def trimesh_reads(monkeypatch):
    """The files trimesh was asked to read during the test."""
    calls = []
    real = trimesh.load

    def spy(path, *args, **kwargs):
        calls.append(path)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(trimesh, "load", spy)
    return calls


def _one_line(info, path: Path) -> str:
    msg = str(info.value)
    assert "\n" not in msg and len(msg) < 400, msg
    assert msg.startswith(str(path.resolve())), msg
    return msg


@pytest.mark.parametrize("kind", list(WRITERS))
def test_every_format_is_refused_over_the_face_limit_before_trimesh_reads_it(tmp_path, trimesh_reads, kind):
    V, F = _surface(101)
    path = WRITERS[kind](tmp_path / "strip", V, F)
    with pytest.raises(MeshError) as info:
        read_mesh(path, max_faces=100)
    msg = _one_line(info, path)
    assert "101" in msg and "100 triangles" in msg and "--max-faces N" in msg, msg
    assert trimesh_reads == []
    model = read_mesh(path, max_faces=101)  # at the limit: read, every triangle kept
    assert len(trimesh_reads) == 1 and len(model.faces) + len(model.edges) > 0
    assert np.allclose(np.sort(model.vertices, axis=0), np.sort(V, axis=0), atol=1e-6)


def test_obj_over_the_byte_limit_is_refused_before_any_parsing(tmp_path, monkeypatch, trimesh_reads):
    path = tmp_path / "bomb.obj"
    with open(path, "wb") as fh:
        fh.write(b"v 0 0 0\nv 1 0 0\nv 0 1 0\n")
        fh.write(b"f 1 2 3\n" * (MAX_MESH_BYTES // 8 + 1))
    assert path.stat().st_size > MAX_MESH_BYTES

    def no_parsing(*args, **kwargs):
        raise AssertionError("the file was parsed")

    monkeypatch.setattr(mesh_module, "_count", no_parsing)
    monkeypatch.setattr(mesh_module, "_check_obj", no_parsing)
    start = time.monotonic()
    with pytest.raises(MeshError) as info:
        load_model(path)
    elapsed = time.monotonic() - start
    assert elapsed < 2.0
    msg = _one_line(info, path)
    assert f"the file holds {path.stat().st_size:,} bytes" in msg, msg
    assert "(200,000 triangles, 600,000 vertices, 64 MB)" in msg and "--max-faces N" in msg, msg
    assert trimesh_reads == []


def test_obj_just_under_the_byte_limit_loads_and_one_byte_more_is_refused(tmp_path):
    V, F = _surface(4)
    path = _obj(tmp_path / "padded.obj", V, F)
    comment = b"# " + b"x" * 4093 + b"\n"  # 4 KB lines: a long comment block, as some exporters write
    size = path.stat().st_size
    with open(path, "ab") as fh:
        fh.write(comment * ((MAX_MESH_BYTES - size) // len(comment)))
        fh.write(b"#" * (MAX_MESH_BYTES - path.stat().st_size - 1) + b"\n")
    assert path.stat().st_size == MAX_MESH_BYTES
    assert len(read_mesh(path).vertices) == len(V)
    with open(path, "ab") as fh:
        fh.write(b"\n")
    with pytest.raises(MeshError, match=r"the file holds 67,108,865 bytes \(64\.0 MB\), beyond"):
        read_mesh(path)


def test_binary_stl_at_the_default_face_limit_and_one_over(tmp_path, trimesh_reads):
    V, F = _surface(MAX_MESH_FACES + 1)
    over = _stl_binary(tmp_path / "over.stl", V, F)
    start = time.monotonic()
    with pytest.raises(MeshError) as info:
        read_mesh(over)
    assert time.monotonic() - start < 2.0
    assert "the binary STL holds 200,001 triangles, beyond mcit's limits" in _one_line(info, over)
    assert trimesh_reads == []
    at = _stl_binary(tmp_path / "at.stl", V, F[:MAX_MESH_FACES])
    model = read_mesh(at)
    assert len(model.vertices) == MAX_MESH_FACES + 2 and len(trimesh_reads) == 1


@pytest.mark.parametrize("count", [10**6, 2**32 - 1, 9, 11])
def test_binary_stl_whose_header_disagrees_with_its_size_is_refused(tmp_path, trimesh_reads, count):
    V, F = _surface(10)
    path = _stl_binary(tmp_path / "liar.stl", V, F, count=count)
    with pytest.raises(MeshError) as info:
        read_mesh(path, max_faces=10**9)
    msg = _one_line(info, path)
    assert (
        f"the binary STL's header declares {count:,} triangles, which take {84 + 50 * count:,} bytes, "
        f"but the file holds 584: it is truncated" in msg
    ), msg
    assert trimesh_reads == []


def test_ply_whose_header_declares_more_than_its_bytes_is_refused(tmp_path, trimesh_reads):
    V, F = _surface(10)
    for ascii in (False, True):
        path = _ply(tmp_path / f"liar-{ascii}.ply", V, F, ascii=ascii, n_vertices=100_000, n_faces=100_000)
        with pytest.raises(MeshError) as info:
            read_mesh(path)
        msg = _one_line(info, path)
        assert (
            "the PLY header declares 100,000 vertex, 100,000 face" in msg and "truncated or its header is wrong" in msg
        ), msg
    # a face list said to hold 255 vertices: the file is too short for it (trimesh takes the first as every face's)
    path = _ply(tmp_path / "long-list.ply", V, F, ascii=False)
    data = bytearray(path.read_bytes())
    data[data.index(b"end_header\n") + 11 + 12 * len(V)] = 255
    path.write_bytes(bytes(data))
    with pytest.raises(MeshError, match="every list as long as the first"):
        read_mesh(path)
    assert trimesh_reads == []


def test_ascii_ply_with_more_lines_or_bytes_than_text_is_refused(tmp_path, trimesh_reads):
    V, F = _surface(10)
    path = _ply(tmp_path / "lines.ply", V, F, ascii=True)
    path.write_bytes(path.read_bytes() + b"\n" * 100_000)  # trimesh would make an array of each line
    with pytest.raises(MeshError, match="100,022 lines follow the PLY header, which declares 12 vertex, 10 face"):
        read_mesh(path)
    path.write_bytes(path.read_bytes()[:-100_000].replace(b"3 0 2 1\n", b"3 0 2 1\x0c" * 3))
    with pytest.raises(MeshError, match="bytes that are not text"):
        read_mesh(path)
    assert trimesh_reads == []


@pytest.mark.parametrize("ascii", [False, True])
def test_ply_polygon_counts_its_triangles(tmp_path, trimesh_reads, ascii):
    V, _ = _surface(200)
    path = tmp_path / "polygon.ply"
    header = (
        f"ply\nformat {'ascii' if ascii else 'binary_little_endian'} 1.0\nelement vertex {len(V)}\n"
        f"property float x\nproperty float y\nproperty float z\nelement face 1\n"
        f"property list uchar int vertex_indices\nend_header\n"
    ).encode()
    ring = np.r_[np.arange(0, len(V), 2), np.arange(len(V) - 1, 0, -2)][:103]  # one polygon of 103 vertices
    if ascii:
        data = "".join(f"{x} {y} {z}\n" for x, y, z in V) + f"{len(ring)} " + " ".join(map(str, ring)) + "\n"
        path.write_bytes(header + data.encode())
    else:
        path.write_bytes(header + V.astype("<f4").tobytes() + bytes([len(ring)]) + ring.astype("<i4").tobytes())
    with pytest.raises(MeshError, match="the PLY's 1 faces make at least 101 triangles"):
        read_mesh(path, max_faces=100)
    assert trimesh_reads == []
    read_mesh(path, max_faces=101)


def test_obj_polygons_and_continued_lines_count_their_triangles(tmp_path, trimesh_reads):
    V, _ = _surface(200)
    verts = "".join(f"v {x} {y} {z}\n" for x, y, z in V)
    refs = [str(i) for i in range(1, 104)]  # a polygon of 103 vertices: 101 triangles
    one_line = tmp_path / "polygon.obj"
    one_line.write_text(verts + "f " + " ".join(refs) + "\n")
    continued = tmp_path / "continued.obj"  # a backslash continues the line: trimesh reads one polygon
    continued.write_text(verts + "f 1 2 3 \\\n" + " \\\n".join(refs[3:]) + "\n")
    for path in (one_line, continued):
        with pytest.raises(MeshError) as info:
            read_mesh(path, max_faces=100)
        assert "the faces up to this line make 101 triangles" in _one_line(info, path)
    assert str(info.value).startswith(f"{continued}:{len(V) + 1}: ")  # where the record starts
    assert trimesh_reads == []
    assert len(read_mesh(continued, max_faces=101).vertices) == 103


def test_glb_accessor_that_overruns_its_buffer_or_has_no_data_is_refused(tmp_path, trimesh_reads):
    V, F = _surface(10)
    liar = _glb(tmp_path / "liar.glb", *_gltf_tree(V, F, indices=3000))
    with pytest.raises(MeshError) as info:
        read_mesh(liar)
    assert "accessor 1 declares 3,000 items, which take 12,000 bytes, but its buffer view 1 holds 120" in _one_line(
        info, liar
    )
    # an accessor without a buffer view: trimesh fills it with zeros (here 12 GB)
    tree, binary = _gltf_tree(V, F)
    tree["accessors"].append({"componentType": 5126, "count": 10**9, "type": "VEC3"})
    zeros = _glb(tmp_path / "zeros.glb", tree, binary)
    with pytest.raises(MeshError) as info:
        read_mesh(zeros)
    assert "accessors without data declare 1,000,000,000 items, beyond mcit's limits" in _one_line(info, zeros)
    assert trimesh_reads == []


def test_glb_mesh_placed_by_many_nodes_counts_every_placement(tmp_path, trimesh_reads):
    V, F = _surface(60)
    twice = _glb(tmp_path / "twice.glb", *_gltf_tree(V, F, n_nodes=2))
    with pytest.raises(MeshError) as info:
        read_mesh(twice, max_faces=100)
    assert "its scene places at least 120 triangles and 124 vertices" in _one_line(info, twice)
    assert len(read_mesh(twice, max_faces=120).faces) > 0
    many = _glb(tmp_path / "many.glb", *_gltf_tree(V[:3], F[:1], n_nodes=MAX_MESH_FACES // 20 + 1))
    with pytest.raises(MeshError, match="the glTF holds 10,001 nodes, beyond"):  # trimesh spends 0.2 ms on each
        read_mesh(many)
    assert trimesh_reads == [str(twice.resolve())]


def test_glb_json_of_many_small_values_or_overlapping_items_is_refused(tmp_path, trimesh_reads):
    V, F = _surface(10)
    tree, binary = _gltf_tree(V, F)
    tree["extras"] = {"junk": [0] * 1000}  # 1,000 values: Python spends 30 to 200 bytes on each
    path = _glb(tmp_path / "json.glb", tree, binary)
    with pytest.raises(MeshError) as info:
        read_mesh(path, max_faces=100)
    assert "the glTF's JSON holds 1,0" in _one_line(info, path) and "more than 1,000" in str(info.value)
    tree, binary = _gltf_tree(V, F)
    tree["bufferViews"][0]["byteStride"] = 4  # 12-byte items every 4 bytes: trimesh's copy would triple the buffer
    path = _glb(tmp_path / "stride.glb", tree, binary)
    with pytest.raises(MeshError, match="buffer view 0's byteStride 4 is shorter than accessor 0's items"):
        read_mesh(path)
    assert trimesh_reads == []


def test_gltf_buffer_files_count_towards_the_bytes(tmp_path, trimesh_reads):
    V, F = _surface(10)
    tree, binary = _gltf_tree(V, F)
    tree["buffers"][0]["uri"] = "strip.bin"
    path = tmp_path / "strip.gltf"
    path.write_text(json.dumps(tree))
    (tmp_path / "strip.bin").write_bytes(binary)
    assert len(read_mesh(path).vertices) == len(V)
    with open(tmp_path / "strip.bin", "r+b") as fh:  # sparse: no disk written
        fh.truncate(MAX_MESH_BYTES - path.stat().st_size + 1)
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    assert f"the file and its buffer files hold {MAX_MESH_BYTES + 1:,} bytes (64.0 MB), beyond" in _one_line(info, path)
    assert trimesh_reads == [str(path)]


def test_the_scene_loader_reads_meshes_within_the_same_limits(tmp_path, trimesh_reads):
    V, F = _surface(MAX_MESH_FACES + 1)
    _stl_binary(tmp_path / "big.stl", V, F)
    d = json.loads((scenes_dir() / "workcell" / "scene.json").read_text())
    d.pop("video", None)
    d["bodies"] = [{"name": "big", "kind": "polyhedron", "model": {"mesh": "big.stl"}, "pose": {"xyz": [0, 0, 0]}}]
    (tmp_path / "scene.json").write_text(json.dumps(d))
    with pytest.raises(SceneError, match=r"big\.stl: the binary STL holds 200,001 triangles, beyond mcit's limits"):
        load_scene(tmp_path)
    assert trimesh_reads == []


def _mcit(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def test_import_refuses_a_mesh_over_the_limit_and_max_faces_raises_it(tmp_path, capsys):
    db = str(tmp_path / "site.sqlite")
    V, F = _surface(MAX_MESH_FACES + 2)
    path = _stl_binary(tmp_path / "part.stl", V, F)
    code, out, err = _mcit(capsys, "db", "import", str(path), "--db", db)
    assert code == 1 and out == "" and err.count("\n") == 1, err
    assert (
        err.startswith(
            f"mcit db import: error: {path}: the binary STL holds 200,002 triangles, beyond mcit's limits "
            f"for one mesh (200,000 triangles, 600,000 vertices, 64 MB)"
        )
        and "--max-faces N" in err
    ), err
    assert not Path(db).exists()  # refused before the database was opened
    small = _obj(tmp_path / "small.obj", *_surface(12))
    code, _, err = _mcit(capsys, "db", "import", str(small), "--db", db, "--max-faces", "11")
    assert code == 1 and "the file holds 12 faces (f lines), beyond mcit's limits for one mesh (11 triangles" in err, (
        err
    )
    code, out, err = _mcit(capsys, "db", "import", str(small), "--db", db, "--max-faces", "12")
    assert code == 0 and "added #" in out, err
    with Database.open(db) as d:
        assert len(d.get("small").model.vertices) == len(_surface(12)[0])
    with pytest.raises(SystemExit):
        main(["db", "import", str(small), "--db", db, "--max-faces", "0"])
    assert "expected at least 1 triangle" in capsys.readouterr().err


def test_the_import_help_gives_the_default_limit(capsys):
    with pytest.raises(SystemExit):
        main(["db", "import", "--help"])
    assert f"default {MAX_MESH_FACES:,}" in " ".join(capsys.readouterr().out.split())


def test_max_faces_must_be_a_positive_whole_number(tmp_path):
    path = _obj(tmp_path / "t.obj", *_surface(2))
    for bad in (0, -1, 2.5, True, "10"):
        with pytest.raises(ValueError, match="max_faces must be a whole number"):
            read_mesh(path, max_faces=bad)


def test_a_mesh_through_a_loop_of_symbolic_links_is_said_as_such(tmp_path):
    a, b = tmp_path / "a.stl", tmp_path / "b.stl"
    a.symlink_to(b)
    b.symlink_to(a)
    with pytest.raises(MeshError, match=r"a\.stl is a loop of symbolic links that never reaches a file"):
        read_mesh(a)


def _obj_groups(path: Path, n: int) -> Path:
    """4 vertices, then n faces each in its own material group (``usemtl m<i>``)."""
    path.write_text(
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\n" + "".join(f"usemtl m{i}\nf {1 + i % 2} 3 4\n" for i in range(n))
    )
    return path


def test_obj_of_many_material_groups_is_refused_before_trimesh_reads_it(tmp_path, trimesh_reads):
    # trimesh builds a mesh for each usemtl group, in time growing as their square: 20,000 took 95 s
    over = _obj_groups(tmp_path / "groups.obj", mesh_module.MAX_OBJ_MATERIALS + 1)
    start = time.monotonic()
    with pytest.raises(MeshError) as info:
        read_mesh(over)
    assert time.monotonic() - start < 2.0
    msg = _one_line(info, over)
    assert "the file holds 1,001 material groups (usemtl), beyond mcit's limit of 1,000" in msg, msg
    assert trimesh_reads == []
    at = _obj_groups(tmp_path / "at.obj", mesh_module.MAX_OBJ_MATERIALS)  # at the limit: read (0.5 s)
    assert len(read_mesh(at).vertices) == 4 and len(trimesh_reads) == 1


def test_obj_faces_without_a_space_and_continued_vertices_are_counted_as_trimesh_reads_them(tmp_path, trimesh_reads):
    # trimesh reads "f1 2 3" as a face and joins "v\" + newline + " x y z" into a vertex: counted before it reads
    V, F = _surface(100)
    verts = "".join(f"v\\\n {x} {y} {z}\n" for x, y, z in V)
    lines = [f"f{a + 1} {b + 1} {c + 1}\n" for a, b, c in F]
    lines[0], lines[-1] = "f " + lines[0][1:], "f " + lines[-1][1:]  # trimesh reads from the first to the last "f "
    faces = "".join(lines)
    at = tmp_path / "at.obj"
    at.write_text(verts + faces)
    model = read_mesh(at, max_faces=100)  # trimesh reads every vertex and face
    assert len(trimesh_reads) == 1 and np.allclose(np.sort(model.vertices, axis=0), np.sort(V, axis=0), atol=1e-6)
    over = tmp_path / "over.obj"
    over.write_text(verts + "f1 2 3\n" + faces)
    with pytest.raises(MeshError) as info:
        read_mesh(over, max_faces=100)
    assert "the file holds 101 faces (f lines), beyond mcit's limits for one mesh (100 triangles" in _one_line(
        info, over
    )
    many = tmp_path / "many.obj"
    many.write_text("v\\\n 0 0 0\n" * 301 + "f 1 2 3\n")
    with pytest.raises(MeshError) as info:
        read_mesh(many, max_faces=100)
    assert "the file holds 301 vertices (v lines), beyond mcit's limits for one mesh (100 triangles" in _one_line(
        info, many
    )
    # at the default limits, as the 63 MB file that reached 1.14 GB and 30 s in trimesh before being refused
    big = tmp_path / "big.obj"
    big.write_text("v\\\n 0 0 0\nv\\\n 1 0 0\nv\\\n 0 1 0\n" + "f1 2 3\n" * MAX_MESH_FACES + "f 1 2 3\n")
    start = time.monotonic()
    with pytest.raises(MeshError) as info:
        read_mesh(big)
    assert time.monotonic() - start < 2.0
    assert "the file holds 200,001 faces (f lines)" in _one_line(info, big)
    assert len(trimesh_reads) == 1  # only the file at the limit


def test_obj_line_numbers_count_the_continued_lines_and_odd_line_breaks_are_refused(tmp_path, trimesh_reads):
    path = tmp_path / "bad.obj"
    path.write_text("\n\nv\\\n 0 0 0\nv 1 0 \\\n 0\nv 0 1 0\nf1 2 4\n")
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    assert _one_line(info, path).startswith(f"{path}:8: face vertex index 4 refers to no vertex (1..3")
    path.write_bytes(b"v 0 0 0\nv 1 0 0\rv 2 0 0\nv 0 1 0\nf 1 2 3\n")  # a lone CR: trimesh may read 2 vertices
    with pytest.raises(MeshError) as info:
        read_mesh(path)
    assert _one_line(info, path).startswith(f"{path}:2: a line break other than LF or CRLF ('\\r')")
    assert trimesh_reads == []
