"""What the command line prints is text, never terminal control: names, operators and methods from
the database may hold escape sequences (an old or hostile database) that would retitle or clear the
user's terminal. ``safe_output()`` shows every control character except a line break and a tab as
its ``\\xNN`` code on stdout and stderr while a command runs."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator

__all__ = ["visible", "safe_output"]

_CONTROLS = {c: f"\\x{c:02x}" for c in [*range(0x20), 0x7F, *range(0x80, 0xA0)] if c not in (0x09, 0x0A)}


def visible(text: str) -> str:
    """``text`` with every control character but a line break and a tab written as ``\\xNN``."""
    return text.translate(_CONTROLS)


class _Visible:
    """A text stream that writes ``visible`` text to the stream it wraps."""

    def __init__(self, stream):
        self._stream = stream

    def write(self, text: str) -> int:
        return self._stream.write(visible(text))

    def __getattr__(self, name: str):
        return getattr(self._stream, name)


@contextlib.contextmanager
def safe_output() -> Iterator[None]:
    """While open, what is printed to stdout and stderr shows control characters as codes."""
    out, err = sys.stdout, sys.stderr
    sys.stdout, sys.stderr = _Visible(out), _Visible(err)
    try:
        yield
    finally:
        sys.stdout, sys.stderr = out, err
