"""The page mcit serves: viser's client with mcit's own script, under a Content-Security-Policy.

viser 1.1's page is one HTML file whose inline loader decodes the client (zstd, base-88 text in a
``data-p`` attribute) and runs it as a second inline ``<script type="module">``; its Markdown
elements render raw HTML unsanitised. mcit escapes every text it shows (``app.markup``); the policy
here is the second wall: script runs only when it is one of those two inline scripts (by their
SHA-256, computed from the installed viser at start) or mcit's own ``/mcit/page.js`` — never an
inline event handler (``<img onerror>``, ``<svg onload>``), a ``javascript:`` link, a planted
``<script>`` or ``eval`` — and the page loads nothing from elsewhere, nor can be framed.

What viser's client needs and the policy therefore allows: WebAssembly (``'wasm-unsafe-eval'``: its
zstd decoder) and JavaScript compiled from strings (``'unsafe-eval'``: the Emscripten glue of a
WebAssembly module it starts with builds functions with ``Function(…)``; this lets code that already
runs compile more, it runs nothing by itself: inline scripts, inline event handlers and
``javascript:`` URLs stay forbidden, since those need ``'unsafe-inline'``), inline styles
(``'unsafe-inline'`` in ``style-src`` only: the UI library sets styles on elements), workers from
``blob:`` URLs, images and fetches of ``data:`` and ``blob:`` URLs (its decoders and the video
frames), and the websocket back to its own address.
"""

from __future__ import annotations

import base64
import functools
import gzip
import hashlib
import html
import http
import inspect
import logging
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import numpy as np

__all__ = ["ClientPage", "PAGE_SCRIPT_PATH", "SECURITY_HEADERS", "client_page"]

PAGE_SCRIPT = Path(__file__).resolve().parents[2] / "static" / "wheel.js"
PAGE_SCRIPT_PATH = "/mcit/page.js"

# Sent with every answer of the interface's HTTP server.
SECURITY_HEADERS = {
    "X-Content-Type-Options": "nosniff",
    "Referrer-Policy": "no-referrer",  # the address may carry ?token=
    "X-Frame-Options": "DENY",
    "Cache-Control": "no-store",
}

_LOADER = re.compile(rb'<script data-p="([^"]*)" data-ss="(\d+)" data-cs="(\d+)">(.*?)</script>', re.S)
_ALPHABET = "!#$%()*+,-./0123456789:;=?@ABCDEFGHIJKLMNOPQRSTUVWXYZ[\\]^_abcdefghijklmnopqrstuvwxyz{|}~"


def _decode88(text: str) -> bytes:
    """viser's base-88 text (5 characters → 4 bytes, big-endian; a last group of r characters → r-1 bytes)."""
    lut = np.full(128, -1, np.int64)
    lut[np.frombuffer(_ALPHABET.encode(), np.uint8)] = np.arange(88)
    raw = np.frombuffer(text.encode("ascii"), np.uint8)
    digits = lut[raw]
    if np.any(digits < 0):
        raise ValueError("a character outside viser's alphabet")
    n, r = divmod(len(digits), 5)
    values = np.zeros(n, np.int64)
    for j in range(5):
        values = values * 88 + digits[j : n * 5 : 5]
    out = (values[:, None] >> np.array([24, 16, 8, 0])) & 255
    tail = b""
    if r:
        v = 0
        for d in digits[n * 5 :]:
            v = v * 88 + int(d)
        tail = v.to_bytes(r - 1, "big")
    return out.astype(np.uint8).tobytes() + tail


def _sha256(data: bytes) -> str:
    return "'sha256-" + base64.b64encode(hashlib.sha256(data).digest()).decode("ascii") + "'"


@dataclass(frozen=True)
class ClientPage:
    """The served page (plain and gzip), mcit's script, and the policy both are served under."""

    html: bytes
    html_gzip: bytes
    script: bytes
    csp: str

    @classmethod
    def from_viser(cls, index_html: bytes, script: bytes) -> ClientPage:
        """Build from viser's ``index.html``; ValueError when its loader is not the one this module reads."""
        import zstandard

        m = _LOADER.search(index_html)
        if m is None:
            raise ValueError("its page has no inline loader with data-p, data-ss and data-cs")
        style_n, code_n = int(m.group(2)), int(m.group(3))
        payload = _decode88(html.unescape(m.group(1).decode("ascii")))
        data = zstandard.ZstdDecompressor().decompress(payload, max_output_size=style_n + code_n)
        if len(data) != style_n + code_n:
            raise ValueError(f"its client decodes to {len(data)} bytes, not {style_n + code_n}")
        code = data[style_n:]
        code.decode("utf-8")  # the page runs it as text: it must be UTF-8 for the hash to match
        scripts = f"'self' {_sha256(m.group(4))} {_sha256(code)} 'unsafe-eval' 'wasm-unsafe-eval'"
        csp = "; ".join(
            (
                "default-src 'none'",
                f"script-src {scripts}",
                "worker-src 'self' blob:",
                "style-src 'self' 'unsafe-inline'",
                "img-src 'self' data: blob:",
                "font-src 'self' data:",
                "media-src 'self' data: blob:",
                "connect-src 'self' data: blob:",
                "frame-src 'none'",
                "object-src 'none'",
                "base-uri 'none'",
                "form-action 'none'",
                "frame-ancestors 'none'",
            )
        )
        tag = f'<script src="{PAGE_SCRIPT_PATH}" defer></script>'.encode()
        page = index_html.replace(b"</head>", tag + b"</head>", 1)
        return cls(html=page, html_gzip=gzip.compress(page, 6), script=script, csp=csp)

    def process_request(self, inner):
        """A ``process_request`` for ``websockets``' ``serve``: the page and its script from here, every
        other request from ``inner`` (viser's), each answer with the policy and ``SECURITY_HEADERS``."""
        from websockets.datastructures import Headers
        from websockets.http11 import Response

        def answer(body: bytes, content_type: str, gzipped: bool) -> Response:
            headers = Headers(
                {
                    "Content-Type": content_type,
                    "Content-Length": str(len(body)),
                    "Content-Encoding": "gzip" if gzipped else "identity",
                }
            )
            return Response(http.HTTPStatus.OK, "OK", headers, body)

        _quiet_http_answers()

        async def serve(connection, request):
            _quiet_http_answers(connection)
            response = None
            if request.headers.get("Upgrade") != "websocket":  # as viser tells a handshake from a file
                path = _file_path(request.path)
                if path == "index.html":
                    gzipped = "gzip" in request.headers.get("Accept-Encoding", "")
                    response = answer(self.html_gzip if gzipped else self.html, "text/html; charset=utf-8", gzipped)
                elif path == PAGE_SCRIPT_PATH.lstrip("/"):
                    response = answer(self.script, "application/javascript; charset=utf-8", False)
            if response is None and inner is not None:
                response = inner(connection, request)
                if inspect.isawaitable(response):
                    response = await response
            if response is not None:
                response.headers["Content-Security-Policy"] = self.csp
                for name, value in SECURITY_HEADERS.items():
                    response.headers[name] = value
            return response

        return serve


def _file_path(target: str) -> str:
    """The file a request asks for, read as viser reads it (query dropped, percent-decoded, backslashes
    as slashes, empty and "." segments dropped; the page when nothing is left), so that every address
    viser would answer with its page gets mcit's."""
    segments = [s for s in unquote(target.partition("?")[0]).replace("\\", "/").split("/") if s and s != "."]
    return "/".join(segments) or "index.html"


class _HttpAnswerNoise(logging.Filter):
    """websockets logs every plain HTTP answer of a websocket server as a failed handshake ("connection
    rejected (200 OK)"): true, and noise for a server whose page is served that way (viser drops the
    same two lines for the answers it makes itself)."""

    def filter(self, record: logging.LogRecord) -> bool:
        return record.getMessage() not in ("opening handshake failed", "connection rejected (200 OK)")


def _quiet_http_answers(connection=None) -> None:
    """Install ``_HttpAnswerNoise`` on the websockets server's logger (a request it cannot take, a HEAD
    before any page was served, logs the same way)."""
    logger = getattr(getattr(connection, "logger", None), "logger", None) or logging.getLogger("websockets.server")
    if not any(isinstance(f, _HttpAnswerNoise) for f in logger.filters):
        logger.addFilter(_HttpAnswerNoise())


@functools.lru_cache(maxsize=1)
def client_page() -> ClientPage:
    """The installed viser's page with mcit's script (built once). RuntimeError when viser's page is
    not one this module can put under a policy: serving it without one is refused."""
    import viser

    index = Path(viser.__file__).parent / "client" / "build" / "index.html"
    try:
        return ClientPage.from_viser(index.read_bytes(), PAGE_SCRIPT.read_bytes())
    except (OSError, ValueError, ImportError) as exc:
        raise RuntimeError(
            f"cannot serve viser {viser.__version__}'s page under mcit's Content-Security-Policy "
            f"({exc}): refusing to serve (update app/ui/page.py)"
        ) from exc
