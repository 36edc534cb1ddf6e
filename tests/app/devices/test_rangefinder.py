"""The DLS driver against its emulator: right values, device errors, and every fault of the line.

Each fault either leaves the measured value exact (the emulator is noiseless here, so the right
value is known to 0.1 mm) or raises a clear error; none returns a wrong value.
"""

import math
import time

import numpy as np
import pytest

from app.devices.drivers.errors import (
    AmbiguousMeasurementError,
    DeviceDisconnected,
    DeviceTimeout,
    NoisyLineError,
    NoTargetError,
    ProtocolError,
    SignalTooStrongError,
)
from app.devices.drivers.rangefinder import RangeFinder
from app.devices.faults import Fault

from .conftest import FAST_DRIVER, aim_steps, box_point, facing_face


def test_measure_returns_the_true_range_to_a_tenth_of_a_millimetre(rf_bench):
    site, rf, tu, expected = rf_bench
    assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["timeouts"] == rf.stats["corrupt"] == rf.stats["resyncs"] == 0


RECOVERED = {
    "drop": Fault("drop", match=b"g0g"),
    "late": Fault("late", match=b"g0g", delay_s=0.4),
    "truncated, line left open": Fault("truncate", match=b"g0g"),
    "truncated, line ended": Fault("truncate", match=b"g0g", at=9, keep_terminator=True),
    "split": Fault("split", match=b"g0g", delay_s=0.05),
    "junk prefix": Fault("junk", match=b"g0g"),
    "junk that looks like a reply": Fault("junk", match=b"g0g", data=b"g0g+9"),
    "garbled digit to letter": Fault("garble", match=b"g0g", at=7, data=b"Z"),
    "garbled leading digit (implausible)": Fault("garble", match=b"g0g", at=4, data=b"9"),
    "garbled tag": Fault("garble", match=b"g0g", at=2, data=b"q"),
    "garbled sign": Fault("garble", match=b"g0g", at=3, data=b"-"),
    "unsolicited line": Fault("unsolicited", match=b"g0g"),
    "unknown error code": Fault("error", match=b"g0g", data=b"g0@E299\r\n"),
    "unplug and replug": Fault("unplug", match=b"g0g", delay_s=0.2),
}


@pytest.mark.parametrize("fault", list(RECOVERED.values()), ids=list(RECOVERED))
def test_each_line_fault_still_gives_the_right_value(rf_bench, fault):
    site, rf, tu, expected = rf_bench
    site.rangefinder.faults.push(fault)
    assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert [k for k, _ in site.rangefinder.faults.applied] == [fault.kind]  # the fault did hit
    assert rf.measure() == pytest.approx(expected, abs=1e-9)  # and the line is clean afterwards


def test_faults_that_need_no_retry_cost_none(rf_bench):
    site, rf, tu, expected = rf_bench
    for kind in ("split", "junk", "unsolicited"):
        site.rangefinder.faults.push(Fault(kind, match=b"g0g", delay_s=0.02))
        assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["timeouts"] == rf.stats["corrupt"] == rf.stats["resyncs"] == 0


def test_faults_that_need_a_retry_resynchronise_first(rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.faults.push(Fault("drop", match=b"g0g"))
    assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["timeouts"] >= 1 and rf.stats["resyncs"] >= 1
    assert "s0c" in site.rangefinder.commands_seen  # stale replies flushed with sNc before retrying


def test_a_late_reply_is_never_taken_for_the_next_measurement(workcell, rf_bench):
    site, rf, tu, first = rf_bench
    site.rangefinder.faults.push(Fault("late", match=b"g0g", delay_s=0.5))
    assert rf.measure() == pytest.approx(first, abs=1e-9)
    table = workcell.body("table")
    top_centre = box_point(
        workcell, "table", table.model.bounds()[1] * [0, 0, 1] + table.model.bounds().mean(axis=0) * [1, 1, 0]
    )
    tu.move_to_steps(*aim_steps(workcell, top_centre))  # somewhere else: another range
    second = round(site.rangefinder.true_range(time.monotonic())[0], 4)
    assert abs(second - first) > 0.05
    assert rf.measure() == pytest.approx(second, abs=1e-9)


def test_device_errors_raise_their_exceptions(workcell, rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.faults.push(Fault("error", match=b"g0g"))  # the emulator's default: 260
    with pytest.raises(AmbiguousMeasurementError, match="260"):
        rf.measure()
    site.rangefinder.faults.push(Fault("error", match=b"g0g", data=b"g0@E256\r\n"))
    with pytest.raises(SignalTooStrongError) as info:
        rf.measure()
    assert info.value.code == 256 and info.value.device == "rangefinder"
    tu.move_to_steps(0, 600)  # up over the table: nothing to hit
    with pytest.raises(NoTargetError):
        rf.measure()


def test_the_same_corruption_on_every_attempt_is_a_noisy_line(rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.faults.push(*[Fault("garble", match=b"g0g", at=6, data=b"?")] * (rf.retries + 1))
    with pytest.raises(NoisyLineError, match="the range finder's line is noisy .*check the cable and the baud rate"):
        rf.measure()


def test_plausibility_limits_reject_a_well_formed_distance(rf_bench):
    site, rf, tu, expected = rf_bench
    strict = RangeFinder(rf.url, plausible_range_m=(0.05, expected - 0.1), **FAST_DRIVER)
    try:
        with pytest.raises(ProtocolError, match="implausible"):
            strict.measure()
    finally:
        strict.close()


def test_a_garbled_digit_that_still_parses_is_an_outlier_of_n_shots_or_read_again(rf_bench):
    site, rf, tu, expected = rf_bench
    digit = b"7" if str(int(expected * 1e4)).zfill(8)[4] != "7" else b"3"
    site.rangefinder.faults.push(Fault("garble", match=b"g0g", at=8, data=digit))
    m = rf.measure_n(5)  # 3 shots or more: the median outvotes it, and it is flagged
    assert m.range_m == pytest.approx(expected, abs=1e-9)
    assert m.outliers.sum() == 1 and m.n_valid == 5 and m.n_kept == 4
    assert abs(m.shots_m[m.outliers][0] - expected) > 0.05
    assert m.spread_m == pytest.approx(0.0, abs=1e-9)
    assert m.shots_m.shape == (5,) and m.outliers.shape == (5,)
    site.rangefinder.faults.push(Fault("garble", match=b"g0g", at=8, data=digit))
    m = rf.measure_n(2)  # fewer: a shot that jumps from the last ones is read again and never kept
    assert np.allclose(m.shots_m, expected, atol=1e-9) and rf.stats["jumps"] == 1


def test_measure_n_counts_misses_and_reports_spread(workcell, make_site, drivers):
    site, rf_url, tu_url = make_site(sigma_m=0.005)
    rf, tu = drivers(rf_url, tu_url)
    tu.move_to_steps(*aim_steps(workcell, facing_face(workcell)[0]))
    truth = site.rangefinder.true_range(time.monotonic())[0]
    site.rangefinder.faults.push(Fault("error", match=b"g0g", data=b"g0@E255\r\n"))
    m = rf.measure_n(12)
    assert m.n_valid == 11 and np.isnan(m.shots_m).sum() == 1
    assert abs(m.range_m - truth) < 0.006 and 0.002 < m.spread_m < 0.009
    tu.move_to_steps(0, 600)
    with pytest.raises(NoTargetError, match="none of 3"):
        rf.measure_n(3)
    with pytest.raises(ValueError, match="positive integer"):
        rf.measure_n(0)


def test_deadline_is_kept_when_the_device_never_answers(rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.faults.set_rates({"drop": 1.0})
    t0 = time.monotonic()
    with pytest.raises(DeviceTimeout, match="no valid reply"):
        rf.measure(timeout_s=0.6)
    assert time.monotonic() - t0 < 0.6 + 0.3


def test_a_device_that_stays_unplugged_raises_device_disconnected(rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.unplug(math.inf)
    time.sleep(0.05)
    t0 = time.monotonic()
    with pytest.raises(DeviceDisconnected, match="could not be opened"):
        rf.measure()
    assert time.monotonic() - t0 < rf.reconnect_timeout_s + 3 * rf.attempt_timeout_s + 0.5
    site.rangefinder.replug()
    time.sleep(0.05)
    assert rf.measure() == pytest.approx(expected, abs=1e-9)  # the next call reconnects
    assert rf.stats["reconnects"] >= 1


def test_other_commands(rf_bench):
    site, rf, tu, expected = rf_bench
    assert rf.temperature_c() == pytest.approx(24.0)
    rf.laser_on()
    assert site.rangefinder.laser_on
    rf.laser_off()
    assert not site.rangefinder.laser_on
    rf.set_user_offset_m(-0.0125)
    assert rf.user_offset_m() == pytest.approx(-0.0125)
    assert rf.measure() == pytest.approx(expected - 0.0125, abs=1e-9)
    rf.set_user_offset_m(0.0)
    rf.stop()
    with pytest.raises(ValueError, match="8-digit"):
        rf.set_user_offset_m(1e5)


def test_bad_arguments_are_refused():
    with pytest.raises(ValueError, match="device_id"):
        RangeFinder("mcit://x", device_id=12, connect=False)
    with pytest.raises(ValueError, match="plausible_range_m"):
        RangeFinder("mcit://x", plausible_range_m=(5.0, 1.0), connect=False)
    with pytest.raises(ValueError, match="timeouts"):
        RangeFinder("mcit://x", attempt_timeout_s=0.0, connect=False)


def test_through_a_real_pty_with_faults_and_a_replug(workcell, make_site, drivers, tmp_path):
    site, rf_path, tu_path = make_site(
        transport="pty", links=(tmp_path / "rf", tmp_path / "tu"), rangefinder_baud=19200, turret_baud=9600
    )
    assert rf_path == str(tmp_path / "rf")
    rf, tu = drivers(rf_path, tu_path)
    tu.move_to_steps(*aim_steps(workcell, facing_face(workcell)[0]))
    expected = round(site.rangefinder.true_range(time.monotonic())[0], 4)
    assert rf.measure() == pytest.approx(expected, abs=1e-9)
    site.rangefinder.faults.push(
        Fault("junk", match=b"g0g"),
        Fault("unplug", match=b"g0g", delay_s=0.2),
        Fault("garble", match=b"g0g", at=5, data=b"x"),
    )
    for _ in range(3):
        assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["reconnects"] >= 1 and (tmp_path / "rf").is_symlink()
    assert [k for k, _ in site.rangefinder.faults.applied] == ["junk", "unplug", "garble"]
    assert site.rangefinder.port.device.startswith("/dev/")  # a new pty behind the same link


def test_nan_and_negative_arguments_are_refused_before_anything_is_sent(rf_bench):
    site, rf, tu, expected = rf_bench
    site.rangefinder.commands_seen.clear()
    nan = float("nan")
    for call in (
        lambda: rf.measure(timeout_s=nan),
        lambda: rf.measure(timeout_s=-0.5),
        lambda: rf.measure_n(3, timeout_s=nan),
        lambda: rf.measure_n(3, outlier_m=nan),
        lambda: rf.stop(timeout_s=nan),
        lambda: rf.temperature_c(timeout_s=nan),
        lambda: rf.user_offset_m(timeout_s=nan),
        lambda: rf.set_user_offset_m(nan),
        lambda: rf.set_user_offset_m(0.0, timeout_s=nan),
    ):
        with pytest.raises(ValueError):
            call()
    assert site.rangefinder.commands_seen == []
    assert rf.measure() == pytest.approx(expected, abs=1e-4)  # and the driver still works
    for options in ({"attempt_timeout_s": nan}, {"reconnect_timeout_s": nan}):
        with pytest.raises(ValueError):
            RangeFinder(rf.url, **(FAST_DRIVER | options))
