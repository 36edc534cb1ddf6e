"""The primitives a B-Rep model is made of, each behind one interface (``Primitive``, see ``base``).

``KINDS`` maps each stored kind tag to its class: a new primitive is one class and one entry here.
"""

from __future__ import annotations

from typing import Any

from .base import CaoPart, Outline, Primitive, SampleGroup, join_outlines
from .circle import Circle
from .polyhedron import Polyhedron
from .revolution import Revolution
from .sphere import Sphere

__all__ = [
    "Primitive",
    "Outline",
    "CaoPart",
    "SampleGroup",
    "Polyhedron",
    "Revolution",
    "Circle",
    "Sphere",
    "KINDS",
    "primitive_from_dict",
    "join_outlines",
]

KINDS: dict[str, type] = {cls.kind: cls for cls in (Polyhedron, Revolution, Circle, Sphere)}


def primitive_from_dict(d: dict[str, Any], default_kind: str) -> Primitive:
    """The primitive a stored dict describes: its ``kind`` tag, else ``default_kind`` (the stored forms
    of the first kinds carry no tag: a model's "solids" are solids of revolution, its "circles" circles).

    Raises KeyError or TypeError on a malformed dict, ValueError on an unknown kind or bad values.
    """
    kind = d.get("kind", default_kind)
    cls = KINDS.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise ValueError(f"unknown primitive kind {kind!r}; known: {', '.join(sorted(KINDS))}")
    return cls.from_dict(d)
