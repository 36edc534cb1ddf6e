"""The PTU-D46 turret emulator, byte for byte: echo, feedback modes, motion at speed, limits, A, R."""

import time

import pytest

from app.devices.drivers.transport import SerialLine
from app.devices.emulators.turret import MountState, TurretEmulator

from .conftest import exact_scene


@pytest.fixture
def emulator(workcell):
    made = []

    def make(baudrate=0, speed_steps_s=4000.0):
        spec = exact_scene(workcell, speed_steps_s=speed_steps_s).turret
        emu = TurretEmulator(spec, baudrate=baudrate)
        made.append(emu)
        line = SerialLine(emu.serve_inprocess(), device="turret")
        line.open()
        return emu, line

    yield make
    for emu in made:
        emu.close()


def ask(line, command, timeout=1.0):
    line.write(command.encode() + b" ")
    return line.read_line(time.monotonic() + timeout)


def terse(line):
    assert ask(line, "ED") == "ED *"  # echo is on at power-up: the command comes back first
    assert ask(line, "FT") == "*"


def test_power_up_echo_and_verbose_then_terse(emulator):
    _, line = emulator()
    assert ask(line, "PP") == "PP * Current Pan position is 0"
    terse(line)
    assert ask(line, "PP") == "* 0"
    assert ask(line, "pr") == "* 185.1428"  # case-insensitive
    assert [ask(line, c) for c in ("PN", "PX", "TN", "TX")] == ["* -3090", "* 3090", "* -907", "* 604"]


def test_motion_at_speed_and_a_waits_for_its_end(emulator):
    emu, line = emulator(speed_steps_s=4000.0)
    terse(line)
    t0 = time.monotonic()
    assert ask(line, "PP800") == "*"
    assert ask(line, "TP-400") == "*"
    mid = int(ask(line, "PP")[2:])
    assert 0 <= mid < 800  # still on its way
    assert ask(line, "A", timeout=2.0) == "*"
    assert time.monotonic() - t0 >= 800 / 4000.0 - 0.01
    assert ask(line, "PP") == "* 800" and ask(line, "TP") == "* -400"
    pan_rad, tilt_rad = emu.mount.angles_rad()
    assert pan_rad == pytest.approx(800 * emu.spec.step_rad) and tilt_rad == pytest.approx(-400 * emu.spec.step_rad)


def test_limits_relative_moves_speed_reset_and_errors(emulator):
    emu, line = emulator()
    terse(line)
    assert ask(line, "PP3091") == "! Maximum allowable Pan position exceeded"
    assert ask(line, "TP-908") == "! Minimum allowable Tilt position exceeded"
    assert ask(line, "A") == "*" and ask(line, "PP") == "* 0"  # a refused move does not move
    assert ask(line, "PP100") == "*" and ask(line, "PO50") == "*" and ask(line, "A") == "*"
    assert ask(line, "PP") == "* 150"
    assert ask(line, "PO3000") == "! Maximum allowable Pan position exceeded"
    assert ask(line, "PS") == "* 4000"
    assert ask(line, "PS0") == "! Pan speed out of range"
    assert ask(line, "PS2000") == "*" and ask(line, "PS") == "* 2000"
    assert ask(line, "PPx") == "! Illegal command argument"
    assert ask(line, "XYZ") == "! Illegal command"
    assert ask(line, "R", timeout=2.0) == "!T!T!P!P*"
    assert ask(line, "PP") == "* 0"


def test_commands_end_with_space_or_cr_and_line_time_is_modelled(emulator):
    _, line = emulator(baudrate=9600)
    line.write(b"ED\r")  # the echoed CR ends the echoed line
    assert [line.read_line(time.monotonic() + 1.0) for _ in range(2)] == ["ED", "*"]
    line.write(b"FT ")
    assert line.read_line(time.monotonic() + 1.0) == "*"
    t0 = time.monotonic()
    assert ask(line, "PP") == "* 0"
    assert time.monotonic() - t0 >= (len("PP ") + len("* 0\r\n")) * 10 / 9600


def test_mount_state_interpolates_at_speed():
    mount = MountState(0.001)
    t0 = 100.0
    end = mount.move("P", 200, 100.0, t0)
    assert end == pytest.approx(t0 + 2.0)
    assert mount.steps_at(t0 + 1.0) == (pytest.approx(100.0), 0.0)
    assert mount.steps_at(t0 + 5.0)[0] == 200
    mount.halt("P", t0 + 0.5)
    with pytest.raises(ValueError):
        MountState(0.0)
