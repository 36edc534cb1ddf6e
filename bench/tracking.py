"""Benchmark of model-based edge tracking (app.vision.track) on real and rendered video.

Run: .venv/bin/python bench/tracking.py [--skip-rendered] [--repeat 3]

Sequences:
* visp-cube (../shared/data/visp-cube, ViSP-images, Inria): 218 real 640×480 grey frames of a
  hand-held camera around a textured 8.4 cm cube and a cylinder, one rigid model
  (cube_and_cylinder.cao), intrinsics cube.xml, initial pose cube.0.pos (ViSP's). Every frame.
  Also every 2nd and every 3rd frame (2× and 3× the motion between frames).
* visp-teabox (../shared/data/visp-teabox): 39 real frames (H.264), box model teabox.cao,
  initialised from the four teabox.init points clicked once on frame 0 (tests/app/vision/test_track.py
  records the pixels and how they were taken) with OpenCV's SQPnP.
* workcell: the project's prerecorded video (scenes/workcell/video.avi, rendered by app.render,
  stored as Motion-JPEG) of the paper's set-up, the parallelepiped tracked from its true pose in
  frame 0 through its large and small motions, against its true pose in every frame.
* rendered: a 20 × 13 × 8 cm box rendered by the project's renderer (app.render: exact ray
  casting, Lambert shading, area-coverage edges) at 640×480, f = 600 px, blur σ = 0.5 px, noise
  σ = 2 grey levels, moving 120 frames along a smooth path (up to 0.6° and 3.6 mm a frame), with its
  true pose known.

Measure of fit on real frames (app.vision.evaluate, independent of the tracker's own search):
the oriented chamfer distance of the projected visible model edges (silhouettes of the cylinder,
not its rims; every 2 px) to OpenCV's Canny edges (σ = 1 px, thresholds 10/30) whose gradient is
within 30° of the edge's normal; capped at 10 px; mean per frame. A perfect overlay scores about
0.25 px (Canny pixels sit on pixel centres). "held" is the initial pose kept without tracking.

Lost or tracked (issue 14): from perturbed starts, on (c) the rendered box (the calibration set),
(a) the workcell video and (b) visp-cube (reference: the tracker's own run from ViSP's pose), how
many frames each lost rule reports as tracked while more than 5° or 1 cm from the truth, and how
often it stops a run on a right frame; the old rule (confidence < 0.3) beside the new one; then
the tracker as it runs (its retries and first-frame capture, which the rule rows leave out),
with the first-frame capture on and off. ``--only confusion --confusion-seeds 1,2,3`` for other draws.

Capture range (issue 16): visp-cube from 10 starts 5° / 1 cm off the reference, 40 frames each:
runs tracked whole, frames reported tracked while wrong, runs lost at their first frame and that
frame's CPU time, with the first-frame coarse-to-fine capture (``start_capture_px``) on and off and
with a ±16 px band instead (the issue's anchors: ViSP 3 of 10, 7 of 10 with a 16 px band); with the
pose search near the given pose (``start_search``, issue 27) and without it (the capture of before).
visp-cube is the sequence the capture was developed on; visp-teabox and Castle-simu are held out.
``--only capture --capture-seeds 0,1,2,3,4,5`` for other draws of starts (seed 0: the issue's).

Fast motion (issue 27): every 2nd and 3rd frame of visp-cube (with cube_and_cylinder.cao and with
the plain cube.cao) and visp-teabox, on default settings ("now": the constant-velocity motion model)
beside the defaults of before ("before": issue 16's tracker), in the same run; with true poses,
Castle-simu (ViSP's, from Debian's visp-images-data, /usr/share/visp-images-data; skipped when
absent; held out: never tuned on) every 1st–3rd frame, and a rendered box on a circle at 10–40 px a
frame from rest (developed on), with the frames reported tracked while more than 5° / 1 cm off.
``--only fast`` for these alone. The capture range also runs on the held-out visp-teabox and
Castle-simu (20 frames a run).

Speed: the tracker alone (frames decoded beforehand), pinned to one core with one thread
(OpenCV, BLAS). Targets: mean edge distance ≤ 1.5 px on every frame of visp-cube, never lost,
≥ 30 frames/s at 640×480 on one core; issue 16: also on every 3rd frame, ≤ 8 ms mean per frame.
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time
from pathlib import Path

os.environ["OMP_NUM_THREADS"] = "1"
os.environ["OPENBLAS_NUM_THREADS"] = "1"
os.environ["MKL_NUM_THREADS"] = "1"

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchenv import pin_one_core  # noqa: E402

from app.models_io import read_cao  # noqa: E402
from app.vision.evaluate import edge_distance, oriented_edges  # noqa: E402
from app.vision.pnp import solve_pnp  # noqa: E402
from app.vision.sequence import iter_frames, read_init_points, read_visp_pose  # noqa: E402
from app.vision.synthetic import render_poses  # noqa: E402
from app.vision.track import EdgeTracker  # noqa: E402
from core.brep import BRep  # noqa: E402
from core.camera import Camera  # noqa: E402
from core.transforms import exp_so3, make_T, pose_error  # noqa: E402

cv2.setNumThreads(1)
DATA = (ROOT / ".." / "shared" / "data").resolve()
CUBE_K = np.array([[547.7367575, 0, 338.7036994], [0, 542.0744058, 234.5083345], [0, 0, 1]])
TEABOX_K = np.array([[839.21470, 0, 325.66776], [0, 839.44555, 243.69727], [0, 0, 1]])
# Pixels of the four teabox.init points on frame 0 (see tests/app/vision/test_track.py).
TEABOX_CLICKS = np.array([[192.0, 84.5], [349.5, 205.5], [324.0, 376.0], [458.5, 351.0]])
TARGET_PX = 1.5
TARGET_FPS = 30.0
TARGET_MS = 8.0
LAST_CPU_MS: list[float] = []  # CPU time per frame (ms) of the last run() kept: less moved by the load than wall time


# The trackers compared (issue 27): today's defaults, and the defaults before the motion model.
TRACKERS = (("now", {}), ("before", dict(motion_model=False, start_search=(0.0, 0.0, 0))))


def run(frames: list[np.ndarray], camera: Camera, model: BRep, T0: np.ndarray, repeat: int = 1, **kw):
    """Track the frames; (poses, confidences, lost index or None, ms per frame (best of repeats))."""
    best = None
    for _ in range(repeat):
        tracker = EdgeTracker(camera, model, T0, **kw)
        poses, conf, ms, cpu, lost_at = [], [], [], [], None
        for i, f in enumerate(frames):
            t0, c0 = time.perf_counter(), time.process_time()
            T, c, lost = tracker.track(f)
            ms.append(1e3 * (time.perf_counter() - t0))
            cpu.append(1e3 * (time.process_time() - c0))
            if lost:
                lost_at = i
                break
            poses.append(T)
            conf.append(c)
        if best is None or np.mean(ms) < np.mean(best[3]):
            best = (poses, np.array(conf), lost_at, np.array(ms))
            LAST_CPU_MS[:] = cpu
    return best


def distances(frames, camera, model, poses):
    out = []
    for f, T in zip(frames, poses):
        out.append(edge_distance(oriented_edges(f), camera, model, T).mean_px)
    return np.array(out)


def row(name, n_total, poses, conf, lost_at, ms, dist, held):
    n = len(poses)
    lost = "never" if lost_at is None else f"frame {lost_at}"
    ok = "yes" if (lost_at is None and dist.max() <= TARGET_PX) else "NO"
    print(
        f"  {name:22s}{n:>5d}/{n_total:<5d}{lost:>9s}{conf.min():7.2f}{conf.mean():7.2f}"
        f"{dist.mean():8.2f}{np.median(dist):8.2f}{dist.max():8.2f}{held.mean():8.2f}{held.max():8.2f}"
        f"{np.mean(ms):8.1f}{np.percentile(ms, 95):8.1f}{1e3 / np.mean(ms):8.0f}{np.mean(LAST_CPU_MS):9.1f}   {ok}"
    )


def real_sequences(repeat: int) -> None:
    """visp-cube (both models) and visp-teabox, every frame and every 2nd and 3rd (fast motion), on
    today's default settings ("now") and on the defaults before the motion model ("before")."""
    cube = DATA / "visp-cube"
    tea = DATA / "visp-teabox"
    print(
        "  sequence                     tracker frames       lost  conf   conf   dist    dist    dist    held    "
        "held    ms/f    ms/f  frames/s  cpu ms/f  ≤1.5 px,"
    )
    print(
        "                                       tracked             min    mean   mean   median   max     mean    "
        "max     mean    95 %    (mean)    mean    not lost"
    )
    if cube.is_dir():
        camera = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
        T0 = read_visp_pose(cube / "cube.0.pos")
        frames = [f for _, f in iter_frames(cube / "frames")]
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for f in frames]
        for cao in ("cube_and_cylinder.cao", "cube.cao"):
            model = read_cao(cube / cao)
            for step in (1, 2, 3):
                sub = frames[::step]
                held = distances(sub, camera, model, [T0] * len(sub))
                for name, kw in TRACKERS:
                    poses, conf, lost_at, ms = run(sub, camera, model, T0, repeat if step == 1 else 1, **kw)
                    dist = distances(sub, camera, model, poses)
                    label = f"cube{'' if cao.startswith('cube_and') else ' (cube.cao)'} every {step}"
                    row(f"{label:28s}{name:>7s}", len(sub), poses, conf, lost_at, ms, dist, held)
    else:
        print(f"  visp-cube: data not found at {cube} (skipped)")
    if tea.is_dir():
        model = read_cao(tea / "teabox.cao")
        camera = Camera.from_intrinsics(TEABOX_K, np.eye(4), 640, 480)
        T0 = solve_pnp(TEABOX_K, read_init_points(tea / "teabox.init"), TEABOX_CLICKS, 640, 480).T_cam_world
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(tea / "teabox.mp4")]
        for step in (1, 2, 3):
            sub = frames[::step]
            held = distances(sub, camera, model, [T0] * len(sub))
            for name, kw in TRACKERS:
                poses, conf, lost_at, ms = run(sub, camera, model, T0, repeat if step == 1 else 1, **kw)
                dist = distances(sub, camera, model, poses)
                row(f"{f'teabox (clicks) every {step}':28s}{name:>7s}", len(sub), poses, conf, lost_at, ms, dist, held)
    else:
        print(f"  visp-teabox: data not found at {tea} (skipped)")


CASTLE = Path("/usr/share/visp-images-data/ViSP-images/mbt-depth/Castle-simu")


def castle_data():
    """ViSP's Castle-simu (Debian's visp-images-data): (camera, model, frames, true poses) or None.

    40 rendered 640×480 frames of a castle (floor and tower, chateau.cao) with the true pose of each
    (CameraPose/Camera_NNN.txt, cMo) and intrinsics px = py = 700, u0 = 320, v0 = 240 (Config/chateau.xml)."""
    if not CASTLE.is_dir():
        return None
    camera = Camera.from_intrinsics(np.array([[700.0, 0, 320.0], [0, 700.0, 240.0], [0, 0, 1]]), np.eye(4), 640, 480)
    model = read_cao(CASTLE / "Models" / "chateau.cao")
    truth = [np.loadtxt(q) for q in sorted((CASTLE / "CameraPose").glob("Camera_*.txt"))]
    frames = [cv2.imread(str(q), cv2.IMREAD_GRAYSCALE) for q in sorted((CASTLE / "Images").glob("Image_*.pgm"))]
    return camera, model, frames, truth


def circle_sequence(speed_px: float, n: int = 40, omega: float = 0.3):
    """A box rendered on a circle at speed_px image pixels a frame (at 0.9 m, f = 600 px),
    turning 1.5° a frame, from rest: frame 1 already moves at full speed. (camera, model, frames, truth)."""
    W, H, f = 640, 480, 600.0
    camera = Camera.from_intrinsics(np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]]), np.eye(4), W, H)
    box = BRep.box(0.2, 0.13, 0.08)
    R0 = exp_so3([2.2, 0.4, 0.3])
    a = speed_px / omega * 0.9 / f
    truth = []
    for k in range(n):
        R = exp_so3(np.radians(1.5) * k * np.array([0.3, 0.8, 0.5])) @ R0
        p = [a * np.sin(omega * k), a * (np.cos(omega * k) - 1.0), 0.9 + 0.01 * np.sin(k / 5.0)]
        truth.append(make_T(R, p))
    frames = render_poses(camera, box, truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=1)
    return camera, box, frames, truth


def truth_rows(name: str, camera, model, frames, truth, steps=(1, 2, 3)) -> None:
    """Every ``step``-th frame from the true first pose, both trackers: frames reported tracked, where
    lost, the error (mean, max) of the frames tracked, the frames reported tracked while wrong (more than
    5° or 1 cm off), the image motion a frame (median over the model's vertices, largest), ms a frame."""
    for step in steps:
        sub, tru = frames[::step], truth[::step]
        move = max(
            float(
                np.median(
                    np.linalg.norm(
                        camera.project_obj(a, model.vertices) - camera.project_obj(b, model.vertices), axis=1
                    )
                )
            )
            for a, b in zip(tru, tru[1:])
        )
        for tname, kw in TRACKERS:
            poses, _, lost_at, ms = run(sub, camera, model, tru[0], **kw)
            err = np.array([pose_error(T, Tt) for T, Tt in zip(poses, tru)]) if poses else np.zeros((1, 2))
            wrong = int(np.sum((err[:, 0] > WRONG_DEG) | (err[:, 1] > WRONG_M))) if poses else 0
            lost = "never" if lost_at is None else f"frame {lost_at}"
            print(
                f"  {f'{name} every {step}':30s}{tname:>7s}{move:7.1f}{len(poses):>6d}/{len(sub):<4d}{lost:>9s}"
                f"{err[:, 0].mean():9.3f}{err[:, 0].max():8.3f}"
                f"{1e3 * err[:, 1].mean():9.2f}{1e3 * err[:, 1].max():8.2f}"
                f"{wrong:>7d}{np.mean(ms):8.1f}{np.mean(LAST_CPU_MS):8.1f}"
            )


def fast_sequences() -> None:
    """Fast motion with true poses: Castle-simu (held out) every 1st–3rd frame; a rendered box on a
    circle at 10–40 px a frame (developed on), both trackers."""
    print(
        "Fast motion with true poses (issue 27: follow 30 px a frame on default settings, 0 frames tracked while "
        f"more than {WRONG_DEG:.0f}° / {100 * WRONG_M:.0f} cm off)"
    )
    print(
        f"  {'sequence':30s}{'tracker':>7s}{'px/f':>7s}{'tracked':>11s}{'lost':>9s}{'rot mean°':>9s}{'max°':>8s}"
        f"{'mm mean':>9s}{'max':>8s}{'wrong':>7s}{'ms/f':>8s}{'cpu ms':>8s}"
    )
    castle = castle_data()
    if castle is None:
        print(f"  Castle-simu: not found at {CASTLE} (apt-get install visp-images-data; skipped)")
    else:
        truth_rows("Castle-simu (held out)", *castle)
    for speed in (10.0, 20.0, 30.0, 40.0):
        truth_rows(f"rendered circle {speed:.0f} px/f", *circle_sequence(speed), steps=(1,))


def rendered_sequence(n: int = 120, seed: int = 0):
    """A box on a smooth path, rendered: (camera, model, frames, true poses)."""
    W, H, f = 640, 480, 600.0
    camera = Camera.from_intrinsics(np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1]]), np.eye(4), W, H)
    box = BRep.box(0.2, 0.13, 0.08)
    R0 = exp_so3([2.2, 0.4, 0.3])
    t = np.arange(n)
    truth = []
    for k in t:
        r = np.radians(8.0) * np.array([np.sin(k / 23.0), np.cos(k / 31.0), np.sin(k / 17.0)])
        R = exp_so3(r) @ R0
        p = np.array([0.08 * np.sin(k / 40.0), 0.05 * np.sin(k / 27.0), 0.9 + 0.08 * np.sin(k / 35.0)])
        truth.append(make_T(R, p))
    frames = render_poses(camera, box, truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=seed)
    return camera, box, frames, truth


def workcell_sequence(repeat: int) -> None:
    """The project's own video (scenes/workcell, rendered by app.render) with its true poses."""
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    if scene.video is None or not scene.video.path.is_file():
        print(f"  workcell: no video at {scene.video.path if scene.video else '(none)'} (skipped)")
        return
    body = scene.body("parallelepiped")
    frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(scene.video.path)]
    truth = [body.pose_at(k / scene.video.fps) for k in range(len(frames))]
    poses, conf, lost_at, ms = run(frames, scene.camera, body.model, truth[0], repeat)
    err = np.array([pose_error(T, Tt) for T, Tt in zip(poses, truth)])
    steps = np.array([pose_error(a, b) for a, b in zip(truth, truth[1:])])
    W, H = scene.camera.size
    lost = "never" if lost_at is None else f"frame {lost_at}"
    print(
        f"  workcell video (app.render, Motion-JPEG), {W}×{H}, the parallelepiped at ~2 m, {len(frames)} frames at "
        f"{scene.video.fps:.0f} fps; motion per frame up to "
        f"{steps[:, 0].max():.2f}° and {1e3 * steps[:, 1].max():.1f} mm"
    )
    print(
        f"  {'':22s}{'tracked':>9s}{'lost':>8s}{'rot mean °':>12s}{'rot max °':>11s}"
        f"{'trans mean mm':>15s}{'trans max mm':>14s}{'ms/f':>8s}{'frames/s':>10s}"
    )
    print(
        f"  {'workcell':22s}{len(poses):>5d}/{len(frames):<3d}{lost:>8s}{err[:, 0].mean():12.3f}{err[:, 0].max():11.3f}"
        f"{1e3 * err[:, 1].mean():15.2f}{1e3 * err[:, 1].max():14.2f}{np.mean(ms):8.1f}{1e3 / np.mean(ms):10.0f}"
    )


WRONG_DEG, WRONG_M = 5.0, 0.01  # a pose further than this from the truth is wrong
# (name, lost below this confidence, lost above this mean distance of the model's edges to the image's)
RULES = (
    ("confidence < 0.3 (old)", 0.3, np.inf),
    ("confidence < 0.5", 0.5, np.inf),
    ("conf. < 0.5 or > 1.5 px (now)", 0.5, 1.5),
)


def ref_error(T: np.ndarray, Tr: np.ndarray) -> tuple[float, float]:
    """(degrees, metres) from T to the reference Tr (4, 4), or to the nearest of several (R, 4, 4): on
    visp-cube the runs of both trackers from ViSP's pose part 3.8° / 17 mm in frames 130–160, where the
    image fits both within 0.6 px, and a pose on either is not wrong."""
    if np.ndim(Tr) == 3:
        return min((pose_error(T, r) for r in Tr), key=lambda e: (e[0] > WRONG_DEG or e[1] > WRONG_M, e[0]))
    return pose_error(T, Tr)


def perturbed(T: np.ndarray, deg: float, m: float, rng: np.random.Generator) -> np.ndarray:
    """T turned by deg about a random axis (object frame) and moved m along a random direction."""
    a, d = rng.normal(size=3), rng.normal(size=3)
    T_d = make_T(exp_so3(np.radians(deg) * a / np.linalg.norm(a)), np.zeros(3))
    out = T @ T_d
    out[:3, 3] += m * d / np.linalg.norm(d)
    return out


def open_runs(frames, camera, model, truth, starts):
    """Track from each (first frame, start pose, frames) with the support tests off (lost_confidence = 0,
    max_edge_distance_px = ∞).

    Returns per run the (confidence, edge distance, wrong) of each frame tracked, and whether another
    test (too few samples, a failed step, a jump) stopped it. Until the first frame a rule flags, a
    tracker with that rule goes exactly the same way, so every rule is read off these runs.
    """
    runs = []
    for s, T0, n in starts:
        tracker = EdgeTracker(camera, model, T0, lost_confidence=0.0, max_edge_distance_px=np.inf)
        conf, dist, wrong, stopped = [], [], [], False
        for f, Tt in zip(frames[s : s + n], truth[s : s + n]):
            T, c, lost = tracker.track(f)
            if lost:
                stopped = True
                break
            deg, m = ref_error(T, Tt)
            conf.append(c)
            dist.append(tracker.diagnostics.edge_distance_px)
            wrong.append(deg > WRONG_DEG or m > WRONG_M)
        runs.append((np.array(conf), np.array(dist), np.array(wrong, bool), stopped))
    return runs


def confusion_rows(name: str, runs) -> None:
    """Print, per lost rule, the frames reported as tracked and how many of them were wrong."""
    n_fr = sum(len(c) for c, _, _, _ in runs)
    n_wrong = sum(int(w.sum()) for _, _, w, _ in runs)
    n_stop = sum(st for _, _, _, st in runs)
    print(f"  {name}: {len(runs)} runs, {n_fr} frames ({n_wrong} wrong), {n_stop} runs stopped by the other tests")
    for rule, thr, max_px in RULES:
        tracked = wrong_tracked = right_lost = wrong_lost = 0
        fr_wrong_kept = fr_right_flagged = 0
        for conf, dist, wrong, _ in runs:
            flag = (conf < thr) | (dist > max_px)
            fr_wrong_kept += int((wrong & ~flag).sum())
            fr_right_flagged += int((~wrong & flag).sum())
            k = int(np.argmax(flag)) if flag.any() else len(conf)  # the run stops at its first flagged frame
            tracked += k
            wrong_tracked += int(wrong[:k].sum())
            if k < len(conf):
                right_lost += int(not wrong[k])
                wrong_lost += int(wrong[k])
        print(
            f"    {rule:30s}{tracked:>9d}{wrong_tracked:>15d}{right_lost:>13d}{wrong_lost:>13d}"
            f"{fr_wrong_kept:>8d}/{n_wrong:<5d}{fr_right_flagged:>9d}/{n_fr - n_wrong:<5d}"
        )


AS_RUN = (
    ("as run, now (motion model, pose search)", {}),
    ("as run, the pose search only when the captures fail", dict(start_check=False)),
    ("as run, without the pose search (last session)", dict(start_search=(0.0, 0.0, 0))),
    ("as run, issue 16's defaults (no motion model)", dict(motion_model=False, start_search=(0.0, 0.0, 0))),
    ("as run, first-frame capture off (before issue 16)", dict(motion_model=False, start_capture_px=())),
)


def as_run_rows(frames, camera, model, truth, starts) -> None:
    """The tracker as it runs (its lost rule, its retries, the first-frame capture on and off) from the
    same starts: frames reported tracked, of them wrong, and runs lost (at the first frame / later).

    The rows above read every rule off runs with the tests off, where no retry or capture happens
    (a capture's answer must pass the tests); these rows show what the retries change."""
    for name, kw in AS_RUN:
        tracked = wrong_tracked = lost_first = lost_later = 0
        for s, T0, n in starts:
            tracker = EdgeTracker(camera, model, T0, **kw)
            for i, (f, Tt) in enumerate(zip(frames[s : s + n], truth[s : s + n])):
                T, _, lost = tracker.track(f)
                if lost:
                    lost_first += i == 0
                    lost_later += i > 0
                    break
                deg, m = ref_error(T, Tt)
                tracked += 1
                wrong_tracked += deg > WRONG_DEG or m > WRONG_M
        print(
            f"    {name:42s}{tracked:>9d}{wrong_tracked:>15d}   runs "
            f"lost at the first frame {lost_first}, later {lost_later}"
        )


def confusion_tables(repeat_seed: int = 0, skip_rendered: bool = False) -> None:
    """Wrong-but-tracked and right-but-lost, old and new lost rule, on sequences with true poses."""
    rng = np.random.default_rng(repeat_seed)
    print(
        f"Lost or tracked (seed {repeat_seed}): from perturbed starts, a frame is wrong when "
        f"its pose is more than {WRONG_DEG:.0f}° or {100 * WRONG_M:.0f} cm from the truth"
    )
    print("  as run (a run stops at its first lost frame): frames reported as tracked, of them wrong (wrong but")
    print("  tracked), runs stopped on a right frame (right but lost) or on a wrong one; per frame, over all")
    print("  frames of the runs with the support tests off: wrong frames not flagged, right frames flagged")
    print(
        f"    {'lost when':30s}{'tracked':>9s}{'wrong+tracked':>15s}{'right+lost':>13s}{'wrong+lost':>13s}"
        f"{'wrong not flagged':>19s}{'right flagged':>14s}"
    )
    if not skip_rendered:
        camera, box, frames, truth = rendered_sequence(seed=3)
        starts = []
        for k in range(24):
            deg = (5.0, 10.0, 15.0, 20.0)[k % 4]
            s = int(rng.integers(0, len(frames) - 30))
            starts.append((s, perturbed(truth[s], deg, 0.002 * deg, rng), 30))
        confusion_rows(
            "(c) rendered box (calibration), starts 5–20° and 1–4 cm off, 30 frames each",
            open_runs(frames, camera, box, truth, starts),
        )
        as_run_rows(frames, camera, box, truth, starts)
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    if scene.video is not None and scene.video.path.is_file():
        body = scene.body("parallelepiped")
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(scene.video.path)]
        truth = [body.pose_at(k / scene.video.fps) for k in range(len(frames))]
        starts = []
        for _ in range(16):
            s = int(rng.integers(0, len(frames) - 40))
            starts.append((s, perturbed(truth[s], 5.0, 0.01, rng), 40))
        confusion_rows(
            "(a) workcell video (truth: the scene), starts 5° and 1 cm off, 40 frames each",
            open_runs(frames, scene.camera, body.model, truth, starts),
        )
        as_run_rows(frames, scene.camera, body.model, truth, starts)
    else:
        print("  (a) workcell: no video (skipped)")
    cube = DATA / "visp-cube"
    if cube.is_dir():
        model = read_cao(cube / "cube_and_cylinder.cao")
        camera = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(cube / "frames")]
        # No true poses come with it: the reference is the trackers' own runs from ViSP's pose (never
        # lost, ≤ 1.28 px from the image edges on every frame, the table above), now's and before's; a
        # frame is wrong when far from both (``ref_error``); the starts are drawn around before's.
        runs = []
        for _, kw in TRACKERS:
            ref_tracker = EdgeTracker(camera, model, read_visp_pose(cube / "cube.0.pos"), **kw)
            runs.append([ref_tracker.track(f).T_world_obj for f in frames])
        ref = np.stack([np.array(r) for r in runs], axis=1)  # (frames, 2, 4, 4)
        starts = []
        for _ in range(16):
            s = int(rng.integers(0, len(frames) - 40))
            starts.append((s, perturbed(ref[s, 1], 5.0, 0.01, rng), 40))
        confusion_rows(
            "(b) visp-cube, real (reference: tracked from ViSP's pose by either tracker), starts 5° and 1 cm off, "
            "40 frames each",
            open_runs(frames, camera, model, ref, starts),
        )
        as_run_rows(frames, camera, model, ref, starts)
    else:
        print(f"  (b) visp-cube: data not found at {cube} (skipped)")


CAPTURE = (
    ("now: ±24/±16 px, the pose search ±5° / 1 cm, checked", {}),
    ("the pose search only when the captures fail", dict(start_check=False)),
    ("before the pose search (issue 27, last session)", dict(start_search=(0.0, 0.0, 0))),
    ("before: issue 16's defaults (no motion model)", dict(motion_model=False, start_search=(0.0, 0.0, 0))),
    ("first-frame capture off (before issue 16)", dict(motion_model=False, start_capture_px=())),
    ("both retries off, band ±16 px", dict(motion_model=False, capture_px=0.0, start_capture_px=(), search_px=16.0)),
)


def capture_table(
    frames, camera, model, ref, n_runs: int, n_frames: int, seeds, variants=CAPTURE, truth_lost_at=None
) -> None:
    """From n_runs starts 5° / 1 cm off the reference, n_frames each, per draw of starts (seed): runs
    tracked whole (never lost, every frame within 5° / 1 cm of the reference), runs captured (their
    first frame tracked within 5° / 1 cm), frames tracked, of them wrong, runs lost at their first
    frame, and the first frame's CPU time, per tracker; with ``truth_lost_at`` (the frame where the tracker
    started on the true pose is lost), the runs lost there or later too.

    ref : the reference poses, or a list of several references (visp-cube: the runs of both trackers
    from ViSP's pose, which part 3.8° / 17 mm in frames 130–160 where the image fits both within
    0.6 px): a frame is wrong when it is far from every one."""
    refs = ref if isinstance(ref, list) and np.ndim(ref[0]) == 3 else [ref]
    for seed in seeds:
        rng = np.random.default_rng(seed)
        starts = []
        for _ in range(n_runs):
            s = int(rng.integers(0, len(frames) - n_frames))
            starts.append((s, perturbed(refs[-1][s], 5.0, 0.01, rng)))
        for name, kw in variants:
            whole = captured = tracked = wrong_tracked = lost_first = lost_there = 0
            first_ms = []
            for s, T0 in starts:
                tracker = EdgeTracker(camera, model, T0, **kw)
                ok = True
                for i, f in enumerate(frames[s : s + n_frames]):
                    c0 = time.process_time()
                    T, _, lost = tracker.track(f)
                    if i == 0:
                        first_ms.append(1e3 * (time.process_time() - c0))
                    if lost:
                        lost_first += i == 0
                        lost_there += truth_lost_at is not None and s + i >= truth_lost_at
                        ok = False
                        break
                    tracked += 1
                    errs = [pose_error(T, r[s + i]) for r in refs]
                    if all(deg > WRONG_DEG or m > WRONG_M for deg, m in errs):
                        wrong_tracked += 1
                        ok = False
                    elif i == 0:
                        captured += 1
                whole += ok
            print(
                f"    {seed:>4d}  {name:52s}{whole:>3d} of {n_runs}{captured:>7d}{tracked:>9d}"
                f"{wrong_tracked:>15d}{lost_first:>13d}{np.mean(first_ms):11.1f} mean, {np.max(first_ms):.0f} max"
                + ("" if truth_lost_at is None else f"; lost where the run from the truth is, or later: {lost_there}")
            )


def capture_range(n_runs: int = 10, n_frames: int = 40, seeds: tuple[int, ...] = (0,)) -> None:
    """visp-cube from starts 5° / 1 cm off the reference (the tracker's own run from ViSP's pose;
    seed 0: the draw the issue 16 target is read on), and the held-out sequences: visp-teabox
    (reference: the tracker of before from the clicks, every frame, never lost) and Castle-simu (its
    true poses), 20 frames each; every 2nd frame of Castle-simu too (fast motion)."""
    header = (
        f"    {'seed':>4s}  {'tracker':52s}{'whole':>9s}{'captured':>9s}{'tracked':>9s}"
        f"{'wrong+tracked':>15s}{'lost at 1st':>13s}{'1st frame cpu ms':>18s}"
    )
    cube = DATA / "visp-cube"
    if cube.is_dir():
        model = read_cao(cube / "cube_and_cylinder.cao")
        camera = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(cube / "frames")]
        ref = []
        for _, kw in TRACKERS:
            ref_tracker = EdgeTracker(camera, model, read_visp_pose(cube / "cube.0.pos"), **kw)
            ref.append(np.array([ref_tracker.track(f).T_world_obj for f in frames]))
        print(
            f"Capture range: visp-cube (tuned on) from {n_runs} starts 5° and 1 cm off (reference: "
            f"tracked from ViSP's pose by either tracker), {n_frames} frames each; whole = never lost and "
            f"every frame within {WRONG_DEG:.0f}° / {100 * WRONG_M:.0f} cm of a reference"
        )
        print(
            "  anchors (issue 16, measured outside this bench on seed 0's kind of draw): ViSP's edge "
            "tracker 3 of 10 whole with its default band, 7 of 10 with a 16 px band; target ≥ 8 of 10"
        )
        print(header)
        capture_table(frames, camera, model, ref, n_runs, n_frames, seeds)
    else:
        print(f"  capture range: data not found at {cube} (skipped)")
    print(
        "  held out (issue 27: ≥ 9 of 10 whole; the issue's held-out teabox, rendered by others: 6 of 10 before, "
        "ViSP 3), 20 frames each:"
    )
    tea = DATA / "visp-teabox"
    if tea.is_dir():
        model = read_cao(tea / "teabox.cao")
        camera = Camera.from_intrinsics(TEABOX_K, np.eye(4), 640, 480)
        T0 = solve_pnp(TEABOX_K, read_init_points(tea / "teabox.init"), TEABOX_CLICKS, 640, 480).T_cam_world
        frames = [cv2.cvtColor(f, cv2.COLOR_RGB2GRAY) for _, f in iter_frames(tea / "teabox.mp4")]
        ref_tracker = EdgeTracker(camera, model, T0, motion_model=False)
        ref = [ref_tracker.track(f).T_world_obj for f in frames]
        print("  visp-teabox, held out (reference: the tracker of before from the clicks)")
        print(header)
        capture_table(frames, camera, model, ref, n_runs, 20, seeds, CAPTURE[:3])
    else:
        print(f"  visp-teabox: data not found at {tea} (skipped)")
    castle = castle_data()
    if castle is not None:
        camera, model, frames, truth = castle
        for step in (1, 2):
            lost_at = run(frames[::step], camera, model, truth[0])[2]  # index in the subsampled frames
            print(
                f"  Castle-simu every {step}, held out (true poses; from the true pose of frame 0 the tracker is lost "
                f"at {'no frame' if lost_at is None else f'frame {step * lost_at}'}: a run through it cannot be whole)"
            )
            print(header)
            n = 20 if step == 1 else 12
            capture_table(frames[::step], camera, model, truth[::step], n_runs, n, seeds, CAPTURE[:3], lost_at)
    else:
        print(f"  Castle-simu: not found at {CASTLE} (apt-get install visp-images-data; skipped)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--skip-rendered", action="store_true")
    ap.add_argument("--repeat", type=int, default=3, help="timing: best of this many runs of the full sequence")
    ap.add_argument(
        "--capture-seeds", default="0", help="draws of starts for the capture range, e.g. 0,1,2,3,4,5 (0: the issue's)"
    )
    ap.add_argument(
        "--confusion-seeds", default="0", help="draws of starts for the lost-or-tracked tables (with --only confusion)"
    )
    ap.add_argument(
        "--only",
        choices=("sequences", "fast", "capture", "confusion"),
        help="print only the real sequences, the capture range or the lost-or-tracked tables",
    )
    args = ap.parse_args()
    pin = pin_one_core()
    print("Model-based edge tracking (bench/tracking.py)")
    print(
        f"  one core, one thread ({pin}; {platform.processor() or platform.machine()}, "
        f"Python {platform.python_version()}, OpenCV {cv2.__version__})"
    )
    print(
        "  dist = mean oriented-chamfer distance (px) of the projected "
        "model edges to Canny edges, per frame; held = initial pose kept"
    )
    print(
        f"  targets: visp-cube every frame: dist ≤ {TARGET_PX} px on "
        f"every frame, never lost; ≥ {TARGET_FPS:.0f} frames/s at 640×480;"
    )
    print(
        f"  issue 16: every 3rd frame too, and ≤ {TARGET_MS:.0f} ms mean per frame (ms/f: wall clock, "
        f"one core; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores at the start)"
    )
    print()
    if args.only == "sequences":
        real_sequences(args.repeat)
        return 0
    if args.only == "fast":
        fast_sequences()
        return 0
    if args.only == "capture":
        capture_range(seeds=tuple(int(k) for k in args.capture_seeds.split(",")))
        return 0
    if args.only == "confusion":
        for k in (int(k) for k in args.confusion_seeds.split(",")):
            confusion_tables(repeat_seed=k, skip_rendered=args.skip_rendered)
        return 0
    real_sequences(args.repeat)
    print()
    fast_sequences()
    print()
    workcell_sequence(args.repeat)
    if not args.skip_rendered:
        camera, box, frames, truth = rendered_sequence()
        step_deg = [
            np.degrees(np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1)))
            for a, b in zip(truth, truth[1:])
        ]
        step_mm = [1e3 * np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(truth, truth[1:])]
        poses, conf, lost_at, ms = run(frames, camera, box, truth[0], args.repeat)
        err = np.array([pose_error(T, Tt) for T, Tt in zip(poses, truth)])
        print()
        print(
            "  rendered box (app.render) 20 × 13 × 8 cm at 0.8–1.0 m, 640×480, f = 600 px, blur 0.5 px, noise "
            f"σ = 2, {len(frames)} frames; motion per frame up to {max(step_deg):.2f}° and {max(step_mm):.1f} mm"
        )
        print(
            f"  {'':22s}{'tracked':>9s}{'lost':>8s}{'rot mean °':>12s}{'rot max °':>11s}"
            f"{'trans mean mm':>15s}{'trans max mm':>14s}{'ms/f':>8s}{'frames/s':>10s}"
        )
        lost = "never" if lost_at is None else f"frame {lost_at}"
        print(
            f"  {'rendered box':22s}{len(poses):>5d}/{len(frames):<3d}{lost:>8s}"
            f"{err[:, 0].mean():12.3f}{err[:, 0].max():11.3f}{1e3 * err[:, 1].mean():15.2f}"
            f"{1e3 * err[:, 1].max():14.2f}{np.mean(ms):8.1f}{1e3 / np.mean(ms):10.0f}"
        )
    print()
    capture_range(seeds=tuple(int(k) for k in args.capture_seeds.split(",")))
    print()
    confusion_tables(skip_rendered=args.skip_rendered)
    return 0


if __name__ == "__main__":
    sys.exit(main())
