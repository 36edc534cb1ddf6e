"""Operator messages as sentences (app.ui.client._sentence): capitalised and ended, except that a
message opening with an object's name keeps the name as the database spells it."""

from __future__ import annotations

import pytest

from app.ui.client import _sentence


@pytest.mark.parametrize(
    "text, want",
    [
        ("no pose fits", "No pose fits."),
        ("cylinder_1 has no straight edges to click", "cylinder_1 has no straight edges to click."),
        ("box2 was marked stale!", "box2 was marked stale!"),
        ("parallelepiped updated (version 2)", "Parallelepiped updated (version 2)."),
        ("", ""),
    ],
)
def test_sentence(text, want):
    assert _sentence(text) == want
