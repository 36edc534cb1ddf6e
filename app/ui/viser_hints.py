"""One type-hint table per viser property class, not one per scene node handle.

viser 1.1 reads a handle's property type hints (``typing.get_type_hints`` on its props class) the first
time a property of that handle is set, once per handle: about 0.25 ms each, 30 % of the CPU time of a
full draw of 2,000 objects (one label each). The hints depend on the class only, so they are computed
once per class here. Applied only where viser has the attribute this replaces (a cached property);
another viser keeps its own.
"""

from __future__ import annotations

import functools
import typing
from functools import cached_property

__all__ = ["share_prop_hints"]


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
