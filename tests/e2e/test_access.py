"""In chromium: a page from another site cannot open the interface's websocket, and the access token
given once in the printed URL keeps the page (and its websocket) open through its cookie."""

from __future__ import annotations

import logging
import time

import pytest
import viser

from app.ui.access import AccessPolicy, open_viser_server

from .harness import free_port

TOKEN = "e2e-token-0123456789"


def _wait(pred, timeout_s: float, what: str):
    deadline = time.monotonic() + timeout_s
    while not pred():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.1)


@pytest.fixture
def served():
    made = []

    def make(**kwargs):
        server = open_viser_server(AccessPolicy(**kwargs), host="127.0.0.1", port=free_port(), verbose=False)
        handshakes = []
        server._websock_server.on_client_connect(lambda conn: handshakes.append(conn.client_id))
        made.append(server)
        return server, handshakes

    yield make
    for server in made:
        server.stop()


@pytest.fixture(scope="module")
def unguarded_browser(browser):
    """Chromium without its local-network-access checks, which would block a public page's websocket
    to 127.0.0.1 on their own: like a browser that has none (older ones, others), where only the
    server's origin check stands in the way (without it this page connects: checked when written)."""
    from .harness import ARGS, CHROMIUM

    b = browser.browser_type.launch(
        executable_path=CHROMIUM, args=ARGS + ["--disable-features=LocalNetworkAccessChecks"]
    )
    yield b
    b.close()


def test_a_page_from_another_site_cannot_open_the_websocket(unguarded_browser, served, caplog):
    server, handshakes = served()
    port = server.get_port()
    page = unguarded_browser.new_page()
    try:
        # the hostile page, as the browser would load it from http://evil.example
        page.route(
            "http://evil.example/**",
            lambda route: route.fulfill(
                status=200,
                content_type="text/html",
                body=f"""
            <html><body><script>
              const ws = new WebSocket("ws://127.0.0.1:{port}", ["viser-v{viser.__version__}"]);
              ws.onopen = () => {{ window.result = "open"; }};
              ws.onclose = () => {{ window.result = window.result || "closed"; }};
            </script></body></html>""",
            ),
        )
        with caplog.at_level(logging.WARNING, logger="mcit.access"):
            page.goto("http://evil.example/")
            page.wait_for_function("window.result !== undefined", timeout=60_000)
        assert page.evaluate("window.result") == "closed"
        assert any("http://evil.example" in r.getMessage() for r in caplog.records), (
            "the server saw no refused handshake"
        )
        assert handshakes == []
    finally:
        page.close()


def test_the_token_url_opens_the_page_and_its_cookie_keeps_it_open(browser, served):
    server, handshakes = served(token=TOKEN)
    base = f"http://127.0.0.1:{server.get_port()}"
    page = browser.new_page()
    try:
        assert page.goto(base + "/").status == 403  # no token, no cookie yet
        assert page.goto(f"{base}/?token={TOKEN}").status == 200
        _wait(lambda: len(server.get_clients()) == 1, 30.0, "the page opened with the token to connect")
        page.goto(base + "/")  # the token is now in the page's cookie
        _wait(lambda: len(handshakes) >= 2 and len(server.get_clients()) == 1, 30.0, "the reloaded page to connect")
    finally:
        page.close()
