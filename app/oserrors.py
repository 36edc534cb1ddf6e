"""What to do about a failed file operation, by its errno: the advice every command's one-line error ends with."""

from __future__ import annotations

import errno

__all__ = ["os_error_advice"]

_ERRNO_ADVICE = {
    errno.ENOENT: "check the path",
    errno.EACCES: "check its permissions",
    errno.EPERM: "check its permissions",
    errno.ENOSPC: "free some space and try again",
    errno.EROFS: "it is on a read-only file system: choose another place",
    errno.EISDIR: "give a file, not a folder",
    errno.ENOTDIR: "check the path",
}


def os_error_advice(exc: OSError) -> str:
    """What to do about a failed file operation, by its errno ("free some space and try again")."""
    return _ERRNO_ADVICE.get(exc.errno, "check the file or device named and try again")
