"""Model import and export: ViSP .cao (every block, includes, errors) and meshes through trimesh."""

import json

import numpy as np
import pytest

from app.models_io import MODEL_LOADERS, CaoError, MeshError, cao_text, load_model, read_cao, save_model
from app.scene import load_scene, scenes_dir
from core.brep import BRep
from core.transforms import exp_so3, make_T

REAL_MODELS = [("visp-teabox", "teabox.cao", 8, 12, 6, 0), ("visp-cube", "cube_and_cylinder.cao", 8, 12, 6, 1)]


def _edge_set(model, T=None, digits=6):
    S = model.edge_segments(T)
    return {tuple(sorted(map(tuple, np.round(s, digits)))) for s in S}


@pytest.mark.parametrize("folder, name, n_v, n_e, n_f, n_cyl", REAL_MODELS)
def test_real_cao_models_read_and_round_trip_identically(shared_data, tmp_path, folder, name, n_v, n_e, n_f, n_cyl):
    m = read_cao(shared_data(folder, name))
    assert (len(m.vertices), len(m.edges), len(m.faces), len(m.solids)) == (n_v, n_e, n_f, n_cyl)
    # every face is planar and its normal points out of the solid
    c = m.vertices.mean(axis=0)
    assert np.all(np.einsum("ij,ij->i", m.face_normals(), m.face_centroids() - c) > 0)
    save_model(m, tmp_path / "out.cao")
    assert read_cao(tmp_path / "out.cao") == m


def test_cylinder_of_the_real_cube_model(shared_data):
    m = read_cao(shared_data("visp-cube", "cube_and_cylinder.cao"))
    s = m.solids[0]
    assert np.allclose(s.p0, [-0.17, -0.03, 0]) and np.allclose(s.p1, [-0.17, -0.03, 0.25]) and s.r0 == s.r1 == 0.04
    # the two axis points are not vertices of the polyhedral part
    assert np.allclose(m.bounds()[0], [-0.21, -0.07, 0.0]) and len(m.vertices) == 8


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".ply", ".gltf", ".glb"])
def test_mesh_export_and_import_keep_the_polyhedral_edges(shared_data, tmp_path, suffix):
    m = read_cao(shared_data("visp-teabox", "teabox.cao"))
    out = tmp_path / f"teabox{suffix}"
    save_model(m, out)
    back = load_model(out)
    assert _edge_set(back) == _edge_set(m)  # 12 edges, no diagonal of the triangulated faces
    assert sorted(len(f) for f in back.faces) == [4] * 6
    if suffix == ".gltf":
        assert sorted(p.name for p in tmp_path.iterdir()) == ["teabox.gltf"]  # buffer embedded


def test_mesh_export_of_a_cylinder_gives_its_rims(tmp_path):
    save_model(BRep.cylinder(0.05, 0.2), tmp_path / "c.stl")
    back = load_model(tmp_path / "c.stl")
    z = back.edge_segments()[..., 2]
    assert len(back.edges) == 96 and np.all(np.isclose(z, 0) | np.isclose(z, 0.2))


CAO_ALL_BLOCKS = """V1
# a hand-written model using every block
6
0 0 0
1 0 0   // trailing text is a comment
1 1 0
0 1 0
0 0 1 # point 4, top of a pole
2 2 2
3                           # lines
0 1 name="bottom edge" useLod=false
1 2
2 0
1                           # faces from lines
3 2 1 0 name=face_a
1                           # faces from points
3 0 3 2
1                           # cylinders
0 4 0.1 name=pole
1                           # circles
0.5 0 1 3
"""


def test_every_block_of_the_format(tmp_path):
    f = tmp_path / "all.cao"
    f.write_text(CAO_ALL_BLOCKS)
    m = read_cao(f)
    assert len(m.vertices) == 4  # points 4 and 5 define no edge: not vertices
    # lines 2, 1, 0 = (2, 0), (1, 2), (0, 1) chain into the loop 0 → 2 → 1
    assert m.faces == ((0, 2, 1), (0, 3, 2))
    assert _edge_set(m) == {
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),
        ((1.0, 0.0, 0.0), (1.0, 1.0, 0.0)),
        ((0.0, 1.0, 0.0), (1.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 1.0, 0.0)),
        ((0.0, 0.0, 0.0), (0.0, 1.0, 0.0)),
    }
    assert len(m.solids) == 1 and m.solids[0].r0 == 0.1 and np.allclose(m.solids[0].p1, [0, 0, 1])
    assert len(m.circles) == 1 and m.circles[0].radius == 0.5 and np.allclose(m.circles[0].normal, [0, 0, 1])
    # round trip through the writer: same geometry (circles to rounding of their plane normal)
    g = tmp_path / "again.cao"
    save_model(m, g)
    m2 = read_cao(g)
    assert np.array_equal(m2.vertices, m.vertices) and np.array_equal(m2.edges, m.edges) and m2.faces == m.faces
    assert m2.solids[0].r0 == 0.1 and np.allclose(m2.circles[0].centre, m.circles[0].centre)
    assert np.allclose(m2.circles[0].normal, m.circles[0].normal) and m2.circles[0].radius == 0.5


def test_faces_from_lines_chain_whatever_the_line_directions(tmp_path):
    f = tmp_path / "sq.cao"
    f.write_text("V1\n4\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n4\n1 0\n1 2\n3 2\n0 3\n1\n4 0 1 2 3\n0\n0\n0\n")
    m = read_cao(f)
    assert len(m.faces) == 1 and len(m.edges) == 4
    loop = m.vertices[list(m.faces[0])]
    # line 0 = (1, 0) is reversed so that it continues into line 1 = (1, 2): the loop is 0, 1, 2, 3
    assert np.allclose(loop, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])


def test_standalone_lines_are_edges_without_faces_and_v2_points(tmp_path):
    f = tmp_path / "v2.cao"
    f.write_text("V2\n3\n0 0 0 10 20\n1 0 0 11 21\n0 2 0 12 22\n2\n0 1\n0 2\n0\n0\n")
    m = read_cao(f)  # old style: no cylinder or circle block
    assert len(m.edges) == 2 and m.faces == ()
    assert np.isclose(sorted(np.linalg.norm(np.diff(m.edge_segments(), axis=1)[:, 0], axis=1))[1], 2.0)


def test_load_includes_with_a_pose(shared_data, tmp_path):
    teabox = shared_data("visp-teabox", "teabox.cao")
    parent = tmp_path / "scene.cao"
    parent.write_text(
        f'V1\nload("{teabox}", t=[0.1; -0.2; 0.3], tu=[0; 0; 90deg])\n'
        f'load("{teabox}", t=[1; 0; 0], tu=[0.1rad; 0.2; 0])\n2\n0 0 0\n0 0 1\n1\n0 1\n0\n0\n0\n0\n'
    )
    m = read_cao(parent)
    box = read_cao(teabox)
    T1 = make_T(exp_so3([0, 0, np.pi / 2]), [0.1, -0.2, 0.3])
    T2 = make_T(exp_so3([0.1, 0.2, 0]), [1, 0, 0])
    assert len(m.vertices) == 18 and len(m.edges) == 25 and len(m.faces) == 12
    assert np.allclose(m.vertices[:8], box.vertices @ T1[:3, :3].T + T1[:3, 3])
    assert np.allclose(m.vertices[8:16], box.vertices @ T2[:3, :3].T + T2[:3, 3])
    assert np.allclose(m.vertices[16:], [[0, 0, 0], [0, 0, 1]])


def test_relative_include_and_cycle(tmp_path):
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "a.cao").write_text('V1\nload("../b.cao")\n0\n0\n0\n0\n')
    (tmp_path / "b.cao").write_text('V1\nload("sub/a.cao")\n0\n0\n0\n0\n')
    with pytest.raises(CaoError, match=r"b\.cao:2: cyclic include"):
        read_cao(tmp_path / "sub" / "a.cao")


BAD_CAO = [
    ("", 0, "ends where the version"),
    ("V1\n", 1, "ends where the number of points"),
    ("W1\n3\n", 1, "version 'V1'"),
    ("V7\n", 1, "unsupported .cao version V7"),
    ("V1\n2\n0 0 0\n1 x 0\n", 4, "point 1: value 2 is not a number"),
    ("V1\n2\n0 0 0\n1 0\n", 4, "point 1: expected 3 numbers"),
    ("V1\n2\n0 0 0\n1 0 0\n1\n0 5\n", 6, "point index 5 out of range 0..1"),
    ("V1\n2\n0 0 0\n1 0 0\n1\n1 1\n", 6, "joins point 1 to itself"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n2 0 1\n", 9, "needs at least 3"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n3 0 1\n", 9, "expected 4 numbers"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n2\n0 1\n1 2\n1\n3 0 1 7\n", 10, "line index 7 out of range"),
    ("V1\n4\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n3\n0 1\n2 3\n1 2\n1\n3 0 1 2\n", 12, "does not continue"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n2\n0 1\n1 2\n1\n2 0 1\n", 10, "has 2 lines"),
    ("V1\n2\n0 0 0\n0 0 1\n0\n0\n0\n1\n0 1 -0.1\n", 9, "radius must be positive"),
    ("V1\n2\n0 0 0\n0 0 1\n0\n0\n0\n1\n0 0 0.1\n", 9, "two distinct axis endpoints"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n0\n0\n1\n-0.5 0 1 2\n", 11, "circle 0: radius must be positive"),
    ("V1\n2\n0 0 0\n0 0 1\n1\n0 1 useLod=maybe\n0\n0\n", 6, "useLod= must be true, false, 1 or 0"),
    ("V1\n2\n0 0 0\n0 0 1\n1\n0 1\n0\n0\n0\n0\nextra\n", 11, "unexpected content"),
    ('V1\nload("nowhere.cao")\n0\n0\n0\n0\n', 2, "included file not found"),
    ('V1\nload("x.cao", s=[1; 2; 3])\n0\n0\n0\n0\n', 2, "unknown parameter"),
    ('V1\nload("x.cao", t=[1; 2])\n0\n0\n0\n0\n', 2, "needs 3 values"),
    ("V1\n0\n0\n0\n0\n", 5, "no lines, faces"),
]


@pytest.mark.parametrize("text, line, problem", BAD_CAO)
def test_malformed_cao_names_file_line_and_problem(tmp_path, text, line, problem):
    f = tmp_path / "bad.cao"
    f.write_text(text)
    (tmp_path / "x.cao").write_text("V1\n2\n0 0 0\n1 0 0\n1\n0 1\n0\n0\n")
    with pytest.raises(CaoError) as info:
        read_cao(f)
    msg = str(info.value)
    assert msg.startswith(f"{f}:{line}:") if line else msg.startswith(f"{f}:"), msg
    assert problem in msg, msg


def test_cao_writer_refuses_cones_and_writes_edges_not_on_faces_as_lines():
    with pytest.raises(ValueError, match="cone"):
        cao_text(BRep.cone(0.1, 0.05, 0.2))
    pole = BRep(np.array([[0, 0, 0], [0, 0, 1.0]]), np.array([[0, 1]]))
    text = cao_text(pole)
    assert "# 3D lines\n1\n0 1\n" in text and "# Faces from 3D points\n0\n" in text


BAD_OBJ = [
    ("v 0 0 0\nv 1 0 0\nv 0 x 0\nf 1 2 3\n", 3, "vertex coordinates must be numbers"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n", 4, "index 7 refers to no vertex"),
    ("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n", 4, "at least 3 vertices"),
    ("v 0 0 0\nv 1 0\n", 2, "3 finite coordinates"),
]


@pytest.mark.parametrize("text, line, problem", BAD_OBJ)
def test_malformed_obj_names_file_line_and_problem(tmp_path, text, line, problem):
    f = tmp_path / "bad.obj"
    f.write_text(text)
    with pytest.raises(MeshError, match=problem) as info:
        load_model(f)
    assert str(info.value).startswith(f"{f}:{line}:")


@pytest.mark.parametrize(
    "name, data, problem",
    [
        ("bad.ply", b"", "cannot read the mesh"),
        ("bad.stl", b"solid x\nfacet normal 0 0 1\n", "no triangles"),
        ("bad.glb", b"glTF\x02\x00\x00\x00garbage", "cannot read the mesh"),
    ],
)
def test_malformed_binary_meshes_name_the_file(tmp_path, name, data, problem):
    f = tmp_path / name
    f.write_bytes(data)
    with pytest.raises(MeshError, match=problem) as info:
        load_model(f)
    assert str(info.value).startswith(str(f))


def test_unknown_suffix_and_missing_file(tmp_path):
    with pytest.raises(ValueError, match="unknown model type"):
        load_model(tmp_path / "m.step")
    with pytest.raises(MeshError, match="no such file"):
        load_model(tmp_path / "m.obj")


def test_scene_files_can_reference_cao_and_mesh_models(shared_data, tmp_path):
    assert MODEL_LOADERS["cao"] is read_cao
    teabox = shared_data("visp-teabox", "teabox.cao")
    save_model(BRep.box(0.1, 0.2, 0.3), tmp_path / "box.stl")
    d = json.loads((scenes_dir() / "workcell" / "scene.json").read_text())
    d.pop("video", None)
    d.pop("robot", None)  # its URDF lies beside the workcell's scene, not in tmp_path
    d["bodies"] = [
        {"name": "tea", "kind": "box", "model": {"cao": str(teabox)}, "pose": {"xyz": [0, 0, 0.1]}},
        {"name": "stl", "kind": "box", "model": {"mesh": "box.stl"}, "pose": {"xyz": [0.3, 0, 0]}},
    ]
    (tmp_path / "scene.json").write_text(json.dumps(d))
    scene = load_scene(tmp_path)
    assert scene.body("tea").model == read_cao(teabox)
    assert _edge_set(scene.body("stl").model) == _edge_set(BRep.box(0.1, 0.2, 0.3))
