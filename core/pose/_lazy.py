"""The compiled kernels (``core.pose._kernels``, numba) loaded on first use, not on import.

Loading numba and llvmlite costs about 0.1–0.2 s, which ``mcit serve`` would pay before its first
page: the pose modules hold ``_k = kernels()`` and reach the kernels through it; the first
attribute read imports the module, and each attribute, once read, is kept on the proxy, so later
calls cost an ordinary attribute lookup.
"""

from __future__ import annotations

import importlib

import numpy as np


class _Kernels:
    def __getattr__(self, name: str):  # only called for names not yet kept
        value = getattr(importlib.import_module("core.pose._kernels"), name)
        setattr(self, name, value)
        return value


_KERNELS = _Kernels()


def kernels() -> _Kernels:
    """The shared proxy of ``core.pose._kernels``."""
    return _KERNELS


def warm_up() -> None:
    """Load (or, the first time on a machine, compile: ~30 s) every kernel, with the argument types
    core.pose passes: call it in a background thread at start-up so that no click waits for it."""
    _KERNELS.warm_up()


def frozen(a) -> np.ndarray:
    """``a`` as a read-only contiguous float array (a view when it is one already; no copy of a contiguous array).

    numba compiles a kernel once per writeability of each input, and callers' arrays are some read-only (a
    ``Camera``'s C, frozen click sets), some not: every array input made read-only, one compiled version serves
    them all, the one ``warm_up`` compiles at start (else a first click compiled another: 10–20 s)."""
    a = np.ascontiguousarray(a, dtype=float)
    if a.flags.writeable:
        a = a.view()
        a.flags.writeable = False
    return a
