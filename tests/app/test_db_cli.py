"""``mcit db …`` end to end, and the real models' round trip import → database → export → import."""

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.db import Database
from app.models_io import load_model, read_cao
from core.brep import BRep


def _mcit(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize("folder, name", [("visp-teabox", "teabox.cao"), ("visp-cube", "cube_and_cylinder.cao")])
def test_real_models_round_trip_through_the_database(shared_data, tmp_path, capsys, folder, name):
    src = shared_data(folder, name)
    db = str(tmp_path / "site.sqlite")
    code, out, err = _mcit(
        capsys, "db", "import", str(src), "--db", db, "--xyz", "0.1", "0.2", "0.0", "--rpy-deg", "0", "0", "30"
    )
    assert code == 0, err
    stem = src.stem
    for suffix in (".cao", ".obj", ".glb"):
        out_file = tmp_path / f"back{suffix}"
        code, out, err = _mcit(capsys, "db", "export", stem, str(out_file), "--db", db)
        assert code == 0, err
        if suffix == ".cao":
            assert read_cao(out_file) == read_cao(src)  # identical geometry, bit for bit
        else:  # surfaces: the polyhedral edges come back through the dihedral-angle reduction
            back, orig = load_model(out_file), read_cao(src)
            poly = {tuple(sorted(map(tuple, np.round(s, 6)))) for s in orig.edge_segments()}
            got = {tuple(sorted(map(tuple, np.round(s, 6)))) for s in back.edge_segments()}
            assert poly <= got and len(got - poly) == 96 * len(orig.solids)  # + the two 48-gon rims of a cylinder
    with Database.open(db) as d:
        rec = d.get(stem)
        assert rec.model == read_cao(src) and rec.source == str(src.resolve()) and rec.status == "known"
        assert np.allclose(rec.T_world_obj[:3, 3], [0.1, 0.2, 0.0])
    # exported in the world frame, the model carries its pose
    code, _, err = _mcit(capsys, "db", "export", stem, str(tmp_path / "world.cao"), "--world", "--db", db)
    assert code == 0, err
    world = read_cao(tmp_path / "world.cao")
    assert np.allclose(world.vertices, read_cao(src).transformed(rec.T_world_obj).vertices)


def test_init_list_show_history_undo(tmp_path, capsys):
    db = str(tmp_path / "site.sqlite")
    code, out, _ = _mcit(capsys, "db", "init", "--db", db)
    assert code == 0 and "parallelepiped" in out
    code, out, _ = _mcit(capsys, "db", "list", "--db", db)
    assert code == 0 and "parallelepiped" in out and "table" in out
    code, out, _ = _mcit(capsys, "db", "show", "parallelepiped", "--db", db)
    assert code == 0 and "size_x = 0.3500 m" in out and "T_world_obj" in out
    with Database.open(db) as d:
        rec = d.get("parallelepiped")
        T = np.array(rec.T_world_obj)
        T[:3, 3] += [0.05, 0.0, 0.0]
        change = d.update_pose(
            rec, T, np.eye(6) * 1e-6, expected_version=rec.version, method="p3l+refine", client="viser:1"
        )
    code, out, _ = _mcit(capsys, "db", "history", "parallelepiped", "--db", db)
    assert code == 0 and "p3l+refine" in out and "viser:1" in out
    last = Database.open(db).history()[-1].id
    code, out, _ = _mcit(capsys, "db", "undo", str(last), "--db", db)
    assert code == 0 and f"before change #{last}" in out
    with Database.open(db) as d:
        assert (
            np.array_equal(d.get("parallelepiped").T_world_obj, rec.T_world_obj)
            and d.get("parallelepiped").version == 3
        )
    code, out, _ = _mcit(capsys, "db", "undo", str(last), "--restore", "--db", db)
    with Database.open(db) as d:
        assert np.array_equal(d.get("parallelepiped").T_world_obj, change.T_world_obj)
        n_changes = len(d.history(limit=100_000))
    # undoing the pose change again would discard the two changes after it: asked for, nothing written
    code, _, err = _mcit(capsys, "db", "undo", str(last), "--db", db)
    assert code == 1 and "discards the 2 later changes" in err and "add --yes" in err and len(err.splitlines()) == 1
    with Database.open(db) as d:
        assert len(d.history(limit=100_000)) == n_changes
    code, out, _ = _mcit(capsys, "db", "undo", str(last), "--yes", "--db", db)
    assert code == 0 and f"before change #{last}" in out
    with Database.open(db) as d:
        assert np.array_equal(d.get("parallelepiped").T_world_obj, rec.T_world_obj)


def test_a_malformed_model_writes_nothing(tmp_path, capsys):
    db = tmp_path / "site.sqlite"
    bad = tmp_path / "bad.cao"
    bad.write_text("V1\n2\n0 0 0\n1 0 0\n1\n0 9\n0\n0\n")
    code, _, err = _mcit(capsys, "db", "import", str(bad), "--db", str(db))
    assert code == 1 and f"{bad}:6: point index 9 out of range" in err
    assert not db.exists()  # the model is read before the database is opened
    Database.open(db).close()
    code, _, err = _mcit(capsys, "db", "import", str(bad), "--db", str(db))
    assert code == 1
    conn = sqlite3.connect(db)
    assert conn.execute("SELECT count(*) FROM objects").fetchone()[0] == 0
    assert conn.execute("SELECT count(*) FROM history").fetchone()[0] == 0


def test_cli_errors_are_one_line_and_exit_1(tmp_path, capsys):
    db = str(tmp_path / "site.sqlite")
    code, _, err = _mcit(capsys, "db", "show", "ghost", "--db", db)  # a read: the file is not created
    assert code == 1 and "there is no database at" in err and "mcit db init" in err and not Path(db).exists()
    code, _, err = _mcit(capsys, "db", "undo", "42", "--db", db)
    assert code == 1 and "no change #42" in err
    code, _, err = _mcit(capsys, "db", "show", "ghost", "--db", db)
    assert code == 1 and "no object 'ghost'" in err and "mcit db list names the objects" in err
    not_db = tmp_path / "notes.txt"
    not_db.write_text("hello\n" * 100)
    code, _, err = _mcit(capsys, "db", "list", "--db", str(not_db))
    assert code == 1 and "will not touch it" in err and not_db.read_text() == "hello\n" * 100
    with Database.open(db) as d:
        d.add_object("cone", "cone", BRep.cone(0.1, 0.05, 0.2), np.eye(4))
    code, _, err = _mcit(capsys, "db", "export", "cone", str(tmp_path / "cone.cao"), "--db", db)
    assert code == 1 and "cone" in err and "glTF" in err
    code, _, err = _mcit(capsys, "db", "export", "cone", str(tmp_path / "cone.glb"), "--db", db)
    assert code == 0
    code, _, err = _mcit(capsys, "db", "import", str(tmp_path / "cone.glb"), "--name", "cone", "--db", db)
    assert code == 1 and err == (
        "mcit db import: error: an object named 'cone' already exists: give the import another name with --name NAME "
        "(a new pose of 'cone' itself: Update pose in mcit serve)\n"
    )


def _disk_full_after(n_bytes: int, real_writer):
    """A writer that writes the first ``n_bytes`` of what ``real_writer`` would, then fails as a full disk does."""
    import errno

    def writer(model, path, *args, **kwargs):
        real_writer(model, path, *args, **kwargs)
        data = Path(path).read_bytes()
        Path(path).write_bytes(data[:n_bytes])
        raise OSError(errno.ENOSPC, "No space left on device")

    return writer


@pytest.mark.parametrize("suffix", [".cao", ".glb"])
@pytest.mark.parametrize("existing", [None, b"the previous export\n"])
def test_export_on_a_full_disk_leaves_out_as_it_was(tmp_path, capsys, monkeypatch, suffix, existing):
    import app.models_io as models_io

    db = str(tmp_path / "site.sqlite")
    assert _mcit(capsys, "db", "init", "--db", db)[0] == 0
    folder = tmp_path / "out"
    folder.mkdir()
    out = folder / f"model{suffix}"
    if existing is not None:
        out.write_bytes(existing)
    name = "write_cao" if suffix == ".cao" else "save_model"
    monkeypatch.setattr(models_io, name, _disk_full_after(100, getattr(models_io, name)))
    code, stdout, err = _mcit(capsys, "db", "export", "parallelepiped", str(out), "--db", db)
    assert code == 1 and stdout == ""
    assert err == (
        f"mcit db export: error: {out}: No space left on device (nothing was written); free some space and try again\n"
    )
    assert [p.name for p in folder.iterdir()] == ([] if existing is None else [out.name])  # no temporary left
    if existing is not None:
        assert out.read_bytes() == existing


def test_export_is_interrupted_cleanly_and_then_replaces_the_file(tmp_path, capsys, monkeypatch):
    import app.models_io as models_io

    db = str(tmp_path / "site.sqlite")
    assert _mcit(capsys, "db", "init", "--db", db)[0] == 0
    out = tmp_path / "box.cao"
    out.write_text("old\n")
    real = models_io.write_cao

    def interrupted(model, path, *args, **kwargs):
        Path(path).write_text("V1\n")
        raise KeyboardInterrupt

    monkeypatch.setattr(models_io, "write_cao", interrupted)
    assert _mcit(capsys, "db", "export", "parallelepiped", str(out), "--db", db)[0] == 130
    assert out.read_text() == "old\n" and sorted(p.name for p in tmp_path.iterdir()) == ["box.cao", "site.sqlite"]
    monkeypatch.setattr(models_io, "write_cao", real)
    assert _mcit(capsys, "db", "export", "parallelepiped", str(out), "--db", db)[0] == 0
    assert len(read_cao(out).faces) == 6 and sorted(p.name for p in tmp_path.iterdir()) == ["box.cao", "site.sqlite"]


def test_export_errors_name_the_file_not_its_temporary(tmp_path, capsys):
    db = str(tmp_path / "site.sqlite")
    edges = tmp_path / "edges.cao"
    edges.write_text("V1\n3\n0 0 0\n1 0 0\n0 1 0\n2\n0 1\n1 2\n0\n0\n")  # two lines, no face
    with Database.open(db) as d:
        d.add_object("wire", "polyhedron", read_cao(edges), np.eye(4))
    out = tmp_path / "wire.stl"
    code, _, err = _mcit(capsys, "db", "export", "wire", str(out), "--db", db)
    assert code == 1 and err == (
        f"mcit db export: error: {out}: the model has no surface to export (edges or circles only); export it as .cao\n"
    )
    code, _, err = _mcit(capsys, "db", "export", "wire", str(tmp_path / "no-folder" / "wire.cao"), "--db", db)
    assert code == 1 and err == (
        f"mcit db export: error: {tmp_path / 'no-folder' / 'wire.cao'}: No such file or directory "
        "(nothing was written); check the path\n"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["edges.cao", "site.sqlite"]


def test_terminal_escapes_in_the_database_are_printed_as_codes(tmp_path, capsys):
    """A name or operator holding terminal control (an old or hostile database) would retitle or clear
    the user's terminal: db list and history print it as \\x1b codes."""
    db = str(tmp_path / "site.sqlite")
    assert main(["db", "init", "--db", db]) == 0
    with sqlite3.connect(db) as conn:
        conn.execute("UPDATE objects SET name = ? WHERE name = 'table'", ("t\x1b]0;pwned\x07\x1b[2J",))
        conn.execute("UPDATE history SET client = ?", ("op\x1b[7m",))
    capsys.readouterr()
    for command in (["db", "list"], ["db", "history"]):
        assert main([*command, "--db", db]) == 0
        out = capsys.readouterr().out
        assert "\x1b" not in out and "\x07" not in out, out
    assert main(["db", "list", "--db", db]) == 0
    assert "t\\x1b]0;pwned\\x07\\x1b[2J" in capsys.readouterr().out
