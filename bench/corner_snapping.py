"""Benchmark of corner snapping (app.vision.corner) for the camera calibration's clicks, on the
workcell's rendered video, and what it does to the calibrated C.

Run: .venv/bin/python bench/corner_snapping.py [--trials 100] [--seed 0]

Setup: the workcell scene (camera 512 × 256 px, f = 500 px) and its prerecorded video
(scenes/workcell/video.avi: frames rendered by app.render — exact ray casting, area-coverage
edges, blur σ = 0.5 px, noise σ = 2 grey levels — stored as Motion-JPEG). The corners are the 13
the recorded operator script pairs in its camera calibration (scenes/workcell/operator.json: the
table's 6 visible corners and the known box's 7), each on the frame at its click's time; the
truth is the corner projected through the scene's true camera. Each trial clicks every corner
with Gaussian noise σ = 1 px per coordinate (the script's noise), then:

* "raw": the clicks as given;
* "cornerSubPix": OpenCV's cornerSubPix in an 11 × 11 window (snap_corner_subpix);
* "edges": the intersection of the vertex's visible model edges snapped to the image
  (snap_corner_edges; directions from the database pose through the seeded C, as the workflow);
* "workflow": what CalibrateCamera uses (snap_corner: edges, else cornerSubPix, else the raw click).

Corner error: distance to the true corner (pixels) over the snaps that succeeded; "refused" counts
the others. DLT: core.calibration.calibrate_dlt on the 13 pairs (raw vs workflow), the calibrated
C against the true one: the reprojection difference at every body's corners (the table, the known
box, the unknown box's corners and the cylinder's bounding box, at the calibration's time: the
demo report's measure) and the optical centre's distance. "snapped, 1/σ" is what CalibrateCamera
does: each point weighted by its precision (a snapped corner σ = 0.15 px, a raw click 1 px).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.demo.results import _body_corners  # noqa: E402
from app.scene import default_scene_path, load_scene  # noqa: E402
from app.vision.corner import snap_corner, snap_corner_edges, snap_corner_subpix  # noqa: E402
from app.workflows.frames import SceneVideoFrames  # noqa: E402
from app.workflows.snapping import SNAPPED_CORNER_SIGMA_PX, vertex_edge_directions  # noqa: E402
from core.calibration import calibrate_dlt  # noqa: E402

cv2.setNumThreads(1)
CLICK_SIGMA_PX = 1.0


def calibration_corners(scene):
    """The script's camera-calibration pairs: (object, vertex, time, X_world (3,), true uv (2,),
    script's click (2,))."""
    actions = json.loads((Path(scene.root) / "operator.json").read_text())["actions"]
    out, pending = [], None
    for a in actions:
        if a["workflow"] != "calibrate_camera":
            continue
        if a["action"] == "choose_vertex":
            pending = (a["name"], int(a["index"]))
        elif a["action"] == "click" and pending is not None:
            out.append(
                (
                    *pending,
                    float(a["t"]),
                    np.array(a["truth"]["X_world"]),
                    np.array(a["truth"]["uv_true"]),
                    np.array(a["uv"]),
                )
            )
            pending = None
    return out


def c_error(scene, camera, t_s):
    """The calibrated camera against the true one: (RMS, max) reprojection difference (px) at the
    bodies' corners, optical centre distance (m)."""
    X = _body_corners(scene, t_s)
    X = X[(scene.camera.depth(X) > 0) & (camera.depth(X) > 0)]
    d = np.linalg.norm(camera.project(X) - scene.camera.project(X), axis=1)
    return float(np.sqrt(np.mean(d**2))), float(d.max()), float(np.linalg.norm(camera.center - scene.camera.center))


def stats(v) -> str:
    v = np.asarray(v, float)
    return f"{v.mean():8.3f}{np.median(v):8.3f}{np.percentile(v, 90):8.3f}{np.percentile(v, 95):8.3f}{v.max():8.3f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--trials", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    scene = load_scene(default_scene_path())
    cam = scene.camera
    frames = SceneVideoFrames(scene.video)
    corners = calibration_corners(scene)
    prepared = []
    for name, k, t, X, uv, click in corners:
        body = scene.body(name)
        D, L = vertex_edge_directions(cam, body.model, body.pose_at(t), k)
        prepared.append((name, k, frames(t), X, uv, click, D, L))
    rng = np.random.default_rng(args.seed)
    err = {m: [] for m in ("raw", "subpix", "edges", "workflow")}
    refused = {m: 0 for m in err}
    per_corner = {(p[0], p[1]): [] for p in prepared}
    dlt = {"raw": [], "workflow": [], "weighted": []}
    times = []
    t_cal = max(c[2] for c in corners)

    def one_set(clicks, record=True):
        uv_w, sig_w = [], []
        for (name, k, img, _X, uv, _, D, L), c in zip(prepared, clicks):
            t0 = time.perf_counter()
            w = snap_corner(img, c, D, L)
            times.append(time.perf_counter() - t0)
            uv_w.append(w.uv if w.ok else c)
            sig_w.append(SNAPPED_CORNER_SIGMA_PX if w.ok else CLICK_SIGMA_PX)
            if not record:
                continue
            err["raw"].append(np.linalg.norm(c - uv))
            for key, res in (
                ("subpix", snap_corner_subpix(img, c)),
                ("edges", snap_corner_edges(img, c, D, L)),
                ("workflow", w),
            ):
                if res.ok:
                    err[key].append(np.linalg.norm(res.uv - uv))
                else:
                    refused[key] += 1
            per_corner[(name, k)].append(np.linalg.norm(uv_w[-1] - uv))
        return np.array(uv_w), np.array(sig_w)

    X_world = np.array([p[3] for p in prepared])
    for _ in range(args.trials):
        clicks = [p[4] + rng.normal(0, CLICK_SIGMA_PX, 2) for p in prepared]
        uv_w, sig_w = one_set(clicks)
        for key, uv, sig in (("raw", np.array(clicks), None), ("workflow", uv_w, None), ("weighted", uv_w, sig_w)):
            camera, _ = calibrate_dlt(X_world, uv, cam.width, cam.height, sigma_px=sig)
            dlt[key].append(c_error(scene, camera, t_cal))
    # the recorded script's own clicks (what mcit demo replays)
    script = [p[5] for p in prepared]
    script_snapped, script_sig = one_set(script, record=False)
    demo = {
        key: c_error(scene, calibrate_dlt(X_world, uv, cam.width, cam.height, sigma_px=sig)[0], t_cal)
        for key, uv, sig in (
            ("raw", np.array(script), None),
            ("workflow", script_snapped, None),
            ("weighted", script_snapped, script_sig),
        )
    }

    n = args.trials * len(prepared)
    print("Corner snapping for the camera calibration (bench/corner_snapping.py)")
    print(
        f"  workcell scene, its video (app.render frames, blur σ = 0.5 px, noise σ = 2 grey levels, Motion-JPEG); "
        f"the operator script's {len(prepared)} calibration corners on the frames of their clicks;"
    )
    print(
        f"  {args.trials} trials of clicks with σ = {CLICK_SIGMA_PX:.0f} px "
        f"per coordinate, seed {args.seed}: {n} clicks"
    )
    print()
    print("  corner error (px, distance to the true corner), over the snaps that succeeded")
    print(f"  {'':14s}{'mean':>8s}{'median':>8s}{'90 %':>8s}{'95 %':>8s}{'max':>8s}  refused")
    for key, name in (
        ("raw", "raw clicks"),
        ("subpix", "cornerSubPix"),
        ("edges", "edges ∩"),
        ("workflow", "workflow"),
    ):
        print(f"  {name:14s}{stats(err[key])}  {refused[key]:4d} ({100 * refused[key] / n:.0f} %)")
    print()
    print("  per corner (workflow: snapped, or the raw click when refused), mean error px")
    line = []
    for (name, k), v in per_corner.items():
        line.append(f"{name[:5]}:{k} {np.mean(v):.2f}")
    for i in range(0, len(line), 7):
        print("   " + "  ".join(line[i : i + 7]))
    print()
    print("  DLT on the 13 pairs: calibrated C vs the true C at the bodies' corners; optical centre")
    print(
        f"  {'':14s}{'RMS px mean':>12s}{'median':>8s}{'max px mean':>12s}"
        f"{'median':>8s}{'95 %':>8s}{'centre cm mean':>15s}{'median':>8s}{'95 %':>8s}"
    )
    for key, name in (("raw", "raw clicks"), ("workflow", "snapped"), ("weighted", "snapped, 1/σ")):
        d = np.array(dlt[key])
        print(
            f"  {name:14s}{d[:, 0].mean():12.2f}{np.median(d[:, 0]):8.2f}{d[:, 1].mean():12.2f}"
            f"{np.median(d[:, 1]):8.2f}{np.percentile(d[:, 1], 95):8.2f}{100 * d[:, 2].mean():15.2f}"
            f"{100 * np.median(d[:, 2]):8.2f}{100 * np.percentile(d[:, 2], 95):8.2f}"
        )
    print(
        f"  the recorded script's clicks (seed 8, as mcit demo replays them): raw {demo['raw'][0]:.2f} px RMS, "
        f"{demo['raw'][1]:.2f} px max, centre {100 * demo['raw'][2]:.1f} cm; snapped {demo['workflow'][0]:.2f} px RMS, "
        f"{demo['workflow'][1]:.2f} px max, centre {100 * demo['workflow'][2]:.1f} cm; "
        f"snapped, 1/σ {demo['weighted'][0]:.2f} px RMS, {demo['weighted'][1]:.2f} px "
        f"max, centre {100 * demo['weighted'][2]:.1f} cm"
    )
    print()
    s = 1e3 * np.asarray(times)
    print(
        f"  snap_corner time: median {np.median(s):.1f} ms, 95 % {np.percentile(s, 95):.1f} ms per click "
        f"(one core; {platform.processor() or platform.machine()}, Python {platform.python_version()})"
    )
    frames.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
