"""Hostile browser messages (app/ui/inbound.py) on a real mcit interface, reached with the `websockets`
client as a page of the interface would (its own Origin, its camera first): a message that does not
fit its type is dropped with one log line, no traceback, no "Internal error", and the server serves on."""

from __future__ import annotations

import logging
import math
import re
import socket
import threading
import time
import uuid

import msgspec
import numpy as np
import pytest
import viser
import websockets.sync.client
import zstandard

from app.ui import inbound
from app.ui.client import ClientPanel
from app.ui.server import InterfaceServer
from app.video import FrameGrabber, open_video
from tests.e2e.harness import free_port

SUBPROTOCOL = f"viser-v{viser.__version__}"
FUZZ_MESSAGES = 1000
FUZZ_TIME_S = 15.0
FUZZ_SEED = 20240611
MODIFIERS = ("cmd/ctrl", "alt", "shift", "cmd/ctrl+alt", "cmd/ctrl+shift", "alt+shift", "cmd/ctrl+alt+shift")


def camera(**changes) -> dict:
    """A ViewerCameraMessage looking at the video plane from in front of it, as the page sends."""
    return dict(
        dict(
            type="ViewerCameraMessage",
            wxyz=[1.0, 0.0, 0.0, 0.0],
            position=[2.56, 1.28, -4.0],
            fov=1.0,
            near=0.01,
            far=1000.0,
            image_height=720,
            image_width=1280,
            look_at=[2.56, 1.28, 0.0],
            up_direction=[0.0, -1.0, 0.0],
        ),
        **changes,
    )


def click(**changes) -> dict:
    return dict(
        dict(
            type="ScenePointerMessage",
            event_type="click",
            ray_origin=[2.56, 1.28, -4.0],
            ray_direction=[0.0, 0.0, 1.0],
            screen_pos=[[0.5, 0.5]],
            modifier=None,
        ),
        **changes,
    )


def _decoded(frame: bytes) -> list[dict]:
    """The messages of one server → browser frame (viser's wire format: two lengths, zstd MessagePack, buffers)."""
    size, compressed = int.from_bytes(frame[:8], "little"), int.from_bytes(frame[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(frame[16 : 16 + compressed], max_output_size=size)
    return msgspec.msgpack.decode(inner)["messages"]


class Page:
    """One websocket to the interface, as its page opens it; a thread reads and decodes what the server sends."""

    def __init__(self, port: int):
        self.ws = websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}/",
            subprotocols=[SUBPROTOCOL],
            origin=f"http://127.0.0.1:{port}",
            open_timeout=10,
            max_size=None,
        )
        self.video_updates = 0
        self.notifications: list[str] = []
        self.closed = threading.Event()
        self._seen = threading.Condition()
        threading.Thread(target=self._read, name="fuzz-page-reader", daemon=True).start()

    def _read(self) -> None:
        try:
            for frame in self.ws:
                for m in _decoded(frame):
                    with self._seen:
                        if m["type"] == "SceneNodeUpdateMessage" and m.get("name") == "/video":
                            self.video_updates += 1
                        elif m["type"] == "NotificationShowMessage":
                            self.notifications.append(m["props"]["title"])
                        self._seen.notify_all()
        except Exception:  # noqa: BLE001 - closed: said by self.closed
            pass
        finally:
            self.closed.set()
            with self._seen:
                self._seen.notify_all()

    def send(self, payload) -> None:
        self.ws.send(msgspec.msgpack.encode(payload) if isinstance(payload, dict) else payload)

    def wait_video(self, n: int, timeout_s: float = 15.0) -> bool:
        """True once ``n`` more video frames arrived (False at the timeout, or when the connection closed)."""
        with self._seen:
            goal = self.video_updates + n
            return (
                self._seen.wait_for(lambda: self.video_updates >= goal or self.closed.is_set(), timeout_s)
                and self.video_updates >= goal
            )

    def close(self) -> None:
        self.ws.close()


class Served:
    """A real mcit interface on the bundled scene and its video, and what it logs and notifies."""

    def __init__(self, site, caplog, monkeypatch):
        self.notified: list[tuple[str, str]] = []
        original = ClientPanel.notify

        def notify(panel, title, body, *args, **kwargs):
            self.notified.append((title, body))
            return original(panel, title, body, *args, **kwargs)

        monkeypatch.setattr(ClientPanel, "notify", notify)
        caplog.set_level(logging.INFO)
        self.caplog = caplog
        video = FrameGrabber(open_video(str(site.scene.video_path)))
        self.server = InterfaceServer(site, video, port=free_port()).start()
        self.port = self.server.port

    def page(self) -> tuple[Page, ClientPanel]:
        """A connected page (its camera sent) and the panel the server built for it."""
        before = set(self.server.clients)
        page = Page(self.port)
        page.send(camera())
        deadline = time.monotonic() + 15
        while not set(self.server.clients) - before:
            assert time.monotonic() < deadline, "the server built no panel for a page that sent its camera"
            time.sleep(0.02)
        (cid,) = set(self.server.clients) - before
        return page, self.server.clients[cid]

    def settle(self, page: Page, panel: ClientPanel, **report) -> None:
        """Wait until the server has read everything ``page`` sent and run the callbacks it caused (``report``: the
        fields of the camera report sent to know it, e.g. where the page's camera is)."""
        fov = 0.9 + 0.1 * np.random.default_rng().random()
        page.send(camera(**(report | {"fov": fov})))  # read after everything sent before it: the reader is in order
        handle = self.server.server.get_clients()[panel.client.client_id]
        deadline = time.monotonic() + 15
        while abs(handle.camera.fov - fov) > 1e-9:
            assert time.monotonic() < deadline, "the server did not read the page's last message"
            time.sleep(0.02)
        # viser's callback pool: once each of its threads holds a barrier task, every earlier callback has ended
        pool = self.server.server._thread_executor
        barrier = threading.Barrier(pool._max_workers + 1)
        for _ in range(pool._max_workers):
            pool.submit(barrier.wait, 15)
        barrier.wait(15)
        panel.click_worker.submit(lambda: None).result(15)  # the panel's clicks, one at a time

    def inbound_lines(self) -> list[logging.LogRecord]:
        return [r for r in self.caplog.records if r.name == "mcit.ui.inbound"]

    def assert_no_failure(self, page: Page | None = None) -> None:
        bad = [
            r
            for r in self.caplog.records
            if r.exc_info
            or "Traceback" in r.getMessage()
            or (r.levelno >= logging.WARNING and r.name != "mcit.ui.inbound")
        ]
        assert not bad, "\n".join(logging.Formatter("%(levelname)s %(name)s: %(message)s").format(r) for r in bad[:5])
        assert not [n for n in self.notified if n[0] == "Internal error"], self.notified
        if page is not None:
            assert "Internal error" not in page.notifications

    def stop(self) -> None:
        self.server.stop()


@pytest.fixture
def served(site, caplog, monkeypatch):
    s = Served(site, caplog, monkeypatch)
    yield s
    s.stop()


# --------------------------------------------------------------------------- the three shapes found by review


@pytest.mark.parametrize(
    "message, said",
    [
        (click(ray_origin=None), "a click without its ray"),
        (click(ray_origin=[2.56, 1.28]), "ScenePointerMessage.ray_origin has 2 items, expected 3"),
        (click(event_type="hover"), "ScenePointerMessage.event_type is 'hover', not one of 'click', 'rect-select'"),
    ],
)
def test_a_pointer_message_of_the_wrong_shape_is_dropped_with_one_line(served, capfd, message, said):
    page, panel = served.page()
    page.send(message)
    served.settle(page, panel)
    (line,) = served.inbound_lines()
    text = line.getMessage()
    assert line.levelno == logging.WARNING and "\n" not in text and said in text, text
    assert f"browser-{panel.client.client_id + served.server.client_number_offset} (127.0.0.1:" in text, text
    assert served.server.inbound.dropped == 1
    served.assert_no_failure(page)
    assert "Traceback" not in capfd.readouterr().err
    assert page.wait_video(3), "the page that sent it gets no more video"
    page.close()


def test_a_request_to_share_through_viser_s_relay_is_dropped(served, capfd):
    """viser's Share opens a tunnel to the interface through its public relay: mcit hides the button
    and drops the request, so no page can open one."""
    page, panel = served.page()
    page.send({"type": "ShareUrlRequest"})
    served.settle(page, panel)
    (line,) = served.inbound_lines()
    assert "share the interface through viser's public relay" in line.getMessage()
    assert served.server.server._share_tunnel is None
    served.assert_no_failure(page)
    page.close()


@pytest.mark.parametrize(
    "change, said",
    [
        (dict(fov=0.0), "a field of view of 0.0 rad"),
        (dict(fov=3.5), "a field of view of 3.5 rad"),
        (dict(image_width=-5), "an image of -5×"),
        (dict(near=2.0, far=1.0), "near 2.0 and far 1.0"),
    ],
)
def test_a_camera_the_panel_cannot_fit_through_is_dropped(served, capfd, change, said):
    """A camera of a valid type that no page has (a zero field of view, a negative image) raised in the
    panel's fit and zoom, once per redraw, unbounded."""
    page, panel = served.page()
    page.send(dict(EXAMPLES["ViewerCameraMessage"], type="ViewerCameraMessage", **change))
    served.settle(page, panel)
    (line,) = served.inbound_lines()
    assert said in line.getMessage(), line.getMessage()
    served.assert_no_failure(page)
    assert "Traceback" not in capfd.readouterr().err
    page.close()


# --------------------------------------------------------------------------- the fuzzer

BAD_NUMBERS = (None, "1.5", math.nan, math.inf, -math.inf, 1e300, -2e9, [1.0], {"x": 1.0}, True, b"\x01")
BAD_INTEGERS = (None, 1.5, "3", math.nan, math.inf, True, [3], 2**60)
BAD_TEXTS = (None, 5, 1.5, [], {"a": 1}, b"name", True)


class Fuzz:
    """Messages over viser's client → server types, each valid or broken in one known way (seeded)."""

    def __init__(self, rng: np.random.Generator, inputs: dict, commands: list[str]):
        self.rng = rng
        self.inputs = inputs  # uuid → viser GUI handle of the fuzzed page's panel
        self.commands = commands

    # -- valid values
    def number(self, scale: float = 10.0) -> float:
        normal = self.rng.normal(0.0, scale, 2)
        return float(self.rng.choice([*normal, 0.0, inbound.MAX_MAGNITUDE, -inbound.MAX_MAGNITUDE, 1e-300]))

    def vector(self, n: int) -> list[float]:
        return [self.number() for _ in range(n)]

    def name(self) -> str:
        return str(self.rng.choice(["/video", "/overlay/db/1", "/world3d/camera", "", "x" * 300, "/ünï\n"]))

    def modifier(self):
        return None if self.rng.random() < 0.5 else str(self.rng.choice(MODIFIERS))

    def valid(self) -> dict:
        kind = self.rng.integers(12)
        rng = self.rng
        if kind == 0:  # a camera a page can have: in front of the video plane (z = 0), looking at a point on it
            q = rng.normal(size=4)
            return camera(
                wxyz=[float(v) for v in q / np.linalg.norm(q)],
                fov=float(rng.uniform(0.2, 2.0)),
                position=self.vector(2) + [float(-rng.uniform(0.5, 50.0))],
                look_at=self.vector(2) + [0.0],
                image_height=int(rng.integers(100, 4000)),
                image_width=int(rng.integers(100, 4000)),
                up_direction=self.vector(3),
            )
        if kind == 1:
            return click(
                ray_origin=self.vector(3),
                ray_direction=self.vector(3),
                screen_pos=[self.vector(2)],
                modifier=self.modifier(),
            )
        if kind == 2:
            return click(
                event_type="rect-select",
                ray_origin=None,
                ray_direction=None,
                screen_pos=[[float(v) for v in rng.random(2)] for _ in range(2)],
                modifier=self.modifier(),
            )
        if kind == 3:
            return dict(
                type="SceneNodeClickMessage",
                name=self.name(),
                instance_index=None,
                ray_origin=self.vector(3),
                ray_direction=self.vector(3),
                screen_pos=self.vector(2),
                modifier=self.modifier(),
            )
        if kind == 4:
            return dict(
                type="SceneNodeDragMessage",
                phase=str(rng.choice(["start", "update", "end"])),
                name=self.name(),
                instance_index=int(rng.integers(0, 5)),
                start_position=self.vector(3),
                start_screen_pos=self.vector(2),
                end_position=self.vector(3),
                end_screen_pos=self.vector(2),
                button=str(rng.choice(["left", "middle", "right"])),
                modifier=self.modifier(),
                owner="",
            )
        if kind == 5:
            return dict(
                type="TransformControlsUpdateMessage",
                name=self.name(),
                wxyz=self.vector(4),
                position=self.vector(3),
                owner="",
            )
        if kind == 6:
            return dict(
                type=str(rng.choice(["TransformControlsDragStartMessage", "TransformControlsDragEndMessage"])),
                name=self.name(),
                owner="",
            )
        if kind == 7:
            update = self.valid_input_update()
            if update is not None:
                return update  # else (no input takes a value) the last kind
        if kind == 8:
            return dict(type="GuiButtonHoldMessage", uuid=self.some_uuid(), frequency=float(rng.uniform(0, 100)))
        if kind == 9:
            return dict(type=str(rng.choice(["GuiFormSubmitMessage", "GuiFormDirtyMessage"])), uuid=self.some_uuid())
        if kind == 10:
            return dict(
                type="FileTransferStartUpload",
                source_component_uuid=str(uuid.uuid4()),
                transfer_uuid=str(uuid.uuid4()),
                filename="a.txt",
                mime_type="text/plain",
                part_count=int(rng.integers(0, 3)),
                size_bytes=int(rng.integers(0, 100)),
            )
        return dict(
            type="FileTransferPart",
            source_component_uuid=None,
            transfer_uuid=str(uuid.uuid4()),
            part_index=int(rng.integers(0, 3)),
            content=bytes(rng.integers(0, 256, 16, dtype=np.uint8)),
        )

    def some_uuid(self) -> str:
        known = list(self.inputs) + self.commands
        return str(self.rng.choice(known)) if known and self.rng.random() < 0.7 else str(uuid.uuid4())

    def valid_input_update(self) -> dict | None:
        """A value the page itself could send to one of the panel's inputs (buttons are not pressed:
        a press starts workflows, whose answers to random clicks are not this test's subject)."""
        rng = self.rng
        choices = [(u, h) for u, h in self.inputs.items() if not isinstance(h, viser.GuiButtonHandle)]
        if not choices:
            return None
        u, h = choices[int(rng.integers(len(choices)))]
        if isinstance(h, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)):
            value = str(rng.choice(list(h.options)))
        elif isinstance(h, viser.GuiCheckboxHandle):
            value = bool(rng.random() < 0.5)
        elif isinstance(h, viser.GuiSliderHandle):
            value = float(rng.uniform(h.min, h.max))
        elif isinstance(h.value, str):
            value = str(rng.choice(["", "0.5 0.5 1", "0.5 0.5 -120 3", "nan nan 0", "1e999 0 0", "x y z", "ü" * 50]))
        else:
            return None
        return dict(type="GuiUpdateMessage", uuid=u, updates={"value": value})

    # -- broken ones
    def broken(self) -> tuple[object, str]:
        """(payload, how it is broken)."""
        rng = self.rng
        kind = int(rng.integers(14))
        pick = lambda seq: seq[int(rng.integers(len(seq)))]  # noqa: E731
        if kind == 0:
            return bytes(rng.integers(0, 256, int(rng.integers(0, 64)), dtype=np.uint8)) + b"\xc1", "not MessagePack"
        if kind == 1:
            return pick(["", "hello", '{"type": "ViewerCameraMessage"}']), "a text frame"
        if kind == 2:
            return msgspec.msgpack.encode(pick([[1, 2], 5, "ViewerCameraMessage", None, {"no": 1}])), "not a message"
        if kind == 3:
            name = pick(["NoSuchMessage", "", "viewercameramessage", "_Dropped", 7, "Camera\nWARNING forged line"])
            return dict(camera(), type=name), "an unknown type"
        message = self.valid()
        fields = [k for k in message if k != "type"]
        if kind == 4:
            message.pop(pick([k for k in fields if k != "owner"]))  # owner has a default
            return message, "a field missing"
        if kind == 5:
            message[pick(["extra", "entity_type", "excluded_self_client", "owner2"])] = 1
            return message, "an extra field"
        if kind == 6:
            return dict(click(), event_type=pick(["hover", "CLICK", "", 1, None])), "an unknown event_type"
        if kind == 7:
            return dict(
                click(),
                ray_origin=pick([None, [1.0, 2.0], [1.0, 2.0, 3.0, 4.0], [math.nan, 0.0, 0.0], ["1", "2", "3"], 1.0]),
            ), "a bad click ray"
        if kind == 8:
            points = pick([[], [[0.5, 0.5], [0.6, 0.6]], [[0.5]], [0.5, 0.5]])
            return dict(click(), screen_pos=points), "bad screen points"
        if kind == 9:
            field = pick(["fov", "near", "far"])
            return dict(camera(), **{field: pick(BAD_NUMBERS)}), "a bad camera number"
        if kind == 10:
            field = pick(["wxyz", "position", "look_at", "up_direction"])
            bad = pick([None, [], [1.0] * 5, [math.inf] * 4, [1e300] * 4, "abc", [[1.0]] * 4])
            return dict(camera(), **{field: bad}), "a bad camera vector"
        if kind == 11:
            return dict(camera(), **{pick(["image_height", "image_width"]): pick(BAD_INTEGERS)}), "a bad camera size"
        if kind == 12:
            if rng.random() < 0.2:
                return dict(
                    type="FileTransferStartUpload",
                    source_component_uuid=pick(list(self.inputs)),
                    transfer_uuid="t",
                    filename="a.txt",
                    mime_type="text/plain",
                    part_count=0,
                    size_bytes=1,
                ), "an upload to an input that takes none"
            return self.broken_input_update(), "a bad input update"
        return dict(
            type="SceneNodeClickMessage",
            name=pick(BAD_TEXTS),
            instance_index=None,
            ray_origin=[0.0] * 3,
            ray_direction=[0.0, 0.0, 1.0],
            screen_pos=[0.5, 0.5],
            modifier=None,
        ), "a bad node name"

    def broken_input_update(self) -> dict:
        rng = self.rng
        u, h = list(self.inputs.items())[int(rng.integers(len(self.inputs)))]
        current = h.value
        if rng.random() < 0.3:
            key = str(rng.choice(["removed", "update_cb", "sync_cb", "disabled", "visible", "label", "options"]))
            return dict(type="GuiUpdateMessage", uuid=u, updates={"value": current, key: rng.random() < 0.5})
        if isinstance(h, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)):
            bad = [h.value + "?", "", 3, None, [h.value]]
        elif isinstance(current, bool):
            bad = ["true", 1, 0.0, None, [True]]
        elif isinstance(h, viser.GuiSliderHandle):
            bad = [h.max + 1.0, h.min - 1e9, math.nan, math.inf, "0.5", None, [h.min], True]
        elif isinstance(current, float):
            bad = [math.nan, "0.5", None, True]
        else:  # a text field
            bad = [5, None, 1.5, [], {"a": 1}, b"text"]
        return dict(type="GuiUpdateMessage", uuid=u, updates={"value": bad[int(rng.integers(len(bad)))]})


def test_a_fuzzing_page_gets_no_traceback_no_internal_error_and_the_server_serves_on(served, capfd):
    page, panel = served.page()
    gui = served.server.server.get_clients()[panel.client.client_id].gui
    fuzz = Fuzz(
        np.random.default_rng(FUZZ_SEED), dict(gui._gui_input_handle_from_uuid), list(gui._command_handle_from_uuid)
    )
    sent = broken = 0
    kinds: dict[str, int] = {}
    start = time.monotonic()
    while sent < FUZZ_MESSAGES and time.monotonic() - start < FUZZ_TIME_S:
        if fuzz.rng.random() < 0.6:
            payload, why = fuzz.broken()
            broken += 1
            kinds[why] = kinds.get(why, 0) + 1
        else:
            payload = fuzz.valid()
        page.send(payload)
        sent += 1
    assert not page.closed.is_set(), "the server closed the fuzzing page's connection"
    served.settle(page, panel)
    elapsed = time.monotonic() - start
    served.assert_no_failure(page)
    assert "Traceback" not in capfd.readouterr().err
    assert sent == FUZZ_MESSAGES, f"only {sent} messages sent in {FUZZ_TIME_S} s"
    assert served.server.inbound.dropped == broken, (served.server.inbound.dropped, broken, kinds)  # and no valid one
    lines = served.inbound_lines()
    assert 1 <= len(lines) <= elapsed / inbound.LOG_INTERVAL_S + 2, len(lines)  # one a second at most
    assert all("\n" not in r.getMessage() and "(127.0.0.1:" in r.getMessage() for r in lines)
    assert page.wait_video(3), "the fuzzing page gets no more video"
    page.close()
    # a fresh page connects and is served
    fresh, _ = served.page()
    assert fresh.wait_video(3), "a new page gets no video after the fuzzing"
    fresh.close()
    served.assert_no_failure(fresh)
    print(f"fuzz: {sent} messages in {elapsed:.1f} s, {broken} broken and dropped ({kinds}), {len(lines)} log lines")


def test_a_flood_is_logged_once_a_second_with_a_count(served):
    page, panel = served.page()
    for _ in range(200):
        page.send(b"\xc1")
    served.settle(page, panel)
    page.close()
    deadline = time.monotonic() + 10
    while not any("before it left" in r.getMessage() for r in served.inbound_lines()):
        assert time.monotonic() < deadline, [r.getMessage() for r in served.inbound_lines()]
        time.sleep(0.02)
    lines = [r.getMessage() for r in served.inbound_lines()]
    assert len(lines) <= 4, lines  # the flood takes well under 3 s
    said = 0  # each line tells one message, plus those it counts
    for line in lines:
        counted = re.search(r"\((\d+) more dropped since the last line\)$", line)
        left = re.match(r"dropped (\d+) more messages from ", line)
        said += int(left[1]) if left else 1 + (int(counted[1]) if counted else 0)
    assert said == served.server.inbound.dropped == 200, lines


EXAMPLES = {  # one message of each type viser handles, as the page sends it (ShareUrl*: no fields)
    "ViewerCameraMessage": camera(),
    "ScenePointerMessage": click(),
    "SceneNodeClickMessage": dict(
        name="/video",
        instance_index=None,
        ray_origin=[0.0, 0.0, -1.0],
        ray_direction=[0.0, 0.0, 1.0],
        screen_pos=[0.5, 0.5],
        modifier="shift",
        owner="",
    ),
    "SceneNodeDragMessage": dict(
        phase="start",
        name="/video",
        instance_index=2,
        start_position=[0, 0, 0],
        start_screen_pos=[0, 0],
        end_position=[1.0, 1.0, 1.0],
        end_screen_pos=[1, 1],
        button="left",
        modifier=None,
    ),
    "TransformControlsUpdateMessage": dict(name="/t", wxyz=[1, 0, 0, 0], position=[0, 0, 0], owner=""),
    "TransformControlsDragStartMessage": dict(name="/t", owner=""),
    "TransformControlsDragEndMessage": dict(name="/t"),
    "GuiUpdateMessage": dict(uuid="u", updates={"value": [1.0, 2]}),
    "GuiButtonHoldMessage": dict(uuid="u", frequency=10),
    "GuiFormSubmitMessage": dict(uuid="u"),
    "GuiFormDirtyMessage": dict(uuid="u"),
    "FileTransferStartUpload": dict(
        source_component_uuid="u",
        transfer_uuid="t",
        filename="a.txt",
        mime_type="text/plain",
        part_count=1,
        size_bytes=3,
    ),
    "FileTransferPart": dict(source_component_uuid=None, transfer_uuid="t", part_index=0, content=b"abc"),
    "CommandTriggerMessage": dict(uuid="u"),
    "GetRenderResponseMessage": dict(payload=b"", render_uuid="r"),
    "LocalStorageGetItemResponseMessage": dict(value=None, error=None, request_uuid="r"),
    "ShareUrlRequest": {},
    "ShareUrlDisconnect": {},
}


def test_every_message_type_viser_handles_is_checked_and_the_page_s_own_pass(served):
    """A type viser handles whose annotations the checks could not read would be dropped every time:
    each handled type has an example here, and each passes."""
    from viser import _messages

    page, panel = served.page()
    client = served.server.server.get_clients()[panel.client.client_id]
    handled = {
        cls.__name__
        for handler in (served.server.server._websock_server, client._websock_connection)
        for cls in handler._incoming_handlers
    }
    assert handled <= EXAMPLES.keys(), f"viser handles types the checks were not shown: {handled - EXAMPLES.keys()}"
    for name, example in EXAMPLES.items():
        assert inbound.message_problem(dict(example, type=name), _messages.Message) is None, name
    page.close()


def test_a_page_connected_before_the_guard_is_closed_and_its_next_connection_checked(caplog):
    from app.ui.access import AccessPolicy, open_viser_server

    server = open_viser_server(AccessPolicy(), host="127.0.0.1", port=free_port(), verbose=False)
    try:
        early = Page(server.get_port())
        deadline = time.monotonic() + 10
        while not server._websock_server._live_connections:
            assert time.monotonic() < deadline
            time.sleep(0.02)
        guard = inbound.guard_inbound_messages(server)
        assert early.closed.wait(10), "a connection read by the unchecked reader stayed open"
        later = Page(server.get_port())
        later.send(click(ray_origin=None))
        while guard.dropped == 0:
            assert time.monotonic() < deadline + 10, "the new connection is not checked"
            time.sleep(0.02)
        later.close()
    finally:
        server.stop()


def test_start_up_fails_loudly_when_viser_no_longer_reads_through_the_hook(site, monkeypatch):
    monkeypatch.setattr(inbound, "_READER", "_no_such_reader")  # as if viser read its messages some other way
    port = free_port()
    with pytest.raises(RuntimeError, match="refusing to serve"):
        InterfaceServer(site, FrameGrabber(open_video(str(site.scene.video_path))), port=port)
    with pytest.raises(ConnectionRefusedError):  # and nothing serves there
        socket.create_connection(("127.0.0.1", port), timeout=5).close()
