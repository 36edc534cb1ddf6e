"""What an object's name may be, checked wherever a name enters: the database (every write), a scene
file, ``mcit db import`` (``--name`` or the file's stem) and a ``.cao`` file's ``name=``.

A name is shown in every operator's browser, written in the history and the pose feed, and typed on
the command line, so it is kept to words: letters and digits (any script), then also spaces and
``_ - . + ( )``, at most ``MAX_NAME_CHARS``. Markup characters (``< > & [ ] * ` |`` …), quotes,
slashes and control characters are refused. The interface escapes every text it shows anyway
(``app.markup``): this rule keeps names readable and safe in the places mcit does not control.
"""

from __future__ import annotations

import re
from typing import Any

__all__ = ["MAX_NAME_CHARS", "NAME_RULE", "check_object_name"]

MAX_NAME_CHARS = 64
NAME_RULE = (
    f"1 to {MAX_NAME_CHARS} characters: a letter or digit first, then letters, digits, spaces and _ - . + ( ), "
    "not ending in a space"
)
_NAME = re.compile(r"[^\W_][\w .+()\-]*", re.UNICODE)


def check_object_name(name: Any, what: str = "an object name") -> str:
    """``name`` when it is a valid object name; ValueError saying the rule and what was given otherwise."""
    if isinstance(name, str) and len(name) <= MAX_NAME_CHARS and _NAME.fullmatch(name) and not name.endswith(" "):
        return name
    shown = repr(name) if not isinstance(name, str) or len(name) <= 80 else repr(name[:80]) + "…"
    raise ValueError(f"{what} must be {NAME_RULE}; got {shown}")
