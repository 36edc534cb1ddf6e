"""The database against the disk and other programs (app/db/storage.py): read-only files, folders and
mounts, a full disk, a write error, a database locked by another writer. Each failure is one line,
exit status 1, the data intact and no file left beside the database; reads work on what cannot be
written.

Real conditions where this machine allows them: chmod (or, for root, whom chmod does not stop, the
immutable attribute), a read-only bind mount and a full tmpfs inside a user namespace (`unshare`),
RLIMIT_FSIZE, a second process holding the write lock. Where a condition cannot be made here the
test is skipped, and a simulation (monkeypatched) checks the same path in every run.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import sqlite3
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from app.cli import main
from app.db import Database, DatabaseUnavailable, storage
from core.brep import BRep

ROOT = Path(__file__).resolve().parents[2]
READS = (("list",), ("history",), ("show", "parallelepiped"))


def _mcit(capsys, *argv):
    code = main(list(argv))
    out = capsys.readouterr()
    return code, out.out, out.err


def _files(folder: Path) -> dict[str, str]:
    """Every file of ``folder`` with its content's digest (what 'nothing written, nothing left' means)."""
    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir()) if p.is_file()}


def _one_line_error(code: int, err: str, *needles: str) -> None:
    assert code == 1, err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    assert "not an SQLite database" not in err and "restore a backup" not in err.lower(), err


def _site(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / "site.sqlite"
    assert main(["db", "init", "--db", str(path)]) == 0
    return path


@contextmanager
def _read_only(path: Path):
    """Make ``path`` (a file or a folder) read-only for this process, for real: chmod for a user; for
    root, whom chmod does not stop, the immutable attribute (chattr +i). Skips when neither works."""
    if os.geteuid() != 0:
        mode = path.stat().st_mode
        path.chmod(0o555 if path.is_dir() else 0o444)
        try:
            yield
        finally:
            path.chmod(mode)
        return
    if not shutil.which("chattr") or subprocess.run(["chattr", "+i", str(path)], capture_output=True).returncode:
        pytest.skip(
            "as root a read-only file needs the immutable attribute (chattr +i), which this file system refuses"
        )
    try:
        assert not os.access(path, os.W_OK)
        yield
    finally:
        subprocess.run(["chattr", "-i", str(path)], check=True)


def _check_reads_work_and_writes_refused(capsys, path: Path, tmp_path: Path, refusal: str) -> None:
    before = _files(path.parent)
    for argv in READS:
        code, out, err = _mcit(capsys, "db", *argv, "--db", str(path))
        assert code == 0 and err == "" and "parallelepiped" in out, (argv, err)
    out_file = tmp_path / "out" / "box.cao"
    out_file.parent.mkdir(exist_ok=True)
    code, _, err = _mcit(capsys, "db", "export", "parallelepiped", str(out_file), "--db", str(path))
    assert code == 0 and out_file.stat().st_size > 0, err
    poses = tmp_path / "out" / "poses.json"  # export-poses only reads too
    code, _, err = _mcit(capsys, "db", "export-poses", str(poses), "--db", str(path))
    assert code == 0 and "parallelepiped" in poses.read_text(), err
    for argv in (("undo", "1"), ("init",), ("import", str(out_file))):
        code, _, err = _mcit(capsys, "db", *argv, "--db", str(path))
        _one_line_error(code, err, refusal, "nothing was written")
    assert _files(path.parent) == before  # same bytes, no -wal/-shm left beside it


def test_a_read_only_file_is_read_and_never_written(tmp_path, capsys):
    path = _site(tmp_path / "site")
    with _read_only(path):
        _check_reads_work_and_writes_refused(capsys, path, tmp_path, "is read-only")
    code, _, err = _mcit(capsys, "db", "undo", "1", "--db", str(path))  # writable again: it works
    assert code == 0, err


def test_a_read_only_folder_is_read_and_never_written(tmp_path, capsys):
    path = _site(tmp_path / "site")
    with _read_only(path.parent):
        _check_reads_work_and_writes_refused(capsys, path, tmp_path, "folder")
        code, _, err = _mcit(capsys, "db", "init", "--db", str(path.parent / "new.sqlite"))
        _one_line_error(code, err, "cannot create", "nothing was written")
        assert not (path.parent / "new.sqlite").exists()


def _unshare(script: str) -> subprocess.CompletedProcess:
    """Run ``script`` (sh) in a new user and mount namespace, where this user may mount."""
    if not shutil.which("unshare"):
        pytest.skip("no unshare here: a read-only mount or a full disk cannot be made")
    probe = subprocess.run(["unshare", "--user", "--map-root-user", "--mount", "true"], capture_output=True)
    if probe.returncode:
        pytest.skip(f"user namespaces are not allowed here ({probe.stderr.decode().strip()})")
    return subprocess.run(
        ["unshare", "--user", "--map-root-user", "--mount", "sh", "-c", script],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )


def _mcit_sh(*argv) -> str:
    words = " ".join(f"'{a}'" for a in argv)
    return f"'{sys.executable}' -m app.cli {words}"


def test_a_read_only_mount_is_read_and_never_written(tmp_path):
    path = _site(tmp_path / "site")
    before = _files(path.parent)
    mnt = tmp_path / "mnt"
    mnt.mkdir()
    ro = mnt / path.name
    script = " && ".join(
        [
            f"mount --bind '{path.parent}' '{mnt}'",
            f"mount -o remount,ro,bind '{mnt}'",
            f"{_mcit_sh('db', 'list', '--db', ro)} > '{tmp_path}/list.out' 2> '{tmp_path}/list.err'",
            f"{_mcit_sh('db', 'history', '--db', ro)} > /dev/null",
            f"! {_mcit_sh('db', 'undo', '1', '--db', ro)} 2> '{tmp_path}/undo.err'",
            f"! {_mcit_sh('db', 'init', '--db', mnt / 'new.sqlite')} 2> '{tmp_path}/init.err'",
        ]
    )
    run = _unshare(script)
    if run.returncode and "mount" in run.stderr and not (tmp_path / "list.out").exists():
        pytest.skip(f"cannot make a read-only bind mount here: {run.stderr.strip()}")
    assert run.returncode == 0, (run.stdout, run.stderr)
    assert "parallelepiped" in (tmp_path / "list.out").read_text() and (tmp_path / "list.err").read_text() == ""
    _one_line_error(1, (tmp_path / "undo.err").read_text(), "read-only file system", "nothing was written")
    _one_line_error(1, (tmp_path / "init.err").read_text(), "cannot create", "nothing was written")
    assert _files(path.parent) == before and not (path.parent / "new.sqlite").exists()


def test_a_read_only_mount_simulated(tmp_path, capsys, monkeypatch):
    """The same as above where a mount cannot be made: the folder reports ST_RDONLY and access()
    refuses writes under it, as the kernel does on a read-only mount (SQLite itself could still
    write: the test shows mcit never asks it to)."""
    path = _site(tmp_path / "site")
    folder = str(path.parent)
    real_access, real_statvfs = os.access, os.statvfs

    def access(p, mode, *a, **k):
        if mode & os.W_OK and str(Path(p).resolve()).startswith(folder):
            return False
        return real_access(p, mode, *a, **k)

    class ReadOnlyStat:
        def __init__(self, st):
            self._st = st
            self.f_flag = st.f_flag | os.ST_RDONLY

    monkeypatch.setattr(os, "access", access)
    monkeypatch.setattr(
        os, "statvfs", lambda p: ReadOnlyStat(real_statvfs(p)) if str(p).startswith(folder) else real_statvfs(p)
    )
    _check_reads_work_and_writes_refused(capsys, path, tmp_path, "read-only file system")


def test_an_older_read_only_database_is_refused_in_one_line(tmp_path, capsys):
    from tests.app.test_db_files import _v1_database

    path = tmp_path / "site" / "v1.sqlite"
    path.parent.mkdir()
    _v1_database(path)
    before = _files(path.parent)
    with _read_only(path):
        code, _, err = _mcit(capsys, "db", "list", "--db", str(path))
        _one_line_error(code, err, "older mcit", "make it writable once")
    assert _files(path.parent) == before
    code, out, err = _mcit(capsys, "db", "list", "--db", str(path))  # writable: upgraded once, then read
    assert code == 0 and "parallelepiped" in out, err


def _big_mesh(path: Path, n: int = 60) -> Path:
    """A closed sphere-like OBJ of n² vertices: a model of several hundred kB in the database."""
    lines = []
    for i in range(n):
        for j in range(n):
            th, ph = np.pi * (i + 0.5) / n, 2 * np.pi * j / n
            lines.append(f"v {np.sin(th) * np.cos(ph):.6f} {np.sin(th) * np.sin(ph):.6f} {np.cos(th):.6f}")
    for i in range(n - 1):
        for j in range(n):
            a, b, c, d = i * n + j + 1, i * n + (j + 1) % n + 1, (i + 1) * n + (j + 1) % n + 1, (i + 1) * n + j + 1
            lines += [f"f {a} {b} {c}", f"f {a} {c} {d}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_a_full_disk_changes_nothing(tmp_path):
    """A real full disk: a 400 kB tmpfs, most of it taken by a filler file."""
    big = _big_mesh(tmp_path / "big.obj")
    disk = tmp_path / "disk"
    disk.mkdir()
    path = disk / "site.sqlite"
    script = " && ".join(
        [
            f"mount -t tmpfs -o size=400k tmpfs '{disk}'",
            f"{_mcit_sh('db', 'init', '--db', path)} > /dev/null",
            f"sha256sum '{path}' > '{tmp_path}/before'",
            f"head -c 250000 /dev/zero > '{disk}/filler'",
            f"! {_mcit_sh('db', 'import', big, '--db', path)} 2> '{tmp_path}/import.err'",
            f"sha256sum '{path}' > '{tmp_path}/after'",
            f"ls -a '{disk}' > '{tmp_path}/ls'",
            f"rm '{disk}/filler'",
            f"{_mcit_sh('db', 'list', '--db', path)} > '{tmp_path}/list.out'",
        ]
    )
    run = _unshare(script)
    if run.returncode and not (tmp_path / "before").exists():
        pytest.skip(f"cannot mount a small tmpfs here: {run.stderr.strip()}")
    assert run.returncode == 0, (run.stdout, run.stderr)
    _one_line_error(
        1, (tmp_path / "import.err").read_text(), "is full", "nothing was written", "free some space, then try again"
    )
    assert (tmp_path / "before").read_text() == (tmp_path / "after").read_text()
    assert (tmp_path / "ls").read_text().split() == [".", "..", "filler", "site.sqlite"]  # no -wal/-shm left
    listed = (tmp_path / "list.out").read_text()
    assert "parallelepiped" in listed and "big" not in listed


def test_a_full_disk_simulated(tmp_path, capsys, monkeypatch):
    """SQLite's answer on a full disk (SQLITE_FULL) raised inside the write: one line, nothing written."""
    path = _site(tmp_path / "site")
    before = _files(path.parent)

    def full(*args, **kwargs):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr(Database, "_log", full)
    code, _, err = _mcit(capsys, "db", "undo", "1", "--db", str(path))
    _one_line_error(code, err, "is full", "free some space")
    assert _files(path.parent) == before


def test_a_write_error_from_the_disk_changes_nothing(tmp_path):
    """A real write error: the import runs with a 40 kB file-size limit (RLIMIT_FSIZE), so the
    journal cannot grow (EFBIG: SQLite's 'disk I/O error')."""
    big = _big_mesh(tmp_path / "big.obj")
    path = _site(tmp_path / "site")
    before = _files(path.parent)
    code = (
        "import resource, signal, sys\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (40000, 40000))\n"
        "from app.cli import main\n"
        "sys.exit(main(sys.argv[1:]))\n"
    )
    run = subprocess.run(
        [sys.executable, "-c", code, "db", "import", str(big), "--db", str(path)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=120,
    )
    _one_line_error(run.returncode, run.stderr, "reported an error", "nothing was written", "check the disk")
    assert _files(path.parent) == before


HOLDER = r"""
import sqlite3, sys
conn = sqlite3.connect(sys.argv[1], isolation_level=None)
conn.execute("BEGIN IMMEDIATE")
conn.execute("UPDATE objects SET name = name")
print("locked", flush=True)
sys.stdin.readline()
conn.execute("ROLLBACK")
"""


def test_a_database_locked_by_another_writer(tmp_path, capsys):
    path = _site(tmp_path / "site")
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(path), "lock-holder-marker"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        code, _, err = _mcit(capsys, "db", "undo", "1", "--db", str(path), "--wait-s", "0.2")
        _one_line_error(
            code, err, "is locked by another program", f"pid {holder.pid}", "still after 0.2 s", "try again"
        )
        holders = storage.lock_holders(path)
        assert len(holders) == 1 and holders[0].startswith(f"pid {holder.pid}: python") and "-c" in holders[0], holders
        code, out, err = _mcit(capsys, "db", "list", "--db", str(path))  # reads do not wait for the writer
        assert code == 0 and "parallelepiped" in out, err
    finally:
        holder.stdin.write("\n")
        holder.stdin.close()
        holder.wait(30)
    assert storage.lock_holders(path) == []
    with Database.open(path) as db:
        # the seed's two objects and three calibrations (camera, turret, the robot's base): the undo was not written
        assert [h.action for h in db.history()][-1] == "calibration" and len(db.history()) == 5
    code, _, err = _mcit(capsys, "db", "undo", "1", "--db", str(path))
    assert code == 0, err


def test_a_refused_new_database_leaves_no_file(tmp_path, monkeypatch):
    path = tmp_path / "new.sqlite"

    def full(conn, target):
        raise sqlite3.OperationalError("database or disk is full")

    monkeypatch.setattr("app.db.database.migrate", full)
    with pytest.raises(DatabaseUnavailable, match="is full"):
        Database.open(path)
    assert list(tmp_path.iterdir()) == []


def test_a_read_only_database_sees_a_writer_that_opens_it_later(tmp_path, monkeypatch):
    """A database read as on disk (immutable: nobody may write it) switches to an ordinary read when
    a writer shows up after all (a -wal appears), so it never misses a committed change."""
    path = tmp_path / "site.sqlite"
    Database.open(path).close()
    monkeypatch.setattr(storage, "can_write", lambda p: False)
    with Database.open(path, readonly=True) as reader:
        assert reader.objects() == [] and reader._local.immutable
        with Database.open(path) as writer:
            writer.add_object("box", "box", BRep.box(1, 1, 1), np.eye(4))
            assert [o.name for o in reader.objects()] == ["box"] and not reader._local.immutable
        with pytest.raises(DatabaseUnavailable, match="only to be read"):
            reader.set_status("box", "stale")


def test_a_read_of_a_writable_database_takes_locks_and_leaves_nothing(tmp_path, capsys):
    """Where a writer may come, a read is an ordinary (locking) SQLite read, never one 'as on disk';
    and like every read it leaves the folder as it found it."""
    path = _site(tmp_path / "site")
    before = _files(path.parent)
    with Database.open(path, readonly=True) as reader:
        assert [o.name for o in reader.objects()] == ["table", "parallelepiped"] and not reader._local.immutable
    for argv in READS:
        assert _mcit(capsys, "db", *argv, "--db", str(path))[0] == 0
    assert _files(path.parent) == before
