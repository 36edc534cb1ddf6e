"""viser's per-handle costs, paid once per class or without numpy's generality.

One type-hint table per viser property class, not one per scene node handle: viser 1.1 reads a handle's
property type hints (``typing.get_type_hints`` on its props class) the first time a property of that
handle is set, once per handle: about 0.25 ms each, 30 % of the CPU time of a full draw of 2,000 objects
(one label each). The hints depend on the class only, so they are computed once per class here.

A node's pose set without ``np.allclose``: viser compares each new position or orientation with the
old one (``_set_pose_vector``) to send nothing when it has not moved, with ``np.allclose`` on 3 or 4
numbers, about 60 of the 80 us a label's move costs (a new label sets two). The same test, written for
a few floats, keeps what viser sends unchanged.

Each is applied only where viser has what it replaces (a cached property; the function with its
parameters); another viser keeps its own.
"""

from __future__ import annotations

import functools
import inspect
import math
import typing
from functools import cached_property

__all__ = ["share_prop_hints", "plain_pose_setter", "close_as_numpy"]


@functools.cache
def _hints(cls: type) -> dict[str, typing.Any]:
    return typing.get_type_hints(cls)


def share_prop_hints() -> bool:
    """Make viser's handles share their class's property hints; True when applied (idempotent)."""
    try:
        from viser._assignable_props_api import AssignablePropsBase
    except ImportError:
        return False
    current = AssignablePropsBase.__dict__.get("_prop_hints")
    if isinstance(current, property) and getattr(current.fget, "__name__", "") == "_shared_prop_hints":
        return True
    if not isinstance(current, cached_property):
        return False

    def _shared_prop_hints(self) -> dict[str, typing.Any]:
        return _hints(type(self._impl.props))

    AssignablePropsBase._prop_hints = property(_shared_prop_hints)
    return True


def close_as_numpy(new: tuple[float, ...], old) -> bool:
    """``np.allclose(new, old)`` (rtol 1e-5, atol 1e-8, NaN never close, equal infinities close) for a few
    floats ``new`` and an array or sequence ``old`` of the same length."""
    return all(
        a == b or (math.isfinite(a) and math.isfinite(b) and abs(a - b) <= 1e-8 + 1e-5 * abs(b))
        for a, b in zip(new, (float(v) for v in old))
    )


def plain_pose_setter() -> bool:
    """Make viser's pose setters compare with ``close_as_numpy``; True when applied (idempotent)."""
    try:
        from viser import _scene_handles
        from viser._scene_api import cast_vector
    except ImportError:
        return False
    current = getattr(_scene_handles, "_set_pose_vector", None)
    if getattr(current, "__name__", "") == "_plain_set_pose_vector":
        return True
    if current is None or list(inspect.signature(current).parameters) != [
        "current",
        "value",
        "length",
        "queue",
        "make_message",
    ]:
        return False

    def _plain_set_pose_vector(current, value, length, queue, make_message) -> None:
        value_cast = cast_vector(value, length)
        if close_as_numpy(value_cast, current.tolist()):
            return
        current[:] = value_cast
        queue(make_message(value_cast))

    _scene_handles._set_pose_vector = _plain_set_pose_vector
    return True
