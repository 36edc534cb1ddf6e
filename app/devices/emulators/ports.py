"""The device side of a serial line: the ports the emulators listen on.

* ``InProcessPort``: an emulator reachable in this process as ``mcit://NAME`` (the URL scheme is
  registered with pyserial through ``serial.protocol_handler_packages`` by
  ``app.devices.drivers.transport``); fast unit tests use it.
* ``PtyPort``: an emulator behind a pseudo-terminal, optionally with a stable symlink
  (e.g. ``/tmp/mcit-turret``) that a driver opens exactly like a real device path.

Both ports can be unplugged and replugged (the path or name vanishes, the host's open port fails),
and deliver bytes as soon as the emulator sends them: line timing is the emulator's job
(``app.devices.emulators.line``).
"""

from __future__ import annotations

import os
import select
import threading
import time
import tty
from collections.abc import Callable
from pathlib import Path

import serial

__all__ = ["URL_SCHEME", "InProcessPort", "PtyPort", "inprocess_port"]

URL_SCHEME = "mcit"

# --------------------------------------------------------------------------------- device side
_INPROCESS: dict[str, InProcessPort] = {}
_INPROCESS_LOCK = threading.Lock()


def inprocess_port(name: str) -> InProcessPort:
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
