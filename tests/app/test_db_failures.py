"""A write the disk or another program refuses while mcit runs: a full disk, a database locked by
another writer, a read-only database. The database raises one exception (DatabaseUnavailable) whose
message says what happened and what to do, the transaction is rolled back whole (tables and the
in-memory caches), the workflow stays open with its result, and the panel says it in one sentence
with one warning line in the log. Once the cause is gone, the same Accept writes.

How each condition is made here (the tests run as root, whom chmod does not stop):
* a full disk: ``PRAGMA max_page_count`` set to the file's size on the writing connection and the
  room left in its pages taken, so that SQLite's pager answers SQLITE_FULL "database or disk is
  full" as on a real full disk; a full disk met at COMMIT (where WAL mode writes a change's pages)
  by a connection whose COMMIT raises that error;
* a lock: a second sqlite3 connection holding ``BEGIN EXCLUSIVE``, with a 0.2 s busy timeout;
* a read-only file: ``PRAGMA query_only`` on the writing connection (SQLite's own SQLITE_READONLY,
  "attempt to write a readonly database") and ``os.access`` refusing writes to the file, as the
  kernel does for a user on a chmod 0o444 file.
"""

from __future__ import annotations

import errno
import logging
import os
import sqlite3
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from app.db import Database, DatabaseUnavailable, seed_from_scene, storage
from app.scene import default_scene_path, load_scene
from app.ui.client import ClientPanel
from app.workflows import History, Session, Site, TrackObject
from core.brep import BRep
from core.transforms import make_T

BOX = "parallelepiped"
FPS = 12.0


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


@pytest.fixture
def db(tmp_path, scene):
    database = Database.open(tmp_path / "site.sqlite", busy_timeout_s=0.2)
    seed_from_scene(database, scene)
    yield database
    database.close()


def _content(path: Path) -> dict:
    """Every row of every table, read by a connection of its own, and SQLite's integrity check."""
    conn = sqlite3.connect(path)
    try:
        tables = [r[0] for r in conn.execute("SELECT name FROM sqlite_master WHERE type = 'table' ORDER BY name")]
        out = {t: conn.execute(f"SELECT * FROM {t} ORDER BY rowid").fetchall() for t in tables}
        out["integrity"] = conn.execute("PRAGMA integrity_check").fetchall()
        return out
    finally:
        conn.close()


def _full_disk(db: Database) -> None:
    """The disk is full from here for this thread's connection: the file may not grow (SQLite's page
    limit set to its size) and the room left in its pages is taken."""
    conn = db._conn()
    conn.execute("CREATE TABLE filler (x BLOB)")
    pages = conn.execute("PRAGMA page_count").fetchone()[0]
    assert conn.execute(f"PRAGMA max_page_count = {pages}").fetchone()[0] == pages
    for size in (4000, 400, 40, 4):  # one transaction each: SQLite rolls back a transaction that met a full disk
        with pytest.raises(sqlite3.OperationalError, match="database or disk is full"):
            for _ in range(10_000):
                conn.execute("INSERT INTO filler VALUES (zeroblob(?))", (size,))


def _space_freed(db: Database) -> None:
    db._conn().execute("PRAGMA max_page_count = 1073741823")


BIG_CLICKS = {"points_uv": np.zeros((2000, 2))}  # ~20 kB in the history: more than a page's room left


def _moved(obj, dx: float = 0.05) -> np.ndarray:
    return make_T(obj.T_world_obj[:3, :3], obj.T_world_obj[:3, 3] + [dx, 0, 0])


# ---------------------------------------------------------------------- the database
def test_a_full_disk_writes_nothing_and_the_same_write_works_once_space_is_freed(db):
    obj = db.get(BOX)
    _full_disk(db)
    before = _content(db.path)
    with pytest.raises(DatabaseUnavailable) as info:
        db.update_pose(obj, _moved(obj), None, expected_version=obj.version, method="m", clicks=BIG_CLICKS)
    said = str(info.value)
    assert "disk holding" in said and "is full" in said and "nothing was written" in said, said
    assert "free some space, then try again" in said, said
    assert isinstance(info.value.__cause__, sqlite3.OperationalError)
    assert not db._conn().in_transaction
    assert _content(db.path) == before  # no row, no half of one
    assert db.get(BOX).version == obj.version
    _space_freed(db)
    rec = db.update_pose(obj, _moved(obj), None, expected_version=obj.version, method="m", clicks=BIG_CLICKS)
    assert rec.version == obj.version + 1 and np.allclose(db.get(BOX).T_world_obj, _moved(obj))


class _CommitMeetsAFullDisk:
    """A connection whose COMMIT meets a full disk (in WAL mode a small change's pages are written at
    COMMIT, so that is where a real full disk is met)."""

    def __init__(self, conn: sqlite3.Connection):
        self._conn = conn

    def execute(self, sql: str, *args):
        if sql.strip().upper() == "COMMIT":
            raise sqlite3.OperationalError("database or disk is full")
        return self._conn.execute(sql, *args)

    def __getattr__(self, name: str):
        return getattr(self._conn, name)


@contextmanager
def _commit_meets_a_full_disk(db: Database):
    """This thread's writes to ``db`` meet a full disk at COMMIT inside the block."""
    real = db._conn()
    db._local.conn = _CommitMeetsAFullDisk(real)
    try:
        yield
    finally:
        db._local.conn = real
    assert not real.in_transaction


def test_a_full_disk_at_commit_leaves_nothing_in_the_tables_nor_in_the_caches(db):
    """The model row added by the refused change is gone, and so is its parsed model: the next model
    written takes the same row id and must be drawn as itself."""
    before = _content(db.path)
    with _commit_meets_a_full_disk(db), pytest.raises(DatabaseUnavailable, match="is full, so nothing was written"):
        db.add_object("ball", "polyhedron", BRep.box(0.3, 0.3, 0.3), np.eye(4))
    assert _content(db.path) == before
    cube = BRep.box(0.1, 0.2, 0.4)
    rec = db.add_object("cube", "box", cube, np.eye(4))
    for seen in (rec, db.get("cube"), next(o for o in db.objects() if o.name == "cube")):
        assert np.array_equal(seen.model.vertices, cube.vertices)


def test_a_database_locked_by_another_connection_writes_nothing_until_it_is_released(db):
    obj = db.get(BOX)
    before = _content(db.path)
    other = sqlite3.connect(db.path, isolation_level=None)
    other.execute("BEGIN EXCLUSIVE")
    try:
        with pytest.raises(DatabaseUnavailable) as info:
            db.set_status(BOX, "stale")
        said = str(info.value)
        assert "is locked by another program" in said and "still after 0.2 s" in said, said
        assert "nothing was written" in said and "try again when that program has finished" in said, said
        assert [o.version for o in db.objects()] == [o.version for o in db.objects()]  # reads go on meanwhile
    finally:
        other.execute("ROLLBACK")
        other.close()
    assert _content(db.path) == before
    assert db.set_status(BOX, "stale").version == obj.version + 1


def test_a_read_only_database_writes_nothing(db, monkeypatch):
    before = _content(db.path)
    db._conn().execute("PRAGMA query_only = ON")
    with pytest.raises(DatabaseUnavailable) as info:
        db.set_status(BOX, "stale")
    said = str(info.value)
    assert "could not be written" in said and "attempt to write a readonly database" in said, said
    assert "nothing was written" in said and "writable, then try again" in said, said

    target = str(db.path.resolve())
    real_access = os.access
    monkeypatch.setattr(
        os,
        "access",
        lambda p, mode, *a, **k: (
            False if (mode & os.W_OK and str(Path(p).resolve()) == target) else real_access(p, mode, *a, **k)
        ),
    )
    with pytest.raises(DatabaseUnavailable) as info:
        db.set_status(BOX, "stale")
    said = str(info.value)
    assert "is read-only, so nothing was written; make it writable" in said and "then try again" in said, said
    assert "list, show" not in said  # the command line's advice is not the interface's
    assert _content(db.path) == before
    monkeypatch.undo()
    db._conn().execute("PRAGMA query_only = OFF")
    assert db.set_status(BOX, "stale").status == "stale"


@pytest.mark.parametrize(
    "code, words",
    [
        (errno.ENOSPC, "is full, so nothing was written; free some space"),
        (errno.EROFS, "read-only file system"),
        (errno.EACCES, "could not be written (permission denied)"),
        (errno.EIO, "reported an error"),
    ],
)
def test_the_system_s_storage_errors_are_said_in_the_same_words(tmp_path, code, words):
    path = tmp_path / "site.sqlite"
    path.touch()
    told = storage.explain(OSError(code, os.strerror(code), str(path)), path, 5.0)
    assert isinstance(told, DatabaseUnavailable) and words in str(told), told
    other = OSError(errno.ENOENT, "No such file or directory")
    assert storage.explain(other, path, 5.0) is other  # not the disk's doing: stays as it is


# ---------------------------------------------------------------------- the workflows
def _tracked(site: Site) -> TrackObject:
    """Track following the box through two frames of the scene's video."""
    wf = TrackObject(site, object_name=BOX)
    for k in (138, 139):
        site.t["t"] = k / FPS
        wf.step()
    assert wf.frames == 2 and not wf.lost
    return wf


@pytest.fixture
def site(scene, db):
    clock = {"t": 0.0}
    s = Site(scene, db, clock=lambda: clock["t"])
    s.t = clock
    return s


def test_a_track_accepted_on_a_full_disk_stays_open_and_is_written_by_the_next_accept(site, db):
    wf = _tracked(site)
    obj, T = db.get(BOX), wf.T_world_obj.copy()
    before = _content(db.path)
    with _commit_meets_a_full_disk(db), pytest.raises(DatabaseUnavailable, match="is full"):
        wf.accept()
    assert not wf.finished and wf.state == "tracking" and np.array_equal(wf.T_world_obj, T)
    assert _content(db.path) == before and site.object(BOX).version == obj.version
    rec = wf.accept()
    assert wf.accepted and rec.version == obj.version + 1 and np.allclose(rec.T_world_obj, T)
    assert [c.what for c in site.changes_since(0)][-1] == f"moved {BOX}"


def test_an_undo_refused_by_a_lock_is_written_by_the_next_press(site, db):
    obj = site.object(BOX)
    db.update_pose(obj.id, _moved(obj), None, expected_version=obj.version, method="test", client="bob")
    site.poll()
    wf = History(site, client="alice")
    last = db.history()[-1].id
    other = sqlite3.connect(db.path, isolation_level=None)
    other.execute("BEGIN EXCLUSIVE")
    try:
        with pytest.raises(DatabaseUnavailable, match="locked by another program"):
            wf.undo(last)
    finally:
        other.execute("ROLLBACK")
        other.close()
    assert not wf.finished and db.history()[-1].id == last
    rec = wf.undo(last)
    assert rec.action == "undo" and np.allclose(site.object(BOX).T_world_obj, obj.T_world_obj)


def test_a_write_whose_feed_read_fails_afterwards_is_still_a_write(site, db, monkeypatch):
    """The change is in the database: the workflow is done, and the change joins the feed later."""
    seq = site.change_seq

    def unreadable(*a, **k):
        raise DatabaseUnavailable("the disk holding the database reported an error")

    monkeypatch.setattr(db, "history_since", unreadable)
    rec = site.set_status(BOX, "stale", client="alice")
    assert rec.status == "stale" and site.changes_since(seq) == []
    monkeypatch.undo()
    site.poll()
    assert [c.what for c in site.changes_since(seq)] == [f"marked {BOX} stale"]


# ---------------------------------------------------------------------- the panel
class _Panel:
    """What ClientPanel._guard touches of its panel."""

    def __init__(self, session: Session):
        self.session = session
        self.error = ""
        self.error_step = None
        self.dirty = False
        self.toasts: list[tuple[str, str]] = []
        self.app = SimpleNamespace(wake=lambda: None)

    def _step_name(self):
        return ClientPanel._step_name(self)

    def notify(self, title, body, color="yellow", stays=False):
        self.toasts.append((title, color))


def test_the_panel_says_a_locked_database_in_one_sentence_and_keeps_the_workflow(site, db, caplog):
    session = Session(site, client="alice")
    session.select(BOX)
    wf = session.start("track")
    for k in (138, 139):
        site.t["t"] = k / FPS
        wf.step()
    wf.pause()
    panel = _Panel(session)
    accept = ClientPanel.guard(panel, lambda: wf.perform("accept"))
    version = db.get(BOX).version
    other = sqlite3.connect(db.path, isolation_level=None)
    other.execute("BEGIN EXCLUSIVE")
    caplog.set_level(logging.DEBUG, logger="mcit")
    try:
        accept()
    finally:
        other.execute("ROLLBACK")
        other.close()
    assert panel.error.startswith(f"The database {db.path} is locked by another program"), panel.error
    assert "nothing was written; try again when that program has finished." in panel.error, panel.error
    assert panel.error.endswith("Your work in Track is kept."), panel.error
    assert panel.error_step == wf.current_step().name and panel.toasts == []
    records = [r for r in caplog.records if r.name.startswith("mcit")]
    assert len(records) == 1 and records[0].levelno == logging.WARNING and records[0].exc_info is None, records
    assert "\n" not in records[0].getMessage() and "locked by another program" in records[0].getMessage()
    assert session.workflow is wf and not wf.finished and "accept" in wf.current_step().enabled
    assert db.get(BOX).version == version
    accept()
    assert wf.accepted and db.get(BOX).version == version + 1
