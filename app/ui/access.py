"""Who may open the interface: an origin check and an optional access token on viser's handshake.

viser 1.1 serves its page and its websocket on one port through ``websockets``' ``serve`` with a
``process_request`` hook, and accepts any ``Origin``: a page from another site open in the
operator's browser could open the websocket to 127.0.0.1 and change the database. Here every HTTP
request and websocket handshake first goes through :func:`AccessPolicy.check`:

- **Origin.** A request that carries an ``Origin`` header (browsers send it on every websocket
  handshake and on cross-site fetches) is admitted only when that origin is the page's own (the
  same scheme-less host and port as the ``Host`` header, and, without a token, a host name the
  server answers to: a loopback name or the ``--host`` it listens on) or one given with
  ``--allow-origin`` (a reverse proxy's public address). The host-name condition also stops DNS
  rebinding (a page at ``http://evil.example:8080`` whose name resolves to 127.0.0.1).
- **Token.** With a token, every request needs it: ``?token=`` on the URL, or the HttpOnly cookie
  the answer to that address sets (the browser sends it with the page's files and its websocket,
  since viser's client drops the query when it builds the websocket URL). The cookie holds a secret
  drawn at this start, not the token: cookies ignore the port, so every other service on the same
  host name receives it, and there it tells nothing of the token; it admits to this server only
  until it stops.

Refusals are HTTP 403 at the handshake: no viser client is created. :func:`open_viser_server` is
the one place that hooks viser; it fails at start-up if viser no longer goes through the hook.
"""

from __future__ import annotations

import hashlib
import hmac
import http
import inspect
import ipaddress
import logging
import secrets
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from http.cookies import CookieError, SimpleCookie
from urllib.parse import parse_qs, urlsplit

from .page import SECURITY_HEADERS, client_page

__all__ = ["AccessPolicy", "normalize_origin", "generate_token", "is_loopback", "open_viser_server", "LOOPBACK_NAMES"]

log = logging.getLogger("mcit.access")

LOOPBACK_NAMES = ("127.0.0.1", "localhost", "::1")
WILDCARD_HOSTS = ("", "0.0.0.0", "::")
_TOKEN_CHARS = frozenset("ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789-_.~")


def is_loopback(host: str) -> bool:
    """True when ``host`` names this machine only (127.0.0.0/8, ::1, localhost)."""
    host = host.strip().strip("[]").lower()
    if host in ("localhost",) or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def generate_token() -> str:
    """A fresh access token (128 random bits, URL-safe)."""
    return secrets.token_urlsafe(16)


def normalize_origin(url: str) -> str:
    """``scheme://host[:port]`` of ``url`` in lower case, default ports dropped; ValueError if it is not one."""
    parts = urlsplit(url.strip())
    if parts.scheme not in ("http", "https") or not parts.hostname:
        raise ValueError(f"--allow-origin {url!r} is not a web address: give it as https://name[:port]")
    if parts.path not in ("", "/") or parts.query or parts.fragment or parts.username or parts.password:
        raise ValueError(
            f"--allow-origin {url!r} has more than a scheme, host and port: give it as https://name[:port]"
        )
    try:
        port = parts.port
    except ValueError as exc:
        raise ValueError(f"--allow-origin {url!r} has an invalid port: give it as https://name[:port]") from exc
    host = parts.hostname.lower()
    if ":" in host:
        host = f"[{host}]"
    default = {"http": 80, "https": 443}[parts.scheme]
    return f"{parts.scheme}://{host}" + ("" if port in (None, default) else f":{port}")


def _split_host(hostport: str) -> tuple[str, int | None]:
    """(host name in lower case without brackets, port or None) of a ``Host`` header or netloc."""
    parts = urlsplit("//" + hostport.strip())
    try:
        port = parts.port
    except ValueError:
        port = -1  # matches nothing
    return (parts.hostname or "").lower(), port


def _values(headers, name: str) -> list[str]:
    """Every value of header ``name`` (websockets' Headers, or any mapping with ``get``)."""
    get_all = getattr(headers, "get_all", None)
    if get_all is not None:
        return list(get_all(name))
    value = headers.get(name)
    return [] if value is None else [value]


@dataclass(frozen=True)
class AccessPolicy:
    """What the interface admits. ``host``: the address it listens on; ``allow_origins``: extra page
    origins (reverse proxies); ``token``: required on every request when set."""

    host: str = "127.0.0.1"
    allow_origins: tuple[str, ...] = ()
    token: str | None = None
    _seen: set = field(default_factory=set, compare=False, repr=False)
    # What the page's cookie holds in place of the token: drawn at each start, it admits to this server
    # only while it runs, and tells nothing of the token to whoever else receives the cookie.
    _cookie_secret: str = field(default_factory=lambda: secrets.token_urlsafe(32), compare=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "allow_origins", tuple(normalize_origin(o) for o in self.allow_origins))
        if self.token is not None and (len(self.token) < 8 or not _TOKEN_CHARS.issuperset(self.token)):
            raise ValueError(
                "the access token must be at least 8 characters among letters, digits and - _ . ~ "
                "(leave --token out to have one generated)"
            )

    @property
    def cookie_name(self) -> str:
        """The cookie that admits the page once its address gave the token: named after this start's
        secret, so two servers on one host name (cookies ignore the port) do not overwrite each other's."""
        return "mcit_" + hashlib.sha256(self._cookie_secret.encode()).hexdigest()[:12]

    def cookie_header(self, secure: bool) -> str:
        """The ``Set-Cookie`` value: this start's secret (never the token), HttpOnly, SameSite=Strict,
        Secure when the page came over HTTPS."""
        return f"{self.cookie_name}={self._cookie_secret}; Path=/; HttpOnly; SameSite=Strict" + (
            "; Secure" if secure else ""
        )

    def _known_hosts(self) -> set[str]:
        hosts = {h for h in LOOPBACK_NAMES}
        bind = self.host.strip().strip("[]").lower()
        if bind not in WILDCARD_HOSTS:
            hosts.add(bind)
        hosts.update(_split_host(urlsplit(o).netloc)[0] for o in self.allow_origins)
        return hosts

    def _host_known(self, name: str) -> bool:
        return name in self._known_hosts() or is_loopback(name)

    def check(self, path: str, headers) -> tuple[str | None, bool]:
        """(why the request is refused or None, whether to set the token cookie) for a request to
        ``path`` (with its query) with ``headers`` (a mapping with ``get``)."""
        values = {name: _values(headers, name) for name in ("Host", "Origin", "Cookie")}
        if len(values["Host"]) > 1 or len(values["Origin"]) > 1:
            return "a request with more than one Host or Origin header", False
        if not all(v.isascii() and v.isprintable() for name in ("Host", "Origin") for v in values[name]):
            return "a Host or Origin header that is not a plain (ASCII) address", False
        host_name, host_port = _split_host(values["Host"][0] if values["Host"] else "")
        origin = values["Origin"][0] if values["Origin"] else None
        if origin is not None and origin.strip().lower() != "null":
            try:
                norm = normalize_origin(origin)
            except ValueError:
                norm = None
            if norm is None or norm not in self.allow_origins:
                same = False
                if norm is not None:
                    o = urlsplit(norm)
                    default = {"http": 80, "https": 443}[o.scheme]
                    same = (o.hostname, o.port or default) == (host_name, host_port or default)
                if not same or (self.token is None and not self._host_known(host_name)):
                    return (
                        f"a page at {origin[:100]} is not this interface's own page "
                        "(add it with --allow-origin if it is a proxy's address)"
                    ), False
        elif origin is not None:  # "null": sandboxed frames, file:// pages
            return "a page without an origin (a local file or a sandboxed frame)", False
        elif self.token is None and host_name and not self._host_known(host_name):
            # No origin (a navigation or a non-browser client) to an unknown host name: DNS rebinding.
            return f"the address {host_name} is not one this interface answers to (add it with --allow-origin)", False
        if self.token is None:
            return None, False
        query = parse_qs(urlsplit(path).query)
        given = query.get("token", [None])[-1]
        if given is not None:
            if hmac.compare_digest(given.encode(), self.token.encode()):
                return None, True
            return "a wrong access token", False
        try:
            cookie = SimpleCookie("; ".join(values["Cookie"]))
        except CookieError:
            cookie = SimpleCookie()
        morsel = cookie.get(self.cookie_name)
        if morsel is not None and hmac.compare_digest(morsel.value.encode(), self._cookie_secret.encode()):
            return None, False
        return "no access token", False

    def refuse_text(self, reason: str) -> str:
        if "token" in reason:
            return (
                f"mcit refused this request: {reason}. Open the address "
                "that mcit serve printed (it ends with ?token=...).\n"
            )
        return f"mcit refused this request: {reason}.\n"

    def note_refusal(self, reason: str, remote) -> None:
        """Log a refusal: once at WARNING per reason, then at DEBUG (a hostile page may retry forever)."""
        level = logging.DEBUG if reason in self._seen or len(self._seen) > 50 else logging.WARNING
        self._seen.add(reason)
        log.log(level, "refused a connection from %s: %s", remote, reason)

    def process_request(self, inner):
        """A ``process_request`` for ``websockets``' ``serve`` that checks this policy and then calls ``inner``."""

        async def guarded(connection, request):
            reason, set_cookie = self.check(request.path, request.headers)
            if reason is not None:
                self.note_refusal(reason, getattr(connection, "remote_address", None))
                refusal = connection.respond(http.HTTPStatus.FORBIDDEN, self.refuse_text(reason))
                refusal.headers["Content-Security-Policy"] = "default-src 'none'; frame-ancestors 'none'"
                for name, value in SECURITY_HEADERS.items():
                    refusal.headers[name] = value
                return refusal
            response = None
            if inner is not None:
                response = inner(connection, request)
                if inspect.isawaitable(response):
                    response = await response
            if set_cookie and response is not None:
                response.headers["Set-Cookie"] = self.cookie_header(secure=came_over_https(request.headers))
            return response

        return guarded


def came_over_https(headers) -> bool:
    """True when a reverse proxy says the browser's request came over HTTPS (``X-Forwarded-Proto`` or
    ``Forwarded: proto=``): the cookie is then sent over HTTPS only. A client that lies here only
    keeps its own cookie from being sent back over plain HTTP."""
    protos = [v.strip().lower() for v in _values(headers, "X-Forwarded-Proto")]
    for value in _values(headers, "Forwarded"):
        for part in value.replace(",", ";").split(";"):
            key, _, proto = part.strip().partition("=")
            if key.lower() == "proto":
                protos.append(proto.strip('"').lower())
    return "https" in protos


# --------------------------------------------------------------------------- the hook into viser

_VISER_MODULE = "viser.infra._infra"
_hook_lock = threading.Lock()


@contextmanager
def _viser_serve_guarded(policy: AccessPolicy):
    """While open, viser's call to ``websockets.asyncio.server.serve`` gets ``policy``'s check in front of
    its ``process_request``. Yields a dict whose "hooked" entry counts the calls that were guarded."""
    import websockets.asyncio.server as ws_server

    original = ws_server.serve
    state = {"hooked": 0}

    def serve(handler, *args, **kwargs):
        if getattr(handler, "__module__", None) != _VISER_MODULE:
            return original(handler, *args, **kwargs)
        # who may ask first (refusals cost nothing), then mcit's page, then viser's own answers
        kwargs["process_request"] = policy.process_request(client_page().process_request(kwargs.get("process_request")))
        state["hooked"] += 1
        return original(handler, *args, **kwargs)

    with _hook_lock:
        ws_server.serve = serve
        try:
            yield state
        finally:
            ws_server.serve = original


def open_viser_server(policy: AccessPolicy, **kwargs):
    """``viser.ViserServer(**kwargs)`` with ``policy`` checked on every request and websocket handshake.

    Raises RuntimeError (after stopping it) when viser did not open its server through the hook,
    rather than serve an interface that any web page could drive."""
    import viser

    with _viser_serve_guarded(policy) as state:
        server = viser.ViserServer(**kwargs)
    if state["hooked"] == 0:
        server.stop()
        raise RuntimeError(
            f"viser {viser.__version__} no longer opens its server through websockets.asyncio.server.serve, so the "
            "origin check and access token could not be installed: refusing to serve (update app/ui/access.py)"
        )
    return server
