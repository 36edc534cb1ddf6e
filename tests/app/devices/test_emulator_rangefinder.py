"""The DLS range-finder emulator, byte for byte: distances from the scene, timing, modes, errors."""

import time
from dataclasses import replace

import numpy as np
import pytest

from app.devices.drivers.transport import SerialLine
from app.devices.emulators.rangefinder import RangeFinderEmulator, format_distance
from app.devices.emulators.turret import MountState
from app.render.raycast import BeamCaster
from core.rangefinder import aim

from .conftest import facing_face


@pytest.fixture
def emulator(workcell):
    """make(spec changes..., **emulator options) -> (emulator, mount, SerialLine opened on it)."""
    made = []

    def make(baudrate=0, measure_delay_s=0.002, spec=None, **options):
        mount = MountState(workcell.turret.step_rad)
        spec = replace(workcell.rangefinder, **({"sigma_range_m": 0.0} | (spec or {})))
        emu = RangeFinderEmulator(
            BeamCaster(workcell),
            spec,
            workcell.turret.T_world_turret,
            mount.angles_rad,
            baudrate=baudrate,
            measure_delay_s=measure_delay_s,
            delay_per_m_s=0.0,
            no_target_delay_s=0.01,
            rng=0,
            **options,
        )
        made.append(emu)
        emu.boot_time_s = 0.2  # time to open the port before the device's power-on line
        line = SerialLine(emu.serve_inprocess(), device="rangefinder")
        line.open()
        assert line.read_line(time.monotonic() + 1.0) == "g0?"  # the power-on line
        return emu, mount, line

    yield make
    for emu in made:
        emu.close()


def ask(line, command, timeout=3.0):
    line.write(command.encode() + b"\r\n")
    return line.read_line(time.monotonic() + timeout)


def point_at(workcell, mount, X_world):
    """Point the beam exactly through X_world (fractional steps); returns the true range."""
    pan, tilt, rho = aim(workcell.turret.T_world_turret, X_world)
    mount.place(float(pan) / mount.step_rad, float(tilt) / mount.step_rad)
    return float(rho)


def test_one_distance_is_the_true_range_to_the_face(workcell, emulator):
    emu, mount, line = emulator()
    rho = point_at(workcell, mount, facing_face(workcell)[0])
    reply = ask(line, "s0g")
    assert reply == "g0g" + format_distance(rho)
    assert abs(int(reply[4:]) * 1e-4 - rho) <= 0.6e-4
    assert emu.measurements[-1][3] == "unknown_box"


def test_noise_has_the_specified_sigma(workcell, emulator):
    emu, mount, line = emulator(spec={"sigma_range_m": 0.005})
    rho = point_at(workcell, mount, facing_face(workcell)[0])
    values = np.array([int(ask(line, "s0g")[4:]) * 1e-4 for _ in range(60)])
    assert abs(values.mean() - rho) < 0.0025
    assert 0.0035 < values.std(ddof=1) < 0.0065


def test_no_target_and_out_of_range_give_error_255(workcell, emulator):
    _, mount, line = emulator()
    mount.place(0.0, 600.0)  # 30° up, over the table: nothing there
    assert ask(line, "s0g") == "g0@E255"
    X, _, rho = facing_face(workcell)
    _, mount, line = emulator(spec={"max_range_m": rho - 0.05})
    point_at(workcell, mount, X)
    assert ask(line, "s0g") == "g0@E255"
    _, mount, line = emulator(spec={"min_range_m": rho + 0.05})
    point_at(workcell, mount, X)
    assert ask(line, "s0g") == "g0@E255"


def test_a_new_command_cancels_the_measurement_under_way(workcell, emulator):
    _, mount, line = emulator(measure_delay_s=0.15)
    point_at(workcell, mount, facing_face(workcell)[0])
    line.write(b"s0g\r\n")
    time.sleep(0.02)
    assert ask(line, "s0t") == "g0t+00000240"  # 24.0 °C
    assert line.read_line(time.monotonic() + 0.4) is None  # the cancelled distance never comes


def test_stop_laser_save_offset_and_unknown_commands(workcell, emulator):
    emu, mount, line = emulator()
    assert ask(line, "s0o") == "g0?" and emu.laser_on
    assert ask(line, "s0p") == "g0?" and not emu.laser_on
    assert ask(line, "s0s") == "g0?"
    assert ask(line, "s0c") == "g0?"
    assert ask(line, "s0xyz") == "g0@E203"
    assert ask(line, "s0uof+00001000") == "g0uof?"
    assert ask(line, "s0uof") == "g0uof+00001000"
    rho = point_at(workcell, mount, facing_face(workcell)[0])
    assert ask(line, "s0g") == "g0g" + format_distance(rho + 0.1)
    line.write(b"s1g\r\n")  # another device id on the bus: silence
    assert line.read_line(time.monotonic() + 0.1) is None


def test_continuous_tracking_until_stopped(workcell, emulator):
    _, mount, line = emulator(measure_delay_s=0.01)
    rho = point_at(workcell, mount, facing_face(workcell)[0])
    line.write(b"s0h\r\n")
    lines = [line.read_line(time.monotonic() + 1.0) for _ in range(4)]
    assert lines == ["g0h" + format_distance(rho)] * 4
    line.write(b"s0g\r\n")
    while (got := line.read_line(time.monotonic() + 1.0)).startswith("g0h"):  # tracking lines on the way
        pass
    assert got == "g0@E212"  # tracking active
    line.write(b"s0c\r\n")
    deadline = time.monotonic() + 1.0
    while (got := line.read_line(deadline)) != "g0?":  # tracking lines already on the way
        assert got.startswith("g0h")
    assert line.read_line(time.monotonic() + 0.1) is None


def test_buffered_tracking_and_its_errors(workcell, emulator):
    _, mount, line = emulator()
    assert ask(line, "s0q") == "g0@E210"  # not tracking
    rho = point_at(workcell, mount, facing_face(workcell)[0])
    assert ask(line, "s0f+10") == "g0f?"
    time.sleep(0.06)
    first = ask(line, "s0q")
    assert first.startswith("g0q" + format_distance(rho)) and first[-2:] in ("+1", "+2")
    # The status of the next read says how many values came since this one: none (+0), one (+1)
    # or several, the older overwritten (+2) — which of them depends on the machine's load.
    second = ask(line, "s0q")
    assert second.startswith("g0q" + format_distance(rho)) and second[-2:] in ("+0", "+1", "+2")
    assert ask(line, "s0c") == "g0?"


def test_reply_time_includes_measurement_delay_and_line_transfer(workcell, emulator):
    _, mount, line = emulator(baudrate=19200, measure_delay_s=0.02)
    point_at(workcell, mount, facing_face(workcell)[0])
    t0 = time.monotonic()
    reply = ask(line, "s0g")
    elapsed = time.monotonic() - t0
    modelled = 0.02 + (len("s0g\r") + len(reply) + 2) * 10 / 19200  # the CR ends the command
    assert reply.startswith("g0g")
    assert modelled <= elapsed < modelled + 0.5
