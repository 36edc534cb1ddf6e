"""Shared strategies for the core's fuzz tests (tests/core/test_fuzz_*.py): valid inputs mutated
into non-finite, huge, tiny and degenerate ones; and the check every fuzzed call must pass."""

from __future__ import annotations

import numpy as np
from hypothesis import strategies as st

NASTY = [np.nan, np.inf, -np.inf, 0.0, -0.0, 5e-324, 1e-300, -1e-200, 1e-12, 1e6, -1e7, 1e12, 1e200, -1e300, 1.7e308]
nasty = st.sampled_from(NASTY)
KINDS = ("same", "entries", "scale", "collapse", "collinear", "shape", "jitter")


@st.composite
def mutated(draw, base, kinds=KINDS) -> np.ndarray:
    """A copy of ``base`` unchanged, with some entries nasty, scaled by a nasty factor, its rows
    collapsed onto the first or onto the line of the first two, cut to a wrong shape, or jittered."""
    a = np.array(base, dtype=float, copy=True)
    kind = draw(st.sampled_from(kinds))
    with np.errstate(all="ignore"):
        if kind == "entries":
            flat = a.reshape(-1)
            for _ in range(draw(st.integers(1, 3))):
                flat[draw(st.integers(0, flat.size - 1))] = draw(nasty)
        elif kind == "scale":
            a = a * draw(nasty)
        elif kind == "collapse" and a.ndim >= 1 and len(a) > 1:
            a[:] = a[0]
        elif kind == "collinear" and a.ndim >= 1 and len(a) > 2:
            t = np.linspace(0.0, 1.0, len(a)).reshape((-1,) + (1,) * (a.ndim - 1))
            a = a[0] + t * (a[1] - a[0]) + draw(st.sampled_from([0.0, 1e-15, 1e-9])) * a
        elif kind == "shape":
            a = a.reshape(-1)[: draw(st.integers(0, max(a.size - 1, 0)))]
        elif kind == "jitter":
            a = a + draw(st.sampled_from([1e-300, 1e-12, 1e-6])) * np.random.default_rng(
                draw(st.integers(0, 9))
            ).normal(size=a.shape)
    return a


scalar = st.one_of(nasty, st.floats(-1e3, 1e3), st.integers(-3, 3))


def finite(x) -> bool:
    """Every number in x (array, float, tuple/list of them) finite."""
    if isinstance(x, (tuple, list)):
        return all(finite(v) for v in x)
    return bool(np.all(np.isfinite(np.asarray(x, dtype=float))))


def call(f, *args, **kwargs):
    """f(*args, **kwargs), or None when it raised ValueError (the documented refusal); any other
    exception fails the test. Numpy's warnings are silenced: only the outcome counts."""
    with np.errstate(all="ignore"):
        try:
            return f(*args, **kwargs)
        except ValueError as exc:
            assert str(exc), "a ValueError must say what was wrong"
            return None
