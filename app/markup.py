"""Text shown in the interface's Markdown: what comes from the database, a file or an operator is
text, never markup.

viser renders a GUI Markdown element with raw HTML enabled and unsanitised (its client parses the
HTML with the browser's own parser), so an object named ``<img src=x onerror=…>`` would run its
script in every operator's browser, and one named ``![x](http://…)`` would load a remote image.
``Md`` is Markdown that mcit's own code wrote; any other ``str`` combined with it — as an
argument of ``Md.format``, an operand of ``+``, a part of ``Md.join`` — is escaped first by
``escape``, the one function that turns text into Markdown. The panel's Markdown elements take
their content through ``as_markdown``, which escapes whatever is not ``Md``.
"""

from __future__ import annotations

import numbers
import re
from collections.abc import Iterable
from typing import Any

__all__ = ["Md", "escape", "as_markdown"]

# HTML's three (an element, an entity), and every character that starts Markdown inline syntax
# (emphasis, code, links and images, tables, strike-through, headings). A line break would start a
# new block (a heading, a list, a table row): it becomes a space.
_ESCAPES = str.maketrans(
    {"&": "&amp;", "<": "&lt;", ">": "&gt;", "\n": " ", "\r": " ", "\t": " ", "\x00": ""}
    | {c: "\\" + c for c in "\\`*_[]|~#!"}
)
# GitHub's autolinks of bare addresses (``scheme://…``, ``www.…``, ``name@host``, ``mailto:``,
# ``xmpp:``) are found in the text once its escapes are read, so a backslash does not stop them: an
# invisible word joiner (U+2060) inside each breaks the pattern and shows the same.
_AUTOLINK = re.compile(r"(:(?=//)|\bwww(?=\.)|@|\bmailto(?=:)|\bxmpp(?=:))", re.IGNORECASE)
WORD_JOINER = "\u2060"


class Md(str):
    """Markdown written by mcit (trusted). Combining it with plain text escapes the text."""

    __slots__ = ()

    def __add__(self, other: Any) -> Md:
        return Md(str.__add__(self, escape(other)))

    def __radd__(self, other: Any) -> Md:
        return Md(str.__add__(escape(other), self))

    def format(self, *args: Any, **kwargs: Any) -> Md:
        return Md(str.format(self, *map(_arg, args), **{k: _arg(v) for k, v in kwargs.items()}))

    def join(self, parts: Iterable[Any]) -> Md:
        return Md(str.join(self, (escape(p) for p in parts)))


def _arg(value: Any) -> Any:
    """A format argument: numbers keep their format specs (``{:.2f}``); anything else is escaped."""
    if isinstance(value, numbers.Number) and not isinstance(value, bool):
        return value
    return escape(value)


def escape(text: Any) -> Md:
    """``text`` as Markdown that shows it verbatim (on one line); ``Md`` passes unchanged."""
    if isinstance(text, Md):
        return text
    return Md(_AUTOLINK.sub(_break_autolink, str(text).translate(_ESCAPES)))


def _break_autolink(m: re.Match) -> str:
    """``:`` of ``://``, ``www``, ``mailto``, ``xmpp`` followed by a word joiner; ``@`` preceded by one."""
    found = m.group(1)
    return WORD_JOINER + found if found == "@" else found + WORD_JOINER


def as_markdown(content: Any) -> str:
    """What a Markdown element may show: ``content`` itself when mcit wrote it (``Md``), else escaped."""
    return str(escape(content))
