"""pyserial handler for ``mcit://NAME``: a serial port whose other end is an in-process emulator.

``serial.serial_for_url("mcit://NAME")`` finds this module through
``serial.protocol_handler_packages`` (``app.devices.drivers.transport`` registers the package) and
connects to the ``InProcessPort`` registered under NAME. Line settings are accepted and ignored,
as on a pseudo-terminal; the emulator models the line's transfer time itself.
"""

from __future__ import annotations

import urllib.parse

from serial.serialutil import PortNotOpenError, SerialBase, SerialException, to_bytes

from app.devices.emulators.ports import URL_SCHEME, inprocess_port


class Serial(SerialBase):
    """Host end of an in-process serial link (see the module docstring)."""

    def open(self) -> None:
        if self.is_open:
            raise SerialException("port is already open")
        if self._port is None:
            raise SerialException("port must be configured before it can be used")
        parts = urllib.parse.urlsplit(self._port)
        if parts.scheme != URL_SCHEME or not parts.netloc:
            raise SerialException(f"expected {URL_SCHEME}://NAME, got {self._port!r}")
        self._device = inprocess_port(parts.netloc)
        self._generation = self._device.host_open()
        self.is_open = True

    def close(self) -> None:
        self.is_open = False

    def _reconfigure_port(self, *args, **kwargs) -> None:
        """Line settings mean nothing in process (the emulator models timing)."""

    def _need_open(self) -> None:
        if not self.is_open:
            raise PortNotOpenError()

    @property
    def in_waiting(self) -> int:
        self._need_open()
        return self._device.host_in_waiting(self._generation)

    def read(self, size: int = 1) -> bytes:
        self._need_open()
        return self._device.host_read(self._generation, size, self._timeout)

    def write(self, data) -> int:
        self._need_open()
        data = to_bytes(data)
        self._device.host_write(self._generation, data)
        return len(data)

    def reset_input_buffer(self) -> None:
        self._need_open()
        self._device.host_reset_input(self._generation)

    def reset_output_buffer(self) -> None:
        self._need_open()

    def flush(self) -> None:
        self._need_open()

    def _update_break_state(self) -> None:
        pass

    def _update_rts_state(self) -> None:
        pass

    def _update_dtr_state(self) -> None:
        pass

    @property
    def cts(self) -> bool:
        return True

    @property
    def dsr(self) -> bool:
        return True

    @property
    def ri(self) -> bool:
        return False

    @property
    def cd(self) -> bool:
        return True
