"""The database file: refusing files mcit must not touch, and migrating from the first schema."""

import hashlib
import json
import sqlite3

import numpy as np
import pytest

from app.db import Database, DatabaseRefused
from app.db.schema import APPLICATION_ID, LATEST_VERSION, migrate
from core.brep import BRep


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _untouched(path, before):
    assert _digest(path) == before
    assert not path.with_name(path.name + "-wal").exists() or path.with_name(path.name + "-wal").stat().st_size == 0


def test_a_file_that_is_not_sqlite_is_refused_and_left_alone(tmp_path):
    f = tmp_path / "notes.sqlite"
    f.write_bytes(b"these are my notes, not a database\n" * 200)
    before = _digest(f)
    with pytest.raises(DatabaseRefused, match="cannot be read as an SQLite database"):
        Database.open(f)
    _untouched(f, before)


def test_another_programs_sqlite_database_is_refused(tmp_path):
    f = tmp_path / "other.sqlite"
    conn = sqlite3.connect(f)
    conn.execute("CREATE TABLE songs (title TEXT)")
    conn.execute("INSERT INTO songs VALUES ('x')")
    conn.commit()
    conn.close()
    before = _digest(f)
    with pytest.raises(DatabaseRefused, match="not mcit's"):
        Database.open(f)
    _untouched(f, before)


def test_a_database_from_a_newer_mcit_is_refused(tmp_path):
    f = tmp_path / "site.sqlite"
    Database.open(f).close()
    conn = sqlite3.connect(f)
    conn.execute(f"PRAGMA user_version = {LATEST_VERSION + 1}")
    conn.close()
    before = _digest(f)
    with pytest.raises(DatabaseRefused, match="newer mcit"):
        Database.open(f)
    _untouched(f, before)


def test_a_corrupt_database_is_refused_and_left_alone(tmp_path):
    f = tmp_path / "site.sqlite"
    rng = np.random.default_rng(0)
    with Database.open(f) as db:
        with db.transaction():
            for i in range(60):
                db.add_object(
                    f"o{i}", "box", BRep.box(*rng.uniform(0.1, 1, 3)), np.eye(4), residuals=rng.normal(size=200)
                )
    conn = sqlite3.connect(f)  # fold the WAL into the file, then damage pages in its middle
    conn.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    page = conn.execute("PRAGMA page_size").fetchone()[0]
    n_pages = conn.execute("PRAGMA page_count").fetchone()[0]
    conn.close()
    assert n_pages > 20
    data = bytearray(f.read_bytes())
    for k in range(n_pages // 3, n_pages // 3 + 4):
        data[k * page : (k + 1) * page] = rng.integers(0, 256, page, dtype=np.uint8).tobytes()
    f.write_bytes(bytes(data))
    before = _digest(f)
    with pytest.raises(DatabaseRefused, match="corrupt"):
        Database.open(f)
    _untouched(f, before)


def test_empty_file_and_directory(tmp_path):
    f = tmp_path / "empty.sqlite"
    f.write_bytes(b"")
    with Database.open(f) as db:  # an empty file is a new database
        assert db.schema_version == LATEST_VERSION
    with pytest.raises(DatabaseRefused, match="is a directory"):
        Database.open(tmp_path)


def _v1_database(path):
    """A database as the first schema made it, filled the way that version's code wrote rows."""
    conn = sqlite3.connect(path, isolation_level=None)
    conn.execute("PRAGMA journal_mode=WAL")
    assert migrate(conn, target=1) == (0, 1)
    brep = json.dumps(BRep.box(0.35, 0.231, 0.132).to_dict(), separators=(",", ":"), sort_keys=True)
    conn.execute("INSERT INTO models (id, sha256, brep) VALUES (1, 'x', ?)", (brep,))
    T = np.eye(4)
    T[:3, 3] = [0.1, 0.2, 0.0]
    conn.execute(
        "INSERT INTO objects (id, name, kind, model_id, dims, sigmas, "
        "T_world_obj, cov, status, version, created_at, updated_at) "
        "VALUES (1, 'parallelepiped', 'box', 1, '{\"size_x\": 0.35}', '{}', ?, NULL, 'known', 2, 1.0, 2.0)",
        (json.dumps(T.tolist()),),
    )
    conn.execute(
        "INSERT INTO history (time, client, method, action, object_id, version, before, after) VALUES "
        "(1.0, 'old', 'seed', 'add', 1, 1, NULL, ?), (2.0, 'old', 'p3l', 'update', 1, 2, ?, ?)",
        (
            json.dumps({"T_world_obj": np.eye(4).tolist()}),
            json.dumps({"T_world_obj": np.eye(4).tolist()}),
            json.dumps({"T_world_obj": T.tolist()}),
        ),
    )
    conn.execute(
        "INSERT INTO calibrations (kind, data, residuals, time, client, "
        "method) VALUES ('camera', ?, '[0.5]', 1.0, 'old', 'dlt')",
        (json.dumps({"C": np.hstack([np.eye(3), np.zeros((3, 1))]).tolist(), "width": 512, "height": 256}),),
    )
    conn.close()


def test_migration_from_the_first_schema_keeps_every_row(tmp_path):
    f = tmp_path / "v1.sqlite"
    _v1_database(f)
    conn = sqlite3.connect(f)
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 1
    assert conn.execute("PRAGMA application_id").fetchone()[0] == APPLICATION_ID
    conn.close()
    with Database.open(f) as db:
        assert db.schema_version == LATEST_VERSION == 3
        (o,) = db.objects()
        assert (o.name, o.version, o.status, o.source) == ("parallelepiped", 2, "known", None)
        assert np.allclose(o.T_world_obj[:3, 3], [0.1, 0.2, 0.0]) and o.model == BRep.box(0.35, 0.231, 0.132)
        assert [h.method for h in db.history("parallelepiped")] == ["seed", "p3l"]
        assert [h.seen_at for h in db.history("parallelepiped")] == [None, None]  # v3: not measured on an image
        assert db.latest_calibration("camera").residuals == [0.5]
        # the migrated file works as a new one: undo the old update, add with a source
        db.undo(2)
        assert np.array_equal(db.get(1).T_world_obj, np.eye(4))
        db.add_object("tea", "box", BRep.box(1, 1, 1), np.eye(4), source="teabox.cao", seen_at=1.7e9)
        assert db.get("tea").source == "teabox.cao" and db.history("tea")[-1].seen_at == 1.7e9
        indexes = {r[0] for r in db._conn().execute("SELECT name FROM sqlite_master WHERE type = 'index'")}
        assert "history_object" in indexes
    with Database.open(f) as db:  # opening again migrates nothing
        assert db.schema_version == 3 and [h.action for h in db.history()] == ["add", "update", "undo", "add"]
