"""Who may open the interface (app/ui/access.py): the origin check and the access token, on real
viser servers, with the `websockets` client viser depends on and plain HTTP requests."""

from __future__ import annotations

import http.client
import socket
import threading

import pytest
import viser
import websockets.sync.client
from websockets.exceptions import InvalidStatus

from app.cli import build_parser
from app.ui.access import AccessPolicy, normalize_origin, open_viser_server
from app.ui.serve import _access_policy
from tests.e2e.harness import free_port

SUBPROTOCOL = f"viser-v{viser.__version__}"
TOKEN = "s3cret-token_123"


class Served:
    """A viser server behind ``policy``, counting the clients viser creates."""

    def __init__(self, policy: AccessPolicy):
        self.server = open_viser_server(policy, host="127.0.0.1", port=free_port(), verbose=False)
        self.port = self.server.get_port()
        self.clients: list[int] = []
        self.connected = threading.Event()

        def on_connect(client):
            self.clients.append(client.client_id)
            self.connected.set()

        # viser's websocket layer: its client exists from the handshake on (ViserServer's own
        # on_client_connect waits for the browser's first camera message).
        self.server._websock_server.on_client_connect(on_connect)

    def ws(self, origin: str | None = None, path: str = "/", headers: dict | None = None, host: str | None = None):
        """Open (and close) a websocket to this server, as if it were at ``host`` (the Host header; default
        127.0.0.1:port); returns None when connected, else the refusal's HTTP status."""
        sock = socket.create_connection(("127.0.0.1", self.port), timeout=10)
        try:
            with websockets.sync.client.connect(
                f"ws://{host or f'127.0.0.1:{self.port}'}{path}",
                sock=sock,
                origin=origin,
                additional_headers=headers,
                subprotocols=[SUBPROTOCOL],
                open_timeout=10,
            ):
                assert self.connected.wait(10), "viser created no client for an admitted connection"
                self.connected.clear()
            return None
        except InvalidStatus as exc:
            return exc.response.status_code

    def get(self, path: str = "/", headers: dict | None = None) -> http.client.HTTPResponse:
        conn = http.client.HTTPConnection("127.0.0.1", self.port, timeout=10)
        conn.request("GET", path, headers=headers or {})
        response = conn.getresponse()
        response.body = response.read()
        conn.close()
        return response


@pytest.fixture
def serve():
    made = []

    def make(**kwargs) -> Served:
        made.append(Served(AccessPolicy(**kwargs)))
        return made[-1]

    yield make
    for s in made:
        s.server.stop()


def test_a_page_from_another_site_is_refused_and_no_client_is_created(serve):
    s = serve()
    own = f"http://127.0.0.1:{s.port}"
    assert s.ws(origin="http://evil.example") == 403
    assert s.ws(origin=f"http://127.0.0.1:{s.port + 1}") == 403  # another local port is another site
    assert s.ws(origin="null") == 403
    assert s.get("/", {"Origin": "http://evil.example"}).status == 403
    assert s.clients == []
    assert s.ws(origin=own) is None  # the page's own origin connects
    assert s.ws(origin=f"http://localhost:{s.port}", host=f"localhost:{s.port}") is None
    assert len(s.clients) == 2  # the two admitted ones; the refused ones created none


def test_the_served_page_itself_works_without_a_token_on_loopback(serve):
    s = serve()
    page = s.get("/")
    assert page.status == 200 and b"<html" in page.body.lower()
    assert s.ws(origin=f"http://127.0.0.1:{s.port}") is None
    assert s.ws() is None  # a non-browser client on this machine sends no Origin


def test_dns_rebinding_is_refused(serve):
    """evil.example resolving to 127.0.0.1: same origin as its Host header, but not a name the server answers to."""
    s = serve()
    assert s.ws(origin=f"http://evil.example:{s.port}", host=f"evil.example:{s.port}") == 403
    assert s.get("/", {"Host": f"evil.example:{s.port}"}).status == 403
    assert s.clients == []


def test_allow_origin_admits_a_proxys_address(serve):
    s = serve(allow_origins=("https://MCIT.example.org/",))
    assert s.ws(origin="https://mcit.example.org") is None
    # a proxy that forwards the public Host header
    assert s.ws(origin="https://mcit.example.org", host="mcit.example.org") is None
    assert s.get("/", {"Host": "mcit.example.org"}).status == 200
    assert s.ws(origin="http://mcit.example.org") == 403  # another scheme is another origin
    assert s.ws(origin="http://evil.example") == 403
    assert len(s.clients) == 2


def test_with_a_token_no_token_or_a_wrong_one_is_refused(serve):
    s = serve(token=TOKEN)
    own = f"http://127.0.0.1:{s.port}"
    assert s.ws(origin=own) == 403
    assert s.ws(origin=own, path="/?token=wrong-token-123") == 403
    assert s.ws(origin=own, headers={"Cookie": "mcit_000000000000=" + TOKEN}) == 403  # another server's cookie
    assert s.get("/").status == 403
    assert b"?token=" in s.get("/").body  # the refusal says what to open
    assert (
        s.ws(origin="http://evil.example", path=f"/?token={TOKEN}") == 403
    )  # the token does not lift the origin check
    assert s.clients == []
    assert s.ws(origin=own, path=f"/?token={TOKEN}") is None
    assert len(s.clients) == 1


def test_the_page_opened_with_the_token_keeps_it_in_a_cookie_for_its_websocket(serve):
    s = serve(token=TOKEN, host="0.0.0.0")
    page = s.get(f"/?token={TOKEN}")
    assert page.status == 200
    cookie = page.getheader("Set-Cookie")
    assert cookie is not None and "HttpOnly" in cookie and "SameSite=Strict" in cookie
    name_value = cookie.split(";")[0]
    # viser's client drops the query from the websocket URL: the cookie admits its websocket
    assert s.ws(origin=f"http://127.0.0.1:{s.port}", headers={"Cookie": name_value}) is None
    assert s.get("/index.html", {"Cookie": name_value}).status == 200
    # exposed with a token, the page's own origin under any name is admitted (the token authenticates)
    lan = f"192.0.2.7:{s.port}"
    assert s.ws(origin=f"http://{lan}", host=lan, headers={"Cookie": name_value}) is None
    assert s.ws(origin="http://evil.example", headers={"Cookie": name_value}) == 403


def test_serve_flags_give_a_token_beyond_loopback_and_none_on_it():
    p = build_parser()
    args = p.parse_args(["serve"])
    assert _access_policy(args).token is None and args.allow_origin == []
    exposed = p.parse_args(["serve", "--host", "0.0.0.0"])
    token = _access_policy(exposed).token
    assert token is not None and len(token) >= 16 and exposed.token == token
    given = p.parse_args(
        ["serve", "--token", TOKEN, "--allow-origin", "https://a.example", "--allow-origin", "https://b.example:8443"]
    )
    policy = _access_policy(given)
    assert policy.token == TOKEN and policy.allow_origins == ("https://a.example", "https://b.example:8443")
    with pytest.raises(ValueError, match="token"):
        _access_policy(p.parse_args(["serve", "--token", "short"]))
    with pytest.raises(ValueError, match="allow-origin"):
        _access_policy(p.parse_args(["serve", "--allow-origin", "mcit.example.org"]))


def test_origins_are_normalized():
    assert normalize_origin("HTTPS://Example.org:443/") == "https://example.org"
    assert normalize_origin("http://example.org:8080") == "http://example.org:8080"
    assert normalize_origin("http://[::1]:8080") == "http://[::1]:8080"
    for bad in ("example.org", "ftp://example.org", "https://example.org/path", "https://u:p@example.org"):
        with pytest.raises(ValueError):
            normalize_origin(bad)


def test_start_up_fails_loudly_when_viser_bypasses_the_hook(monkeypatch):
    import app.ui.access as access

    monkeypatch.setattr(access, "_VISER_MODULE", "not.viser")  # as if viser opened its server some other way
    with pytest.raises(RuntimeError, match="refusing to serve"):
        open_viser_server(AccessPolicy(), host="127.0.0.1", port=free_port(), verbose=False)


def test_duplicate_host_or_origin_headers_are_refused_not_an_error():
    from websockets.datastructures import Headers

    policy = AccessPolicy()
    own = Headers([("Host", "127.0.0.1:8080"), ("Origin", "http://127.0.0.1:8080")])
    assert policy.check("/", own) == (None, False)
    for extra in (("Origin", "http://evil.example"), ("Host", "evil.example:8080")):
        headers = Headers(list(own.raw_items()) + [extra])
        reason, _ = policy.check("/", headers)
        assert reason is not None and "more than one" in reason


def test_the_cookie_carries_no_token_and_admits_to_this_server_only_while_it_runs(serve):
    """Cookies ignore the port: every service on the same host name receives the cookie. It holds a
    secret of this start, not the token, so another server with the same token refuses it."""
    a, b = serve(token=TOKEN), serve(token=TOKEN)
    cookie = a.get(f"/?token={TOKEN}").getheader("Set-Cookie")
    name_value = cookie.split(";")[0]
    assert TOKEN not in cookie and "Secure" not in cookie  # plain HTTP: a Secure cookie would not come back
    assert a.ws(origin=f"http://127.0.0.1:{a.port}", headers={"Cookie": name_value}) is None
    # the same token on another port (another start): the first one's cookie is refused there
    assert b.ws(origin=f"http://127.0.0.1:{b.port}", headers={"Cookie": name_value}) == 403
    # both cookies side by side in one browser (one host name): each server finds its own
    other = b.get(f"/?token={TOKEN}").getheader("Set-Cookie").split(";")[0]
    assert other.split("=")[0] != name_value.split("=")[0]
    both = {"Cookie": f"{name_value}; {other}"}
    assert a.ws(origin=f"http://127.0.0.1:{a.port}", headers=both) is None
    assert b.ws(origin=f"http://127.0.0.1:{b.port}", headers=both) is None


def test_the_cookie_is_secure_when_a_proxy_says_the_page_came_over_https(serve):
    s = serve(token=TOKEN, allow_origins=("https://mcit.example.org",))
    for header in ({"X-Forwarded-Proto": "https"}, {"Forwarded": 'for=192.0.2.1;proto=https;host="mcit.example.org"'}):
        assert "; Secure" in s.get(f"/?token={TOKEN}", header).getheader("Set-Cookie")
    assert "Secure" not in s.get(f"/?token={TOKEN}", {"X-Forwarded-Proto": "http"}).getheader("Set-Cookie")


def test_a_non_ascii_origin_or_host_is_refused_with_403(serve):
    s = serve()
    for headers in (
        {"Origin": "http://\u00e9vil.example"},
        {"Host": f"\u00e9vil.example:{s.port}"},
        {"Origin": f"http://127.0.0.1:{s.port}/\u00e9"},
    ):
        conn = socket.create_connection(("127.0.0.1", s.port), timeout=10)
        lines = ["GET / HTTP/1.1"] + [f"{k}: {v}" for k, v in headers.items()]
        if "Host" not in headers:
            lines.append(f"Host: 127.0.0.1:{s.port}")
        conn.sendall(("\r\n".join(lines) + "\r\n\r\n").encode("utf-8"))
        status = conn.recv(4096).split(b"\r\n", 1)[0]
        conn.close()
        assert b" 403 " in status, (headers, status)
    assert s.get("/").status == 200  # still serving


def test_every_answer_carries_the_content_security_policy(serve):
    """The page runs only viser's two inline scripts (by hash) and mcit's own; no inline handler, no eval,
    nothing from elsewhere, no frames; viser needs eval (see page.py) (app/ui/page.py)."""
    s = serve()
    for path in ("/", "/index.html", "/mcit/page.js", "/no-such-file"):
        answer = s.get(path)
        csp = answer.getheader("Content-Security-Policy")
        assert csp is not None, path
        assert answer.getheader("X-Content-Type-Options") == "nosniff"
        assert answer.getheader("Referrer-Policy") == "no-referrer"  # the address may carry ?token=
        rules = dict(rule.strip().split(" ", 1) for rule in csp.split(";"))
        assert "'unsafe-inline'" not in rules["script-src"] and "'unsafe-hashes'" not in rules["script-src"]
        assert rules["script-src"].count("'sha256-") == 2
        assert rules["frame-src"] == "'none'" and rules["object-src"] == "'none'" and rules["default-src"] == "'none'"
        assert rules["frame-ancestors"] == "'none'"
    page = s.get("/").body
    assert b'<script src="/mcit/page.js" defer></script></head>' in page
    # every address viser answers with its page gets mcit's (and its script)
    for path in ("//index.html", "/%69ndex.html", "/index.html/", "/./", "/?x=1"):
        assert s.get(path).body == page, path
    assert s.get("/", {"Upgrade": "WebSocket"}).body == page
    refused = s.get("/", {"Origin": "http://evil.example"})
    assert (
        refused.status == 403
        and refused.getheader("Content-Security-Policy") == "default-src 'none'; frame-ancestors 'none'"
    )
    assert refused.getheader("X-Content-Type-Options") == "nosniff"
    assert b"mcit-dblclick" in s.get("/mcit/page.js").body
