"""argparse ``type=`` checks for the command line's numbers: each refusal is argparse's one line,
"argument --X: expected …, got '…'"."""

from __future__ import annotations

import argparse
from collections.abc import Callable

__all__ = [
    "MAX_FPS",
    "MAX_COORD_M",
    "number",
    "frame_rate",
    "port_number",
    "coordinate_m",
    "angle_deg",
    "percent",
    "pixel_uv",
    "frame_index",
    "frame_total",
]

MAX_FPS = 240.0  # the fastest rate a command replays, renders or writes at (frames per second)
MAX_COORD_M = 1e6  # |coordinate| of a site, metres (as model files: app.models_io.cao.MAX_COORD_M)


def number(convert: Callable[[str], float], ok: Callable[[float], bool], *, kind: str, expected: str):
    """A ``type=`` that reads ``convert(text)`` (else "expected {kind}") and keeps it when ``ok`` (else
    "expected {expected}"); ``ok`` is false for NaN when written as a comparison."""

    def parse(text: str):
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {kind}, got {text!r}") from None
        if not ok(value):
            raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}")
        return value

    return parse


frame_rate = number(
    float,
    lambda v: 0.0 < v <= MAX_FPS,
    kind="frames per second (a number)",
    expected=f"a frame rate above 0 and at most {MAX_FPS:g} frames per second",
)
port_number = number(
    int, lambda v: 0 <= v <= 65535, kind="a TCP port number", expected="a TCP port from 1 to 65535 (0: any free port)"
)
coordinate_m = number(
    float,
    lambda v: abs(v) <= MAX_COORD_M,
    kind="metres (a number)",
    expected=f"a finite coordinate within ±{MAX_COORD_M:g} m",
)
angle_deg = number(
    float, lambda v: abs(v) <= 3600.0, kind="degrees (a number)", expected="a finite angle within ±3600 degrees"
)
frame_index = number(
    int, lambda v: 0 <= v <= 10**9, kind="a frame number (a whole number)", expected="a frame number from 0"
)
frame_total = number(
    int, lambda v: 1 <= v <= 10**9, kind="a number of frames (a whole number)", expected="at least 1 frame"
)
percent = number(int, lambda v: 1 <= v <= 100, kind="a whole number from 1 to 100", expected="1 to 100")


def pixel_uv(text: str) -> tuple[float, float]:
    """A clicked pixel ``u,v`` (u right, v down; e.g. ``192,84.5``)."""
    try:
        u, v = (float(x) for x in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"a clicked pixel is 'u,v' (e.g. 192,84.5), got {text!r}") from None
    if not (abs(u) <= 1e6 and abs(v) <= 1e6):
        raise argparse.ArgumentTypeError(f"a clicked pixel is two finite numbers within ±1e6, got {text!r}")
    return u, v
