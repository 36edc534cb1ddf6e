"""Model files' paths: one way to follow symbolic links, with one error for a loop of them."""

from __future__ import annotations

import errno
from pathlib import Path

__all__ = ["resolve_file"]


def resolve_file(path: Path, error: type[Exception], where: str | None = None) -> Path:
    """``path`` absolute, its symbolic links followed; ``error`` (naming ``where``, e.g. the file:line
    that names it) for links that lead back to each other or cannot be followed."""
    try:
        return path.resolve()
    except (RuntimeError, OSError) as exc:  # RuntimeError before Python 3.13, OSError ELOOP since
        if isinstance(exc, OSError) and exc.errno != errno.ELOOP:
            raise error(f"{where or path}: cannot follow {path}: {exc.strerror or type(exc).__name__}") from None
        raise error(
            f"{where + ': ' if where else ''}{path} is a loop of symbolic links that never reaches a file; "
            "point the link at the model file"
        ) from None
