"""Serial plumbing of the drivers (the host side of a serial line).

* ``SerialLine``: a port opened with ``serial.serial_for_url`` (a device path, a pseudo-terminal,
  ``socket://host:port`` or ``mcit://NAME``), read as text lines before a deadline. Every failure
  of the port (``SerialException``, ``OSError``, ``termios.error`` — the last is not an OSError)
  becomes ``DeviceDisconnected``.
* ``LineDriver``: the request/retry policy both drivers follow: a deadline on every call;
  retries only for idempotent operations; after a timeout or a malformed reply, resynchronise
  (flush stale replies) before retrying; after an unplug, reopen with back-off and redo the
  handshake.

The device side (the emulators' ports, ``mcit://NAME`` in process or a pseudo-terminal) is
``app.devices.emulators.ports``; the ``mcit://`` scheme's pyserial handler is registered here, so
that a driver opens an in-process emulator like any other port.
"""

from __future__ import annotations

import logging
import termios
import threading
import time
from collections import Counter
from collections.abc import Callable
from typing import TypeVar

import numpy as np
import serial

from .errors import (
    DeviceDisconnected,
    DeviceError,
    DeviceTimeout,
    MotionUnconfirmedError,
    NoisyLineError,
    ProtocolError,
)

__all__ = [
    "PORT_ERRORS",
    "SerialLine",
    "LineDriver",
    "NOISE",
    "clip",
    "deadline_after",
]

log = logging.getLogger("mcit.devices")

# What a vanished port raises: pyserial's own exception, the OS's, and termios.error (not an OSError).
PORT_ERRORS = (serial.SerialException, OSError, termios.error)

_HANDLER_PACKAGE = "app.devices.emulators.urlhandler"  # pyserial's handler of mcit:// (in-process emulators)
if _HANDLER_PACKAGE not in serial.protocol_handler_packages:
    serial.protocol_handler_packages.append(_HANDLER_PACKAGE)

T = TypeVar("T")

CLIP_BYTES = 200  # received data quoted in a message or a log line is cut to this
MAX_LINE_BYTES = 1024  # a line longer than this without an end is garbage: all but its tail is dropped
KEEP_TAIL_BYTES = 256  # the tail kept, where a reply behind the garbage may be starting


def clip(data: str | bytes, limit: int = CLIP_BYTES) -> str:
    """Received data as a quoted string of at most ``limit`` characters (and how long it really was)."""
    text = data.decode("latin-1") if isinstance(data, (bytes, bytearray)) else str(data)
    if len(text) <= limit:
        return repr(text)
    return f"{text[:limit]!r}… ({len(text)} bytes)"


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
        self.dropped_bytes = 0  # bytes of over-long lines thrown away (garbage), since opened

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
            if len(self._buffer) > MAX_LINE_BYTES and b"\r" not in self._buffer and b"\n" not in self._buffer:
                drop = len(self._buffer) - KEEP_TAIL_BYTES  # an endless line is garbage; keep its tail only
                del self._buffer[:drop]
                self.dropped_bytes += drop

    def read_line_soon(self, end: float) -> str | None:
        """The next line if one completes before ``end`` (a short listen: polls every 0.5 ms rather
        than blocking a whole poll period), else None."""
        while True:
            line = self._take_line()
            if line is not None:
                return line
            if self._port is None:
                raise DeviceDisconnected(f"{self.device}: port {self.url} is not open", device=self.device)
            try:
                n = self._port.in_waiting
                if n:
                    self._buffer += self._port.read(n)
                    continue
            except PORT_ERRORS as exc:
                raise self._lost(exc, "reading") from exc
            except (TypeError, ValueError) as exc:  # the fd vanished under the read
                raise self._lost(exc, "reading") from exc
            if time.monotonic() >= end:
                return None
            time.sleep(0.0005)

    def pending_text(self) -> str:
        """Bytes received but not yet ending a line (for diagnostics; at most MAX_LINE_BYTES)."""
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
    display_name = "device"  # how messages name it ("the range finder's line is noisy")

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
                f"timeouts must be positive, got attempt_timeout_s={attempt_timeout_s}, "
                f"reconnect_timeout_s={reconnect_timeout_s}"
            )
        if int(retries) < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self._line = SerialLine(
            url, device=self.device, baudrate=baudrate, bytesize=bytesize, parity=parity, stopbits=stopbits
        )
        self.attempt_timeout_s = float(attempt_timeout_s)
        self.retries = int(retries)
        self.reconnect_timeout_s = float(reconnect_timeout_s)
        self.stats: Counter = Counter()
        self._noise = [0, 0, ""]  # during the call under way: garbage lines, their bytes, the last one
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
            deadline = time.monotonic() + (
                self.reconnect_timeout_s + 2 * self.attempt_timeout_s if timeout_s is None else timeout_s
            )
            self._line.open_with_backoff(deadline)
            self._noise = [0, 0, ""]
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

    def _is_garbage(self, line: str) -> bool:
        """Whether a line that is not the awaited reply is garbage rather than one of the device's own
        (a stale reply, an unsolicited line). Overridden by each driver; everything is garbage here."""
        return True

    def _garbage(self, line: str) -> None:
        self.stats["garbage"] += 1
        self._noise[0] += 1
        self._noise[1] += len(line)
        self._noise[2] = line

    def _noisy(self, what: str, last: DeviceError) -> NoisyLineError | None:
        """The error to raise instead of ``last`` when the call saw garbage: the line is noisy."""
        lines, nbytes, sample = self._noise
        dropped = self._line.dropped_bytes
        # Bytes still waiting for a line end count when no reply could be like them: a byte no
        # device sends, or more than any reply holds (a slow reply cut by the deadline does not count).
        partial = self._line.pending_text()
        if not (len(partial) > 64 or any(not 32 <= ord(ch) < 127 for ch in partial.strip("\r\n"))):
            partial = ""
        if not (lines or dropped or partial):
            return None
        got = (
            f"{lines} unreadable line(s), {nbytes + dropped} bytes"
            if lines
            else f"{dropped + len(partial)} bytes without a line end"
        )
        return NoisyLineError(
            f"the {self.display_name}'s line is noisy ({got} during {what}"
            + (f", the last {clip(sample, 40)}" if lines else "")
            + "): check the cable and the baud rate",
            device=self.device,
            command=last.command,
        )

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
                    + (f" (received only {clip(partial)})" if partial else ""),
                    device=self.device,
                    command=command,
                )
            try:
                result = parse(line)
            except ProtocolError:
                self._garbage(line)
                raise
            if result is NOISE:
                self.stats["noise"] += 1
                if self._is_garbage(line):
                    self._garbage(line)
                log.debug("%s: skipped %s while waiting for the reply to %r", self.device, clip(line), command)
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
            if outer == float("inf"):  # the outermost call: count its garbage afresh
                self._noise = [0, 0, ""]
                self._line.dropped_bytes = 0
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
        if isinstance(last, (DeviceTimeout, ProtocolError)) and not isinstance(last, NoisyLineError):
            noisy = self._noisy(what, last)
            if noisy is not None:
                raise noisy from last
        if isinstance(last, NoisyLineError):
            raise last
        kind = type(last)
        raise kind(
            f"{last} — gave up on {what} after {attempt + 1} attempt(s)", device=self.device, command=last.command
        ) from last

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
            log.warning("%s: resynchronisation failed (%s); retrying anyway", self.device, clip(str(exc)))
