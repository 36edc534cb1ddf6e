"""Nothing silently wrong from the line (issue 14): noise and garbage say the line is noisy, quoted
data is cut to 200 bytes, and a reply that does not answer its request is never returned as a value."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from app.devices.drivers.errors import NoisyLineError
from app.devices.drivers.rangefinder import RangeFinder
from app.devices.drivers.turret import Turret
from app.devices.emulators.ports import InProcessPort
from app.devices.faults import Fault

from .conftest import aim_steps, facing_face

QUICK = dict(attempt_timeout_s=0.1, retries=2, reconnect_timeout_s=0.2)


class NoiseLine:
    """A port that answers every write with garbage: random bytes (with '!', '*', digits and line
    ends among them), or one endless line without an end."""

    def __init__(self, name: str, seed: int = 0, endless_bytes: int = 0):
        self.rng = np.random.default_rng(seed)
        self.endless_bytes = endless_bytes
        self.port = InProcessPort(name, self._on_receive)

    def _on_receive(self, data: bytes) -> None:
        if self.endless_bytes:
            for _ in range(self.endless_bytes // 65536):
                self.port.send(bytes(self.rng.integers(32, 127, 65536).astype(np.uint8)))  # no CR, no LF
            return
        pool = np.frombuffer(b"!*0123456789 PTgs?@E+-\r\n\x00\x93\xff" + bytes(range(33, 127)), np.uint8)
        self.port.send(bytes(self.rng.choice(pool, int(self.rng.integers(5, 80))).tolist()))

    def close(self) -> None:
        self.port.close()


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("driver", [Turret, RangeFinder])
def test_a_line_of_noise_says_the_line_is_noisy(driver, seed):
    line = NoiseLine(f"noise-{driver.__name__}-{seed}", seed)
    try:
        with pytest.raises(NoisyLineError) as info:
            driver(line.port.url, **QUICK)
        name = "turret" if driver is Turret else "range finder"
        assert str(info.value).startswith(f"the {name}'s line is noisy (")
        assert str(info.value).endswith("): check the cable and the baud rate")
        assert "refused" not in str(info.value) and len(str(info.value)) < 200
    finally:
        line.close()


@pytest.mark.parametrize("driver", [Turret, RangeFinder])
def test_an_endless_line_is_noisy_and_no_message_or_log_carries_more_than_200_bytes(driver, caplog):
    line = NoiseLine(f"endless-{driver.__name__}", endless_bytes=512 * 1024)
    caplog.set_level(logging.DEBUG, logger="mcit.devices")
    try:
        with pytest.raises(NoisyLineError, match="line is noisy .* bytes without a line end") as info:
            driver(line.port.url, **QUICK)
    finally:
        line.close()
    assert len(str(info.value)) < 300
    texts = [r.getMessage() for r in caplog.records]
    assert all(len(t) < 400 for t in texts)  # each quotes at most 200 received bytes


@pytest.mark.parametrize("fake", [None, "near"], ids=["random value", "a value within 5 sigma"])
def test_a_complete_distance_injected_before_the_real_one_is_not_returned(rf_bench, fake):
    site, rf, tu, expected = rf_bench
    data = None if fake is None else f"g0g+{int(round((expected + 0.01) * 1e4)):08d}\r\n".encode()
    for _ in range(3):  # first shot of a fresh driver (no history), and after
        site.rangefinder.faults.push(Fault("early", match=b"g0g", data=data))
        assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["two_replies"] + rf.stats["corrupt"] >= 3  # a random value is mostly implausible (corrupt)
    if fake is not None:
        assert rf.stats["two_replies"] >= 3
    assert [rf.measure() for _ in range(3)] == [pytest.approx(expected, abs=1e-9)] * 3  # no reply left behind


def test_a_distance_that_jumps_is_read_again_and_a_garbled_one_is_not_returned(rf_bench):
    site, rf, tu, expected = rf_bench
    assert rf.measure() == pytest.approx(expected, abs=1e-9)
    for at, digit in ((8, b"9"), (7, b"3"), (9, b"0")):  # 10 cm, 1 m, 1 cm digits: plausible, wrong
        site.rangefinder.faults.push(Fault("garble", match=b"g0g", at=at, data=digit))
        assert rf.measure() == pytest.approx(expected, abs=1e-9)
    assert rf.stats["jumps"] >= 2


def test_a_real_jump_is_confirmed_by_a_second_reading(rf_bench, workcell):
    site, rf, tu, expected = rf_bench
    rf.measure()
    X, _, _ = facing_face(workcell, "back_wall")
    tu.move_to_steps(*aim_steps(workcell, X))  # onto the back wall: a real jump
    far = rf.measure()
    dist, _ = site.rangefinder.true_range(time.monotonic())
    assert far == pytest.approx(round(dist, 4), abs=1e-9) and abs(far - expected) > 0.1
    assert rf.stats["jumps"] == 1


@pytest.fixture
def tu_bench(make_site, drivers):
    # the real line's timing: a reply pushed behind arrives late; a turret ten times as fast as the bench's others (the
    # moves' length does not matter here: 6 s of the test was the turret moving)
    site, rf_url, tu_url = make_site(turret_baud=9600, speed_steps_s=40000.0)
    _, tu = drivers(rf_url, tu_url)
    tu.speed_steps_s()
    return site, tu


def test_a_position_injected_before_the_real_one_is_not_returned(tu_bench):
    site, tu = tu_bench
    rng = np.random.default_rng(1)
    for _ in range(6):
        target = (int(rng.integers(-3000, 3000)), int(rng.integers(-900, 600)))
        site.turret.faults.push(Fault("early", match=f"* {target[0]}\r".encode()))  # the read-back of the pan
        assert tu.move_to_steps(*target) == target
        site.turret.faults.push(Fault("early", match=f"* {target[1]}\r".encode()))  # a position query's tilt
        assert tu.position_steps() == target
        assert tuple(int(round(v)) for v in site.turret.mount.steps_at()) == target
    assert len(site.turret.faults.applied) == 12


def test_turret_failures_are_told_from_garbage(tu_bench):
    site, tu = tu_bench
    from app.devices.drivers.errors import TurretLimitError

    site.turret.faults.push(Fault("error", data=b"! Maximum allowable Pan position exceeded\r\n"))
    with pytest.raises(TurretLimitError, match="refused"):
        tu.wait()
    site.turret.faults.push(Fault("error", data=b"!\x93\x01Q\xff*-\r\n"))  # garbage with a '!': not a refusal
    tu.wait()
