"""The site's database: objects, their full history, calibrations, in one SQLite file.

``Database.open(path)`` creates the file (schema ``app.db.schema``) or opens and migrates it;
it refuses, without writing, a file that is not mcit's, is newer than this code or is corrupt.

* Every change is one transaction (``BEGIN IMMEDIATE`` … ``COMMIT``) that also writes its
  history row; a failed or refused operation writes nothing. ``with db.transaction():`` groups
  several changes into one.
* Each object has a ``version``. A writer passes the version it read (``expected_version``);
  if another writer changed the object since, the change is refused with ``ConflictError``.
* WAL journal, ``synchronous=FULL`` (a committed change survives a crash of the process or of
  the machine), foreign keys on, a busy timeout for concurrent writers (other threads, other
  processes). One SQLite connection per thread; the object cache is shared behind a lock.
* ``objects()`` is the overlay's read: it asks SQLite only for (id, version) of every object
  and re-parses the rows whose version moved; models are parsed once per model row.
"""

from __future__ import annotations

import hashlib
import json
import os
import sqlite3
import threading
import time
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from app.names import check_object_name
from core.brep import BRep
from core.transforms import check_T

from .records import (
    STATUSES,
    CalibrationRecord,
    ChangeRecord,
    ConflictError,
    NotFoundError,
    ObjectRecord,
    frozen_array,
    mapping,
    to_json,
)
from .schema import LATEST_VERSION, DatabaseRefused, inspect_file, migrate
from .storage import DatabaseUnavailable, can_write, check_writable, explain, read_uri, side_files

__all__ = ["Database", "default_db_path"]

_KEEP = object()
_OBJECT_COLUMNS = (
    "id, name, kind, status, version, model_id, T_world_obj, cov, dims, sigmas, source, created_at, updated_at, removed"
)
_SNAPSHOT_FIELDS = ("name", "kind", "status", "model_id", "T_world_obj", "cov", "dims", "sigmas", "source", "removed")


def default_db_path() -> Path:
    """``$XDG_DATA_HOME/mcit/mcit.sqlite`` (``~/.local/share/mcit/mcit.sqlite`` by default)."""
    base = os.environ.get("XDG_DATA_HOME") or str(Path.home() / ".local" / "share")
    return Path(base) / "mcit" / "mcit.sqlite"


# ---------------------------------------------------------------------- validation
def _check_name(name: Any) -> str:
    return check_object_name(name)


def _check_kind(kind: Any) -> str:
    if not isinstance(kind, str) or not kind:
        raise ValueError(f"kind must be a non-empty string (box, cylinder, polyhedron, ...), got {kind!r}")
    return kind


def _check_status(status: Any) -> str:
    if status not in STATUSES:
        raise ValueError(f"status must be one of {STATUSES}, got {status!r}")
    return status


def _check_seen_at(t: Any) -> float:
    """A capture time: unix seconds, finite and positive."""
    try:
        t = float(t)
    except (TypeError, ValueError):
        raise ValueError(f"seen_at must be a time in unix seconds, got {t!r}") from None
    if not np.isfinite(t) or t <= 0:
        raise ValueError(f"seen_at must be a time in unix seconds, got {t!r}")
    return t


def _check_pose(T: Any) -> list:
    try:
        T = np.asarray(T, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"T_world_obj must be a 4×4 matrix of numbers, got {T!r}") from None
    return check_T(T, "T_world_obj").tolist()


def _check_cov(cov: Any) -> list | None:
    if cov is None:
        return None
    try:
        C = np.asarray(cov, dtype=float)
    except (TypeError, ValueError):
        raise ValueError("cov must be a 6×6 matrix of numbers or None") from None
    if C.shape != (6, 6) or not np.all(np.isfinite(C)):
        raise ValueError(f"cov must be a finite 6×6 matrix (pose covariance) or None, got shape {C.shape}")
    if not np.allclose(C, C.T, rtol=1e-6, atol=1e-12 * max(1.0, float(np.abs(C).max()))):
        raise ValueError("cov must be symmetric")
    return C.tolist()


def _check_values(d: Any, what: str, non_negative: bool) -> dict:
    if d is None:
        return {}
    if not isinstance(d, Mapping):
        raise ValueError(f"{what} must be a mapping name → metres, got {type(d).__name__}")
    out = {}
    for k, v in d.items():
        try:
            x = float(v)
        except (TypeError, ValueError):
            raise ValueError(f"{what}[{k!r}] must be a number, got {v!r}") from None
        if not np.isfinite(x) or (non_negative and x < 0):
            raise ValueError(f"{what}[{k!r}] must be finite{' and ≥ 0' if non_negative else ''}, got {x}")
        out[str(k)] = x
    return out


def _row_id(value: Any) -> int:
    """An id for SQLite: one beyond its 64-bit integers matches no row (-1) instead of overflowing."""
    i = int(value)
    return i if -(2**63) <= i < 2**63 else -1


def _model_json(model: Any) -> tuple[str, str]:
    if not isinstance(model, BRep):
        raise ValueError(f"model must be a core.brep.BRep, got {type(model).__name__}")
    text = json.dumps(model.to_dict(), separators=(",", ":"), sort_keys=True)
    return text, hashlib.sha256(text.encode()).hexdigest()


def _remove_if_unwritten(path: Path) -> None:
    """After a refused open that created ``path``: remove it and its side files if it holds nothing
    (no schema committed), so that a refused open leaves no file behind."""
    try:
        if inspect_file(path, quick_check=False).exists:
            return
    except (DatabaseRefused, DatabaseUnavailable):
        return
    for f in (path, *side_files(path)):
        try:
            f.unlink(missing_ok=True)
        except OSError:
            pass


class Database:
    """The site's SQLite database; see the module docstring. Open it with ``Database.open``.

    Every writing method takes ``client`` (who: "viser:3", "cli", "demo"; default: the one given
    to ``open``) and ``method`` (how: "p3l+refine", "import", "seed", ...), and records them with
    the change in the history.
    """

    def __init__(self, path: Path, client: str, busy_timeout_s: float, readonly: bool = False):
        self._path = path
        self.client = client
        self._busy_timeout_s = busy_timeout_s
        self.readonly = readonly
        self._local = threading.local()
        self._lock = threading.Lock()
        self._connections: list[sqlite3.Connection] = []
        self._records: dict[int, ObjectRecord] = {}
        self._models: dict[int, BRep] = {}
        self._closed = False

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(
        cls,
        path: str | Path | None = None,
        *,
        client: str = "local",
        busy_timeout_s: float = 10.0,
        quick_check: bool = True,
        readonly: bool = False,
    ) -> Database:
        """Open (creating it with the schema if absent or empty) the database at ``path``.

        path : the file; default ``default_db_path()``. quick_check : run SQLite's quick_check on
        an existing file before using it (milliseconds for a site's database). busy_timeout_s :
        how long a write waits for another writer to finish. readonly : only read (works on a
        read-only file, folder or mount; never creates the file, nor any file beside it).

        Raises DatabaseRefused (file untouched) for a file that is not SQLite, is corrupt, belongs
        to another program or was written by a newer mcit; DatabaseUnavailable (nothing written,
        no file left behind) when it cannot be written (read-only, disk full, locked past the
        busy timeout), or, with ``readonly``, when there is none.
        """
        path = Path(path) if path is not None else default_db_path()
        state = inspect_file(path, quick_check=quick_check)
        if readonly:
            return cls._open_readonly(path, state, client, busy_timeout_s)
        new = not path.exists()
        if new:
            try:
                path.parent.mkdir(parents=True, exist_ok=True)
            except OSError as exc:
                raise DatabaseUnavailable(
                    f"cannot make the folder for {path} ({exc.strerror}), so nothing was written; "
                    "choose a writable place with --db"
                ) from None
            if not os.access(path.parent, os.W_OK):
                raise DatabaseUnavailable(
                    f"cannot create {path}: its folder is read-only, so nothing was written; "
                    "choose a writable place with --db"
                )
        else:
            check_writable(path)
        db = cls(path, client, busy_timeout_s)
        try:
            with db._errors():
                conn = db._conn()
                mode = conn.execute("PRAGMA journal_mode=WAL").fetchone()[0]
                if mode.lower() != "wal":
                    raise DatabaseRefused(
                        f"{path}: SQLite refused WAL mode (got {mode!r}); put the database on a local disk"
                    )
                if state.version < LATEST_VERSION:  # a file at the latest version needs no write lock to open
                    migrate(conn, LATEST_VERSION)
        except BaseException:
            db.close()
            if new:
                _remove_if_unwritten(path)
            raise
        return db

    @classmethod
    def _open_readonly(cls, path: Path, state, client: str, busy_timeout_s: float) -> Database:
        if not state.exists:
            raise DatabaseUnavailable(
                f"there is no database at {path}; create one with `mcit db init` or `mcit db import` "
                "(with --db to choose the file)"
            )
        if state.version < LATEST_VERSION:  # upgraded once, by a writable open
            if not can_write(path.resolve()):
                raise DatabaseUnavailable(
                    f"{path} was written by an older mcit (schema version {state.version}) and is read-only, so it "
                    "cannot be upgraded to be read; make it writable once, or read it with the mcit that wrote it"
                )
            cls.open(path, client=client, busy_timeout_s=busy_timeout_s, quick_check=False).close()
        db = cls(path, client, busy_timeout_s, readonly=True)
        try:
            with db._errors():
                db._conn()
        except BaseException:
            db.close()
            raise
        return db

    @contextmanager
    def _errors(self) -> Iterator[None]:
        """SQLite's (or the system's) errors the disk or other programs cause become one sentence
        (DatabaseUnavailable)."""
        try:
            yield
        except (sqlite3.Error, OSError) as exc:
            if isinstance(exc, sqlite3.IntegrityError):
                raise
            told = explain(exc, self._path, self._busy_timeout_s)
            if told is exc:
                raise
            raise told from exc

    @property
    def path(self) -> Path:
        return self._path

    @property
    def schema_version(self) -> int:
        return int(self._conn().execute("PRAGMA user_version").fetchone()[0])

    def close(self) -> None:
        """Close every thread's connection (the file stays consistent whenever this is skipped)."""
        with self._lock:
            self._closed = True
            for conn in self._connections:
                try:
                    conn.close()
                except sqlite3.Error:
                    pass
            self._connections.clear()

    def __enter__(self) -> Database:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _conn(self) -> sqlite3.Connection:
        conn = getattr(self._local, "conn", None)
        if conn is None:
            if self._closed:
                raise RuntimeError(f"the database {self._path} is closed")
            if self.readonly:
                uri, immutable = read_uri(self._path)
                conn = sqlite3.connect(
                    uri, uri=True, isolation_level=None, timeout=self._busy_timeout_s, check_same_thread=False
                )
                conn.execute("PRAGMA query_only = ON")
            else:
                immutable = False
                conn = sqlite3.connect(
                    self._path, isolation_level=None, timeout=self._busy_timeout_s, check_same_thread=False
                )
            conn.execute("PRAGMA foreign_keys = ON")
            conn.execute(f"PRAGMA busy_timeout = {int(self._busy_timeout_s * 1000)}")
            conn.execute("PRAGMA synchronous = FULL")
            self._local.conn = conn
            self._local.immutable = immutable  # read as on disk: no lock (see app/db/storage.py)
            self._local.depth = 0
            self._local.commits = 0  # this connection's commits (PRAGMA data_version counts the others')
            self._local.snapshot = None  # (data_version, commits, objects) of the last objects() read
            with self._lock:
                self._connections.append(conn)
        return conn

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """One write transaction; calls nested inside (on this thread) join it. All or nothing."""
        conn = self._conn()
        if self._local.depth:
            self._local.depth += 1
            try:
                yield conn
            finally:
                self._local.depth -= 1
            return
        if self.readonly:
            raise DatabaseUnavailable(f"{self._path} was opened only to be read; nothing was written")
        with self._errors():
            conn.execute("BEGIN IMMEDIATE")
            self._local.depth = 1
            try:
                yield conn
                conn.execute("COMMIT")
                self._local.commits += 1
            except BaseException:
                if conn.in_transaction:
                    conn.execute("ROLLBACK")
                raise
            finally:
                self._local.depth = 0

    @contextmanager
    def _read(self) -> Iterator[sqlite3.Connection]:
        """A read snapshot (or the current write transaction)."""
        conn = self._conn()
        if self._local.depth:
            yield conn
            return
        if self._local.immutable and self._path.with_name(self._path.name + "-wal").exists():
            self._reconnect()  # another program opened it since: read its committed changes too
            conn = self._conn()
        with self._errors():
            conn.execute("BEGIN")
            try:
                yield conn
            finally:
                conn.execute("COMMIT")

    def _reconnect(self) -> None:
        conn = self._local.conn
        with self._lock:
            self._connections.remove(conn)
        conn.close()
        self._local.conn = None

    # ------------------------------------------------------------------ objects: reading
    def _model(self, conn: sqlite3.Connection, model_id: int) -> BRep:
        model = self._models.get(model_id)
        if model is None:
            row = conn.execute("SELECT brep FROM models WHERE id = ?", (model_id,)).fetchone()
            if row is None:
                raise NotFoundError(f"model {model_id} is missing from the database")
            model = BRep.from_dict(json.loads(row[0]))
            if not self._local.depth:  # a row read inside a write transaction may yet be rolled back (its id reused)
                with self._lock:
                    self._models[model_id] = model
        return model

    def _record(self, conn: sqlite3.Connection, row: tuple) -> ObjectRecord:
        i, name, kind, status, version, model_id, T, cov, dims, sigmas, source, created, updated, _removed = row
        return ObjectRecord(
            id=i,
            name=name,
            kind=kind,
            status=status,
            version=version,
            model=self._model(conn, model_id),
            model_id=model_id,
            T_world_obj=frozen_array(json.loads(T), (4, 4)),
            cov=None if cov is None else frozen_array(json.loads(cov), (6, 6)),
            dims=mapping(dims),
            sigmas=mapping(sigmas),
            source=source,
            created_at=created,
            updated_at=updated,
        )

    def objects(self) -> list[ObjectRecord]:
        """Every live object (ordered by id): the overlay's read. Records are shared: do not mutate.

        When no connection has committed since this thread's last call (SQLite's data_version and
        this connection's own commits), the previous list is returned without a query.
        """
        with self._read() as conn:
            key = None
            if not self._local.depth:
                key = (conn.execute("PRAGMA data_version").fetchone()[0], self._local.commits)
                snap = self._local.snapshot
                if snap is not None and snap[0] == key:
                    return list(snap[1])
            objs = self._objects(conn)
            if key is not None:
                self._local.snapshot = (key, objs)
            return list(objs)

    def _objects(self, conn: sqlite3.Connection) -> list[ObjectRecord]:
        ids = conn.execute("SELECT id, version FROM objects WHERE removed = 0 ORDER BY id").fetchall()
        cache = self._records
        moved = [i for i, v in ids if (r := cache.get(i)) is None or r.version != v]
        if not moved:
            return [cache[i] for i, _ in ids]
        fresh = {}
        for k in range(0, len(moved), 500):
            chunk = moved[k : k + 500]
            q = f"SELECT {_OBJECT_COLUMNS} FROM objects WHERE id IN ({','.join('?' * len(chunk))})"
            for row in conn.execute(q, chunk):
                fresh[row[0]] = self._record(conn, row)
        if self._local.depth:  # inside a write transaction: may roll back, do not cache
            return [fresh.get(i) or cache[i] for i, _ in ids]
        with self._lock:
            cache.update(fresh)
            return [cache[i] for i, _ in ids]

    def _row(self, conn: sqlite3.Connection, obj: Any, include_removed: bool = False) -> tuple:
        if isinstance(obj, ObjectRecord):
            obj = obj.id
        if isinstance(obj, (int, np.integer)) and not isinstance(obj, bool):
            row = conn.execute(f"SELECT {_OBJECT_COLUMNS} FROM objects WHERE id = ?", (_row_id(obj),)).fetchone()
        elif isinstance(obj, str):
            row = conn.execute(
                f"SELECT {_OBJECT_COLUMNS} FROM objects WHERE name = ? AND removed = 0", (obj,)
            ).fetchone()
        else:
            raise ValueError(f"an object is named by its id (int), name (str) or record, got {type(obj).__name__}")
        if row is None or (row[-1] and not include_removed):
            raise NotFoundError(f"no object {obj!r} in the database {self._path}")
        return row

    def get(self, obj: int | str | ObjectRecord) -> ObjectRecord:
        """One live object by id or name; NotFoundError if there is none."""
        with self._read() as conn:
            return self._record(conn, self._row(conn, obj))

    # ------------------------------------------------------------------ objects: writing
    def _model_id(self, conn: sqlite3.Connection, model: BRep) -> int:
        text, sha = _model_json(model)
        conn.execute("INSERT OR IGNORE INTO models (sha256, brep) VALUES (?, ?)", (sha, text))
        return int(conn.execute("SELECT id FROM models WHERE sha256 = ?", (sha,)).fetchone()[0])

    @staticmethod
    def _snapshot(row: tuple) -> dict:
        _, name, kind, status, _, model_id, T, cov, dims, sigmas, source, _, _, removed = row
        return {
            "name": name,
            "kind": kind,
            "status": status,
            "model_id": model_id,
            "T_world_obj": json.loads(T),
            "cov": None if cov is None else json.loads(cov),
            "dims": json.loads(dims),
            "sigmas": json.loads(sigmas),
            "source": source,
            "removed": int(removed),
        }

    def _log(
        self,
        conn,
        action,
        method,
        client,
        *,
        object_id=None,
        calibration_id=None,
        version=None,
        before=None,
        after=None,
        clicks=None,
        measurements=None,
        residuals=None,
        note=None,
        undoes=None,
        seen_at=None,
    ) -> int:
        if not isinstance(method, str) or not method:
            raise ValueError(f"method must be a non-empty string saying how the change was made, got {method!r}")
        cur = conn.execute(
            "INSERT INTO history (time, client, method, action, object_id, calibration_id, version, before, after, "
            "clicks, measurements, residuals, note, undoes, seen_at) VALUES (" + ", ".join("?" * 15) + ")",
            (
                time.time(),
                str(client or self.client),
                method,
                action,
                object_id,
                calibration_id,
                version,
                to_json(before),
                to_json(after),
                to_json(clicks),
                to_json(measurements),
                to_json(residuals),
                note,
                undoes,
                None if seen_at is None else _check_seen_at(seen_at),
            ),
        )
        return int(cur.lastrowid)

    def add_object(
        self,
        name: str,
        kind: str,
        model: BRep,
        T_world_obj: np.ndarray,
        *,
        cov: np.ndarray | None = None,
        dims: Mapping[str, float] | None = None,
        sigmas: Mapping[str, float] | None = None,
        status: str = "modelled",
        source: str | None = None,
        method: str = "add",
        client: str | None = None,
        clicks: Any = None,
        measurements: Any = None,
        residuals: Any = None,
        note: str | None = None,
        seen_at: float | None = None,
    ) -> ObjectRecord:
        """Add an object (one transaction, history "add"); ValueError if the name is taken.

        T_world_obj : array, shape (4, 4), the pose (maps object to world). cov : (6, 6) or None.
        dims, sigmas : name → metres. status : "known", "modelled" or "stale". seen_at : when the image it
        was measured on was taken (unix seconds; ``ChangeRecord.seen_at``).
        """
        _check_name(name)
        _check_kind(kind)
        _check_status(status)
        T = to_json(_check_pose(T_world_obj))
        C = to_json(_check_cov(cov))
        D = to_json(_check_values(dims, "dims", False))
        S = to_json(_check_values(sigmas, "sigmas", True))
        _model_json(model)
        with self.transaction() as conn:
            model_id = self._model_id(conn, model)
            now = time.time()
            try:
                cur = conn.execute(
                    "INSERT INTO objects (name, kind, model_id, dims, sigmas, T_world_obj, cov, "
                    "status, source, created_at, updated_at) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
                    (name, kind, model_id, D, S, T, C, status, source, now, now),
                )
            except sqlite3.IntegrityError:
                raise ValueError(f"an object named {name!r} already exists; choose another name") from None
            row = self._row(conn, int(cur.lastrowid))
            self._log(
                conn,
                "add",
                method,
                client,
                object_id=row[0],
                version=1,
                after=self._snapshot(row),
                clicks=clicks,
                measurements=measurements,
                residuals=residuals,
                note=note,
                seen_at=seen_at,
            )
            return self._record(conn, row)

    def _change(self, conn, row, fields: dict, action, method, client, expected_version, **log) -> ObjectRecord:
        """Apply ``fields`` (snapshot keys → values already validated) to the object row, log it."""
        name, version = row[1], row[4]
        if expected_version is not None and int(expected_version) != version:
            raise ConflictError(name, int(expected_version), version)
        before = self._snapshot(row)
        after = dict(before, **fields)
        sets = {k: after[k] for k in _SNAPSHOT_FIELDS}
        for k in ("T_world_obj", "cov", "dims", "sigmas"):
            sets[k] = to_json(sets[k])
        assign = ", ".join(f"{k} = ?" for k in sets)
        try:
            cur = conn.execute(
                f"UPDATE objects SET {assign}, version = version + 1, updated_at = ? WHERE id = ? AND version = ?",
                (*sets.values(), time.time(), row[0], version),
            )
        except sqlite3.IntegrityError:
            raise ValueError(
                f"cannot bring back {name!r}: another live object has that name; remove or rename it first"
            ) from None
        assert cur.rowcount == 1, "the write lock is held: the version cannot have moved"
        self._log(
            conn, action, method, client, object_id=row[0], version=version + 1, before=before, after=after, **log
        )
        return self._record(conn, self._row(conn, row[0], include_removed=True))

    def update(
        self,
        obj: int | str | ObjectRecord,
        *,
        expected_version: int | None,
        method: str,
        T_world_obj: Any = _KEEP,
        cov: Any = _KEEP,
        status: Any = _KEEP,
        model: Any = _KEEP,
        kind: Any = _KEEP,
        dims: Any = _KEEP,
        sigmas: Any = _KEEP,
        client: str | None = None,
        clicks: Any = None,
        measurements: Any = None,
        residuals: Any = None,
        note: str | None = None,
        seen_at: float | None = None,
    ) -> ObjectRecord:
        """Change any of an object's pose, covariance, status, model, kind, dims, sigmas at once.

        expected_version : the version the caller read; ConflictError if it moved (None: no check,
        for operator commands that name the object explicitly). seen_at : when the image it was measured on
        was taken (unix seconds). Returns the new record.
        """
        fields: dict[str, Any] = {}
        if T_world_obj is not _KEEP:
            fields["T_world_obj"] = _check_pose(T_world_obj)
        if cov is not _KEEP:
            fields["cov"] = _check_cov(cov)
        if status is not _KEEP:
            fields["status"] = _check_status(status)
        if kind is not _KEEP:
            fields["kind"] = _check_kind(kind)
        if dims is not _KEEP:
            fields["dims"] = _check_values(dims, "dims", False)
        if sigmas is not _KEEP:
            fields["sigmas"] = _check_values(sigmas, "sigmas", True)
        if model is not _KEEP:
            _model_json(model)
        for value in (clicks, measurements, residuals):
            to_json(value)
        with self.transaction() as conn:
            row = self._row(conn, obj)
            if model is not _KEEP:
                fields["model_id"] = self._model_id(conn, model)
            return self._change(
                conn,
                row,
                fields,
                "update",
                method,
                client,
                expected_version,
                clicks=clicks,
                measurements=measurements,
                residuals=residuals,
                note=note,
                seen_at=seen_at,
            )

    def update_pose(
        self,
        obj: int | str | ObjectRecord,
        T_world_obj: np.ndarray,
        cov: np.ndarray | None = None,
        *,
        expected_version: int | None,
        method: str,
        client: str | None = None,
        clicks: Any = None,
        measurements: Any = None,
        residuals: Any = None,
        note: str | None = None,
        status: str = "known",
        seen_at: float | None = None,
    ) -> ObjectRecord:
        """New pose (and its covariance) of an object; its status becomes ``status`` ("known").

        clicks, measurements, residuals : what the estimate used (JSON values or arrays), kept in
        the history. ConflictError when the object's version is not ``expected_version``.
        """
        return self.update(
            obj,
            expected_version=expected_version,
            method=method,
            T_world_obj=T_world_obj,
            cov=cov,
            status=status,
            client=client,
            clicks=clicks,
            measurements=measurements,
            residuals=residuals,
            note=note,
            seen_at=seen_at,
        )

    def set_status(
        self,
        obj: int | str | ObjectRecord,
        status: str,
        *,
        expected_version: int | None = None,
        method: str = "operator",
        client: str | None = None,
        note: str | None = None,
    ) -> ObjectRecord:
        """Mark an object known, modelled or stale (e.g. stale when it is seen to have moved)."""
        return self.update(
            obj, expected_version=expected_version, method=method, status=status, client=client, note=note
        )

    def remove(
        self,
        obj: int | str | ObjectRecord,
        *,
        expected_version: int | None = None,
        method: str = "operator",
        client: str | None = None,
        note: str | None = None,
    ) -> ChangeRecord:
        """Remove an object from the site (kept in the history; ``undo`` brings it back)."""
        with self.transaction() as conn:
            row = self._row(conn, obj)
            self._change(conn, row, {"removed": 1}, "remove", method, client, expected_version, note=note)
            return self._change_record(conn, self._last_change_id(conn))

    # ------------------------------------------------------------------ history and undo
    @staticmethod
    def _last_change_id(conn) -> int:
        return int(conn.execute("SELECT max(id) FROM history").fetchone()[0])

    @staticmethod
    def _change_from_row(row: tuple) -> ChangeRecord:
        (
            i,
            t,
            client,
            method,
            action,
            oid,
            cid,
            version,
            before,
            after,
            clicks,
            meas,
            res,
            note,
            undoes,
            seen,
            name,
        ) = row
        load = lambda s: None if s is None else json.loads(s)  # noqa: E731
        return ChangeRecord(
            i,
            t,
            client,
            method,
            action,
            oid,
            name,
            cid,
            version,
            load(before),
            load(after),
            load(clicks),
            load(meas),
            load(res),
            note,
            undoes,
            seen,
        )

    _HISTORY_SELECT = (
        "SELECT h.id, h.time, h.client, h.method, h.action, h.object_id, h.calibration_id, "
        "h.version, h.before, h.after, h.clicks, h.measurements, h.residuals, h.note, "
        "h.undoes, h.seen_at, o.name FROM history h LEFT JOIN objects o ON o.id = h.object_id"
    )

    def _change_record(self, conn, change_id: int) -> ChangeRecord:
        row = conn.execute(f"{self._HISTORY_SELECT} WHERE h.id = ?", (_row_id(change_id),)).fetchone()
        if row is None:
            raise NotFoundError(f"no change #{change_id} in the history of {self._path}")
        return self._change_from_row(row)

    def change(self, change_id: int) -> ChangeRecord:
        """One entry of the history; NotFoundError if there is none."""
        with self._read() as conn:
            return self._change_record(conn, change_id)

    def history(self, obj: int | str | ObjectRecord | None = None, *, limit: int | None = None) -> list[ChangeRecord]:
        """The history, oldest first (the last ``limit`` entries), of one object (even removed) or of all."""
        with self._read() as conn:
            where, args = "", []
            if obj is not None:
                if isinstance(obj, str):
                    ids = [r[0] for r in conn.execute("SELECT id FROM objects WHERE name = ?", (obj,))]
                    if not ids:
                        raise NotFoundError(f"no object named {obj!r} has ever been in {self._path}")
                else:
                    ids = [self._row(conn, obj, include_removed=True)[0]]
                where = f" WHERE h.object_id IN ({','.join('?' * len(ids))})"
                args = ids
            q = f"{self._HISTORY_SELECT}{where} ORDER BY h.id DESC"
            if limit is not None:
                q += f" LIMIT {max(0, int(limit))}"
            rows = conn.execute(q, args).fetchall()
        return [self._change_from_row(r) for r in reversed(rows)]

    def later_changes(self, change_id: int) -> list[ChangeRecord]:
        """The changes of change ``change_id``'s object made after it, oldest first (what undoing it discards too);
        empty for a calibration's change. NotFoundError if there is no such change."""
        entry = self.change(change_id)
        if entry.object_id is None:
            return []
        return [c for c in self.history(entry.object_id) if c.id > entry.id]

    def history_since(self, change_id: int, *, limit: int | None = None) -> list[ChangeRecord]:
        """The changes after change ``change_id`` (every object and calibration), oldest first, at
        most ``limit`` of them (the oldest). A range on the history's primary key: cheap to ask
        often (an empty list when nothing happened)."""
        q = f"{self._HISTORY_SELECT} WHERE h.id > ? ORDER BY h.id"
        if limit is not None:
            q += f" LIMIT {max(0, int(limit))}"
        with self._read() as conn:
            rows = conn.execute(
                q, (max(-1, min(int(change_id), 2**63 - 1)),)
            ).fetchall()  # clamped to SQLite's integers
        return [self._change_from_row(r) for r in rows]

    def last_change_id(self) -> int:
        """The id of the latest change in the history (0 when it is empty)."""
        with self._read() as conn:
            return int(conn.execute("SELECT coalesce(max(id), 0) FROM history").fetchone()[0])

    def _revert(self, change_id: int, which: str, expected_version, client, note) -> ChangeRecord:
        with self.transaction() as conn:
            change = self._change_record(conn, change_id)
            if change.action == "calibration":
                return self._revert_calibration(conn, change, which, client, note)
            if change.object_id is None:
                raise ValueError(f"change #{change_id} changed no object; nothing to {which}")
            row = self._row(conn, change.object_id, include_removed=True)
            target = change.before if which == "undo" else change.after
            if target is None:  # undoing an "add": the object leaves the site
                target = {"removed": 1}
            fields = {k: target[k] for k in _SNAPSHOT_FIELDS if k in target and k != "name"}
            self._change(conn, row, fields, which, which, client, expected_version, note=note, undoes=change.id)
            return self._change_record(conn, self._last_change_id(conn))

    def undo(
        self, change_id: int, *, expected_version: int | None = None, client: str | None = None, note: str | None = None
    ) -> ChangeRecord:
        """Bring the object back to its state just before change ``change_id`` (pose, covariance,
        status, model, presence). It is itself a change ("undo") and can be undone in turn.
        Undoing a calibration makes the calibration before it the latest again.
        """
        return self._revert(change_id, "undo", expected_version, client, note)

    def restore(
        self, change_id: int, *, expected_version: int | None = None, client: str | None = None, note: str | None = None
    ) -> ChangeRecord:
        """Bring the object back to its state just after change ``change_id`` (any earlier pose)."""
        return self._revert(change_id, "restore", expected_version, client, note)

    # ------------------------------------------------------------------ calibrations
    def _calibration_from_row(self, row: tuple) -> CalibrationRecord:
        i, kind, data, res, t, client, method = row
        return CalibrationRecord(i, kind, json.loads(data), None if res is None else json.loads(res), t, client, method)

    def _insert_calibration(self, conn, kind, data_json, res_json, method, client, note=None, undoes=None):
        cur = conn.execute(
            "INSERT INTO calibrations (kind, data, residuals, time, client, method) VALUES (?, ?, ?, ?, ?, ?)",
            (kind, data_json, res_json, time.time(), str(client or self.client), method),
        )
        cid = int(cur.lastrowid)
        self._log(
            conn, "calibration", method, client, calibration_id=cid, after={"kind": kind}, note=note, undoes=undoes
        )
        row = conn.execute(
            "SELECT id, kind, data, residuals, time, client, method FROM calibrations WHERE id = ?", (cid,)
        ).fetchone()
        return self._calibration_from_row(row)

    def add_calibration(
        self,
        kind: str,
        data: Mapping[str, Any],
        residuals: Any = None,
        *,
        method: str = "calibration",
        client: str | None = None,
        note: str | None = None,
    ) -> CalibrationRecord:
        """Store a calibration (one transaction, logged): kind "camera" with data {"C": (3, 4),
        "width", "height", ...}, "turret" with data {"T_world_turret": (4, 4), ...} or "robot_base" with
        data {"T_world_base": (4, 4), "nominal": bool, "cov": (6, 6), ...}; residuals as the method gives
        them (pixels, metres)."""
        if not isinstance(kind, str) or not kind:
            raise ValueError(f"kind must be a non-empty string ('camera', 'turret'), got {kind!r}")
        if not isinstance(data, Mapping):
            raise ValueError(f"data must be a mapping, got {type(data).__name__}")
        if kind == "camera" or kind.startswith("camera:"):  # "camera:NAME": a site's other cameras
            C = np.asarray(data.get("C"), dtype=float) if "C" in data else None
            if C is None or C.shape != (3, 4) or not np.all(np.isfinite(C)):
                raise ValueError("a camera calibration needs data['C'], a finite 3×4 matrix")
        if kind == "turret":
            check_T(np.asarray(data.get("T_world_turret"), dtype=float), "data['T_world_turret']")
        if kind == "robot_base":
            check_T(np.asarray(data.get("T_world_base"), dtype=float), "data['T_world_base']")
        data_json, res_json = to_json(dict(data)), to_json(residuals)
        with self.transaction() as conn:
            return self._insert_calibration(conn, kind, data_json, res_json, method, client, note)

    def latest_calibration(self, kind: str) -> CalibrationRecord | None:
        """The most recent calibration of this kind, or None."""
        with self._read() as conn:
            row = conn.execute(
                "SELECT id, kind, data, residuals, time, client, method "
                "FROM calibrations WHERE kind = ? ORDER BY id DESC LIMIT 1",
                (kind,),
            ).fetchone()
        return None if row is None else self._calibration_from_row(row)

    def calibrations(self, kind: str | None = None) -> list[CalibrationRecord]:
        """Every calibration (of one kind), oldest first."""
        with self._read() as conn:
            q = "SELECT id, kind, data, residuals, time, client, method FROM calibrations"
            rows = conn.execute(
                q + (" WHERE kind = ? ORDER BY id" if kind else " ORDER BY id"), (kind,) if kind else ()
            ).fetchall()
        return [self._calibration_from_row(r) for r in rows]

    def _revert_calibration(self, conn, change: ChangeRecord, which: str, client, note) -> ChangeRecord:
        cid = change.calibration_id
        kind = conn.execute("SELECT kind FROM calibrations WHERE id = ?", (cid,)).fetchone()[0]
        if which == "undo":
            row = conn.execute(
                "SELECT data, residuals FROM calibrations WHERE kind = ? AND id < ? ORDER BY id DESC LIMIT 1",
                (kind, cid),
            ).fetchone()
            if row is None:
                raise ValueError(
                    f"change #{change.id} is the first {kind} calibration; there is none before it to go back to"
                )
        else:
            row = conn.execute("SELECT data, residuals FROM calibrations WHERE id = ?", (cid,)).fetchone()
        self._insert_calibration(conn, kind, row[0], row[1], which, client, note, undoes=change.id)
        return self._change_record(conn, self._last_change_id(conn))
