"""Serial plumbing shared by the drivers and the emulators.

Host side (the drivers):

* ``SerialLine``: a port opened with ``serial.serial_for_url`` (a device path, a pseudo-terminal,
  ``socket://host:port`` or ``mcit://NAME``), read as text lines before a deadline. Every failure
  of the port (``SerialException``, ``OSError``, ``termios.error`` — the last is not an OSError)
  becomes ``DeviceDisconnected``.
* ``LineDriver``: the request/retry policy both drivers follow: a deadline on every call;
  retries only for idempotent operations; after a timeout or a malformed reply, resynchronise
  (flush stale replies) before retrying; after an unplug, reopen with back-off and redo the
  handshake.

Device side (the emulators):

* ``InProcessPort``: an emulator reachable in this process as ``mcit://NAME`` (the URL scheme is
  registered with pyserial through ``serial.protocol_handler_packages``); fast unit tests use it.
* ``PtyPort``: an emulator behind a pseudo-terminal, optionally with a stable symlink
  (e.g. ``/tmp/mcit-turret``) that a driver opens exactly like a real device path.

Both device ports can be unplugged and replugged (the path or name vanishes, the host's open
port fails), and deliver bytes as soon as the emulator sends them: line timing is the emulator's
job (``app.devices.line_emulator``).
"""

from __future__ import annotations

import logging
import os
import select
import termios
import threading
import time
import tty
from collections import Counter
from pathlib import Path
from typing import Callable, TypeVar

import numpy as np
import serial

from .errors import DeviceDisconnected, DeviceError, DeviceTimeout, MotionUnconfirmedError, ProtocolError

__all__ = [
    "PORT_ERRORS",
    "SerialLine",
    "LineDriver",
    "NOISE",
    "InProcessPort",
    "PtyPort",
    "inprocess_port",
    "deadline_after",
]

log = logging.getLogger("mcit.devices")

# What a vanished port raises: pyserial's own exception, the OS's, and termios.error (not an OSError).
PORT_ERRORS = (serial.SerialException, OSError, termios.error)

URL_SCHEME = "mcit"
_HANDLER_PACKAGE = "app.devices.urlhandler"
if _HANDLER_PACKAGE not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(_HANDLER_PACKAGE)

T = TypeVar("T")


def deadline_after(timeout_s: float | None, name: str = "timeout_s") -> float | None:
    """The monotonic deadline timeout_s seconds from now (None: none); ValueError for NaN or a negative time."""
    if timeout_s is None:
        return None
    if isinstance(timeout_s, bool) or not isinstance(timeout_s, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number of seconds or None, got {timeout_s!r}")
    v = float(timeout_s)
    if v != v or v < 0:
        raise ValueError(f"{name} must be a number of seconds >= 0 or None, got {timeout_s!r}")
    return time.monotonic() + v


class _Noise:
    """Marker a reply parser returns for a line that is not the reply it waits for."""

    def __repr__(self) -> str:
        return "NOISE"


NOISE = _Noise()


# ----------------------------------------------------------------------------------- host side
class SerialLine:
    """One serial port, read as lines of text (latin-1, CR and LF both end a line, empty lines skipped).

    url : a device path, a pty, ``socket://host:port`` or ``mcit://NAME`` (opened with
        ``serial.serial_for_url``). device : name used in error messages.
    baudrate, bytesize, parity, stopbits : the line settings (pseudo-terminals ignore them).
    poll_s : how long one blocking read waits; bounds how late a deadline is noticed.
    """

    def __init__(
        self,
        url: str,
        *,
        device: str,
        baudrate: int = 9600,
        bytesize: int = 8,
        parity: str = "N",
        stopbits: float = 1,
        poll_s: float = 0.01,
    ):
        if not isinstance(url, str) or not url:
            raise ValueError(f"a port URL or device path is required, got {url!r}")
        self.url = url
        self.device = device
        self._settings = dict(baudrate=int(baudrate), bytesize=int(bytesize), parity=parity, stopbits=stopbits)
        self._poll_s = float(poll_s)
        self._port: serial.SerialBase | None = None
        self._buffer = bytearray()

    @property
    def is_open(self) -> bool:
        return self._port is not None

    @property
    def baudrate(self) -> int:
        return self._settings["baudrate"]

    def open(self) -> None:
        """Open the port once; DeviceDisconnected when it cannot be opened now."""
        self.close()
        try:
            self._port = serial.serial_for_url(self.url, timeout=self._poll_s, write_timeout=1.0, **self._settings)
        except PORT_ERRORS as exc:
            self._port = None
            raise DeviceDisconnected(f"{self.device}: cannot open {self.url}: {exc}", device=self.device) from exc
        self._buffer.clear()

    def open_with_backoff(self, deadline: float, first_wait_s: float = 0.02, max_wait_s: float = 0.5) -> int:
        """Open the port, retrying with exponential back-off until the deadline; returns the tries used."""
        wait = first_wait_s
        tries = 0
        while True:
            tries += 1
            try:
                self.open()
                return tries
            except DeviceDisconnected:
                now = time.monotonic()
                if now + wait > deadline:
                    raise DeviceDisconnected(
                        f"{self.device}: {self.url} could not be opened in {tries} tries before the deadline "
                        "(unplugged? wrong path? is the emulator running?)",
                        device=self.device,
                    ) from None
                time.sleep(wait)
                wait = min(2 * wait, max_wait_s)

    def close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except PORT_ERRORS:
                pass

    def _lost(self, exc: BaseException, doing: str) -> DeviceDisconnected:
        self.close()
        return DeviceDisconnected(f"{self.device}: port {self.url} failed while {doing}: {exc}", device=self.device)

    def write(self, data: bytes) -> None:
        if self._port is None:
            raise DeviceDisconnected(f"{self.device}: port {self.url} is not open", device=self.device)
        try:
            self._port.write(data)
        except PORT_ERRORS as exc:
            raise self._lost(exc, f"writing {data!r}") from exc

    def discard_input(self) -> None:
        """Forget every byte received so far (stale replies)."""
        self._buffer.clear()
        if self._port is None:
            return
        try:
            self._port.reset_input_buffer()
        except PORT_ERRORS as exc:
            raise self._lost(exc, "flushing input") from exc

    def _take_line(self) -> str | None:
        while True:
            cut = [i for i in (self._buffer.find(b"\r"), self._buffer.find(b"\n")) if i >= 0]
            if not cut:
                return None
            i = min(cut)
            raw = bytes(self._buffer[:i])
            del self._buffer[: i + 1]
            if raw:
                return raw.decode("latin-1")

    def read_line(self, deadline: float) -> str | None:
        """The next non-empty line (without its terminator), or None when the deadline passes first."""
        while True:
            line = self._take_line()
            if line is not None:
                return line
            if time.monotonic() >= deadline:
                return None
            if self._port is None:
                raise DeviceDisconnected(f"{self.device}: port {self.url} is not open", device=self.device)
            try:
                chunk = self._port.read(max(1, self._port.in_waiting))
            except PORT_ERRORS as exc:
                raise self._lost(exc, "reading") from exc
            except (TypeError, ValueError) as exc:  # the fd vanished under a blocking read
                raise self._lost(exc, "reading") from exc
            self._buffer += chunk

    def pending_text(self) -> str:
        """Bytes received but not yet ending a line (for diagnostics)."""
        return bytes(self._buffer).decode("latin-1")


class LineDriver:
    """Request/reply over a ``SerialLine`` with deadlines, retries, resynchronisation and reconnection.

    Subclasses implement ``_handshake(deadline)`` (after every (re)open) and ``_resync(deadline)``
    (consume stale replies so the next reply read is the next command's).

    attempt_timeout_s : deadline of one attempt (one command and its reply).
    retries : further attempts of an idempotent operation after a timeout, a malformed reply or
        an unplug. Non-idempotent operations (relative moves) are tried once.
    reconnect_timeout_s : how long to keep reopening a vanished port (with back-off).
    ``stats`` counts what happened (attempts, timeouts, corrupt, resyncs, reconnects, noise).
    """

    device = "device"

    def __init__(
        self,
        url: str,
        *,
        baudrate: int,
        bytesize: int = 8,
        parity: str = "N",
        stopbits: float = 1,
        attempt_timeout_s: float = 1.0,
        retries: int = 2,
        reconnect_timeout_s: float = 5.0,
    ):
        if not (attempt_timeout_s > 0 and reconnect_timeout_s >= 0):  # NaN fails too
            raise ValueError(
                f"timeouts must be positive, got attempt_timeout_s={attempt_timeout_s}, reconnect_timeout_s={reconnect_timeout_s}"
            )
        if int(retries) < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self._line = SerialLine(url, device=self.device, baudrate=baudrate, bytesize=bytesize, parity=parity, stopbits=stopbits)
        self.attempt_timeout_s = float(attempt_timeout_s)
        self.retries = int(retries)
        self.reconnect_timeout_s = float(reconnect_timeout_s)
        self.stats: Counter = Counter()
        self._lock = threading.RLock()
        self._call_deadline = float("inf")  # the deadline of the call under way (set by _transact)

    # -- life cycle
    @property
    def url(self) -> str:
        return self._line.url

    @property
    def is_connected(self) -> bool:
        return self._line.is_open

    def connect(self, timeout_s: float | None = None) -> None:
        """Open the port (retrying with back-off) and run the handshake, within timeout_s."""
        with self._lock:
            deadline = time.monotonic() + (self.reconnect_timeout_s + 2 * self.attempt_timeout_s if timeout_s is None else timeout_s)
            self._line.open_with_backoff(deadline)
            self._transact(self._handshake, what="handshake", idempotent=True, deadline=deadline, reopen=False)

    def close(self) -> None:
        with self._lock:
            self._line.close()

    def __enter__(self):
        if not self.is_connected:
            self.connect()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # -- hooks
    def _handshake(self, deadline: float) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def _resync(self, deadline: float) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    # -- requests
    def _default_deadline(self, attempts: int) -> float:
        return time.monotonic() + attempts * self.attempt_timeout_s + self.reconnect_timeout_s

    def _request(self, command: str, parse: Callable[[str], T], deadline: float, terminator: str) -> T:
        """Send one command and return ``parse`` of the first line it does not call NOISE.

        ``parse`` raises ProtocolError for a malformed reply and a DeviceError for a device error.
        """
        self._line.discard_input()
        self._line.write((command + terminator).encode("latin-1"))
        while True:
            line = self._line.read_line(deadline)
            if line is None:
                self.stats["timeouts"] += 1
                partial = self._line.pending_text()
                raise DeviceTimeout(
                    f"{self.device}: no valid reply to {command!r} in time"
                    + (f" (received only {partial!r})" if partial else ""),
                    device=self.device,
                    command=command,
                )
            result = parse(line)
            if result is NOISE:
                self.stats["noise"] += 1
                log.debug("%s: skipped %r while waiting for the reply to %r", self.device, line, command)
                continue
            return result

    def _reopen(self, deadline: float) -> None:
        self.stats["reconnects"] += 1
        log.warning("%s: port %s lost; reconnecting", self.device, self.url)
        self._line.open_with_backoff(deadline)
        self._handshake(min(deadline, time.monotonic() + self.attempt_timeout_s))

    def _transact(
        self,
        op: Callable[[float], T],
        *,
        what: str,
        idempotent: bool,
        deadline: float | None = None,
        attempts: int | None = None,
        reopen: bool = True,
    ) -> T:
        """Run ``op(attempt_deadline)`` under the retry policy (see the class docstring)."""
        with self._lock:
            attempts = (self.retries + 1 if idempotent else 1) if attempts is None else attempts
            if deadline is None:
                deadline = self._default_deadline(attempts)
            outer, self._call_deadline = self._call_deadline, min(self._call_deadline, deadline)
            try:
                return self._attempts(op, what, idempotent, deadline, attempts, reopen)
            finally:
                self._call_deadline = outer

    def _attempts(self, op, what: str, idempotent: bool, deadline: float, attempts: int, reopen: bool):
        """The attempts of ``_transact`` (under its lock)."""
        last: DeviceError | None = None
        for attempt in range(attempts):
            now = time.monotonic()
            if now >= deadline:
                break
            try:
                if reopen and not self._line.is_open:
                    self._reopen(min(deadline, now + self.reconnect_timeout_s))
                self.stats["attempts"] += 1
                return op(min(deadline, time.monotonic() + self.attempt_timeout_s))
            except DeviceDisconnected as exc:
                last = exc
                if not reopen:
                    raise
                try:
                    self._reopen(min(deadline, time.monotonic() + self.reconnect_timeout_s))
                except DeviceDisconnected:
                    raise
                except (DeviceTimeout, ProtocolError) as hs_exc:
                    last = hs_exc
                    self._line.close()  # redo the whole reopen at the next attempt
                if not idempotent:
                    raise MotionUnconfirmedError(
                        f"{self.device}: the port was lost during {what}; it was reconnected, but whether the "
                        "command took effect is unknown and it is not retried: query the state first",
                        device=self.device,
                    ) from exc
            except (DeviceTimeout, ProtocolError) as exc:
                last = exc
                if isinstance(exc, ProtocolError):
                    self.stats["corrupt"] += 1
                if not idempotent:
                    raise MotionUnconfirmedError(
                        f"{self.device}: {what} was sent but not confirmed ({exc}); it is not retried "
                        "because it may already have happened: query the state first",
                        device=self.device,
                    ) from exc
                if attempt + 1 < attempts:
                    self._try_resync(deadline)
        if last is None:
            raise DeviceTimeout(f"{self.device}: no time left for {what} (deadline already passed)", device=self.device)
        kind = type(last)
        raise kind(f"{last} — gave up on {what} after {attempt + 1} attempt(s)", device=self.device, command=last.command) from last

    def _step(self, fn: Callable[[float], T], timeout_s: float | None = None) -> T:
        """One idempotent step of a longer operation (a query, an absolute set-point), retried on its own.

        ``fn(deadline)`` is retried after a timeout or a malformed reply, with a resynchronisation
        in between, up to ``retries`` times, within the deadline of the call under way; an unplug
        goes up to ``_transact``, which reconnects and restarts the whole operation.
        """
        timeout_s = self.attempt_timeout_s if timeout_s is None else timeout_s
        last: DeviceError | None = None
        for attempt in range(self.retries + 1):
            now = time.monotonic()
            if now >= self._call_deadline:
                break
            try:
                return fn(min(self._call_deadline, now + timeout_s))
            except (DeviceTimeout, ProtocolError) as exc:
                last = exc
                if isinstance(exc, ProtocolError):
                    self.stats["corrupt"] += 1
                if attempt < self.retries:
                    self._try_resync(self._call_deadline)
        if last is None:
            raise DeviceTimeout(f"{self.device}: the call's deadline passed", device=self.device)
        raise last

    def _try_resync(self, deadline: float) -> None:
        self.stats["resyncs"] += 1
        try:
            self._resync(min(deadline, time.monotonic() + self.attempt_timeout_s))
        except DeviceDisconnected:
            pass  # the next attempt reopens the port
        except (DeviceTimeout, ProtocolError) as exc:
            log.warning("%s: resynchronisation failed (%s); retrying anyway", self.device, exc)


# --------------------------------------------------------------------------------- device side
_INPROCESS: dict[str, "InProcessPort"] = {}
_INPROCESS_LOCK = threading.Lock()


def inprocess_port(name: str) -> "InProcessPort":
    """The registered in-process port called ``name``; serial.SerialException when there is none."""
    with _INPROCESS_LOCK:
        port = _INPROCESS.get(name)
    if port is None:
        raise serial.SerialException(f"no in-process device named {name!r} (known: {sorted(_INPROCESS)})")
    return port


class InProcessPort:
    """An emulator's end of an in-process serial link, opened by a driver as ``mcit://NAME``.

    on_receive(data: bytes) is called (in the host's thread) with every byte string the host
    writes; it must return quickly. ``send`` delivers bytes to the host at once.
    """

    def __init__(self, name: str, on_receive: Callable[[bytes], None]):
        if not name or "/" in name:
            raise ValueError(f"an in-process port name is a non-empty word without '/', got {name!r}")
        self.name = name
        self._on_receive = on_receive
        self._cond = threading.Condition()
        self._to_host = bytearray()
        self._plugged = True
        self._generation = 0
        with _INPROCESS_LOCK:
            if name in _INPROCESS:
                raise ValueError(f"an in-process device named {name!r} already exists; close it or pick another name")
            _INPROCESS[name] = self

    @property
    def url(self) -> str:
        return f"{URL_SCHEME}://{self.name}"

    @property
    def plugged(self) -> bool:
        return self._plugged

    def send(self, data: bytes) -> None:
        with self._cond:
            if self._plugged:
                self._to_host += data
                self._cond.notify_all()

    def unplug(self) -> None:
        """The device vanishes: the host's open port fails, opening it fails until ``replug``."""
        with self._cond:
            self._plugged = False
            self._generation += 1
            self._to_host.clear()
            self._cond.notify_all()

    def replug(self) -> None:
        with self._cond:
            self._plugged = True
            self._cond.notify_all()

    def close(self) -> None:
        self.unplug()
        with _INPROCESS_LOCK:
            if _INPROCESS.get(self.name) is self:
                del _INPROCESS[self.name]

    # -- host side (used by app/devices/urlhandler/protocol_mcit.py)
    def host_open(self) -> int:
        with self._cond:
            if not self._plugged:
                raise serial.SerialException(f"could not open port {self.url}: device unplugged")
            self._generation += 1
            self._to_host.clear()
            return self._generation

    def _check(self, generation: int) -> None:
        if not self._plugged or generation != self._generation:
            raise serial.SerialException(f"{self.url}: device disconnected")

    def host_write(self, generation: int, data: bytes) -> None:
        with self._cond:
            self._check(generation)
        self._on_receive(bytes(data))

    def host_read(self, generation: int, size: int, timeout_s: float | None) -> bytes:
        """Up to ``size`` bytes: returns when it has them all or the timeout passes (pyserial's read)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        out = bytearray()
        with self._cond:
            while True:
                self._check(generation)
                if self._to_host:
                    take = size - len(out)
                    out += self._to_host[:take]
                    del self._to_host[:take]
                    if len(out) >= size:
                        return bytes(out)
                remaining = None if deadline is None else deadline - time.monotonic()
                if remaining is not None and remaining <= 0:
                    return bytes(out)
                self._cond.wait(remaining)

    def host_in_waiting(self, generation: int) -> int:
        with self._cond:
            self._check(generation)
            return len(self._to_host)

    def host_reset_input(self, generation: int) -> None:
        with self._cond:
            self._check(generation)
            self._to_host.clear()


class PtyPort:
    """An emulator's end of a pseudo-terminal; the host opens ``path`` (the stable link, if any).

    on_receive(data: bytes) is called from a reader thread with the bytes the host writes.
    link_path : optional symlink made to point at the pty's slave (replaced atomically on replug);
    an existing file there that is not a symlink is refused.
    """

    def __init__(self, on_receive: Callable[[bytes], None], link_path: str | os.PathLike | None = None):
        self._on_receive = on_receive
        self.link_path = None if link_path is None else Path(link_path)
        if self.link_path is not None and self.link_path.exists() and not self.link_path.is_symlink():
            raise ValueError(f"{self.link_path} exists and is not a symlink; choose another link path")
        self._lock = threading.Lock()
        self._master: int | None = None
        self._slave: int | None = None
        self._slave_name = ""
        self._closed = False
        self._plug()
        self._thread = threading.Thread(target=self._read_loop, name=f"pty-{self._slave_name}", daemon=True)
        self._thread.start()

    @property
    def path(self) -> str:
        """What a driver opens: the link when there is one, else the pty's slave device."""
        return str(self.link_path) if self.link_path is not None else self._slave_name

    url = path

    @property
    def device(self) -> str:
        """The pty's slave device (``/dev/pts/N``); it changes at every replug, the link does not."""
        return self._slave_name

    @property
    def plugged(self) -> bool:
        return self._master is not None

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # at once, or the pty echoes the emulator's own output back to it
        name = os.ttyname(slave)
        with self._lock:
            self._master, self._slave, self._slave_name = master, slave, name
        if self.link_path is not None:
            tmp = self.link_path.with_name(f".{self.link_path.name}.{os.getpid()}.tmp")
            if tmp.is_symlink() or tmp.exists():
                tmp.unlink()
            os.symlink(name, tmp)
            os.replace(tmp, self.link_path)

    def send(self, data: bytes) -> None:
        with self._lock:
            fd = self._master
        if fd is None:
            return
        try:
            view = memoryview(data)
            while view:
                n = os.write(fd, view)
                view = view[n:]
        except OSError:
            pass  # unplugged meanwhile: the bytes are lost, as on a real line

    def unplug(self) -> None:
        """The device vanishes: the link is removed and the host's open port fails (EIO)."""
        with self._lock:
            fds = (self._master, self._slave)
            self._master = self._slave = None
        if self.link_path is not None and self.link_path.is_symlink():
            self.link_path.unlink()
        for fd in fds:
            if fd is not None:
                try:
                    os.close(fd)
                except OSError:
                    pass

    def replug(self) -> None:
        if self._master is None and not self._closed:
            self._plug()

    def close(self) -> None:
        self._closed = True
        self.unplug()
        self._thread.join(timeout=1.0)

    def _read_loop(self) -> None:
        while not self._closed:
            with self._lock:
                fd = self._master
            if fd is None:
                time.sleep(0.01)
                continue
            try:
                ready, _, _ = select.select([fd], [], [], 0.05)
                if not ready:
                    continue
                data = os.read(fd, 4096)
            except (OSError, ValueError):
                time.sleep(0.01)  # closed by unplug; wait for a replug
                continue
            if data:
                self._on_receive(data)
