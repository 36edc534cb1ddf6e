"""A browser message the interface cannot read logs one line (app/ui/wslog.py), on a real viser server
reached with the `websockets` client viser depends on; the server keeps serving."""

from __future__ import annotations

import logging
import sys
import threading
import time

import msgspec
import pytest
import viser
import websockets.sync.client

from app.ui.access import AccessPolicy, open_viser_server
from app.ui.wslog import MalformedMessageFilter, quiet_malformed_messages
from tests.e2e.harness import free_port

SUBPROTOCOL = f"viser-v{viser.__version__}"
CAMERA = dict(
    type="ViewerCameraMessage",
    wxyz=[1.0, 0.0, 0.0, 0.0],
    position=[0.0, 0.0, 0.0],
    fov=1.0,
    near=0.1,
    far=10.0,
    image_height=10,
    image_width=10,
    look_at=[0.0, 0.0, 0.0],
    up_direction=[0.0, 0.0, 1.0],
)
MALFORMED = {
    "not MessagePack": b"\x00garbage",
    "empty": b"",
    "a text frame": "hello",
    "an unknown type": msgspec.msgpack.encode({"type": "NoSuchMessage"}),
    "not a mapping": msgspec.msgpack.encode([1, 2, 3]),
    "missing fields": msgspec.msgpack.encode({"type": "ViewerCameraMessage"}),
    "a field of the wrong type": msgspec.msgpack.encode(dict(CAMERA, fov="wide")),
    "a field of the wrong shape": msgspec.msgpack.encode(dict(CAMERA, wxyz=[1.0, 0.0])),
}


class Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []
        self.records_lock = threading.Lock()  # not self.lock: Handler.handle() holds that one around emit()

    def emit(self, record):
        with self.records_lock:
            self.records.append(record)

    def warnings_and_errors(self):
        with self.records_lock:
            return [r for r in self.records if r.levelno >= logging.WARNING]


@pytest.fixture
def served():
    handler = Records()
    loggers = [logging.getLogger(n) for n in ("websockets.server", "mcit.ui")]
    for lg in loggers:
        lg.addHandler(handler)
    old_levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.INFO)
    quiet_malformed_messages()
    port = free_port()
    server = open_viser_server(AccessPolicy(), host="127.0.0.1", port=port, verbose=False)
    try:
        yield port, handler
    finally:
        server.stop()
        for lg, level in zip(loggers, old_levels):
            lg.removeHandler(handler)
            lg.setLevel(level)


def _send(port: int, payload, linger_s: float = 10.0, until=lambda: False) -> None:
    """Send ``payload`` on a new connection and read until the server closes it, ``until()`` holds, or
    ``linger_s`` has passed (a message of a wrong shape is logged but leaves the connection open)."""
    with websockets.sync.client.connect(f"ws://127.0.0.1:{port}/", subprotocols=[SUBPROTOCOL], open_timeout=10) as ws:
        ws.send(payload)
        end = time.monotonic() + linger_s
        while time.monotonic() < end and not until():
            try:
                ws.recv(timeout=0.1)
            except TimeoutError:  # quiet: look again
                continue
            except Exception:  # noqa: BLE001 - closed (the expected end for a malformed message)
                return


def _wait_for(handler: Records, n: int) -> list[logging.LogRecord]:
    deadline = time.monotonic() + 30
    while len(handler.warnings_and_errors()) < n and time.monotonic() < deadline:
        time.sleep(0.05)
    return handler.warnings_and_errors()


@pytest.mark.parametrize("what", sorted(MALFORMED))
def test_a_malformed_message_logs_one_line(served, what):
    port, handler = served
    _send(port, MALFORMED[what], until=handler.warnings_and_errors)
    (record,) = _wait_for(handler, 1)
    line = logging.Formatter("%(levelname)s %(name)s: %(message)s").format(record)
    assert "\n" not in line and record.exc_info is None, line
    assert record.levelno == logging.WARNING and ("cannot read" in line or "wrong shape" in line), line
    if "cannot read" in line:
        assert "127.0.0.1:" in line  # who sent it
    time.sleep(0.3)
    assert len(handler.warnings_and_errors()) == 1  # and nothing else after it
    # the server still serves: a well-formed message is read without a word (the connection kept 0.5 s meanwhile)
    _send(port, msgspec.msgpack.encode(CAMERA), linger_s=0.5)
    assert len(handler.warnings_and_errors()) == 1


def test_a_server_fault_keeps_its_traceback():
    """Only a failure inside viser's message reader is the message's fault; another keeps its traceback."""
    try:
        raise RuntimeError("the producer broke")
    except RuntimeError:
        exc_info = sys.exc_info()
    record = logging.LogRecord(
        "websockets.server", logging.ERROR, __file__, 1, "connection handler failed", (), exc_info
    )
    assert MalformedMessageFilter().filter(record) and record.exc_info is exc_info and record.levelno == logging.ERROR
