"""The database file's schema: its identity, its version and the forward migrations.

An mcit database is an SQLite file whose header carries ``application_id`` = ``APPLICATION_ID``
("MCIT") and ``user_version`` = the schema version. ``MIGRATIONS[k]`` takes a file from version
k to k + 1; a migration, once released, is never edited (files in the field were made by it):
change the schema by appending one. ``inspect_file`` looks at a file read-only and refuses, with a
message saying what to do, a file that is not SQLite, is corrupt, is another program's database
or was written by a newer mcit; nothing is ever written to such a file.
"""

from __future__ import annotations

import os
import sqlite3
from dataclasses import dataclass
from pathlib import Path

from .storage import DatabaseRefused, DatabaseUnavailable, read_uri

__all__ = ["APPLICATION_ID", "LATEST_VERSION", "MIGRATIONS", "DatabaseRefused", "FileState", "inspect_file", "migrate"]

APPLICATION_ID = 0x4D434954  # "MCIT"


# Version 1: the first schema.
_V1 = """
CREATE TABLE meta (
    key TEXT PRIMARY KEY,
    value TEXT NOT NULL
);
CREATE TABLE models (
    id INTEGER PRIMARY KEY,
    sha256 TEXT NOT NULL UNIQUE,          -- of the canonical JSON below: identical models share a row
    brep TEXT NOT NULL                    -- core.brep.BRep.to_dict() as JSON
);
CREATE TABLE objects (
    id INTEGER PRIMARY KEY,
    name TEXT NOT NULL CHECK (length(name) > 0),
    kind TEXT NOT NULL,
    model_id INTEGER NOT NULL REFERENCES models(id),
    dims TEXT NOT NULL DEFAULT '{}',      -- JSON {name: metres}
    sigmas TEXT NOT NULL DEFAULT '{}',    -- JSON {name: standard deviation, metres}
    T_world_obj TEXT NOT NULL,            -- JSON 4x4, rows
    cov TEXT,                             -- JSON 6x6 or NULL
    status TEXT NOT NULL CHECK (status IN ('known', 'modelled', 'stale')),
    version INTEGER NOT NULL DEFAULT 1 CHECK (version >= 1),
    removed INTEGER NOT NULL DEFAULT 0 CHECK (removed IN (0, 1)),
    created_at REAL NOT NULL,             -- unix seconds
    updated_at REAL NOT NULL
);
CREATE UNIQUE INDEX objects_live_name ON objects(name) WHERE removed = 0;
CREATE TABLE calibrations (
    id INTEGER PRIMARY KEY,
    kind TEXT NOT NULL,                   -- 'camera', 'turret', ...
    data TEXT NOT NULL,                   -- JSON
    residuals TEXT,                       -- JSON or NULL
    time REAL NOT NULL,
    client TEXT NOT NULL,
    method TEXT NOT NULL
);
CREATE INDEX calibrations_kind ON calibrations(kind, id);
CREATE TABLE history (
    id INTEGER PRIMARY KEY AUTOINCREMENT, -- never reused, even after a rollback
    time REAL NOT NULL,
    client TEXT NOT NULL,
    method TEXT NOT NULL,
    action TEXT NOT NULL,                 -- add, update, undo, restore, remove, calibration
    object_id INTEGER REFERENCES objects(id),
    calibration_id INTEGER REFERENCES calibrations(id),
    version INTEGER,                      -- the object's version after the change
    before TEXT,                          -- JSON snapshot of the object before (NULL for add)
    after TEXT,                           -- JSON snapshot after
    clicks TEXT,                          -- JSON: the image clicks the method used
    measurements TEXT,                    -- JSON: range measurements, scans
    residuals TEXT,                       -- JSON
    note TEXT,
    undoes INTEGER REFERENCES history(id)
);
"""

# Version 2: where an object's model came from (an imported file), and the history by object.
_V2 = """
ALTER TABLE objects ADD COLUMN source TEXT;
CREATE INDEX history_object ON history(object_id, id);
"""

# Version 3: when the image a change was measured on was taken (unix seconds; NULL: not from an image).
_V3 = """
ALTER TABLE history ADD COLUMN seen_at REAL;
"""

MIGRATIONS: tuple[str, ...] = (_V1, _V2, _V3)
LATEST_VERSION = len(MIGRATIONS)


@dataclass(frozen=True)
class FileState:
    """What ``inspect_file`` found: ``exists`` (with content), ``version`` (0 for a new file)."""

    exists: bool
    version: int


def _statements(sql: str) -> list[str]:
    lines = [line.split("--", 1)[0] for line in sql.splitlines()]
    return [s.strip() for s in "\n".join(lines).split(";") if s.strip()]


def inspect_file(path: Path, quick_check: bool = True) -> FileState:
    """Look at ``path`` read-only; DatabaseRefused when mcit must not open it.

    A missing or empty file, or an SQLite file with no table, is new (version 0).
    """
    if path.is_dir():
        raise DatabaseRefused(f"{path} is a directory; give a database file path with --db")
    if not path.exists() or path.stat().st_size == 0:
        return FileState(False, 0)
    if not os.access(path, os.R_OK):
        raise DatabaseUnavailable(f"{path} cannot be read (permission denied); check its owner and permissions")
    uri, _ = read_uri(path)  # a look that leaves no -wal/-shm file behind, even on a read-only disk
    try:
        conn = sqlite3.connect(uri, uri=True)
        conn.execute("PRAGMA query_only = ON")
    except sqlite3.Error as exc:
        raise DatabaseUnavailable(
            f"{path} cannot be opened to be read ({exc}); check it and its folder's permissions"
        ) from None
    try:
        app_id = conn.execute("PRAGMA application_id").fetchone()[0]
        version = conn.execute("PRAGMA user_version").fetchone()[0]
        n_tables = conn.execute("SELECT count(*) FROM sqlite_master").fetchone()[0]
        if app_id != APPLICATION_ID:
            if n_tables == 0 and version == 0:
                return FileState(False, 0)
            raise DatabaseRefused(
                f"{path} is an SQLite database but not mcit's (application_id {app_id:#x}, {n_tables} schema "
                "entries); mcit will not touch it: choose another file with --db"
            )
        if version > LATEST_VERSION:
            raise DatabaseRefused(
                f"{path} was written by a newer mcit (schema version {version}; this mcit knows up to "
                f"{LATEST_VERSION}); upgrade mcit to open it. The file was not changed"
            )
        if quick_check:
            problems = [r[0] for r in conn.execute("PRAGMA quick_check(5)").fetchall()]
            if problems != ["ok"]:
                raise DatabaseRefused(
                    f"{path} is corrupt (SQLite's quick_check: {'; '.join(problems)}); it was not changed. "
                    "Restore a backup, or recover it with the sqlite3 shell's .recover, then open the copy"
                )
        return FileState(True, version)
    except sqlite3.OperationalError as exc:  # the disk or another program, not the file's content
        raise DatabaseUnavailable(f"{path} could not be read ({exc}); check the disk and try again") from None
    except sqlite3.DatabaseError as exc:
        raise DatabaseRefused(
            f"{path} cannot be read as an SQLite database ({exc}): it is not one, or it is corrupt. mcit will not "
            "touch it: restore a backup or choose another file with --db"
        ) from None
    finally:
        conn.close()


def migrate(conn: sqlite3.Connection, target: int = LATEST_VERSION) -> tuple[int, int]:
    """Bring the database to schema ``target`` in one transaction; returns (from, to) versions.

    ``conn`` must be in autocommit mode (``isolation_level=None``). The version is read after the
    write lock is taken, so two processes opening one new file migrate it once.
    """
    if not 1 <= target <= LATEST_VERSION:
        raise ValueError(f"target schema version must be in 1..{LATEST_VERSION}, got {target}")
    conn.execute("BEGIN IMMEDIATE")
    try:
        current = conn.execute("PRAGMA user_version").fetchone()[0]
        app_id = conn.execute("PRAGMA application_id").fetchone()[0]
        if current > LATEST_VERSION or (current > 0 and app_id != APPLICATION_ID):
            raise DatabaseRefused(
                f"the database changed under us (application_id {app_id:#x}, version {current}); not migrating"
            )
        for version in range(current, target):
            for statement in _statements(MIGRATIONS[version]):
                conn.execute(statement)
        if current == 0:
            conn.execute(f"PRAGMA application_id = {APPLICATION_ID}")
        if target > current:
            conn.execute(f"PRAGMA user_version = {int(target)}")
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
    return current, max(current, target)
