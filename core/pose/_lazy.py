"""The compiled kernels (``core.pose._kernels``, numba) loaded on first use, not on import.

Loading numba and llvmlite costs about 0.1–0.2 s, which ``mcit serve`` would pay before its first
page: the pose modules hold ``_k = kernels()`` and reach the kernels through it; the first
attribute read imports the module, and each attribute, once read, is kept on the proxy, so later
calls cost an ordinary attribute lookup.
"""

from __future__ import annotations

import importlib


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
