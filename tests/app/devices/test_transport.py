"""Transports: the in-process mcit:// scheme, pseudo-terminals with stable links, line reading, unplugs."""

import os
import time
import uuid

import pytest
import serial

from app.devices.drivers.errors import DeviceDisconnected
from app.devices.drivers.transport import SerialLine
from app.devices.emulators.ports import InProcessPort, PtyPort


def unique(prefix="t"):
    return f"{prefix}-{uuid.uuid4().hex[:8]}"


@pytest.fixture
def upper_port():
    """An in-process device that answers every write with its upper-case copy."""
    box = {}
    port = InProcessPort(unique(), lambda data: box["port"].send(data.upper()))
    box["port"] = port
    yield port
    port.close()


def test_inprocess_scheme_round_trip_through_serial_for_url(upper_port):
    ser = serial.serial_for_url(upper_port.url, baudrate=19200, timeout=0.5)
    ser.write(b"abc\r\n")
    assert ser.read(5) == b"ABC\r\n"
    assert ser.read(1) == b""  # timeout, nothing more
    ser.close()


def test_inprocess_unknown_name_and_unplug_raise_serial_exceptions(upper_port):
    with pytest.raises(serial.SerialException, match="no in-process device"):
        serial.serial_for_url("mcit://nobody-here", timeout=0.1)
    ser = serial.serial_for_url(upper_port.url, timeout=0.1)
    upper_port.unplug()
    with pytest.raises(serial.SerialException):
        ser.read(1)
    with pytest.raises(serial.SerialException, match="unplugged"):
        serial.serial_for_url(upper_port.url, timeout=0.1)
    upper_port.replug()
    with pytest.raises(serial.SerialException):  # the old handle stays dead after a replug
        ser.write(b"x")
    fresh = serial.serial_for_url(upper_port.url, timeout=0.5)
    fresh.write(b"ok\n")
    assert fresh.read(3) == b"OK\n"


def test_duplicate_inprocess_names_are_refused(upper_port):
    with pytest.raises(ValueError, match="already exists"):
        InProcessPort(upper_port.name, lambda d: None)


def test_serial_line_frames_cr_lf_and_crlf_and_skips_empty_lines(upper_port):
    line = SerialLine(upper_port.url, device="test")
    line.open()
    line.write(b"one\r\ntwo\n\r\nthree\rfour")
    deadline = time.monotonic() + 0.5
    assert [line.read_line(deadline) for _ in range(3)] == ["ONE", "TWO", "THREE"]
    t0 = time.monotonic()
    assert line.read_line(time.monotonic() + 0.1) is None  # "FOUR" has no terminator yet
    assert 0.09 <= time.monotonic() - t0 < 1.0
    assert line.pending_text() == "FOUR"
    line.discard_input()
    line.write(b"five\r\n")
    assert line.read_line(time.monotonic() + 0.5) == "FIVE"


def test_serial_line_joins_a_reply_split_across_reads():
    port = InProcessPort(unique(), lambda d: None)
    try:
        line = SerialLine(port.url, device="test")
        line.open()
        port.send(b"g0g+000")
        assert line.read_line(time.monotonic() + 0.05) is None
        port.send(b"12345\r\n")
        assert line.read_line(time.monotonic() + 0.5) == "g0g+00012345"
    finally:
        port.close()


def test_serial_line_turns_an_unplug_into_device_disconnected(upper_port):
    line = SerialLine(upper_port.url, device="test")
    line.open()
    upper_port.unplug()
    with pytest.raises(DeviceDisconnected, match="failed while reading"):
        line.read_line(time.monotonic() + 0.5)
    assert not line.is_open
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="could not be opened"):
        line.open_with_backoff(time.monotonic() + 0.2)
    assert time.monotonic() - t0 < 1.0
    upper_port.replug()
    assert line.open_with_backoff(time.monotonic() + 1.0) >= 1


def test_pty_with_stable_link_round_trip_unplug_and_replug(tmp_path):
    box = {}
    link = tmp_path / "dev-link"
    port = PtyPort(lambda data: box["port"].send(data[::-1]), link)
    box["port"] = port
    try:
        first_device = os.path.realpath(link)
        assert link.is_symlink() and first_device == port.device and port.path == str(link)
        line = SerialLine(str(link), device="pty", baudrate=19200, bytesize=7, parity="E")
        line.open()
        line.write(b"\ncba")
        assert line.read_line(time.monotonic() + 1.0) == "abc"
        port.unplug()
        assert not link.exists()
        with pytest.raises(DeviceDisconnected):
            line.write(b"x\n")
            line.read_line(time.monotonic() + 1.0)
        port.replug()
        assert link.is_symlink()
        line.open_with_backoff(time.monotonic() + 1.0)
        line.write(b"\nzyx")
        assert line.read_line(time.monotonic() + 1.0) == "xyz"
    finally:
        port.close()
    assert not link.exists()


def test_pty_refuses_to_replace_a_real_file(tmp_path):
    f = tmp_path / "taken"
    f.write_text("not a link")
    with pytest.raises(ValueError, match="not a symlink"):
        PtyPort(lambda d: None, f)
