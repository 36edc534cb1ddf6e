""".cao and .init files as ViSP reads them (issue 15, item 4): load-only files, load(…, R=[…]),
degenerate circles left out with a warning, .init files with load() lines, every real file loads."""

import warnings
from pathlib import Path

import numpy as np
import pytest

from app.models_io import CaoError, CaoWarning, cao_text, read_cao, read_init
from core.transforms import exp_so3

BOX = (
    "V1\n8\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n0 0 1\n1 0 1\n1 1 1\n0 1 1\n0\n0\n6\n"
    "4 0 3 2 1\n4 4 5 6 7\n4 0 1 5 4\n4 1 2 6 5\n4 2 3 7 6\n4 3 0 4 7\n0\n0\n"
)
RZ90_ROWS = "0; -1; 0; 1; 0; 0; 0; 0; 1"  # rotation of +90° about z, row by row


@pytest.fixture
def box(tmp_path):
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "box.cao").write_text(BOX)
    return read_cao(tmp_path / "parts" / "box.cao")


def test_a_file_of_load_lines_only_loads(tmp_path, box):
    f = tmp_path / "square.cao"
    f.write_text(
        'V1\n# two boxes\nload("parts/box.cao")\nload("parts/box.cao", t=[2; 0; 0], tu=[0; 0; 90 deg]) # placed\n'
    )
    m = read_cao(f)
    assert len(m.vertices) == 16 and len(m.faces) == 12
    assert np.allclose(m.vertices[8:], box.vertices @ exp_so3([0, 0, np.pi / 2]).T + [2, 0, 0])
    g = tmp_path / "again.cao"
    g.write_text(cao_text(m))
    assert read_cao(g) == m


def test_an_empty_file_after_the_version_is_still_refused(tmp_path):
    f = tmp_path / "v.cao"
    f.write_text("V1\n# nothing\n")
    with pytest.raises(CaoError, match=r"v\.cao:2: the file ends where the number of points was expected"):
        read_cao(f)


def test_load_with_a_rotation_matrix_row_by_row(tmp_path, box):
    by_tu = tmp_path / "tu.cao"
    by_tu.write_text('V1\nload("parts/box.cao", t=[0.1; 0.2; 0.3], tu=[0; 0; 90deg])\n')
    by_r = tmp_path / "r.cao"
    by_r.write_text(f'V1\nload("parts/box.cao", t=[0.1; 0.2; 0.3], R=[{RZ90_ROWS}])\n')
    assert np.allclose(read_cao(by_r).vertices, read_cao(by_tu).vertices, atol=1e-15)
    # the transposed matrix is the opposite rotation: the order is rows, not columns
    assert np.allclose(read_cao(by_r).vertices[1], [0.1, 0.2 + 1, 0.3])


def test_a_rotation_written_with_few_digits_is_made_exact(tmp_path):
    c, s = 0.7071, 0.7071  # 45° to 4 digits: |RᵀR − I| ≈ 1e-4
    f = tmp_path / "r.cao"
    f.write_text(f'V1\nload("parts/box.cao", R=[{c}; {-s}; 0; {s}; {c}; 0; 0; 0; 1])\n')
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "box.cao").write_text(BOX)
    m = read_cao(f)
    edge_lengths = np.linalg.norm(np.diff(m.edge_segments(), axis=1)[:, 0], axis=1)
    assert np.allclose(edge_lengths, 1.0, atol=1e-12)  # no shear, no scale


@pytest.mark.parametrize(
    "params, problem",
    [
        ("R=[1; 0; 0; 0; 1; 0]", "R=[...] needs 9 values"),
        ("R=[1; 0; 0; 0; 1; 0; 0; 0; -1]", "is not a rotation"),
        ("R=[2; 0; 0; 0; 2; 0; 0; 0; 2]", "is not a rotation"),
        ("R=[1; 0; 0; 0; 1; 0; 0; 0; x]", "a value of R=[...] is not a number"),
        ("R=[1; 0; 0; 0; 1; 0; 0; 0; nan]", "is not a rotation"),
        ("tu=[0; 0; 1], R=[1; 0; 0; 0; 1; 0; 0; 0; 1]", "one rotation, tu= or R="),
        ("t=[0; 0; 1], t=[0; 0; 2]", "give t= once"),
    ],
)
def test_bad_rotations_are_refused_with_file_and_line(tmp_path, params, problem):
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "box.cao").write_text(BOX)
    f = tmp_path / "bad.cao"
    f.write_text(f'V1\nload("parts/box.cao", {params})\n')
    with pytest.raises(CaoError) as info:
        read_cao(f)
    assert str(info.value).startswith(f"{f}:2: load(): ") and problem in str(info.value), str(info.value)


DEGENERATE_CIRCLE = "V1\n3\n0 1 2\n3 4 5\n6 7 8\n0\n0\n0\n0\n1\n0.5 0 1 2 name=circle\n"  # as ViSP's own test file


def test_a_circle_without_a_plane_is_left_out_with_a_warning_naming_its_line(tmp_path):
    f = tmp_path / "model.cao"
    f.write_text("V1\n4\n0 1 2\n3 4 5\n6 7 8\n0 0 1\n1\n0 3\n0\n0\n0\n2\n0.5 0 1 2\n0.25 3 0 1\n")
    with pytest.warns(CaoWarning, match=rf"^{f}:13: circle 0 is left out: its centre and two points are on one line"):
        m = read_cao(f)
    assert len(m.edges) == 1 and len(m.circles) == 1 and m.circles[0].radius == 0.25  # the good circle is kept


def test_a_hierarchy_including_a_degenerate_circle_loads(tmp_path):
    (tmp_path / "circle.cao").write_text(DEGENERATE_CIRCLE)
    (tmp_path / "line.cao").write_text("V1\n2\n0 0 0\n0 0 1\n1\n0 1 name=line_0\n0\n0\n")
    top = tmp_path / "all.cao"
    top.write_text('V1\nload("line.cao")\nload("circle.cao")\n0\n0\n0\n0\n0\n0\n')
    with pytest.warns(CaoWarning, match=r"circle\.cao:11: circle 0 is left out"):
        m = read_cao(top)
    assert len(m.edges) == 1 and m.circles == ()


def test_a_model_of_nothing_but_a_degenerate_circle_says_so(tmp_path):
    f = tmp_path / "circle.cao"
    f.write_text(DEGENERATE_CIRCLE)
    with pytest.warns(CaoWarning), pytest.raises(CaoError, match="nothing mcit can draw"):
        read_cao(f)


def test_degenerate_faces_are_still_refused(tmp_path):
    f = tmp_path / "face.cao"
    f.write_text("V1\n3\n0 1 2\n3 4 5\n6 7 8\n0\n0\n1\n3 0 1 2 name=face_from_3D_points\n0\n0\n")
    with pytest.raises(CaoError, match=r"face\.cao:9: face 0 has no area"):
        read_cao(f)


# --- .init files ---


def test_init_files_as_before(tmp_path):
    f = tmp_path / "box.init"
    f.write_text("# clicked points\n4\n0 0 0 # corner\n1 0 0\n1 1 0\n0 1 1\n")
    assert np.array_equal(read_init(f), [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 1]])


def test_init_files_with_load_lines(tmp_path):
    (tmp_path / "parts").mkdir()
    (tmp_path / "parts" / "brick.init").write_text("2\n0 0 0\n1 0 0\n")
    top = tmp_path / "square.init"
    top.write_text(f'load("parts/brick.init")\nload("parts/brick.init", t=[0; 2; 0], R=[{RZ90_ROWS}])\n1\n5 5 5\n')
    assert np.allclose(read_init(top), [[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 3, 0], [5, 5, 5]])
    only = tmp_path / "only.init"
    only.write_text('load("parts/brick.init", tu=[0; 0; 180deg])\n')
    assert np.allclose(read_init(only), [[0, 0, 0], [-1, 0, 0]])


@pytest.mark.parametrize(
    "text, line, problem",
    [
        ("", 0, "ends where the number of points"),
        ("4\n0 0 0\n1 0 0\n", 1, "number of points is more than the 2 lines left"),
        ("2\n0 0 0\n1 x 0\n", 3, "point 1: value 2 is not a number"),
        ("2\n0 0 0\n1 1e300 0\n", 3, "point 1 is beyond"),
        ('load("self.init")\n', 1, "cyclic include"),
        ('load("nowhere.init")\n', 1, "included file not found"),
    ],
)
def test_bad_init_files_name_file_and_line(tmp_path, text, line, problem):
    f = tmp_path / "self.init"
    f.write_text(text)
    with pytest.raises(CaoError) as info:
        read_init(f)
    assert str(info.value).startswith(f"{f}:{line}: ") and problem in str(info.value), str(info.value)


def test_init_load_of_a_system_file_quotes_nothing(tmp_path):
    secret = tmp_path / "shadow"
    secret.write_text("root:s3cr3t:19000:0:99999:7:::\n")
    f = tmp_path / "x.init"
    f.write_text(f'load("{secret}")\n')
    with pytest.raises(CaoError) as info:
        read_init(f)
    assert "s3cr3t" not in str(info.value) and "root" not in str(info.value).replace(str(tmp_path), "")


def test_init_fan_out_is_bounded(tmp_path):
    (tmp_path / "f12.init").write_text("1\n0 0 0\n")
    for k in range(11, -1, -1):
        (tmp_path / f"f{k}.init").write_text(f'load("f{k + 1}.init")\nload("f{k + 1}.init")\n')
    with pytest.raises(CaoError, match="nested more than 8 levels"):
        read_init(tmp_path / "f0.init")


# --- every real ViSP file there is ---


def _real_files(suffix):
    root = Path(__file__).resolve().parents[2].parent / "shared" / "data"
    files = sorted(root.rglob(f"*{suffix}")) if root.is_dir() else []
    return files or [pytest.param(None, marks=pytest.mark.skip(reason=f"no {suffix} files under ../shared/data"))]


@pytest.mark.parametrize("path", _real_files(".cao"), ids=lambda p: p.name if p else "absent")
def test_every_real_cao_file_loads_without_warning_and_round_trips(tmp_path, path):
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        m = read_cao(path)
    g = tmp_path / "again.cao"
    g.write_text(cao_text(m))
    assert read_cao(g) == m


@pytest.mark.parametrize("path", _real_files(".init"), ids=lambda p: p.name if p else "absent")
def test_every_real_init_file_loads(path):
    P = read_init(path)
    assert P.shape[1] == 3 and len(P) >= 4 and np.all(np.isfinite(P))


# --- name= and LOD options through import and export ---

NAMED = """V1
5
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
2
0 4 name=pole useLod=true minLineLengthThreshold=40
1 4
0
1
4 0 1 2 3 name=floor useLod=false minPolygonAreaThreshold=2500
1
0 4 0.1 name=shaft
1
0.5 0 1 3 name=rim
"""


def test_name_and_lod_options_survive_import_and_export(tmp_path):
    from app.models_io import read_cao_options, write_cao

    f = tmp_path / "named.cao"
    f.write_text(NAMED)
    m, opts = read_cao_options(f)
    pole = tuple(
        sorted(
            int(i)
            for i in np.flatnonzero(
                np.all(m.vertices == [[0, 0, 0]], axis=1) | np.all(m.vertices == [[0, 0, 1]], axis=1)
            )
        )
    )
    assert opts.edges == {pole: "name=pole useLod=true minLineLengthThreshold=40"}
    assert opts.faces == {0: "name=floor useLod=false minPolygonAreaThreshold=2500"}
    assert opts.cylinders == {0: "name=shaft"} and opts.circles == {0: "name=rim"}
    out = tmp_path / "out.cao"
    write_cao(m, out, options=opts)
    text = out.read_text()
    assert "name=pole useLod=true minLineLengthThreshold=40" in text and "name=floor useLod=false" in text
    assert " name=shaft\n" in text and " name=rim\n" in text
    m2, opts2 = read_cao_options(out)
    assert m2 == m and opts2 == opts
    assert "name=" not in cao_text(m)  # without options, none are invented


def test_options_of_included_files_follow_their_records(tmp_path):
    from app.models_io import read_cao_options, write_cao

    (tmp_path / "named.cao").write_text(NAMED)
    top = tmp_path / "two.cao"
    top.write_text(
        'V1\nload("named.cao")\nload("named.cao", t=[5; 0; 0])\n2\n0 0 0\n0 0 9\n1\n0 1 name=mast\n0\n0\n0\n0\n'
    )
    m, opts = read_cao_options(top)
    floor = "name=floor useLod=false minPolygonAreaThreshold=2500"
    assert opts.faces == {0: floor, 1: floor}
    assert sorted(opts.cylinders) == [0, 1] and sorted(opts.circles) == [0, 1]
    named_edges = {
        tuple(tuple(float(x) for x in m.vertices[i]) for i in k): v.split()[0] for k, v in opts.edges.items()
    }
    assert named_edges == {
        ((0, 0, 0), (0, 0, 1)): "name=pole",
        ((5, 0, 0), (5, 0, 1)): "name=pole",
        ((0, 0, 0), (0, 0, 9)): "name=mast",
    }
    out = tmp_path / "out.cao"
    write_cao(m, out, options=opts)
    m2, opts2 = read_cao_options(out)
    assert opts2 == opts  # the model itself round-trips (circle normals to rounding: see test_models_io)
    assert np.array_equal(m2.vertices, m.vertices) and m2.faces == m.faces
    assert sorted(map(tuple, m2.edges.tolist())) == sorted(map(tuple, m.edges.tolist()))  # faces' sides come first


def test_name_and_lod_options_survive_the_database(tmp_path, capsys):
    """mcit db import keeps a .cao's ViSP options in the import's history; mcit db export writes them
    back while the object's model is the imported one."""
    from app.cli import main
    from app.models_io import read_cao_options

    f = tmp_path / "named.cao"
    f.write_text(NAMED)
    db = str(tmp_path / "site.sqlite")
    assert main(["db", "init", "--db", db]) == 0
    assert main(["db", "import", str(f), "--db", db, "--name", "pole"]) == 0
    out = tmp_path / "out.cao"
    assert main(["db", "export", "pole", str(out), "--db", db]) == 0
    capsys.readouterr()
    m, opts = read_cao_options(f)
    m2, opts2 = read_cao_options(out)
    assert m2 == m and opts2 == opts and opts2.faces == {0: "name=floor useLod=false minPolygonAreaThreshold=2500"}
    mesh = tmp_path / "out.obj"  # another format: no options to keep, nothing breaks
    assert main(["db", "export", "pole", str(mesh), "--db", db]) == 0
