"""What every serial device emulator shares: a clocked event loop, command framing, line timing, faults.

A ``LineEmulator`` runs one thread that executes timed events in order. Bytes written by the
host arrive through a port (``InProcessPort`` or ``PtyPort``) and are framed into commands; a
command is handled when its last byte would have arrived on the real line (bytes × 10 / baud
after its first: one start bit, 7 or 8 data bits, parity or none, one stop bit make 10 bits a
character at 7E1 and 8N1 alike). Replies pass through the ``FaultInjector`` and leave through
the same modelled line: a reply is delivered when its last byte would have been sent, and the
line sends one thing at a time, in order.

Subclasses implement ``handle_command(command, t)`` (run in the emulator's thread at the
command's arrival time ``t``, ``time.monotonic()`` seconds) and ``on_power_up()`` (at start and
after every replug), and answer with ``reply(text, at=t)``.
"""

from __future__ import annotations

import heapq
import itertools
import logging
import math
import os
import threading
import time
from collections.abc import Callable

from ..faults import FaultInjector
from .ports import InProcessPort, PtyPort

__all__ = ["LineEmulator", "Timer"]

log = logging.getLogger("mcit.devices.emulator")

BITS_PER_CHAR = 10


class Timer:
    """Handle of a scheduled event; ``cancel()`` stops it if it has not run yet."""

    __slots__ = ("due", "cancelled")

    def __init__(self, due: float):
        self.due = due
        self.cancelled = False

    def cancel(self) -> None:
        self.cancelled = True


class LineEmulator:
    """Base of the device emulators (see the module docstring).

    baudrate : the modelled line rate (bits/s); 0 or None models an infinitely fast line.
    faults : the FaultInjector applied to replies (one is made when None).
    terminators : bytes that end a command. eol : what ends a reply.
    echo : echo every received byte back (the turret does so until told ``ED``).
    boot_time_s : time from the port appearing (serve, replug) to the device's power-up; input
    before it is lost, as on a device still booting.
    """

    name = "device"
    terminators = b"\r\n"
    eol = b"\r\n"

    def __init__(self, *, baudrate: int | None, faults: FaultInjector | None = None, boot_time_s: float = 0.0):
        if baudrate is not None and baudrate < 0:
            raise ValueError(f"baudrate must be >= 0, got {baudrate}")
        if boot_time_s < 0:
            raise ValueError(f"boot_time_s must be >= 0, got {boot_time_s}")
        self.boot_time_s = float(boot_time_s)
        self.baudrate = int(baudrate or 0)
        self.faults = faults if faults is not None else FaultInjector()
        self.echo = False
        self._heap: list[tuple[float, int, Timer, Callable, tuple]] = []
        self._seq = itertools.count()
        self._cond = threading.Condition()
        self._stopped = False
        self._rx = bytearray()
        self._rx_free = 0.0
        self._tx_free = 0.0
        self._powered = True
        self._port: InProcessPort | PtyPort | None = None
        self.commands_seen: list[str] = []
        self._thread = threading.Thread(target=self._loop, name=f"emulator-{self.name}", daemon=True)
        self._thread.start()

    # ----------------------------------------------------------------------------- ports
    @property
    def char_time_s(self) -> float:
        """Time one character takes on the modelled line."""
        return BITS_PER_CHAR / self.baudrate if self.baudrate else 0.0

    def serve_inprocess(self, name: str | None = None) -> str:
        """Listen as ``mcit://NAME`` (default: a unique name); returns the URL a driver opens."""
        self._need_no_port()
        name = name or f"{self.name}-{os.getpid()}-{id(self):x}"
        self._port = InProcessPort(name, self.receive)
        self._boot()
        return self._port.url

    def serve_pty(self, link_path: str | os.PathLike | None = None) -> str:
        """Listen on a new pseudo-terminal (with a stable symlink when given); returns the path to open."""
        self._need_no_port()
        self._port = PtyPort(self.receive, link_path)
        self._boot()
        return self._port.path

    def _boot(self) -> None:
        self._powered = False
        self.call_later(self.boot_time_s, self._power_up)

    def _need_no_port(self) -> None:
        if self._port is not None:
            raise ValueError(f"{self.name} emulator already serves {self.url}; make another emulator for another port")

    @property
    def port(self) -> InProcessPort | PtyPort | None:
        """The device-side port (None before ``serve_*``)."""
        return self._port

    @property
    def url(self) -> str:
        """What a driver opens (URL or path); empty before ``serve_*``."""
        return "" if self._port is None else self._port.url

    @property
    def plugged(self) -> bool:
        return self._port is not None and self._port.plugged

    def unplug(self, replug_after_s: float = math.inf) -> None:
        """Pull the cable (and power): pending work is lost; replugged by itself after replug_after_s."""
        self.call_later(0.0, self._unplug_now, replug_after_s)

    def replug(self) -> None:
        self.call_later(0.0, self._replug_now)

    def _unplug_now(self, replug_after_s: float) -> None:
        log.info("%s emulator: unplugged", self.name)
        self._powered = False
        with self._cond:
            for item in self._heap:
                item[2].cancel()
        self._rx.clear()
        self.on_power_down()
        if self._port is not None:
            self._port.unplug()
        if math.isfinite(replug_after_s):
            self.call_later(replug_after_s, self._replug_now)

    def _replug_now(self) -> None:
        if self._port is None or self._port.plugged:
            return
        log.info("%s emulator: replugged", self.name)
        self._port.replug()
        self._boot()

    def _power_up(self) -> None:
        self._powered = True
        self._rx.clear()
        now = time.monotonic()
        self._rx_free = self._tx_free = now
        self.on_power_up(now)

    def close(self) -> None:
        """Stop the emulator and remove its port."""
        with self._cond:
            self._stopped = True
            self._cond.notify_all()
        self._thread.join(timeout=2.0)
        if self._port is not None:
            self._port.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # --------------------------------------------------------------------------- events
    def call_at(self, due: float, fn: Callable, *args) -> Timer:
        timer = Timer(due)
        with self._cond:
            heapq.heappush(self._heap, (due, next(self._seq), timer, fn, args))
            self._cond.notify_all()
        return timer

    def call_later(self, delay_s: float, fn: Callable, *args) -> Timer:
        return self.call_at(time.monotonic() + delay_s, fn, *args)

    def _loop(self) -> None:
        while True:
            with self._cond:
                while not self._stopped:
                    if self._heap:
                        wait = self._heap[0][0] - time.monotonic()
                        if wait <= 0:
                            break
                        self._cond.wait(wait)
                    else:
                        self._cond.wait()
                if self._stopped:
                    return
                _, _, timer, fn, args = heapq.heappop(self._heap)
            if timer.cancelled:
                continue
            try:
                fn(*args)
            except Exception:  # an emulator bug must not kill the device silently
                log.exception("%s emulator: event %s failed", self.name, getattr(fn, "__name__", fn))

    # ---------------------------------------------------------------------------- input
    def receive(self, data: bytes) -> None:
        """Bytes from the host (any thread)."""
        self.call_at(time.monotonic(), self._on_bytes, bytes(data), time.monotonic())

    def _on_bytes(self, data: bytes, t_arrival: float) -> None:
        if not self._powered:
            return
        start = max(t_arrival, self._rx_free)
        self._rx_free = start + len(data) * self.char_time_s
        if self.echo:
            self.send_raw(data, at=self._rx_free)
        for k, byte in enumerate(data):
            if byte in self.terminators:
                command = self._rx.decode("latin-1").strip()
                self._rx.clear()
                if command:
                    self.call_at(start + (k + 1) * self.char_time_s, self._dispatch, command)
            else:
                self._rx.append(byte)

    def _dispatch(self, command: str) -> None:
        if not self._powered:
            return
        self.commands_seen.append(command)
        self.handle_command(command, time.monotonic())

    # --------------------------------------------------------------------------- output
    def reply(self, text: str | bytes, at: float | None = None) -> None:
        """Send one reply line (the terminator is added) at time ``at``, through the fault injector."""
        line = (text.encode("latin-1") if isinstance(text, str) else bytes(text)) + self.eol
        delivery = self.faults.process(line)
        if delivery.fault is not None:
            log.info("%s emulator: fault %s on %r", self.name, delivery.fault.kind, line)
        if delivery.unplug:
            self._unplug_now(delivery.replug_after_s)
            return
        cursor = time.monotonic() if at is None else at
        for pause_s, chunk in delivery.chunks:
            cursor = self._transmit(chunk, cursor + pause_s)

    def send_raw(self, data: bytes, at: float | None = None) -> None:
        """Send bytes without faults (echo, power-on banners)."""
        self._transmit(bytes(data), time.monotonic() if at is None else at)

    def _transmit(self, data: bytes, ready: float) -> float:
        start = max(ready, self._tx_free)
        done = start + len(data) * self.char_time_s
        self._tx_free = done
        if data:
            self.call_at(done, self._deliver, data)
        return done

    def _deliver(self, data: bytes) -> None:
        if self._powered and self._port is not None:
            self._port.send(data)

    # ---------------------------------------------------------------------------- hooks
    def handle_command(self, command: str, t: float) -> None:  # pragma: no cover - overridden
        raise NotImplementedError

    def on_power_up(self, t: float) -> None:
        """Called at start and after every replug."""

    def on_power_down(self) -> None:
        """Called at an unplug (pending events are already cancelled)."""
