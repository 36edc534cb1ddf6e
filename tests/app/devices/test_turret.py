"""The PTU-D46 driver against its emulator: units, moves, limits, and every fault of the line.

Each fault either leaves the turret where it was told to go (read back from the emulator's own
state, not only from the driver) or raises a clear error; a relative move is never re-sent.
"""

import math
import time

import pytest

from app.devices.drivers.errors import (
    DeviceDisconnected,
    DeviceTimeout,
    MotionUnconfirmedError,
    NoisyLineError,
    TurretError,
    TurretLimitError,
)
from app.devices.drivers.turret import Turret
from app.devices.faults import Fault

from .conftest import FAST_DRIVER

ACK = b"*\r\n"


@pytest.fixture
def bench(make_site, drivers):
    site, rf_url, tu_url = make_site()
    rf, tu = drivers(rf_url, tu_url)
    tu.speed_steps_s()  # known speed: the replies of a move are then PP, TP, A, PP?, TP?
    return site, tu


def emulated_steps(site):
    """Where the emulated head really is (steps), from the emulator's own state."""
    return tuple(int(round(v)) for v in site.turret.mount.steps_at())


def test_handshake_reads_resolution_and_limits_and_converts_units(workcell, bench):
    site, tu = bench
    assert tu.resolution_arcsec == (pytest.approx(185.1428), pytest.approx(185.1428))
    assert tu.pan_step_rad == pytest.approx(workcell.turret.step_rad, rel=1e-9)
    assert tu.pan_limits_steps == tuple(workcell.turret.pan_limits_steps)
    assert tu.tilt_limits_steps == tuple(workcell.turret.tilt_limits_steps)
    assert tu.steps_to_rad(100, -50) == (pytest.approx(100 * tu.pan_step_rad), pytest.approx(-50 * tu.tilt_step_rad))
    assert tu.rad_to_steps(*tu.steps_to_rad(123, -45)) == (123, -45)
    assert tu.pan_limits_rad[1] == pytest.approx(3090 * tu.pan_step_rad)
    assert site.turret.commands_seen[:2] == ["EE", "FT"]  # echo on (replies are told apart by it), terse feedback first
    assert site.turret.echo


def test_absolute_moves_in_steps_radians_and_degrees(bench):
    site, tu = bench
    assert tu.move_to_steps(400, -300) == (400, -300)
    assert emulated_steps(site) == (400, -300) and tu.position_steps() == (400, -300)
    pan, tilt = tu.move_to(0.1, -0.05)
    assert emulated_steps(site) == tu.rad_to_steps(0.1, -0.05)
    assert pan == pytest.approx(0.1, abs=tu.pan_step_rad / 2) and tilt == pytest.approx(-0.05, abs=tu.tilt_step_rad / 2)
    assert tu.move_to_deg(10.0, 5.0) == (pytest.approx(10.0, abs=0.03), pytest.approx(5.0, abs=0.03))
    assert tu.position_deg() == (pytest.approx(10.0, abs=0.03), pytest.approx(5.0, abs=0.03))
    mount_pan, mount_tilt = site.turret.mount.angles_rad()
    assert math.degrees(mount_pan) == pytest.approx(10.0, abs=0.03) and math.degrees(mount_tilt) == pytest.approx(
        5.0, abs=0.03
    )
    tu.move_to_steps(tilt=100)  # one axis only
    assert emulated_steps(site)[1] == 100 and emulated_steps(site)[0] == tu.rad_to_steps(math.radians(10.0), 0)[0]


def test_moves_take_the_time_the_speed_says(bench):
    site, tu = bench
    tu.set_speed_steps_s(2000)
    assert tu.speed_steps_s() == (2000, 2000)
    tu.move_to_steps(0, 0)
    t0 = time.monotonic()
    tu.move_to_steps(600, 0)
    assert time.monotonic() - t0 >= 600 / 2000 - 0.01
    assert tu.move_to_steps(0, 0, wait=False) == (0, 0)
    tu.wait()
    assert emulated_steps(site) == (0, 0)


def test_limits_are_refused_before_sending(bench):
    site, tu = bench
    sent = len(site.turret.commands_seen)
    with pytest.raises(TurretLimitError, match="beyond the limits"):
        tu.move_to_steps(3091, 0)
    with pytest.raises(ValueError):  # a TurretLimitError is also a ValueError: bad input
        tu.move_to_deg(0.0, -60.0)
    with pytest.raises(ValueError, match="whole number"):
        tu.move_to_steps(1.5, 0)
    assert len(site.turret.commands_seen) == sent


def test_relative_moves(bench):
    site, tu = bench
    tu.move_to_steps(100, 100)
    assert tu.move_by_steps(50, -20) == (150, 80)
    assert emulated_steps(site) == (150, 80)
    assert tu.move_by_deg(1.0, 0.0)[0] == pytest.approx(150 * math.degrees(tu.pan_step_rad) + 1.0, abs=0.03)
    with pytest.raises(TurretLimitError):
        tu.move_by_steps(5000, 0)


def test_a_lost_relative_move_confirmation_is_an_error_and_never_resent(bench):
    site, tu = bench
    tu.move_to_steps(0, 0)
    site.turret.faults.push(Fault("drop", match=ACK))
    with pytest.raises(MotionUnconfirmedError, match="not retried"):
        tu.move_by_steps(200, 0)
    assert site.turret.commands_seen.count("PO200") == 1
    assert tu.position_steps()[0] in (0, 200)  # the driver asks; here the move did happen
    assert emulated_steps(site)[0] == 200


RECOVERED = {
    "drop": Fault("drop", match=ACK),
    "late": Fault("late", match=ACK, delay_s=0.4),
    "truncated": Fault("truncate", match=ACK),
    "split": Fault("split", match=ACK, at=1, delay_s=0.05),
    "junk prefix": Fault("junk", match=ACK),
    "junk with a star": Fault("junk", match=ACK, data=b"x* 5!"),
    "garbled ack": Fault("garble", match=ACK, at=0, data=b"#"),
    "unsolicited limit line": Fault("unsolicited", match=ACK),
    "unplug and replug": Fault("unplug", match=ACK, delay_s=0.2),
}


@pytest.mark.parametrize("fault", list(RECOVERED.values()), ids=list(RECOVERED))
def test_each_line_fault_on_an_absolute_move_still_gets_there(bench, fault):
    site, tu = bench
    tu.move_to_steps(0, 0)
    site.turret.faults.push(fault)
    assert tu.move_to_steps(-700, 250) == (-700, 250)
    assert emulated_steps(site) == (-700, 250)
    assert [k for k, _ in site.turret.faults.applied] == [fault.kind]


POSITION_FAULTS = {
    "garbled digit": Fault("garble", match=b"* -7", at=3, data=b"1"),
    "truncated but terminated": Fault("truncate", match=b"* -7", at=3, keep_terminator=True),
    "late": Fault("late", match=b"* -7", delay_s=0.4),
    "junk with digits": Fault("junk", match=b"* -7", data=b"* 12"),
}


@pytest.mark.parametrize("fault", list(POSITION_FAULTS.values()), ids=list(POSITION_FAULTS))
def test_each_line_fault_on_a_position_query_still_reads_right(bench, fault):
    site, tu = bench
    tu.move_to_steps(-777, 0)
    site.turret.faults.push(fault)
    assert tu.position_steps() == (-777, 0)
    assert [k for k, _ in site.turret.faults.applied] == [fault.kind]


def test_unsolicited_limit_lines_are_recorded(bench):
    site, tu = bench
    site.turret.faults.push(Fault("unsolicited", match=ACK, data=b"!T!P\r\n"))
    tu.move_to_steps(10, 10)
    assert [axis for _, axis in tu.limit_events] == ["T", "P"]


def test_device_errors_raise_turret_errors(bench):
    site, tu = bench
    site.turret.faults.push(Fault("error", match=ACK))
    with pytest.raises(TurretError, match="Illegal command"):
        tu.move_to_steps(10, 10)
    site.turret.faults.push(Fault("error", match=ACK, data=b"! Maximum allowable Pan position exceeded\r\n"))
    with pytest.raises(TurretLimitError):
        tu.move_to_steps(20, 10)


def test_garbled_handshake_values_are_asked_again(make_site):
    site, rf_url, tu_url = make_site()
    site.turret.faults.push(Fault("garble", match=b"185", at=4, data=b"9"))  # * 195.1428 once
    tu = Turret(tu_url, **FAST_DRIVER)
    try:
        assert tu.resolution_arcsec == (pytest.approx(185.1428), pytest.approx(185.1428))
        assert site.turret.commands_seen.count("PR") >= 3
    finally:
        tu.close()


def test_the_speed_survives_a_replug(bench):
    site, tu = bench
    tu.set_speed_steps_s(3000, 2500)
    site.turret.unplug(0.2)  # the unit powers up again with its default speed
    time.sleep(0.3)
    assert tu.move_to_steps(100, 100) == (100, 100)
    assert tu.stats["reconnects"] >= 1
    assert site.turret.speed == {"P": 3000.0, "T": 2500.0}


def test_deadlines_and_a_unit_that_stays_away(bench):
    site, tu = bench
    site.turret.faults.set_rates({"drop": 1.0})
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout):
        tu.position_steps(timeout_s=0.5)
    assert time.monotonic() - t0 < 0.5 + 0.3
    site.turret.faults.set_rates({})
    site.turret.unplug(math.inf)
    time.sleep(0.05)
    with pytest.raises(DeviceDisconnected):
        tu.position_steps()


def test_home_and_halt(bench):
    site, tu = bench
    tu.move_to_steps(300, 300)
    tu.home()
    assert emulated_steps(site) == (0, 0) and tu.position_steps() == (0, 0)
    tu.move_to_steps(2000, 0, wait=False)
    time.sleep(0.05)
    tu.halt()
    stopped = emulated_steps(site)[0]
    assert 0 < stopped < 2000
    time.sleep(0.05)
    assert emulated_steps(site)[0] == stopped


def test_the_same_corruption_every_time_is_a_noisy_line(bench):
    site, tu = bench
    site.turret.faults.set_rates({"garble": 1.0})
    with pytest.raises(NoisyLineError, match="the turret's line is noisy .*check the cable and the baud rate"):
        tu.position_steps()


def test_a_replugged_unit_is_put_back_on_both_axes_before_a_one_axis_move(bench):
    """The unit homes at power-up: a pan-only move after a replug must send the tilt again."""
    site, tu = bench
    assert tu.move_to_steps(100, -300) == (100, -300)
    site.turret.unplug(0.05)
    time.sleep(0.15)
    assert emulated_steps(site) == (0, 0)  # homed
    assert tu.move_to_steps(200, None) == (200, -300)
    assert emulated_steps(site) == (200, -300)
    assert tu.stats["reconnects"] >= 1
    # confirmed since: a pan-only move sends only the pan, but still reads both axes back
    site.turret.commands_seen.clear()
    assert tu.move_to_steps(250) == (250, -300)
    assert [c for c in site.turret.commands_seen if c.startswith(("PP", "TP")) and len(c) > 2] == ["PP250"]
    assert {"PP", "TP"} <= set(site.turret.commands_seen)


def test_an_unplug_during_a_one_axis_move_restores_the_other_axis(bench):
    site, tu = bench
    tu.move_to_steps(-400, 250)
    site.turret.faults.push(Fault("unplug", match=ACK, delay_s=0.05))  # instead of the PP's '*'
    assert tu.move_to_steps(-350, None) == (-350, 250)
    assert emulated_steps(site) == (-350, 250)
    assert [k for k, _ in site.turret.faults.applied] == ["unplug"]


def test_an_axis_never_commanded_stays_where_it_is(bench):
    site, tu = bench
    site.mount.place(0.0, 123.0)  # e.g. left there by an earlier session
    assert tu.move_to_steps(pan=40) == (40, 123)
    assert emulated_steps(site) == (40, 123)


def test_nan_and_negative_times_and_angles_are_refused_before_anything_is_sent(bench):
    site, tu = bench
    site.turret.commands_seen.clear()
    nan = float("nan")
    for call in (
        lambda: tu.position_steps(timeout_s=nan),
        lambda: tu.move_to_steps(10, 10, timeout_s=nan),
        lambda: tu.move_to_steps(10, 10, timeout_s=-1.0),
        lambda: tu.move_to(nan, 0.0),
        lambda: tu.move_to_deg(0.0, nan),
        lambda: tu.move_by_deg(nan, 0.0),
        lambda: tu.move_by_steps(1, 0, timeout_s=nan),
        lambda: tu.wait(timeout_s=nan),
        lambda: tu.set_speed_deg_s(nan),
        lambda: tu.speed_steps_s(timeout_s=nan),
        lambda: tu.halt(timeout_s=nan),
        lambda: tu.home(timeout_s=nan),
    ):
        with pytest.raises(ValueError):
            call()
    assert site.turret.commands_seen == []
    for options in ({"attempt_timeout_s": nan}, {"reconnect_timeout_s": nan}, {"motion_margin_s": nan}):
        with pytest.raises(ValueError):
            Turret(tu.url, **(FAST_DRIVER | options))


def test_still_at_sees_a_unit_that_power_cycled_since_the_move(bench):
    site, tu = bench
    tu.move_to_steps(300, -200)
    assert tu.still_at(300, -200)
    site.turret.unplug(0.0)  # powers up again at once, homed; no reply was lost, the driver was not told
    time.sleep(0.1)
    assert not tu.still_at(300, -200)
    site.turret.commands_seen.clear()
    assert tu.move_to_steps(310, None) == (310, -200)  # the tilt is sent again
    assert "TP-200" in site.turret.commands_seen and emulated_steps(site) == (310, -200)
