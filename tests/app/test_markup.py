"""app/markup.py: text from the database, a file or an operator is shown verbatim, never as markup."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from app.markup import Md, as_markdown, escape

HOSTILE = [
    "<script>alert(1)</script>",
    '<iframe srcdoc="<script>alert(1)</script>"></iframe>',
    "<img src=x onerror=alert(1)>",
    "<svg onload=alert(1)>",
    "[click](javascript:alert(1))",
    "![x](http://127.0.0.1:9/x)",
    "<http://127.0.0.1:9/x>",
    "http://127.0.0.1:9/x and www.example.com and a@b.example",
    "**bold** _it_ `code` ~~s~~ | cell | # heading",
    "line\n# heading\n- item\n| a | b |",
    "&lt;img src=x onerror=alert(1)&gt;",
    "\\<img src=x onerror=alert(1)>",
]


@pytest.mark.parametrize("text", HOSTILE)
def test_escaped_text_holds_no_markup_character_unescaped(text):
    out = escape(text)
    assert isinstance(out, Md)
    assert "<" not in out and ">" not in out and "\n" not in out
    raw = out.replace("\\\\", "")  # what is left once escaped backslashes are taken out
    for ch in "`*_[]|~#!":
        assert raw.count(ch) == raw.count("\\" + ch), (ch, out)  # every one escaped
    # no bare-address autolink: a word joiner breaks each pattern (a backslash would not)
    assert "://" not in out and "www." not in out.lower() and out.count("@") == out.count("\u2060@")
    assert "&" not in out.replace("&amp;", "").replace("&lt;", "").replace("&gt;", "")


@given(st.text(max_size=80))
def test_any_text_escapes_without_html_or_line_breaks(text):
    out = escape(text)
    assert "<" not in out and ">" not in out and "\n" not in out and "\r" not in out


def test_md_keeps_its_own_markup_and_escapes_what_it_is_combined_with():
    name = "<b>box_1</b>"
    assert Md("**{}** is selected").format(name) == "**&lt;b&gt;box\\_1&lt;/b&gt;** is selected"
    assert Md("{:.2f} px").format(0.5) == "0.50 px"  # numbers keep their format
    assert Md("**a**") + "*b*" == "**a**\\*b\\*"
    assert "*b*" + Md("**a**") == "\\*b\\***a**"
    assert Md(", ").join(["a_b", Md("**c**")]) == "a\\_b, **c**"
    assert as_markdown(Md("**x**")) == "**x**" and as_markdown("**x**") == "\\*\\*x\\*\\*"
    assert escape(Md("**x**")) == "**x**"  # not escaped twice


def test_the_panels_texts_escape_names():
    from app.ui.controls import report_markdown
    from app.ui.panel_text import idle_text as _idle_text

    assert _idle_text("<img src=x onerror=alert(1)>").startswith("**&lt;img src=x onerror=alert(1)&gt;** is selected")
    table = report_markdown({"changes": [{"who": "[x](javascript:alert(1))", "what": "a|b"}]})
    assert "\\[x\\](javascript:alert(1))" in table and "a\\|b" in table
