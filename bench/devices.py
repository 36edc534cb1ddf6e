"""Benchmark of the device chain: drivers ↔ emulators, with the serial line's rate modelled.

Run: .venv/bin/python bench/devices.py [--trials 5] [--shots 10] [--beams 20] [--seed 0] [--full]
(--full: the timing tables with every configuration; by default the fault matrix and the quick ones.)

Fault matrix: for each device fault (rows) and each device, N seeded trials, each one operation
through the driver with the fault injected into a reply of it (which reply: drawn among the
operation's replies of the matching kind); the outcome is "right" (the value returned is the
truth, no retry), "recovered" (right after a retry, resync, re-read or reconnect), "error" (a
DeviceError that says what happened), or "WRONG" (a value returned that is not the truth: the
target is zero). Turret trial: an absolute move to a random position and a position query; right
when both return where the emulated head is. Range-finder trial: one ``measure()`` at a random
point of the box's facing face (the last ones near it); right within 5 σ_ρ of the true range.
Lines modelled at 19200 (DLS) and 9600 (PTU) baud, 10 ms measurements, driver deadlines 0.15 s.

Setup: the bundled scene (scenes/workcell), static (t = 0); the turret's beam on the centre of
the unknown box's face that faces it (~1.46 m). Emulators as shipped: the DLS measures in
100 ms + 5 ms/m (normal mode; 50 ms for "fast"), range noise σ_ρ = 5 mm; the PTU moves at
1000 steps/s (0.0514° a step). The line rate is modelled by the emulators: every byte costs
10 bits / baud each way (start + 7E1 or 8N1 + stop), the measurement delay is added, and a reply
is delivered when its last byte would have arrived. The "model" column is that arithmetic alone:
  shot    = delay + 5 ms/m × range + (len("s0g\\r") + len("g0g+dddddddd\\r\\n")) × 10 / baud
            + 16 × 10 / baud + 2 ms (listening one line more: a second reply voids the shot)
  step    = 2 × (len("PPnnnn ") + len("A ") + len("PP ") + len("TP ")) + 3 + 3 + len("* nnnn\\r\\n") × 2) × 10 / baud
            + 1 step / speed
            (absolute move, wait for the end, read the position back: what every scan beam does;
            each command comes back as its echo before its reply)
  check   = (2 × (len("PP ") + len("TP ")) + 2 × len("* nnnn\\r\\n")) × 10 / baud
            (after the shot: is the head still there? a unit that power-cycled has homed)
  beam    = step + shot + check
"Measured" is wall-clock time through the driver (median and 90th percentile), on this shared
machine (load average printed): the difference is the host's own cost (Python, threads, pty);
the "∞" rows (no line model, no measurement time) show that cost alone.
Faults: each reply faulty with the given probability, kinds drawn evenly among the line faults
drop, late (0.3 s), truncate, split, junk, garble, unsolicited (a device error stops a scan by
design, an unplug costs a reconnection: both are tested, not benchmarked); the scan's points are
then checked against the true surfaces.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import trimesh  # noqa: E402

from app.devices.acquisition import profile_scan  # noqa: E402
from app.devices.drivers.rangefinder import RangeFinder  # noqa: E402
from app.devices.drivers.turret import Turret  # noqa: E402
from app.devices.site import EmulatedSite  # noqa: E402
from app.scene import default_scene_path, load_scene  # noqa: E402
from core.rangefinder import aim  # noqa: E402

SHOT_CHARS = len("s0g\r") + len("g0g+00014603\r\n") + 16  # and one line's listen for a second reply
GUARD_S = 0.002


def step_chars(pan: int, tilt: int) -> int:
    """Characters on the line for a pan step: PP, A, and the read-back of both axes (PP?, TP?)."""
    return (
        2 * (len(f"PP{pan} ") + len("A ") + len("PP ") + len("TP "))
        + 3
        + 3
        + len(f"* {pan}\r\n")
        + len(f"* {tilt}\r\n")
    )


def check_chars(pan: int, tilt: int) -> int:
    """Characters on the line for the check after a shot that the head is still there (PP?, TP?)."""
    return 2 * (len("PP ") + len("TP ")) + len(f"* {pan}\r\n") + len(f"* {tilt}\r\n")


def face_target(scene):
    """Centre of the unknown box's face that looks most toward the turret (world (3,))."""
    b = scene.body("unknown_box")
    T = b.pose_at(0.0)
    C = b.model.face_centroids() @ T[:3, :3].T + T[:3, 3]
    N = b.model.face_normals() @ T[:3, :3].T
    o = scene.turret.T_world_turret[:3, 3]
    k = int(np.argmax(np.einsum("ij,ij->i", N, (o - C) / np.linalg.norm(o - C, axis=1)[:, None])))
    return C[k]


class Chain:
    """An emulated site and its two drivers."""

    def __init__(
        self, scene, *, rf_baud, tu_baud, delay_s, per_m_s=0.005, transport="pty", rates=None, seed=0, tmp=None
    ):
        self.site = EmulatedSite(
            scene,
            clock=lambda: 0.0,
            seed=seed,
            rangefinder_baud=rf_baud,
            turret_baud=tu_baud,
            measure_delay_s=delay_s,
            delay_per_m_s=per_m_s,
            fault_rates=rates,
        )
        if transport == "pty":
            urls = self.site.serve_pty(
                tmp / f"rf-{rf_baud}-{tu_baud}-{delay_s}", tmp / f"tu-{rf_baud}-{tu_baud}-{delay_s}"
            )
        else:
            urls = self.site.serve_inprocess()
        self.rf = RangeFinder(urls[0], baudrate=rf_baud or 19200, attempt_timeout_s=1.0)
        self.tu = Turret(urls[1], baudrate=tu_baud or 9600, attempt_timeout_s=1.0)

    def close(self):
        self.rf.close()
        self.tu.close()
        self.site.close()


def stats_ms(samples):
    a = np.asarray(samples) * 1e3
    return float(np.median(a)), float(np.percentile(a, 90))


def bench_shots(scene, target, shots, tmp, full=False):
    rows = []
    configs = (
        ("pty", 19200, 0.1, 0.005),
        ("pty", 9600, 0.1, 0.005),
        ("pty", 19200, 0.05, 0.005),
        ("mcit://", 19200, 0.1, 0.005),
        ("pty", 0, 0.0, 0.0),
        ("mcit://", 0, 0.0, 0.0),
    )
    if not full:
        configs = configs[:1] + configs[-1:]
    for transport, rf_baud, delay, per_m in configs:
        chain = Chain(
            scene,
            rf_baud=rf_baud,
            tu_baud=9600,
            delay_s=delay,
            per_m_s=per_m,
            transport="pty" if transport == "pty" else "inprocess",
            tmp=tmp,
        )
        try:
            pan, tilt, rho = aim(scene.turret.T_world_turret, target)
            chain.tu.move_to(float(pan), float(tilt))
            chain.rf.measure()
            times = []
            for _ in range(shots):
                t0 = time.perf_counter()
                chain.rf.measure()
                times.append(time.perf_counter() - t0)
            line = SHOT_CHARS * 10 / rf_baud if rf_baud else 0.0
            model = delay + per_m * float(rho) + line + GUARD_S
            rows.append((transport, rf_baud or "∞", f"{delay * 1e3:.0f}", model * 1e3, *stats_ms(times)))
        finally:
            chain.close()
    print("\nRange-finder shot round trip (RangeFinder.measure), ms")
    print(f"{'transport':>9} {'baud':>6} {'delay':>6} {'model':>8} {'median':>8} {'p90':>8} {'host cost':>9}")
    for t, b, d, model, med, p90 in rows:
        print(f"{t:>9} {b!s:>6} {d:>6} {model:8.1f} {med:8.1f} {p90:8.1f} {med - model:9.1f}")


def bench_steps(scene, target, shots, tmp, full=False):
    rows = []
    for tu_baud in (9600, 19200, 0) if full else (9600,):
        chain = Chain(scene, rf_baud=19200, tu_baud=tu_baud, delay_s=0.1, tmp=tmp)
        try:
            pan, tilt, _ = aim(scene.turret.T_world_turret, target)
            p, t = chain.tu.rad_to_steps(float(pan), float(tilt))
            chain.tu.move_to_steps(p, t)
            times = []
            for i in range(shots):
                t0 = time.perf_counter()
                chain.tu.move_to_steps(p + 1 + i, None)
                times.append(time.perf_counter() - t0)
            model = (step_chars(p, t) * 10 / tu_baud if tu_baud else 0.0) + 1 / scene.turret.speed_steps_s
            rows.append((tu_baud or "∞", model * 1e3, *stats_ms(times)))
        finally:
            chain.close()
    print("\nTurret one-step absolute move with wait and read-back (Turret.move_to_steps), ms")
    print(f"{'baud':>6} {'model':>8} {'median':>8} {'p90':>8} {'host cost':>9}")
    for b, model, med, p90 in rows:
        print(f"{b!s:>6} {model:8.1f} {med:8.1f} {p90:8.1f} {med - model:9.1f}")


def surface_distance(scene, X):
    best = np.full(len(X), np.inf)
    for b in scene.bodies:
        V, F = b.model.triangles()
        T = b.pose_at(0.0)
        mesh = trimesh.Trimesh(V @ T[:3, :3].T + T[:3, 3], F, process=False)
        best = np.minimum(best, trimesh.proximity.closest_point(mesh, X)[1])
    return best


def bench_scans(scene, target, beams, tmp, seed, full=False):
    kinds = [
        "drop",
        "late",
        "truncate",
        "split",
        "junk",
        "garble",
        "unsolicited",
        "early",
    ]  # line faults; a device error stops a scan by design
    rows = []
    configs = (
        (19200, 9600, 0.1, 0.0),
        (19200, 9600, 0.05, 0.0),
        (9600, 9600, 0.1, 0.0),
        (0, 0, 0.1, 0.0),
        (19200, 9600, 0.1, 0.02),
        (19200, 9600, 0.1, 0.10),
    )
    for rf_baud, tu_baud, delay, rate in configs if full else configs[:1]:
        rates = {k: rate / len(kinds) for k in kinds} if rate else None
        chain = Chain(scene, rf_baud=rf_baud, tu_baud=tu_baud, delay_s=delay, rates=rates, seed=seed, tmp=tmp)
        for emu in (chain.site.rangefinder, chain.site.turret):
            emu.faults.default_delay_s = 0.3
        try:
            pan, tilt, rho = aim(scene.turret.T_world_turret, target)
            step = chain.tu.pan_step_rad
            start = float(pan) - beams // 2 * 2 * step
            chain.tu.move_to(start, float(tilt))
            t0 = time.perf_counter()
            scan = profile_scan(
                chain.tu,
                chain.rf,
                tilt_rad=float(tilt),
                pan_start_rad=start,
                pan_stop_rad=start + (beams - 1) * 2 * step,
                pan_step_rad=2 * step,
            )
            elapsed = time.perf_counter() - t0
            X = scan.points(scene.turret.T_world_turret)[scan.hits]
            worst = float(surface_distance(scene, X).max() / scene.rangefinder.sigma_range_m) if len(X) else np.nan
            shot = delay + 0.005 * float(rho) + (SHOT_CHARS * 10 / rf_baud if rf_baud else 0.0) + GUARD_S
            steps = chain.tu.rad_to_steps(float(pan), float(tilt))
            move = (
                (step_chars(*steps) + check_chars(*steps)) * 10 / tu_baud if tu_baud else 0.0
            ) + 2 / scene.turret.speed_steps_s
            retries = chain.rf.stats["resyncs"] + chain.tu.stats["resyncs"]
            faults = len(chain.site.rangefinder.faults.applied) + len(chain.site.turret.faults.applied)
            rows.append(
                (
                    rf_baud or "∞",
                    tu_baud or "∞",
                    f"{delay * 1e3:.0f}",
                    f"{rate:.0%}",
                    1 / (shot + move),
                    len(scan) / elapsed,
                    f"{faults}/{retries}",
                    f"{int(scan.hits.sum())}/{len(scan)}",
                    worst,
                )
            )
        finally:
            chain.close()
    print(f"\nProfile scan across the unknown box ({beams} beams, 2 steps = 0.103° apart, 1 shot each), beams/s")
    print(
        f"{'RF baud':>7} {'PTU baud':>8} {'delay':>6} {'faults':>6} {'model':>7}"
        f" {'measured':>8} {'faults/resyncs':>14} {'hits':>7} {'max |d|/σ':>9}"
    )
    for rb, tb, d, fr, model, meas, fx, hits, worst in rows:
        print(f"{rb!s:>7} {tb!s:>8} {d:>6} {fr:>6} {model:7.2f} {meas:8.2f} {fx:>14} {hits:>7} {worst:9.2f}")
    print("max |d|/σ: largest distance of a scanned point to the true surfaces, in σ_ρ (all within the noise if ≲ 4)")


# --------------------------------------------------------------------------- fault matrix
def _garbage_line(rng) -> bytes:
    pool = np.frombuffer(b"!*0123456789 PTg?@E+-\x00\x93\xff" + bytes(range(33, 127)), np.uint8)
    return bytes(rng.choice(pool, int(rng.integers(3, 40))).tolist()) + b"\r\n"


def matrix_rows(device: str):
    """(row name, f(rng) -> faults to push) for a device; `m` draws which reply the fault hits."""
    from app.devices.faults import Fault

    def m(rng):
        if device == "rangefinder":
            return b"g0g"
        return [b"*\r", b"* "][int(rng.integers(2))]  # an acknowledgement, or a position's value

    rows = [
        ("noise (junk bytes before a reply)", lambda r: [Fault("junk", match=m(r))]),
        ("garbage line", lambda r: [Fault("unsolicited", match=m(r), data=_garbage_line(r))]),
        (
            "dropped bytes (truncated reply)",
            lambda r: [Fault("truncate", match=m(r), keep_terminator=bool(r.random() < 0.5))],
        ),
        ("split reply", lambda r: [Fault("split", match=m(r), delay_s=float(r.uniform(0.0, 0.1)))]),
        ("late reply", lambda r: [Fault("late", match=m(r), delay_s=float(r.uniform(0.05, 0.3)))]),
        ("timeout (dropped reply)", lambda r: [Fault("drop", match=m(r))]),
        ("garbled character", lambda r: [Fault("garble", match=m(r))]),
        ("unsolicited line", lambda r: [Fault("unsolicited", match=m(r))]),
        ("early reply (injected before)", lambda r: [Fault("early", match=m(r))]),
        ("device error", lambda r: [Fault("error", match=m(r))]),
        ("unplug and replug", lambda r: [Fault("unplug", match=m(r), delay_s=float(r.uniform(0.05, 0.3)))]),
    ]
    if device == "rangefinder":
        rows.insert(
            7,
            (
                "jump (garbled digit, >= 1 cm)",
                lambda r: [
                    Fault("garble", match=b"g0g", at=int(r.integers(4, 10)), data=bytes([48 + int(r.integers(10))]))
                ],
            ),
        )
    else:
        rows.insert(
            7,
            (
                "swapped digits in a position",
                lambda r: [
                    Fault("garble", match=b"* ", at=int(r.integers(2, 4)), data=bytes([48 + int(r.integers(10))]))
                ],
            ),
        )
    rows.append(
        ("three faults at once", lambda r: [f for _ in range(3) for f in rows[int(r.integers(len(rows) - 1))][1](r)])
    )
    return rows


RECOVERY_STATS = (
    "resyncs",
    "reconnects",
    "timeouts",
    "corrupt",
    "jumps",
    "two_replies",
)  # a retry, re-read or reconnect


def matrix_trials(scene, trials: int, seed: int, attempt_timeout_s: float = 0.15, workers: int = 1):
    """{(device, row): Counter of outcomes}. ``attempt_timeout_s``: the drivers' wait for one reply (a loaded
    machine's emulator answers late: the suite gives it longer than the bench). ``workers``: rows run side by side,
    each on its own emulated site (a row mostly waits on the serial lines' timing and the drivers' deadlines)."""
    from concurrent.futures import ThreadPoolExecutor

    from app.render.raycast import BeamCaster

    caster = BeamCaster(scene)
    face = face_target(scene)
    rows = [
        (device, r_i, row, make)
        for device in ("turret", "rangefinder")
        for r_i, (row, make) in enumerate(matrix_rows(device))
    ]

    def run(job):
        device, r_i, row, make = job
        return (device, row), _matrix_row(scene, caster, face, device, r_i, make, trials, seed, attempt_timeout_s)

    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        return dict(pool.map(run, rows))


def _matrix_row(scene, caster, face, device: str, r_i: int, make, trials: int, seed: int, attempt_timeout_s: float):
    """One fault row's ``trials`` on a new emulated site: a Counter of outcomes."""
    from collections import Counter

    from app.devices import DeviceError
    from core.rangefinder import beam_ray

    exact_site = dict(
        rangefinder_baud=19200, turret_baud=9600, measure_delay_s=0.01, delay_per_m_s=0.0, no_target_delay_s=0.05
    )
    driver = dict(attempt_timeout_s=attempt_timeout_s, retries=2, reconnect_timeout_s=max(1.0, 4 * attempt_timeout_s))
    sigma = scene.rangefinder.sigma_range_m
    rng = np.random.default_rng([seed, r_i, device == "turret"])
    site = EmulatedSite(scene, clock=lambda: 0.0, seed=seed + r_i, **exact_site)
    urls = site.serve_inprocess()
    rf = RangeFinder(urls[0], **driver)
    tu = Turret(urls[1], **driver)
    out = Counter()
    try:
        tu.speed_steps_s()
        aim0 = tu.rad_to_steps(*aim(scene.turret.T_world_turret, face)[:2])
        emu = site.turret if device == "turret" else site.rangefinder
        drv = tu if device == "turret" else rf
        for _ in range(trials):
            if device == "turret":
                target = (aim0[0] + int(rng.integers(-300, 301)), aim0[1] + int(rng.integers(-200, 201)))
            else:  # a point of the facing face within ±2 cm of its centre
                target = tu.rad_to_steps(*aim(scene.turret.T_world_turret, face + rng.uniform(-0.02, 0.02, 3))[:2])
                tu.move_to_steps(*target)
            before = sum(drv.stats[k] for k in RECOVERY_STATS)
            emu.faults.push(*make(rng))
            try:
                if device == "turret":
                    got = tu.move_to_steps(*target)
                    pos = tu.position_steps()
                    truth = tuple(int(round(v)) for v in site.mount.steps_at())
                    ok = got == truth == target and pos == truth
                else:
                    value = rf.measure()
                    o, d = beam_ray(scene.turret.T_world_turret, *site.mount.angles_rad())
                    ok = abs(value - caster.cast(o, d)[0]) <= 5 * sigma
                retried = sum(drv.stats[k] for k in RECOVERY_STATS) > before
                out["WRONG" if not ok else "recovered" if retried else "right"] += 1
            except DeviceError:
                out["error"] += 1
                emu.faults.clear()
                time.sleep(0.05)  # let a late reply or a replug land before the next trial
                try:  # back to a known state, fault-free
                    tu.move_to_steps(*aim0)
                except DeviceError:
                    tu.connect()
                    tu.move_to_steps(*aim0)
            emu.faults.clear()
    finally:
        rf.close()
        tu.close()
        site.close()
    return out


def bench_fault_matrix(scene, trials, seed):
    t0 = time.perf_counter()
    results = matrix_trials(scene, trials, seed)
    cols = ("right", "recovered", "error", "WRONG")
    print(f"\nFault matrix: {trials} seeded trials per fault and device (seed {seed}); outcomes")
    print(f"{'device':>11} {'fault':<36} " + " ".join(f"{c:>9}" for c in cols))
    total = {c: 0 for c in cols}
    for (device, row), out in results.items():
        print(f"{device:>11} {row:<36} " + " ".join(f"{out[c]:>9}" for c in cols))
        for c in cols:
            total[c] += out[c]
    print(f"{'all':>11} {'':<36} " + " ".join(f"{total[c]:>9}" for c in cols))
    print(f"silently wrong: {total['WRONG']} of {sum(total.values())} trials ({time.perf_counter() - t0:.0f} s)")
    return total["WRONG"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", type=int, default=5, help="trials per fault and device in the fault matrix")
    ap.add_argument("--shots", type=int, default=10)
    ap.add_argument("--beams", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--full", action="store_true", help="every timing configuration (slower)")
    ap.add_argument("--matrix-only", action="store_true", help="only the fault matrix")
    args = ap.parse_args()
    import logging
    import tempfile

    logging.getLogger("mcit.devices").setLevel(logging.ERROR)  # the injected faults' warnings would drown the tables

    scene = load_scene(default_scene_path())
    scene = replace(scene, turret=replace(scene.turret, speed_steps_s=1000.0))
    target = face_target(scene)
    print(__doc__.split("\n\n", 2)[2])
    print(
        f"\nmachine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at "
        f"start; σ_ρ = {scene.rangefinder.sigma_range_m * 1e3:.0f} mm; target at "
        f"{np.linalg.norm(target - scene.turret.T_world_turret[:3, 3]):.3f} m"
    )
    wrong = bench_fault_matrix(
        replace(scene, turret=replace(scene.turret, speed_steps_s=4000.0)), args.trials, args.seed
    )
    if not args.matrix_only:
        with tempfile.TemporaryDirectory() as tmp:
            tmp = Path(tmp)
            bench_shots(scene, target, args.shots, tmp, args.full)
            bench_steps(scene, target, args.shots, tmp, args.full)
            bench_scans(scene, target, args.beams, tmp, args.seed, args.full)
    print(f"\nload average {os.getloadavg()[0]:.1f} at the end")
    return 1 if wrong else 0


if __name__ == "__main__":
    sys.exit(main())
