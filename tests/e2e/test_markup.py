"""Nothing from the database, a file or another operator is ever markup in the operator's browser
(app/markup.py escapes; app/ui/page.py's Content-Security-Policy is the second wall).

Names, operators' names, methods and notes carrying ``<script>``, ``<iframe srcdoc>``, ``<img
onerror>``, ``<svg onload>``, a ``javascript:`` link and a remote Markdown image are planted in the
database the way an old or a hostile database would hold them (every entry refuses such names
now: tests/app/test_names.py). An operator then opens every panel that shows them. Each payload
asks a canary server on this machine for its own path: no request may arrive, the page's policy
must refuse nothing (nothing was even tried), no planted element may exist in the page, and the
payloads must be on screen as text.
"""

from __future__ import annotations

import http.server
import threading
import time

import numpy as np
import pytest

from core.transforms import make_T

from .flows import Operator
from .harness import click_control, close_notifications, free_port, press, wait_until

pytestmark = pytest.mark.e2e


class Canary:
    """An HTTP server on 127.0.0.1 that records every path asked of it."""

    def __init__(self):
        self.port = free_port()
        self.hits: list[str] = []
        hits = self.hits

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):  # noqa: N802 - http.server's name
                hits.append(self.path)
                self.send_response(204)
                self.end_headers()

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", self.port), Handler)
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def url(self, tag: str) -> str:
        return f"http://127.0.0.1:{self.port}/{tag}"

    def close(self):
        self.server.shutdown()
        self.server.server_close()


def payloads(canary: Canary) -> dict[str, str]:
    fetch = "fetch('{}')".format
    return {
        "script": f"<script>{fetch(canary.url('script'))}</script>",
        "iframe": f'<iframe srcdoc="<script>{fetch(canary.url("iframe"))}</script>"></iframe>',
        "img": f'<img src=x onerror="{fetch(canary.url("img"))}">',
        "svg": f'<svg onload="{fetch(canary.url("svg"))}"></svg>',
        "link": f"[open](javascript:{fetch(canary.url('link'))})",
        "image": f"![x]({canary.url('md-image')})",
        "autolink": f"see {canary.url('autolink')} or www.example.org or x@example.org",  # bare addresses
    }


@pytest.fixture
def canary():
    c = Canary()
    yield c
    c.close()


def _plant(ui, evil: dict[str, str], monkeypatch) -> list[str]:
    """Objects named by the payloads (copies of the parallelepiped's model, in view), and changes by
    an operator, with a method and a note, named by them, as an old or hostile database holds them."""
    monkeypatch.setattr("app.db.database._check_name", lambda name: name)  # what every entry now refuses
    box = ui.site.object("parallelepiped")
    names = []
    for k, (_tag, text) in enumerate(evil.items()):
        T = box.T_world_obj @ make_T(np.eye(3), [0.0, 0.0, 0.0])
        T[:3, 3] += [-0.25 + 0.1 * k, -0.35, 0.0]
        ui.site.add_object(
            text, "box", box.model, T, method=evil["img"], client=evil["svg"], status="modelled", note=evil["iframe"]
        )
        names.append(text)
    ui.site.set_status(names[0], "stale", client=evil["autolink"], method=evil["script"])
    monkeypatch.undo()
    return names


def _shows(page, text: str, timeout_s: float = 10.0) -> None:
    """Wait until the page's text shows ``text`` verbatim."""
    # (app.markup puts an invisible word joiner into bare addresses so that they are not made links)
    wait_until(
        lambda: text in page.locator("body").inner_text().replace("\u2060", ""), timeout_s, f"the page to show {text!r}"
    )


def _no_markup_ran(page, ui, canary, evil) -> None:
    page.wait_for_timeout(500)  # a planted fetch would have arrived; the page's console events are taken meanwhile
    assert canary.hits == [], f"a planted script or image reached the canary: {canary.hits}"
    assert ui.csp_refusals == [], f"the page tried what its policy refused: {ui.csp_refusals[:3]}"
    planted = page.evaluate(
        """() => ({
        iframes: document.querySelectorAll('iframe').length,
        handlers: document.querySelectorAll('[onerror], [onload]').length,
        svgs: [...document.querySelectorAll('svg')].filter(s => s.getAttribute('onload') !== null).length,
        scripts: [...document.querySelectorAll('script')].filter(s => s.textContent.includes(CANARY)).length,
        links: [...document.querySelectorAll('a')].map(a => a.getAttribute('href') || '')
                   .filter(h => h.includes('example.org') || h.includes('127.0.0.1')).length,
        jslinks: [...document.querySelectorAll('a')].filter(a => (a.getAttribute('href') || '').trim()
                                                                 .toLowerCase().startsWith('javascript')).length,
        images: [...document.querySelectorAll('img')].filter(i => (i.getAttribute('src') || '')"""
        """.includes(CANARY)).length,
    })""".replace("CANARY", repr(f":{canary.port}/"))
    )
    assert planted == dict(iframes=0, handlers=0, svgs=0, scripts=0, links=0, jslinks=0, images=0), planted


def test_names_methods_operators_and_notes_with_markup_are_shown_as_text(browser, interface, canary, monkeypatch):
    ui = interface
    evil = payloads(canary)
    names = _plant(ui, evil, monkeypatch)
    page = ui.open(browser)
    op = Operator(ui, page)
    close_notifications(page, required=False)

    # the object list, and each object selected from it: the panel names it
    for name in names:
        op.choose("Object", name)
        wait_until(lambda: page.panel.session.selected == name, what=f"{name!r} selected")
        _shows(page, f"{name} is selected")
    _no_markup_ran(page, ui, canary, evil)

    # a workflow on it: its title names it; Cancel
    op.press("Update pose")
    wait_until(
        lambda: (
            page.panel.session.workflow is not None
            and page.panel.workflow_controls.built_for is page.panel.session.workflow
        ),
        what="Update pose's controls",
    )
    _shows(page, f"Update pose: {names[-1]}")
    op.press("Cancel")
    wait_until(lambda: page.panel.session.workflow is None or page.panel.session.workflow.finished, what="cancelled")

    # History: who, what and how of every change
    op.press("History")
    wait_until(
        lambda: (
            page.panel.session.workflow is not None
            and page.panel.session.workflow.name == "history"
            and page.panel.workflow_controls.built_for is page.panel.session.workflow
        ),
        what="History's controls",
    )
    result = page.get_by_text("Changes", exact=True).first
    result.wait_for(timeout=60_000)
    shown = page.locator("body").inner_text().replace("\u2060", "")  # the word joiners of bare addresses
    assert evil["svg"] in shown and evil["autolink"] in shown  # operators, verbatim
    assert evil["img"] in shown or evil["img"][:20] in shown  # a method, as its words
    _no_markup_ran(page, ui, canary, evil)
    press(page, "Close")

    # another operator's change while the page is open: the notification names them and the object
    ui.site.set_status(names[1], "stale", client=evil["link"], method="operator")
    page.locator(".mantine-Notification-root", has_text="Changed by another operator").first.wait_for(timeout=60_000)

    # the 3D world: the objects' labels
    click_control(page.get_by_role("button", name="3D world", exact=True))
    time.sleep(1.0)
    click_control(page.get_by_role("button", name="Video", exact=True))
    _no_markup_ran(page, ui, canary, evil)
    ui.close_pages(park=False)  # not kept for the next test: its page showed the planted markup


def test_the_pages_policy_refuses_markup_that_escaping_would_have_missed(browser, interface, canary):
    """The second wall alone: Markdown put on the page unescaped (as if escaping had been forgotten)
    runs nothing and loads nothing, and the policy says what it refused."""
    from app.markup import Md

    ui = interface
    evil = payloads(canary)
    page = ui.open(browser)
    page.panel.client.gui.add_markdown(Md("\n\n".join(evil.values())))  # bypassing app.markup
    # (playwright takes the page's console events only while one of its calls runs)
    # the remote image and an inline script at least: which inline code reaches the policy, and its wording, depend
    # on Chromium's version (150: the srcdoc frame's script alone, "Executing inline script"; earlier ones also the
    # <img onerror> and <svg onload> handlers, "Refused to execute inline event handler")
    wait_until(lambda: page.wait_for_timeout(50) or len(ui.csp_refusals) >= 2, 30.0, "the policy's refusals")
    page.wait_for_timeout(500)
    assert canary.hits == [], f"markup ran or loaded despite the policy: {canary.hits}"
    said = " ".join(ui.csp_refusals)
    assert "script-src" in said and "img-src" in said, ui.csp_refusals  # an inline script's directive, the image's
    ui.close_pages(park=False)  # its later refusals (the page goes on refusing until it is closed) are expected too
    ui.csp_refusals.clear()
