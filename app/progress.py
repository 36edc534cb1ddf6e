"""The progress of a long command (``mcit track``, ``calibrate-intrinsics``, ``render``, ``demo``): a tqdm
bar on standard error while it is a terminal, nothing otherwise.

``progress_bar(label)`` is ``show(done, total)`` (total None when unknown), the callback form the long
jobs take (``render_video(progress=)``, ``track_sequence(progress=)``, the demo's replay), and a context
manager that closes the bar however the job ends. The bar goes to stderr, so stdout stays the command's
result for a script to read; it is drawn only when stderr is a terminal (a log file, a pipe, CI and
the tests that read a command's output get nothing) and not with ``quiet`` (the commands' ``--quiet``).
"""

from __future__ import annotations

import sys
from typing import TextIO

__all__ = ["ProgressBar", "progress_bar"]


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):  # no isatty, or a closed stream
        return False


def _size(stream) -> dict:
    """tqdm's size options: follow the terminal's size when it has one; 80 × 24 when it says 0 × 0 (a
    terminal whose size was never set, where tqdm would hide its bar as beyond the screen)."""
    import os

    try:
        size = os.get_terminal_size(stream.fileno())
        if size.columns > 0 and size.lines > 0:
            return {"dynamic_ncols": True}
    except (AttributeError, ValueError, OSError):  # no file descriptor (a StringIO), or not a terminal
        pass
    return {"ncols": 80, "nrows": 24}


class ProgressBar:
    """``show(done, total)``: a tqdm bar labelled ``label`` on ``stream`` (default: stderr as it is when
    made), drawn on a terminal only and not when ``quiet``; closed when ``done`` reaches ``total`` or on
    ``close()`` / leaving its ``with`` block (calls after that are ignored)."""

    def __init__(self, label: str, *, quiet: bool = False, stream: TextIO | None = None):
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.enabled = not quiet and _is_terminal(self.stream)
        self._bar = None
        self._closed = False

    def __call__(self, done: int, total: int | None = None) -> None:
        if not self.enabled or self._closed:
            return
        if self._bar is None:
            from tqdm import tqdm

            self._bar = tqdm(total=total, desc=self.label, unit="", file=self.stream, **_size(self.stream))
        elif total is not None and total != self._bar.total:
            self._bar.total = total
        self._bar.update(max(0, int(done) - self._bar.n))
        if total is not None and done >= total:
            self.close()

    def close(self) -> None:
        """End the bar's line (it stays, showing where the job stopped)."""
        self._closed = True
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def progress_bar(label: str, *, quiet: bool = False, stream: TextIO | None = None) -> ProgressBar:
    """A ``ProgressBar`` (see there): ``with progress_bar("frames", quiet=args.quiet) as show: job(progress=show)``."""
    return ProgressBar(label, quiet=quiet, stream=stream)
