"""Checks of the core's inputs at its public entry points: a clear ``ValueError`` (saying what was
received) instead of a NaN, an inf or an ``OverflowError`` further in.

Bounds: world coordinates within ±``MAX_M`` metres, pixels within ±``MAX_PX``, noise scales
(σ, thresholds) within [``MIN_SCALE``, ``MAX_SCALE``]. They are far beyond any workcell, image or
sensor, and small enough that the solvers' products of a few such numbers stay finite.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MAX_M", "MAX_PX", "MIN_SCALE", "MAX_SCALE", "finite_array", "positive_scale", "image_size"]

#: The largest world coordinate accepted, metres (1000 km).
MAX_M = 1e6
#: The largest pixel coordinate accepted (a click 10⁷ px off the image is no click).
MAX_PX = 1e7
#: Range of a noise scale or threshold (σ in px, m or rad; a Huber threshold): 1/σ² and σ² stay finite.
MIN_SCALE = 1e-9
MAX_SCALE = 1e9
#: The largest image side accepted, pixels.
MAX_IMAGE_PX = 1_000_000


def _describe(a: np.ndarray) -> str:
    """A short description of a bad array: its shape and its worst entry."""
    bad = ~np.isfinite(a)
    if bad.any():
        return f"shape {a.shape} with {int(bad.sum())} NaN/inf value(s)"
    return f"shape {a.shape} with max |value| {float(np.abs(a).max()):.3g}"


def finite_array(
    x, shape: tuple, name: str, *, max_abs: float | None = None, unit: str = "", min_count: int = 0
) -> np.ndarray:
    """``x`` as a float array of ``shape`` (``None`` for any size along that axis), every entry
    finite and, when ``max_abs`` is given, at most ``max_abs`` in magnitude; else ValueError naming
    ``name`` and what was received (``unit`` follows the bound in the message, e.g. " m").
    ``min_count``: the least size of the first axis."""
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be an array of numbers of shape {_shape_text(shape)}, got {x!r:.80}") from None
    if a.ndim != len(shape) or any(s is not None and s != n for s, n in zip(shape, a.shape)):
        raise ValueError(f"{name} must have shape {_shape_text(shape)}, got {a.shape}")
    if a.ndim and a.shape[0] < min_count:
        raise ValueError(f"{name} needs at least {min_count} rows, got {a.shape[0]}")
    if a.size:
        if not np.isfinite(a).all():
            raise ValueError(f"{name} must be finite, got {_describe(a)}")
        if max_abs is not None and np.abs(a).max() > max_abs:
            raise ValueError(f"{name} must lie within ±{max_abs:g}{unit}, got {_describe(a)}")
    return a


def _shape_text(shape: tuple) -> str:
    return "(" + ", ".join("N" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"


def positive_scale(x, name: str, unit: str = "") -> float:
    """A noise scale or threshold as a float in [MIN_SCALE, MAX_SCALE]; else ValueError."""
    try:
        v = float(x)
    except (TypeError, ValueError, OverflowError):
        raise ValueError(f"{name} must be a number, got {x!r:.80}") from None
    if not (MIN_SCALE <= v <= MAX_SCALE):
        raise ValueError(
            f"{name} must be a positive finite number between {MIN_SCALE:g} and {MAX_SCALE:g}{unit}, got {x!r}"
        )
    return v


def image_size(width, height) -> tuple[int, int]:
    """(width, height) as positive integers up to MAX_IMAGE_PX; else ValueError."""
    out = []
    for name, v in (("width", width), ("height", height)):
        try:
            f = float(v)
        except (TypeError, ValueError, OverflowError):
            f = math.nan
        if not (math.isfinite(f) and f == int(f) and 0 < f <= MAX_IMAGE_PX):
            raise ValueError(f"{name} must be a positive finite integer (pixels, at most {MAX_IMAGE_PX}), got {v!r}")
        out.append(int(f))
    return out[0], out[1]
