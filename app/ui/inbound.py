"""Each browser message checked against its declared type before viser dispatches it.

viser 1.1 reads a browser's messages in ``_message_consumer`` (viser.infra._infra): it decodes each
one (``Message.deserialize``) and hands it to every handler registered for its type, checking little
on the way: a tuple of the wrong length is passed on as sent (with a UserWarning), a null reaches a
handler that asserts a ray, an unknown ``event_type`` one that indexes by it, and a GUI update may
set any attribute of an input's state. The handler then fails (a traceback on the event loop) or
mcit's callback does (an "Internal error" shown to the operator).

:func:`guard_inbound_messages` wraps that reader for one viser server. Each message is decoded and
checked first against its class's annotations: a map with a known ``type``, the declared fields only
and every required one, the right types, tuple lengths, finite numbers within ``MAX_MAGNITUDE``,
Literal values among the allowed ones, None only where Optional; then what viser's handlers need
beyond the annotations (``_NEEDS``); then a GUI update against the input it names (of the input's
type and length, among a dropdown's options, within a slider's range) and an upload against its
button. A message that fails is dropped, never dispatched, with one WARNING line (logger
``mcit.ui.inbound``) naming the sender and what was wrong: at most one a second per connection, with
a count of the rest. The connection stays open; a text frame is dropped the same way. The guard
fails at start-up, stopping the server, if viser no longer reads messages that way.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import logging
import math
import reprlib
import threading
import time
import types
import weakref
from collections.abc import Callable
from typing import Any, Literal, Union, get_args, get_origin

import msgspec
from typing_extensions import get_type_hints

__all__ = [
    "InboundGuard",
    "guard_inbound_messages",
    "message_problem",
    "gui_update_problem",
    "LOG_INTERVAL_S",
    "MAX_MAGNITUDE",
]

log = logging.getLogger("mcit.ui.inbound")

LOG_INTERVAL_S = 1.0  # at most one line per connection in this time; the drops in between are counted
_INFRA = "viser.infra._infra"
_READER = "_message_consumer"  # the coroutine viser runs per connection to read and dispatch messages
_READER_PARAMETERS = ["websocket", "handle_message", "message_class"]
_MAX_DEPTH = 16  # nesting of a free-form value (a GUI update's value); the browser sends at most 2
# Numbers a browser sends (metres, pixels, radians, screen fractions) are far below this; above it a
# finite value overflows to inf in the arithmetic downstream (a camera at 1e300 made NaN zooms).
MAX_MAGNITUDE = 1e9
MAX_INTEGER = 2**53  # JavaScript's largest exact integer


class _Dropped:
    """What the checking reader returns for a dropped message: no handler is registered for its type."""


_DROPPED = _Dropped()

_show = reprlib.Repr()
_show.maxstring, _show.maxother, _show.maxlist, _show.maxtuple, _show.maxdict, _show.maxlevel = 40, 40, 4, 4, 4, 2


def _shown(value: Any) -> str:
    if isinstance(value, (bytes, bytearray)):
        return f"{len(value)} bytes"
    return _show.repr(value)


def _type_name(annotation: Any) -> str:
    text = str(annotation).replace("typing.", "")
    return getattr(annotation, "__name__", text) if isinstance(annotation, type) else text


# --------------------------------------------------------------------------- checks by annotation


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _number_problem(value: int | float, path: str) -> str | None:
    if isinstance(value, int):
        return None if abs(value) <= MAX_INTEGER else f"{path} is {value}, beyond ±2**53"
    if not math.isfinite(value):
        return f"{path} is {value!r}, not a finite number"
    return None if abs(value) <= MAX_MAGNITUDE else f"{path} is {value:g}, beyond ±{MAX_MAGNITUDE:g}"


def _plain_problem(value: Any, path: str, depth: int = 0) -> str | None:
    """Why ``value`` is not a plain value (null, bool, finite number, text, bytes, lists and maps of them)."""
    if depth > _MAX_DEPTH:
        return f"{path} is nested more than {_MAX_DEPTH} deep"
    if value is None or isinstance(value, (bool, str, bytes)):
        return None
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        return _number_problem(value, path)
    if isinstance(value, list):
        for i, item in enumerate(value):
            if (problem := _plain_problem(item, f"{path}[{i}]", depth + 1)) is not None:
                return problem
        return None
    if isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                return f"{path} has a key {_shown(key)} that is not text"
            if (problem := _plain_problem(item, f"{path}.{key}", depth + 1)) is not None:
                return problem
        return None
    return f"{path} is {type(value).__name__} {_shown(value)}"


def _value_problem(value: Any, annotation: Any, path: str) -> str | None:
    """Why ``value`` (as msgspec decodes MessagePack: lists for arrays) does not fit ``annotation``, or None."""
    if annotation is Any:
        return _plain_problem(value, path)
    if annotation is None or annotation is type(None):
        return None if value is None else f"{path} is {_shown(value)}, expected null"
    origin = get_origin(annotation)
    args = get_args(annotation)
    if origin is Union or origin is types.UnionType:
        if value is None:
            return None if type(None) in args else f"{path} is null, expected {_type_name(annotation)}"
        problems = [_value_problem(value, arm, path) for arm in args if arm is not type(None)]
        if any(p is None for p in problems):
            return None
        return problems[0] if len(problems) == 1 else f"{path} is {_shown(value)}, expected {_type_name(annotation)}"
    if origin is Literal:
        if any(value == allowed and type(value) is type(allowed) for allowed in args):
            return None
        return f"{path} is {_shown(value)}, not one of {', '.join(map(repr, args))}"
    if value is None:
        return f"{path} is null, expected {_type_name(annotation)}"
    if annotation is float:
        return _number_problem(value, path) if _is_number(value) else f"{path} is {_shown(value)}, expected a number"
    if annotation is int:
        # JavaScript has one number type: 3 may come as 3.0
        if _is_number(value) and (isinstance(value, int) or (math.isfinite(value) and value.is_integer())):
            return _number_problem(value, path)
        return f"{path} is {_shown(value)}, expected an integer"
    if annotation in (bool, str, bytes):
        return None if isinstance(value, annotation) else f"{path} is {_shown(value)}, expected {annotation.__name__}"
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            return f"{path} is {_shown(value)}, expected {_type_name(annotation)}"
        if len(args) == 2 and args[1] is Ellipsis:
            args = (args[0],) * len(value)
        elif len(value) != len(args):
            return f"{path} has {len(value)} items, expected {len(args)}: {_shown(value)}"
        for i, (item, arm) in enumerate(zip(value, args)):
            if (problem := _value_problem(item, arm, f"{path}[{i}]")) is not None:
                return problem
        return None
    if origin is list:
        if not isinstance(value, list):
            return f"{path} is {_shown(value)}, expected a list"
        for i, item in enumerate(value):
            if (problem := _value_problem(item, args[0] if args else Any, f"{path}[{i}]")) is not None:
                return problem
        return None
    if origin is dict:
        if not isinstance(value, dict):
            return f"{path} is {_shown(value)}, expected a map"
        key_type, item_type = args if args else (Any, Any)
        for key, item in value.items():
            if (problem := _value_problem(key, key_type, f"{path} key")) is not None:
                return problem
            if (problem := _value_problem(item, item_type, f"{path}.{key}")) is not None:
                return problem
        return None
    return f"{path} is declared {_type_name(annotation)}, which the interface does not take from a browser"


@functools.cache
def _fields(cls: type) -> tuple[dict[str, Any], frozenset[str]]:
    """(annotation of each field a message of type ``cls`` carries, the names it must carry)."""
    hints = get_type_hints(cls)
    fields = dataclasses.fields(cls)
    annotations = {f.name: hints[f.name] for f in fields if f.name in hints}
    required = frozenset(
        f.name
        for f in fields
        if f.name in annotations
        and f.init
        and f.default is dataclasses.MISSING
        and f.default_factory is dataclasses.MISSING
    )
    return annotations, required


@functools.cache
def _types(message_class: type) -> dict[str, type]:
    return {cls.__name__: cls for cls in message_class.get_subclasses()}


def _pointer_needs(mapping: dict) -> str | None:
    # viser's handler asserts the rays of a click and reads screen_pos[0] (click) or [0] and [1] (rect-select)
    points = 1 if mapping["event_type"] == "click" else 2
    if points == 1 and (mapping["ray_origin"] is None or mapping["ray_direction"] is None):
        return "ScenePointerMessage: a click without its ray (ray_origin and ray_direction are null)"
    if len(mapping["screen_pos"]) != points:
        return (
            f"ScenePointerMessage: a {mapping['event_type']} with {len(mapping['screen_pos'])} screen points, "
            f"expected {points}"
        )
    return None


def _gui_update_needs(mapping: dict) -> str | None:
    # the page only ever sends {"value": v}; viser sets any key on the input's state (its callbacks too)
    if set(mapping["updates"]) != {"value"}:
        return f"GuiUpdateMessage sets {_shown(sorted(mapping['updates']))}: a browser may only set an input's value"
    return None


def _camera_needs(mapping: dict) -> str | None:
    # the panel fits and zooms through this camera: a field of view within (0°, 180°), an image of pixels,
    # a look-at point apart from the position, planes in front of it
    if not 0.0 < mapping["fov"] < math.pi:
        return f"ViewerCameraMessage: a field of view of {mapping['fov']!r} rad, not within (0, π)"
    if not (1 <= mapping["image_width"] <= 100_000 and 1 <= mapping["image_height"] <= 100_000):
        return f"ViewerCameraMessage: an image of {mapping['image_width']!r}×{mapping['image_height']!r} pixels"
    if not 0.0 < mapping["near"] < mapping["far"]:
        return f"ViewerCameraMessage: near {mapping['near']!r} and far {mapping['far']!r} planes"
    if all(abs(a - b) < 1e-12 for a, b in zip(mapping["position"], mapping["look_at"])):
        return "ViewerCameraMessage: a look-at point at the camera's position"
    return None


_NEEDS: dict[str, Callable[[dict], str | None]] = {
    "ViewerCameraMessage": _camera_needs,
    "ScenePointerMessage": _pointer_needs,
    "GuiUpdateMessage": _gui_update_needs,
}


def message_problem(mapping: Any, message_class: type) -> str | None:
    """Why a decoded message ``mapping`` is not one that viser's handlers can take, or None.

    Parameters
    ----------
    mapping : what MessagePack decoded (a dict with a "type" naming a subclass of ``message_class``)
    message_class : viser's message base class (``viser._messages.Message``)
    """
    if not isinstance(mapping, dict):
        return f"a {type(mapping).__name__} ({_shown(mapping)}), not a message"
    name = mapping.get("type")
    cls = _types(message_class).get(name) if isinstance(name, str) else None
    if cls is None:
        return f"an unknown message type {_shown(name)}"
    annotations, required = _fields(cls)
    extra = [k for k in mapping if k != "type" and k not in annotations]
    if extra:
        return f"{name} has unexpected fields {_shown(extra)}"
    missing = sorted(required - mapping.keys())
    if missing:
        return f"{name} lacks fields {', '.join(missing)}"
    for key, value in mapping.items():
        if key != "type" and (problem := _value_problem(value, annotations[key], f"{name}.{key}")) is not None:
            return problem
    needs = _NEEDS.get(name)
    return None if needs is None else needs(mapping)


# --------------------------------------------------------------------------- GUI updates


def gui_update_problem(value: Any, handle: Any) -> str | None:
    """Why ``value``, a plain value a GUI update sets, does not fit the input ``handle`` it names, or None."""
    import viser

    current = handle.value
    path = f"the value of {type(handle).__name__} {_shown(getattr(handle, 'label', ''))}"
    if isinstance(current, tuple):
        if current and len({type(v) for v in current}) != 1:
            return f"{path}: an input of mixed types, which the interface does not take from a browser"
        annotation: Any = tuple[(type(current[0]),) * len(current)] if current else tuple[()]
    elif isinstance(current, (bool, int, float, str)):
        annotation = type(current)
    else:
        return f"{path}: an input of type {type(current).__name__}, which the interface does not take from a browser"
    if (problem := _value_problem(value, annotation, path)) is not None:
        return problem
    if isinstance(handle, (viser.GuiDropdownHandle, viser.GuiButtonGroupHandle)) and value not in handle.options:
        return f"{path} is {_shown(value)}, not one of its options"
    if isinstance(handle, (viser.GuiSliderHandle, viser.GuiMultiSliderHandle)):
        low, high = float(handle.min), float(handle.max)
        slack = 1e-9 * max(1.0, high - low)
        if any(not (low - slack <= v <= high + slack) for v in (value if isinstance(value, list) else [value])):
            return f"{path} is {_shown(value)}, outside its range {low:g} to {high:g}"
    return None


# --------------------------------------------------------------------------- the hook into viser


class InboundGuard:
    """The checks on one viser server's incoming messages; ``dropped`` counts the messages dropped."""

    def __init__(self, server, name_of: Callable[[int], str] | None = None):
        self._server = weakref.ref(server)  # the registry keeps this guard as long as the server lives
        self.name_of = name_of
        self.dropped = 0

    @property
    def server(self):
        return self._server()

    def client_id_of(self, websocket) -> int | None:
        server = self.server
        if server is None:
            return None
        for client_id, connection in list(server._websock_server._live_connections.items()):
            if connection is websocket:
                return int(client_id)
        return None

    def gui_handle(self, client_id: int, uuid: str):
        """The input ``uuid`` of this server's panel or of the client's own, or None (gone)."""
        handle = self.server.gui._gui_input_handle_from_uuid.get(uuid)
        client = self.server.get_clients().get(client_id)
        if handle is None and client is not None:
            handle = client.gui._gui_input_handle_from_uuid.get(uuid)
        return handle

    def input_problem(self, client_id: int, mapping: dict) -> str | None:
        """Why a well-formed message that names an input of the panel does not fit that input, or None.
        An input that is gone passes: viser ignores a message about it."""
        import viser

        if mapping["type"] in ("ShareUrlRequest", "ShareUrlDisconnect"):
            # viser's Share opens a tunnel through viser's public relay: mcit's interface is not shared that way
            return "a request to share the interface through viser's public relay (mcit hides that button)"
        if mapping["type"] == "GuiUpdateMessage":
            handle = self.gui_handle(client_id, mapping["uuid"])
            return None if handle is None else gui_update_problem(mapping["updates"]["value"], handle)
        if mapping["type"] == "FileTransferStartUpload":
            handle = self.gui_handle(client_id, mapping["source_component_uuid"])
            if handle is not None and not isinstance(handle, viser.GuiUploadButtonHandle):
                return (
                    f"FileTransferStartUpload names {type(handle).__name__} "
                    f"{_shown(getattr(handle, 'label', ''))}, not an upload button"
                )
        return None

    def sender(self, client_id: int, websocket) -> str:
        peer = getattr(websocket, "remote_address", None)
        where = f"{peer[0]}:{peer[1]}" if isinstance(peer, tuple) and len(peer) >= 2 else "an unknown address"
        try:
            name = self.name_of(client_id) if self.name_of is not None else f"viser client {client_id}"
        except Exception:  # noqa: BLE001 - a name is not worth losing the line for
            name = f"viser client {client_id}"
        return f"{name} ({where})"


class _CheckingReader:
    """What viser's reader gets, for one connection: ``deserialize`` checks before it builds, and
    ``dispatch`` passes on all but the dropped; one log line a second at most."""

    def __init__(self, guard: InboundGuard, client_id: int, websocket, message_class: type):
        self.guard = guard
        self.client_id = client_id
        self.message_class = message_class
        self.sender = guard.sender(client_id, websocket)
        self.last_said = -math.inf
        self.unsaid = 0

    def drop(self, problem: str) -> _Dropped:
        self.guard.dropped += 1
        now = time.monotonic()
        if now - self.last_said < LOG_INTERVAL_S:
            self.unsaid += 1
            return _DROPPED
        more = f" ({self.unsaid} more dropped since the last line)" if self.unsaid else ""
        log.warning("dropped a message from %s that the interface cannot read: %s%s", self.sender, problem, more)
        self.last_said, self.unsaid = now, 0
        return _DROPPED

    def close(self) -> None:
        if self.unsaid:
            log.warning(
                "dropped %d more messages from %s that the interface cannot read, before it left",
                self.unsaid,
                self.sender,
            )
            self.unsaid = 0

    def deserialize(self, raw: Any) -> Any:
        if not isinstance(raw, bytes):
            return self.drop(f"a text frame ({len(raw)} characters), not MessagePack")
        try:
            mapping = msgspec.msgpack.decode(raw)
        except msgspec.DecodeError as exc:
            return self.drop(f"not MessagePack ({' '.join(str(exc).split())[:100]}; {len(raw)} bytes)")
        problem = message_problem(mapping, self.message_class) or self.guard.input_problem(self.client_id, mapping)
        if problem is not None:
            return self.drop(problem)
        try:
            return self.message_class.deserialize(raw)
        except Exception as exc:  # noqa: BLE001 - a check above missed it: still the message's fault
            return self.drop(f"viser could not build it ({type(exc).__name__}: {' '.join(str(exc).split())[:100]})")

    def dispatching(self, handle_message: Callable[[Any], None]) -> Callable[[Any], None]:
        def dispatch(message: Any) -> None:
            if message is not _DROPPED:
                handle_message(message)

        return dispatch


class _TextFramesToReader:
    """The connection as viser's reader sees it: a text frame goes to the checking reader (which
    drops it) instead of failing viser's ``assert isinstance(raw, bytes)`` and closing the connection."""

    def __init__(self, websocket, reader: _CheckingReader):
        self._websocket = websocket
        self._reader = reader

    async def recv(self, *args, **kwargs):
        while True:
            raw = await self._websocket.recv(*args, **kwargs)
            if isinstance(raw, bytes):
                return raw
            self._reader.deserialize(raw)

    def __getattr__(self, name):
        return getattr(self._websocket, name)


_guards: weakref.WeakKeyDictionary[Any, InboundGuard] = weakref.WeakKeyDictionary()  # by viser server
_install_lock = threading.Lock()


def _guard_of(websocket) -> tuple[InboundGuard | None, int | None]:
    for guard in list(_guards.values()):
        client_id = guard.client_id_of(websocket)
        if client_id is not None:
            return guard, client_id
    return None, None


def _checking(original):
    @functools.wraps(original)
    async def _message_consumer(websocket, handle_message, message_class):
        guard, client_id = _guard_of(websocket)  # viser lists the connection before it starts reading it
        if guard is None:  # a viser server this process did not guard
            return await original(websocket, handle_message, message_class)
        reader = _CheckingReader(guard, client_id, websocket, message_class)
        try:
            return await original(_TextFramesToReader(websocket, reader), reader.dispatching(handle_message), reader)
        finally:
            reader.close()

    _message_consumer.mcit_checking = True
    return _message_consumer


def _code_objects(code: types.CodeType):
    yield code
    for const in code.co_consts:
        if isinstance(const, types.CodeType):
            yield from _code_objects(const)


def _why_not_hookable(server) -> str | None:
    """Why viser no longer reads messages the way the guard hooks, or None."""
    import importlib

    infra = importlib.import_module(_INFRA)
    reader = getattr(infra, _READER, None)
    if reader is None:
        return f"{_INFRA} has no {_READER}"
    reader = getattr(reader, "__wrapped__", reader)
    if not inspect.iscoroutinefunction(reader) or list(inspect.signature(reader).parameters) != _READER_PARAMETERS:
        return f"{_READER} is no longer a coroutine of ({', '.join(_READER_PARAMETERS)})"
    if not {"recv", "deserialize"} <= set(reader.__code__.co_names):
        return f"{_READER} no longer reads with websocket.recv() and message_class.deserialize()"
    worker = getattr(getattr(infra, "WebsockServer", None), "_background_worker", None)
    if worker is None or not any(_READER in code.co_names for code in _code_objects(worker.__code__)):
        return f"WebsockServer no longer starts {_READER} for each connection"
    ws_server = getattr(server, "_websock_server", None)
    if not isinstance(getattr(ws_server, "_live_connections", None), dict) or not hasattr(
        ws_server, "disconnect_all_clients"
    ):
        return "the websocket layer no longer lists its connections (_live_connections, disconnect_all_clients)"
    if not isinstance(getattr(getattr(server, "gui", None), "_gui_input_handle_from_uuid", None), dict):
        return "the GUI no longer lists its inputs by uuid (_gui_input_handle_from_uuid)"
    return None


def guard_inbound_messages(server, name_of: Callable[[int], str] | None = None) -> InboundGuard:
    """Check every message a browser sends to ``server`` (a ``viser.ViserServer``) before viser
    dispatches it; ``name_of(client_id)`` names a sender in the log. Returns the guard.

    Raises RuntimeError (after stopping the server) when viser no longer reads messages through the
    hook, rather than serve with messages unchecked."""
    import importlib

    import viser

    problem = _why_not_hookable(server)
    if problem is not None:
        server.stop()
        raise RuntimeError(
            f"viser {viser.__version__}: {problem}, so browser messages could not be checked: "
            "refusing to serve (update app/ui/inbound.py)"
        )
    infra = importlib.import_module(_INFRA)
    with _install_lock:
        if not getattr(getattr(infra, _READER), "mcit_checking", False):
            setattr(infra, _READER, _checking(getattr(infra, _READER)))
    guard = _guards[server] = InboundGuard(server, name_of)
    # A browser that connected before the reader was wrapped is read unchecked: close it, and it
    # reconnects (viser's page does) through the checking reader.
    if server._websock_server._live_connections:
        server._websock_server.disconnect_all_clients()
    return guard
