""".cao files that a careless or hostile author could write: bounded includes, counts checked before
allocating, degenerate geometry refused with file:line, no file content quoted (issue 14, item 4)."""

import os
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from app.models_io import CaoError, cao_text, load_model, read_cao, save_model
from app.models_io import cao as cao_module

TRIANGLE = "V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n3 0 1 2\n0\n0\n"


def _chain(folder: Path, depth: int, includes_per_file: int) -> Path:
    """Files f0 … f{depth}: each includes the next ``includes_per_file`` times; the last is a triangle."""
    (folder / f"f{depth}.cao").write_text(TRIANGLE)
    for k in range(depth - 1, -1, -1):
        loads = "".join(f'load("f{k + 1}.cao", t=[0; 0; {j}])\n' for j in range(includes_per_file))
        (folder / f"f{k}.cao").write_text(f"V1\n{loads}0\n0\n0\n0\n")
    return folder / "f0.cao"


@pytest.fixture
def parses(monkeypatch):
    """How many times a file's text was parsed during the test."""
    calls = []
    real = cao_module._parse

    def counting(path, *args):
        calls.append(path)
        return real(path, *args)

    monkeypatch.setattr(cao_module, "_parse", counting)
    return calls


def _one_line(exc_info) -> str:
    msg = str(exc_info.value)
    assert "\n" not in msg and len(msg) < 400, msg
    return msg


@pytest.mark.parametrize("depth", [9, 12, 16, 40])
def test_includes_fanning_out_deeper_than_8_levels_are_refused_after_9_files(tmp_path, parses, depth):
    top = _chain(tmp_path, depth, includes_per_file=2)
    with pytest.raises(CaoError) as info:
        read_cao(top)
    msg = _one_line(info)
    assert msg.startswith(f"{tmp_path / 'f8.cao'}:2: includes are nested more than 8 levels deep"), msg
    assert "8 levels of includes, 256 files" in msg and "64 MB" in msg
    assert len(parses) <= 9  # the reader went straight down and stopped: it never expanded the 2^depth tree


def test_includes_8_levels_deep_load_and_one_more_is_refused(tmp_path):
    (tmp_path / "ok").mkdir()
    (tmp_path / "deep").mkdir()
    m = read_cao(_chain(tmp_path / "ok", 8, 1))
    assert len(m.vertices) == 3 and len(m.faces) == 1
    with pytest.raises(CaoError, match="nested more than 8 levels"):
        read_cao(_chain(tmp_path / "deep", 9, 1))


def test_fan_out_within_8_levels_is_refused_at_256_files(tmp_path, parses):
    # 2^0 + … + 2^8 = 511 files to read: refused at the 257th, each distinct file parsed once
    with pytest.raises(CaoError) as info:
        read_cao(_chain(tmp_path, 8, includes_per_file=2))
    assert "includes more than 256 files" in _one_line(info)
    assert len(parses) == 9


def test_256_files_load_and_257_are_refused(tmp_path):
    (tmp_path / "t.cao").write_text(TRIANGLE)
    for n, ok in ((255, True), (256, False)):  # the top file counts too
        top = tmp_path / f"top{n}.cao"
        top.write_text("V1\n" + 'load("t.cao")\n' * n + "0\n0\n0\n0\n")
        if ok:
            assert len(read_cao(top).faces) == n
        else:
            with pytest.raises(CaoError, match=rf"top{n}\.cao:257: the model includes more than 256 files"):
                read_cao(top)


def test_total_size_is_bounded_repeats_counted(tmp_path, monkeypatch):
    monkeypatch.setattr(cao_module, "MAX_TOTAL_BYTES", 200)
    (tmp_path / "t.cao").write_text(TRIANGLE)  # 38 bytes
    top = tmp_path / "top.cao"
    top.write_text("V1\n" + 'load("t.cao")\n' * 4 + "0\n0\n0\n0\n")  # 75 + 4 × 38 = 227 bytes
    with pytest.raises(CaoError, match=r"top\.cao:5: the model's files hold more than .* MB of text"):
        read_cao(top)
    top.write_text("V1\n" + 'load("t.cao")\n' * 3 + "0\n0\n0\n0\n")
    assert len(read_cao(top).faces) == 3


def test_a_file_over_64_mb_is_refused_before_it_is_read(tmp_path, parses):
    big = tmp_path / "big.cao"
    big.write_bytes(b"V1\n")
    os.truncate(big, 64 * 2**20 + 1)  # sparse: nothing written
    with pytest.raises(CaoError, match=r"big\.cao: the model's files hold more than 64 MB"):
        read_cao(big)
    assert parses == []


@pytest.mark.parametrize("name", ["/dev/zero", "/dev/null", "."])
def test_devices_and_folders_are_refused_as_not_regular_files(tmp_path, name):
    target = Path(name) if name.startswith("/") else tmp_path
    if not target.exists():
        pytest.skip(f"{name} absent here")
    with pytest.raises(CaoError, match="is not a regular file"):
        read_cao(target)
    top = tmp_path / "top.cao"
    top.write_text(f'V1\nload("{target}")\n0\n0\n0\n0\n')
    with pytest.raises(CaoError, match=r"top\.cao:2: .* is not a regular file"):
        read_cao(top)


def test_self_include_is_a_cycle(tmp_path):
    f = tmp_path / "me.cao"
    f.write_text('V1\nload("me.cao")\n0\n0\n0\n0\n')
    with pytest.raises(CaoError, match=r"me\.cao:2: cyclic include"):
        read_cao(f)


@pytest.mark.parametrize(
    "links", [{"a.cao": "b.cao", "b.cao": "a.cao"}, {"a.cao": "a.cao"}], ids=["two links", "one link"]
)
def test_an_include_through_a_symlink_loop_is_said_as_such(tmp_path, links):
    for name, target in links.items():
        (tmp_path / name).symlink_to(target)
    top = tmp_path / "top.cao"
    top.write_text('V1\nload("a.cao")\n0\n0\n0\n0\n')
    loop = tmp_path / "a.cao"
    with pytest.raises(CaoError) as info:
        read_cao(top)
    assert _one_line(info) == (
        f"{top}:2: {loop} is a loop of symbolic links that never reaches a file; point the link at the model file"
    )
    with pytest.raises(CaoError) as info:  # the model itself
        read_cao(loop)
    assert (
        _one_line(info)
        == f"{loop} is a loop of symbolic links that never reaches a file; point the link at the model file"
    )
    init = tmp_path / "top.init"
    init.write_text('load("a.init")\n')
    (tmp_path / "a.init").symlink_to("a.init")
    with pytest.raises(CaoError, match=r"top\.init:1: .*a\.init is a loop of symbolic links"):
        cao_module.read_init(init)


def test_mcit_db_import_of_a_symlink_loop_is_one_line_not_a_bug(tmp_path, capsys):
    from app.cli import main

    (tmp_path / "a.cao").symlink_to("b.cao")
    (tmp_path / "b.cao").symlink_to("a.cao")
    top = tmp_path / "top.cao"
    top.write_text('V1\nload("a.cao")\n0\n0\n0\n0\n')
    db = tmp_path / "site.sqlite"
    assert main(["db", "import", str(top), "--db", str(db)]) == 1
    err = capsys.readouterr().err
    assert err == (
        f"mcit db import: error: {top}:2: {tmp_path / 'a.cao'} is a loop of symbolic links that never reaches "
        "a file; point the link at the model file\n"
    )
    assert not db.exists()


HUGE_COUNTS = [
    ("V1\n1000000000000000\n0 0 0\n", 2, "number of points"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n1000000000\n0 1\n", 6, "number of lines"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n1000000000\n3 0 1 2\n", 7, "number of faces from lines"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1000000000\n3 0 1 2\n", 8, "number of faces from points"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n100000000000000\n3 0 1 2\n", 8, "number of faces from points"),
    (
        "V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n100000000000000 0 1 2\n",
        9,
        "face 0: expected 100000000000001 numbers, got 4",
    ),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n1000000000 0 1 2\n", 9, "face 0: expected 1000000001 numbers, got 4"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n3 0 1 2\n1000000000\n", 10, "number of cylinders"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n3 0 1 2\n0\n1000000000\n1 0 1 2\n", 11, "number of circles"),
    ("V1\n" + "9" * 5000 + "\n", 2, "number of points: value 1 is not an integer"),
]


@pytest.mark.parametrize("text, line, problem", HUGE_COUNTS)
def test_huge_counts_are_refused_with_file_and_line_before_allocating(tmp_path, text, line, problem):
    f = tmp_path / "huge.cao"
    f.write_text(text)
    tracemalloc.start()
    try:
        with pytest.raises(CaoError) as info:
            read_cao(f)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    msg = _one_line(info)
    assert msg.startswith(f"{f}:{line}: ") and problem in msg, msg
    assert peak < 2**20, f"{peak / 2**20:.1f} MB allocated before refusing"


DEGENERATE = [
    ("V1\n3\n0 0 0\n0 0 0\n0 0 0\n0\n0\n1\n3 0 1 2\n", 9, "face 0: its points 0 and 1 are at the same place"),
    ("V1\n4\n0 0 0\n1 0 0\n1 1 0\n1 0 0\n0\n0\n1\n4 0 1 2 3\n", 10, "face 0: its points 1 and 3 are at the same place"),
    ("V1\n3\n0 0 0\n1 0 0\n2 0 0\n0\n0\n1\n3 0 1 2\n", 9, "face 0 has no area"),
    ("V1\n3\n0 0 0\n1 0 0\n2 1e-12 0\n0\n0\n1\n3 0 1 2\n", 9, "face 0 has no area"),
    (
        "V1\n4\n0 0 0\n1 1 0\n1 0 0\n0 1 0\n0\n0\n1\n4 0 1 2 3\n",
        10,
        "face 0 has no area",
    ),  # a bow tie folds over itself
    ("V1\n3\n0 0 0\n1 0 0\n2 0 0\n3\n0 1\n1 2\n2 0\n1\n3 0 1 2\n0\n0\n", 11, "face 0 has no area"),  # from lines
    ("V1\n2\n0 0 0\n0 0 0\n1\n0 1\n0\n0\n", 6, "line 0: its points 0 and 1 are at the same place"),
    ("V1\n3\n0 0 0\n1e300 0 0\n0 1e300 0\n0\n0\n1\n3 0 1 2\n", 4, "point 1 is beyond ±1e+06 m"),
    ("V1\n3\n0 0 0\n1000001 0 0\n0 1 0\n0\n0\n1\n3 0 1 2\n", 4, "point 1 is beyond ±1e+06 m"),
    ("V1\n3\n0 0 0\n1 0 0\n0 nan 0\n0\n0\n1\n3 0 1 2\n", 5, "point 2: value 2 is not finite"),
    ("V1\n3\n0 0 0\n1 0 0\n0 -inf 0\n0\n0\n1\n3 0 1 2\n", 5, "point 2: value 2 is not finite"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1e999 0\n0\n0\n1\n3 0 1 2\n", 5, "point 2: value 2 is not finite"),
    ("V1\n2\n0 0 0\n0 0 1\n0\n0\n0\n1\n0 1 1e300\n", 9, "cylinder 0: the radius is beyond"),
    ("V1\n2\n0 0 0\n0 0 1e-12\n0\n0\n0\n1\n0 1 0.1\n", 9, "cylinder 0: needs two distinct axis endpoints"),
    ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n0\n0\n1\n1e300 0 1 2\n", 11, "circle 0: the radius is beyond"),
    ('V1\nload("t.cao", t=[1e300; 0; 0])\n0\n0\n0\n0\n', 2, "value 1 of t=[...] is not finite or beyond"),
    ('V1\nload("t.cao", tu=[0; nan; 0])\n0\n0\n0\n0\n', 2, "value 2 of tu=[...] is not finite"),
    (
        'V1\nload("t.cao", t=[999999.5; 0; 0])\n0\n0\n0\n0\n',
        2,
        "the included model, placed by its t= and rotation, reaches beyond",
    ),
]


@pytest.mark.parametrize("text, line, problem", DEGENERATE)
def test_degenerate_geometry_is_refused_with_file_and_line(tmp_path, text, line, problem):
    (tmp_path / "t.cao").write_text(TRIANGLE)
    f = tmp_path / "bad.cao"
    f.write_text(text)
    with pytest.raises(CaoError) as info:
        read_cao(f)
    msg = _one_line(info)
    assert msg.startswith(f"{f}:{line}: ") and problem in msg, msg


@pytest.mark.parametrize("suffix", [".cao", ".obj", ".stl", ".glb"])
def test_thin_but_real_faces_load_export_and_read_back(tmp_path, suffix):
    # a 1 m × 1 µm sliver is real geometry: kept
    f = tmp_path / "ok.cao"
    f.write_text("V1\n4\n0 0 0\n1 0 0\n0.5 1e-6 0\n0.5 0 1\n0\n0\n2\n3 0 1 2\n3 0 1 3\n0\n0\n")
    m = read_cao(f)
    assert len(m.faces) == 2
    save_model(m, tmp_path / f"out{suffix}")
    back = load_model(tmp_path / f"out{suffix}")
    assert (
        back == m
        if suffix == ".cao"
        else (len(back.vertices) == 4 and np.allclose(back.bounds(), m.bounds(), atol=1e-7))
    )


def test_a_model_1000_km_away_loads_and_round_trips(tmp_path):
    f = tmp_path / "far.cao"
    f.write_text(
        "V1\n4\n999999 0 0\n1000000 0 0\n999999 1 0\n999999 0 -1e6\n1\n0 3\n0\n1\n3 0 1 2\n1\n0 2 0.1\n1\n0.5 0 1 2\n"
    )
    m = read_cao(f)
    save_model(m, tmp_path / "out.cao")
    assert _same(read_cao(tmp_path / "out.cao"), m)


def _same(a, b) -> bool:
    """Equal models; a circle's normal to rounding (the writer stores it as two points on the rim)."""
    polyhedra = np.array_equal(a.vertices, b.vertices) and np.array_equal(a.edges, b.edges) and a.faces == b.faces
    solids = len(a.solids) == len(b.solids) and all(
        np.array_equal(s.p0, t.p0) and np.array_equal(s.p1, t.p1) and (s.r0, s.r1) == (t.r0, t.r1)
        for s, t in zip(a.solids, b.solids)
    )
    circles = len(a.circles) == len(b.circles) and all(
        np.array_equal(c.centre, d.centre)
        and c.radius == d.radius
        and np.allclose(c.normal, d.normal, rtol=0, atol=1e-9)
        for c, d in zip(a.circles, b.circles)
    )
    return polyhedra and solids and circles


SECRET = "s3cr3t-Root-Passw0rd"
LEAKS = [
    f"root:{SECRET}:0:0:root:/root:/bin/bash\ndaemon:x:1:1\n",  # a system file
    f"{SECRET}\n",
    f"V1\n2\n0 0 0\n1 {SECRET} 0\n",
    f"V1\n{SECRET}\n",
    f"V1\n2\n0 0 0\n0 0 1\n1\n0 {SECRET}\n0\n0\n",
    f"V1\n2\n0 0 0\n0 0 1\n1\n0 1 useLod={SECRET}\n0\n0\n",
    f"V1\n2\n0 0 0\n0 0 1\n1\n0 1 minLineLengthThreshold={SECRET}\n0\n0\n",
    f"V1\n2\n0 0 0\n0 0 1\n1\n0 1\n0\n0\n0\n0\n{SECRET}\n",
    f'V1\nload("t.cao", {SECRET}=[1; 2; 3])\n0\n0\n0\n0\n',
    f'V1\nload("t.cao", t=[{SECRET}; 2; 3])\n0\n0\n0\n0\n',
    f'V1\nload("t.cao", t=[{SECRET}])\n0\n0\n0\n0\n',
    f'V1\nload("t.cao" {SECRET})\n0\n0\n0\n0\n',
    f"V{SECRET}\n",
]


@pytest.mark.parametrize("text", LEAKS)
def test_errors_quote_nothing_of_the_file(tmp_path, text):
    (tmp_path / "t.cao").write_text(TRIANGLE)
    f = tmp_path / "bad.cao"
    f.write_text(text)
    with pytest.raises(CaoError) as info:
        read_cao(f)
    msg = _one_line(info)
    assert msg.startswith(f"{f}:") and SECRET not in msg, msg


def test_an_include_naming_a_system_file_does_not_echo_it(tmp_path):
    secret = tmp_path / "passwd"
    secret.write_text(f"root:{SECRET}:0:0:root:/root:/bin/bash\n")
    binary = tmp_path / "key.bin"
    binary.write_bytes(b"\xff\xfe" + SECRET.encode() + b"\x00\x81")
    for target in [secret, binary] + [Path("/etc/passwd")] * Path("/etc/passwd").is_file():
        top = tmp_path / "top.cao"
        top.write_text(f'V1\nload("{target}")\n0\n0\n0\n0\n')
        with pytest.raises(CaoError) as info:
            read_cao(top)
        msg = _one_line(info)
        assert msg.startswith(f"{target}:1: not a .cao model"), msg
        first = target.read_bytes().split(b"\n")[0].decode("utf-8", "replace")
        assert (
            SECRET not in msg and first not in msg and first.split(":")[0] + ":" not in msg.replace(f"{target}:", "")
        ), msg


# --- fuzz: random .cao text, structured enough to reach every block ---

_TOKENS = [
    "0",
    "1",
    "-1",
    "2",
    "3",
    "0.5",
    "1e-12",
    "1e300",
    "nan",
    "-inf",
    "1000001",
    "4294967296",
    "x",
    SECRET,
    "3.5",
    "-0",
]


@st.composite
def cao_texts(draw):
    n_points = draw(st.integers(0, 6))
    coord = st.sampled_from(["0", "1", "-1", "0.5", "2", "1e-10", "999999", "3"])
    points = [" ".join(draw(st.lists(coord, min_size=3, max_size=3))) for _ in range(n_points)]
    idx = st.integers(0, max(n_points - 1, 0)).map(str)
    lines = [f"{draw(idx)} {draw(idx)}" for _ in range(draw(st.integers(0, 4)))]
    idx_l = st.integers(0, max(len(lines) - 1, 0)).map(str)
    fl = [" ".join([str(k)] + [draw(idx_l) for _ in range(k)]) for k in draw(st.lists(st.integers(3, 4), max_size=2))]
    fp = [" ".join([str(k)] + [draw(idx) for _ in range(k)]) for k in draw(st.lists(st.integers(3, 5), max_size=3))]
    cyl = [
        f"{draw(idx)} {draw(idx)} {draw(st.sampled_from(['0.1', '1', '-1', '0']))}"
        for _ in range(draw(st.integers(0, 2)))
    ]
    circ = [
        f"{draw(st.sampled_from(['0.1', '2']))} {draw(idx)} {draw(idx)} {draw(idx)}"
        for _ in range(draw(st.integers(0, 2)))
    ]
    loads = [
        f'load("t.cao", t=[{draw(coord)}; 0; 0], tu=[0; {draw(coord)}deg; 0])' for _ in range(draw(st.integers(0, 2)))
    ]
    out = ["V1"] + loads
    for block in (points, lines, fl, fp, cyl, circ):
        out += [str(len(block))] + block
    # then damage it: replace tokens, drop or repeat lines, change a count
    for _ in range(draw(st.integers(0, 3))):
        k = draw(st.integers(0, len(out) - 1))
        tokens = out[k].split(" ")
        action = draw(st.sampled_from(["token", "drop", "repeat", "append"]))
        if action == "token":
            tokens[draw(st.integers(0, len(tokens) - 1))] = draw(st.sampled_from(_TOKENS))
            out[k] = " ".join(tokens)
        elif action == "drop" and len(out) > 1:
            out.pop(k)
        elif action == "repeat":
            out.insert(k, out[k])
        else:
            out[k] += " " + draw(st.sampled_from(_TOKENS + ["name=a", "useLod=true", f"name={SECRET}"]))
    return "\n".join(out) + "\n"


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=cao_texts())
# found by this test: a circle whose centre is within ±1e6 m and whose rim is not loaded, and its export did
# not read back
@example(text="V1\n4\n0 1 0\n0 0 0\n0 0 999999\n0 0 0\n0\n0\n0\n2\n0 1 0.1\n0 1 0.1\n2\n0.1 0 0 0\n2 2 1 0\n")
@example(text="V1\n2\n0 0 999999.5\n0 0 999999\n0\n0\n0\n1\n0 1 1\n0\n")  # and a cylinder's side
def test_fuzz_any_text_loads_cleanly_or_is_refused_in_one_line(tmp_path, text):
    (tmp_path / "t.cao").write_text(TRIANGLE)
    f = tmp_path / "fuzz.cao"
    f.write_text(text)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            m = read_cao(f)
        except CaoError as exc:
            msg = str(exc)
            assert msg.startswith(f"{f}:") and "\n" not in msg and SECRET not in msg, msg
            m = None
    assert all(SECRET not in str(w.message) and "\n" not in str(w.message) for w in caught)
    if m is None:
        return
    # what loads is sane and survives its own export
    assert np.all(np.isfinite(m.vertices)) and np.abs(m.vertices).max(initial=0) <= 2e6
    for face in m.faces:
        Q = m.vertices[list(face)]
        assert np.linalg.norm(np.cross(Q, np.roll(Q, -1, axis=0)).sum(axis=0)) > 0
    g = tmp_path / "again.cao"
    g.write_text(cao_text(m))
    assert _same(read_cao(g), m)


@pytest.fixture
def faces_checked(monkeypatch):
    """The faces the parser built (checked) during the test."""
    calls = []
    real = cao_module._check_face

    def counting(lines, number, k, P, loop):
        calls.append(k)
        return real(lines, number, k, P, loop)

    monkeypatch.setattr(cao_module, "_check_face", counting)
    return calls


SQUARE = "V1\n4\n0 0 0\n1 0 0\n0 1 0\n1 1 0\n0\n0\n"


@pytest.mark.parametrize(
    "text, line, problem",
    [
        # 999,996 faces over 4 points (8 MB) took 10 min and 854 MB
        (SQUARE + "200001\n" + "3 0 1 2\n" * 200_001, 9, "the faces from points make the model hold 200,001 faces"),
        (SQUARE[:-2] + "200001\n" + "3 0 1 2\n" * 200_001, 8, "the faces from lines make the model hold 200,001 faces"),
        # one face over 10^6 points (34 MB) took 3 min and 1.23 GB
        (
            "V1\n1000000\n" + "0 0 0\n" * 1_000_000 + "0\n0\n1\n1000000 " + " ".join(map(str, range(10**6))) + "\n",
            2,
            "the points make the model hold 1,000,000 points, more than 600,000",
        ),
        (
            SQUARE + "1\n600001 " + "0 1 2 3 " * 150_001 + "\n",
            10,
            "the points of face 0 make the model hold 600,001 face indices, more than 600,000",
        ),
        ("V1\n3\n0 0 0\n1 0 0\n0 1 0\n600001\n" + "0 1\n" * 600_001, 6, "hold 600,001 lines, more than 600,000"),
    ],
    ids=["faces from points", "faces from lines", "points", "one face's points", "lines"],
)
def test_a_model_beyond_the_mesh_limits_is_refused_when_its_count_is_read(tmp_path, faces_checked, text, line, problem):
    f = tmp_path / "big.cao"
    f.write_text(text)
    start = time.monotonic()
    with pytest.raises(CaoError) as info:
        read_cao(f)
    assert time.monotonic() - start < 2.0
    msg = _one_line(info)
    assert msg.startswith(f"{f}:{line}: ") and problem in msg and "mcit's limit for one model" in msg, msg
    assert faces_checked == []


def test_the_limits_count_every_file_of_the_model_includes_and_repeats_too(tmp_path, monkeypatch):
    monkeypatch.setitem(cao_module.MAX_COUNTS, "faces", 3)
    (tmp_path / "t.cao").write_text(TRIANGLE)  # one face
    top = tmp_path / "top.cao"
    top.write_text("V1\n" + 'load("t.cao")\n' * 3 + "0\n0\n0\n0\n")
    assert len(read_cao(top).faces) == 3
    top.write_text("V1\n" + 'load("t.cao")\n' * 4 + "0\n0\n0\n0\n")
    with pytest.raises(CaoError) as info:
        read_cao(top)
    assert _one_line(info).startswith(f"{top}:5: the model holds 4 faces with this include, more than 3")
    top.write_text("V1\n" + 'load("t.cao")\n' * 3 + "3\n0 0 0\n1 0 0\n0 1 0\n0\n0\n1\n3 0 1 2\n")
    with pytest.raises(CaoError) as info:
        read_cao(top)
    assert _one_line(info).startswith(f"{top}:11: the faces from points make the model hold 4 faces, more than 3")
