"""Unplugging the turret mid-scan never yields a beam reported where the head was not.

A powered-up PTU-D46 homes itself, so after a replug the head is at (0, 0) whatever it was told
before. Each trial runs a scan on the bundled scene's box and unplugs the turret (replugged
0.05 s later) at the reply of a random turret command after a random beam; every beam the scan
returns is then compared with the scene's truth: the emulator's own ray cast at the beam's
reported angles (through the scene's true turret pose). A beam is right when its range is within
5 σ_ρ of the true range there (a miss where the truth is a miss too); a scan may instead raise a
DeviceError. ``wrong_beams`` counts the others; the test asserts there are none.
"""

from __future__ import annotations

import threading
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

from app.devices.acquisition import face_patch_scan, measure_at_pixel, profile_scan
from app.devices.drivers.errors import DeviceError
from app.devices.faults import Fault
from app.render.raycast import BeamCaster
from core.rangefinder import aim, beam_ray

from .conftest import facing_face

SIGMA = 0.005
TRIALS = 16  # 96 scans over the six cases (30 each before: 2× the suite time, no new failure found)


def true_range(scene, raycaster, pan_rad: float, tilt_rad: float) -> float:
    """The range the emulated range finder would see at these angles (inf: no return)."""
    origin, d = beam_ray(scene.turret.T_world_turret, pan_rad, tilt_rad)
    dist, _ = raycaster.cast(origin, d, 0.0)
    spec = scene.rangefinder
    return dist if spec.min_range_m <= dist <= spec.max_range_m else np.inf


def wrong_beams(scene, raycaster, beams) -> list[tuple[float, float, float, float]]:
    """The beams (pan, tilt, range) whose range is not the truth at their angles: (pan°, tilt°, range, true)."""
    wrong = []
    for pan, tilt, rho in beams:
        truth = true_range(scene, raycaster, pan, tilt)
        ok = abs(rho - truth) < 5 * SIGMA if np.isfinite(rho) else not np.isfinite(truth)
        if not ok:
            wrong.append((np.degrees(pan), np.degrees(tilt), rho, truth))
    return wrong


def run_trial(kind: str, seed: int, workcell, make_site, drivers, timed: bool = False):
    """One scan with an unplug at a random point: (beams returned, DeviceError or None, unplugs applied).

    timed: the unit power-cycles (and homes) just as the range finder starts a shot after a random
    beam, with no reply lost: the driver learns of it only when it next talks to the turret.
    """
    rng = np.random.default_rng(seed)
    site, rf_url, tu_url = make_site(sigma_m=SIGMA, seed=seed)
    rf, tu = drivers(rf_url, tu_url)
    T = workcell.turret.T_world_turret
    C, _, _ = facing_face(workcell)
    n_beams = {"profile": 13, "face_patch": 9, "pixel": 4}[kind]
    at_beam = int(rng.integers(0, n_beams))
    # the unplug replaces the reply to one of the next turret commands: an ack or a position answer
    match = [None, b"*\r\n", b"* "][int(rng.integers(0, 3))]
    fault = Fault("unplug", match=match, delay_s=0.05)
    armed = [False]
    unplugs = []
    true_range_of_emulator = site.rangefinder.true_range
    power_cycle = threading.Event()

    def shot_after_a_power_cycle(t):
        if power_cycle.is_set():
            power_cycle.clear()
            unplugs.append("unplug")
            site.turret.unplug(0.0)  # replugged at once: the unit powers up and homes
            until = time.monotonic() + 1.0
            while site.mount.steps_at() != (0.0, 0.0) and time.monotonic() < until:
                time.sleep(0.001)
        return true_range_of_emulator(time.monotonic())

    site.rangefinder.true_range = shot_after_a_power_cycle

    def progress(p):
        if not armed[0] and p.done >= at_beam:
            armed[0] = True
            power_cycle.set() if timed else site.turret.faults.push(fault)

    try:
        if kind == "profile":
            pan, tilt, _ = aim(T, C)
            scan = profile_scan(
                tu,
                rf,
                tilt_rad=float(tilt),
                pan_start_rad=float(pan) - 0.05,
                pan_stop_rad=float(pan) + 0.05,
                pan_step_rad=8 * tu.pan_step_rad,
                progress=progress,
            )
            beams = list(zip(scan.pan_rad, scan.tilt_rad, scan.range_m))
        elif kind == "face_patch":
            uv = workcell.camera.project(C[None])[0]
            scan = face_patch_scan(
                workcell.camera, T, tu, rf, center_uv=uv, half_size_px=6.0, spacing_px=4.0, progress=progress
            )
            beams = list(zip(scan.pan_rad, scan.tilt_rad, scan.range_m))
        else:
            uv = workcell.camera.project(C[None])[0] + rng.uniform(-5, 5, 2)
            got = []
            pm = measure_at_pixel(
                workcell.camera,
                T,
                uv,
                tu,
                rf,
                shots=3,
                progress=lambda p: (got.append(p.beam) if p.beam is not None else None, progress(p)),
            )
            beams = [b for b in got if b is not None] + [(pm.pan_rad, pm.tilt_rad, pm.range_m)]
        error = None
    except DeviceError as exc:
        beams, error = [], exc
    finally:
        rf.close()
        tu.close()
    return beams, error, unplugs + [k for k, _ in site.turret.faults.applied]


@pytest.mark.parametrize("timed", [False, True], ids=["at a reply", "during a shot"])
@pytest.mark.parametrize("kind", ["profile", "face_patch", "pixel"])
def test_an_unplug_mid_scan_never_gives_a_wrong_beam(kind, timed, workcell, make_site, drivers):
    raycaster = BeamCaster(workcell)
    total = unplugged = errors = 0
    wrong: list = []
    # The trials side by side (each its own emulated site and drivers): a trial mostly waits on its drivers'
    # deadlines after the unplug, 0.4-0.6 s of its 0.5-0.7.
    with ThreadPoolExecutor(max_workers=4) as pool:
        trials = list(pool.map(lambda seed: run_trial(kind, seed, workcell, make_site, drivers, timed), range(TRIALS)))
    for seed, (beams, error, applied) in enumerate(trials):
        unplugged += applied.count("unplug")
        errors += error is not None
        total += len(beams)
        wrong += [(seed, *w) for w in wrong_beams(workcell, raycaster, beams)]
    bad_scans = len({w[0] for w in wrong})
    print(
        f"\n{kind}, unplug {'during a shot' if timed else 'at a reply'}: {TRIALS} scans, {unplugged} unplugs, "
        f"{errors} DeviceErrors, {len(wrong)} wrong beams of {total} (in {bad_scans} scans)"
    )
    assert unplugged >= TRIALS - 2  # the fault really happened (a scan may end before the last reply it matches)
    assert not wrong, (
        f"{len(wrong)} of {total} beams reported where the head was not (seed, pan°, tilt°, range, true): {wrong[:5]}"
    )


def test_a_head_that_reports_another_position_stops_the_scan(workcell, make_site, drivers, monkeypatch):
    """The scans record the position the head reports; one that differs from the plan is a DeviceError."""
    site, rf_url, tu_url = make_site(sigma_m=SIGMA)
    rf, tu = drivers(rf_url, tu_url)
    C, _, _ = facing_face(workcell)
    pan, tilt, _ = aim(workcell.turret.T_world_turret, C)
    real = tu.move_to_steps
    calls = [0]

    def drifting(pan=None, tilt=None, **kw):
        calls[0] += 1
        got = real(pan, tilt, **kw)
        return got if calls[0] < 3 else (got[0], got[1] - 1)  # from the third beam on, one step low

    monkeypatch.setattr(tu, "move_to_steps", drifting)
    with pytest.raises(DeviceError, match="instead of"):
        profile_scan(tu, rf, tilt_rad=float(tilt), pan_start_rad=float(pan), pan_stop_rad=float(pan) + 0.02)
    calls[0] = 0
    uv = workcell.camera.project(C[None])[0]
    with pytest.raises(DeviceError, match="instead of"):
        face_patch_scan(
            workcell.camera, workcell.turret.T_world_turret, tu, rf, center_uv=uv, half_size_px=6.0, spacing_px=4.0
        )
