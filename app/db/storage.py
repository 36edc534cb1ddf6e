"""What the disk and other programs do to the database file, in the operator's words.

* ``read_uri(path)``: how to read a database without leaving files behind. SQLite's WAL mode
  keeps ``-wal`` and ``-shm`` files beside the database while a connection is open, and a
  read-only connection (``mode=ro``) never deletes them. So a file mcit may write is read through
  an ordinary connection (closed, it removes them; the caller sets ``query_only``); a file or
  folder it may not write (an immutable file, a read-only mount, another account's folder) is
  read as it is on disk (``immutable=1``: no lock, no side file) unless a ``-wal`` is already
  there (another program has it open), where ``mode=ro`` reads the committed changes in it.
* ``check_writable(path)``: refuse, before SQLite creates anything, a write to a read-only file,
  a read-only folder (the journal files could not be made) or a read-only file system.
* ``explain(exc, path, wait_s)``: an SQLite error (or the system's OSError: ENOSPC, EROFS, EACCES,
  EIO) turned into ``DatabaseUnavailable`` with one sentence that says nothing was written and what
  to do before trying again (disk full, read-only, locked by another writer and by whom, I/O error).
* ``lock_holders(path)``: the processes of this computer holding the database's write lock, from
  ``/proc/locks`` (SQLite's POSIX locks: byte 120 of the ``-shm`` file is the WAL write lock).
"""

from __future__ import annotations

import errno
import os
import sqlite3
from pathlib import Path

__all__ = [
    "DatabaseRefused",
    "DatabaseUnavailable",
    "read_uri",
    "can_write",
    "check_writable",
    "explain",
    "lock_holders",
    "side_files",
]

_WAL_WRITE_LOCK_BYTE = 120  # os_unix.c: UNIX_SHM_BASE, the first of the -shm file's lock bytes
_SIDE_SUFFIXES = ("-wal", "-shm", "-journal")


class DatabaseUnavailable(RuntimeError):
    """The database cannot be read or written now (read-only, disk full, locked by another writer,
    I/O error, missing for a read); nothing was written. The message says what to do."""


class DatabaseRefused(RuntimeError):
    """The file is not one mcit may open (not SQLite, corrupt, not mcit's, newer); left untouched."""


def side_files(path: Path) -> list[Path]:
    """The files SQLite may keep beside ``path`` (``-wal``, ``-shm``, ``-journal``)."""
    return [path.with_name(path.name + s) for s in _SIDE_SUFFIXES]


def can_write(path: Path) -> bool:
    """Whether this process may write ``path`` (an existing file) and create files beside it."""
    return os.access(path, os.W_OK) and os.access(path.parent, os.W_OK)


def read_uri(path: Path) -> tuple[str, bool]:
    """(SQLite URI, immutable) to read the existing database ``path`` leaving no file behind.

    A writable file gives ``mode=rw`` (the caller must set ``PRAGMA query_only``); otherwise
    ``mode=ro``, with ``immutable=1`` when no ``-wal`` is beside it (nothing uncommitted to the
    main file to miss, and no side file can or need be made).
    """
    p = path.resolve()
    base = p.as_uri()
    if can_write(p):
        return f"{base}?mode=rw", False
    if p.with_name(p.name + "-wal").exists():
        return f"{base}?mode=ro", False
    return f"{base}?mode=ro&immutable=1", True


def _read_only_fs(path: Path) -> bool:
    try:
        return bool(os.statvfs(path).f_flag & os.ST_RDONLY)
    except OSError:
        return False


def _read_only(path: Path) -> tuple[str, str, str] | None:
    """(what is read-only, how to make it writable, what else to do instead) when this process may not
    write the database ``path`` or its folder; None when it may."""
    p = path.resolve()
    copy = " or work on a copy (list, show, history and export work on it as it is)"
    if _read_only_fs(p.parent):
        return f"{path} is on a read-only file system", "remount it read-write", copy
    if not os.access(p, os.W_OK):
        return f"{path} is read-only", "make it writable", copy
    if not os.access(p.parent, os.W_OK):
        return (
            f"the folder {p.parent} is read-only and the database needs to keep its journal files beside {p.name}",
            "make the folder writable",
            " or move the database",
        )
    return None


def check_writable(path: Path) -> None:
    """DatabaseUnavailable unless mcit may write the existing database ``path`` and its side files."""
    found = _read_only(path)
    if found is None:
        return
    what, remedy, instead = found
    raise DatabaseUnavailable(f"{what}, so nothing was written; {remedy}{instead}")


def _describe(pid: int) -> str:
    try:
        args = Path(f"/proc/{pid}/cmdline").read_bytes().rstrip(b"\0").split(b"\0")
    except OSError:
        return f"pid {pid}"
    words = [a.decode(errors="replace") for a in args if a]
    if len(words) > 1 and Path(words[0]).name.startswith("python") and not words[1].startswith("-"):
        words = words[1:]  # "python /path/bin/mcit serve" -> "mcit serve"
    if words:
        words[0] = Path(words[0]).name
    command = " ".join(" ".join(words).split())  # one line, whatever the arguments hold
    command = "".join(c if c.isprintable() else "?" for c in command)
    if len(command) > 80:
        command = command[:77] + "..."
    return f"pid {pid}: {command}" if command else f"pid {pid}"


def lock_holders(path: Path) -> list[str]:
    """Who holds the database's write lock, as "pid N: command" (this computer only; [] if unknown).

    Reads ``/proc/locks`` for POSIX write locks on byte 120 of the ``-shm`` file (the WAL write
    lock) or on the database file itself (a writer in another journal mode).
    """
    p = path.resolve()
    wanted: dict[tuple[int, int, int], tuple[int, int]] = {}
    for target, span in ((p.with_name(p.name + "-shm"), (_WAL_WRITE_LOCK_BYTE, _WAL_WRITE_LOCK_BYTE)), (p, (0, 2**63))):
        try:
            st = os.stat(target)
        except OSError:
            continue
        wanted[(os.major(st.st_dev), os.minor(st.st_dev), st.st_ino)] = span
    try:
        lines = Path("/proc/locks").read_text().splitlines()
    except OSError:
        return []
    pids: list[int] = []
    for line in lines:
        f = line.split()
        if "->" in f:  # a waiter ("1: -> POSIX ..."), not a holder
            continue
        if len(f) < 8 or f[1] != "POSIX" or f[3] != "WRITE":
            continue
        try:
            pid = int(f[4])
            major, minor, ino = f[5].split(":")
            key = (int(major, 16), int(minor, 16), int(ino))
            start, end = int(f[6]), (2**63 if f[7] == "EOF" else int(f[7]))
        except ValueError:
            continue
        span = wanted.get(key)
        if span and start <= span[1] and end >= span[0] and pid > 0 and pid != os.getpid() and pid not in pids:
            pids.append(pid)
    return [_describe(pid) for pid in pids]


def _code(exc: sqlite3.Error) -> str:
    name = getattr(exc, "sqlite_errorname", None) or ""
    if name:
        return name
    text = str(exc).lower()
    for needle, code in (
        ("disk is full", "SQLITE_FULL"),
        ("readonly", "SQLITE_READONLY"),
        ("read-only", "SQLITE_READONLY"),
        ("is locked", "SQLITE_BUSY"),
        ("i/o error", "SQLITE_IOERR"),
        ("unable to open", "SQLITE_CANTOPEN"),
        ("malformed", "SQLITE_CORRUPT"),
        ("not a database", "SQLITE_NOTADB"),
    ):
        if needle in text:
            return code
    return ""


# The system's storage errors as the SQLite codes that mean the same to the operator.
_OS_CODES = {
    errno.ENOSPC: "SQLITE_FULL",
    errno.EDQUOT: "SQLITE_FULL",
    errno.EROFS: "SQLITE_READONLY",
    errno.EACCES: "SQLITE_READONLY",
    errno.EPERM: "SQLITE_READONLY",
    errno.EIO: "SQLITE_IOERR",
}


def explain(exc: Exception, path: Path, wait_s: float) -> Exception:
    """The operator's exception for an SQLite error, or an OSError of the system, met writing ``path``
    (``exc`` itself when it is not one the disk or another program caused: a programming error stays
    visible). Each message says that nothing was written and what to do before trying again."""
    if isinstance(exc, OSError):
        code = _OS_CODES.get(exc.errno, "")
        detail = (exc.strerror or str(exc)).lower()
    elif isinstance(exc, sqlite3.Error):
        code = _code(exc)
        detail = f"SQLite: {exc}"
    else:
        return exc
    if code.startswith("SQLITE_FULL"):
        return DatabaseUnavailable(
            f"the disk holding {path} is full, so nothing was written; free some space, then try again"
        )
    if code.startswith("SQLITE_READONLY"):
        found = _read_only(path)
        if found is not None:
            what, remedy, _ = found  # (the command line's "instead" is no advice for a running server)
            return DatabaseUnavailable(f"{what}, so nothing was written; {remedy}, then try again")
        return DatabaseUnavailable(
            f"{path} could not be written ({detail}), so nothing was written; check that the file "
            "and its folder are writable, then try again"
        )
    if code.startswith(("SQLITE_BUSY", "SQLITE_LOCKED")):
        holders = lock_holders(path)
        who = f" ({'; '.join(holders)})" if holders else ""
        return DatabaseUnavailable(
            f"the database {path} is locked by another program{who}, still after {wait_s:g} s, so "
            "nothing was written; try again when that program has finished"
        )
    if code.startswith("SQLITE_IOERR"):
        return DatabaseUnavailable(
            f"the disk holding {path} reported an error ({detail}), so nothing was written; check "
            "the disk (space, cable, dmesg), then try again"
        )
    if code.startswith("SQLITE_CANTOPEN"):
        return DatabaseUnavailable(
            f"{path} cannot be opened ({detail}); check that it and its folder exist and are readable"
        )
    if code.startswith(("SQLITE_CORRUPT", "SQLITE_NOTADB")):
        return DatabaseRefused(
            f"{path} is damaged ({detail}); nothing was written. Restore a backup, or recover it with "
            "the sqlite3 shell's .recover, then open the copy"
        )
    return exc
