"""What the snap gates see: how far snaps move a click, and how well the image fits them where they land.

Run: .venv/bin/python bench/snap_gates.py [--seed 0]

Setup: the workcell scene rendered at t = 5 s and 16 s (``tests/e2e/harness.site_frame``, as ``mcit serve``
shows it). Every visible true edge longer than 25 px is clicked 5 times, its two clicks at 25 % and 75 % of it,
each 0-3 px off along the edge's normal (uniform); every visible true corner with two or more visible edges
3 times, 0-2.5 px off (uniform per coordinate), snapped as the workflows do (``snap_segment``; ``snap_corner``
with the vertex's model edges, and ``snap_corner_subpix`` alone). A snap is "right" when it lands within 0.5 px
of the true edge / corner.

Printed: the snaps that moved a click more than 2 px (the old gate, ``MAX_SNAP_MOVE_PX``) and how many of them
were right; the fit at the snapped place (``ClickSnap.fit_px``: a segment's edge points' RMS about its line, a
corner's lines' largest RMS, cornerSubPix's gradient-line distance) of the right and the wrong snaps, beside
the limits (``WEAK_EDGE_RMS_PX``, ``WEAK_CORNER_FIT_PX``) that now flag a snap weak.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)

    from app.scene import default_scene_path, load_scene
    from app.vision.corner import snap_corner, snap_corner_subpix
    from app.vision.snap import snap_segment
    from app.workflows.snapping import WEAK_CORNER_FIT_PX, WEAK_EDGE_RMS_PX, vertex_edge_directions
    from tests.e2e.harness import site_frame

    scene = load_scene(default_scene_path())
    cam = scene.camera
    rng = np.random.default_rng(args.seed)
    rows = {"segment": [], "corner edges": [], "corner subpix": []}  # (moved_px, fit_px, error_px)
    for t in (5.0, 16.0):
        image = site_frame(scene, None, t)
        for body in scene.bodies:
            T = body.pose_at(t)
            wf = body.model.wireframe(cam.center, T)
            segs = cam.project(body.model.edge_segments(T).reshape(-1, 3)).reshape(-1, 2, 2)
            for k, shown, kind in zip(wf.edge_index, wf.visible, wf.kind):
                if not shown or kind != "edge":
                    continue
                a, b = segs[k]
                if np.linalg.norm(b - a) < 25:
                    continue
                n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
                for _ in range(5):
                    off = rng.uniform(-3, 3, 2)
                    r = snap_segment(
                        image, np.array([a + 0.25 * (b - a) + off[0] * n, a + 0.75 * (b - a) + off[1] * n])
                    )
                    if r.ok:
                        rows["segment"].append((r.moved_px, r.rms_px, float(np.abs((r.seg_uv - a) @ n).max())))
            for v in range(len(body.model.vertices)):
                D, L = vertex_edge_directions(cam, body.model, T, v)
                uv = cam.project((body.model.vertices[v] @ T[:3, :3].T + T[:3, 3])[None])[0]
                if len(D) < 2 or not (10 < uv[0] < cam.width - 10 and 10 < uv[1] < cam.height - 10):
                    continue
                for _ in range(3):
                    click = uv + rng.uniform(-2.5, 2.5, 2)
                    for name, r in (("corner edges", snap_corner(image, click, D, L)), ("corner subpix", None)):
                        r = r if r is not None else snap_corner_subpix(image, click)
                        if r.ok and (name == "corner subpix" or r.method == "edges"):
                            rows[name].append((r.moved_px, r.fit_px, float(np.linalg.norm(r.uv - uv))))
    limits = {"segment": WEAK_EDGE_RMS_PX, "corner edges": WEAK_CORNER_FIT_PX["edges"]}
    limits["corner subpix"] = WEAK_CORNER_FIT_PX["subpix"]
    print(
        f"{'snap':<14} {'n':>4} {'moved>2px':>10} {'of them right':>14} {'fit right p50/p95/max (px)':>28} "
        f"{'fit wrong (px)':>22} {'limit':>6} {'right flagged':>14}"
    )
    for name, r in rows.items():
        R = np.array(r).reshape(-1, 3)
        right = R[:, 2] <= 0.5
        far = R[:, 0] > 2.0
        fit = np.percentile(R[right, 1], [50, 95, 100]) if right.any() else np.full(3, np.nan)
        wrong = ", ".join(f"{x:.2f}" for x in np.sort(R[~right, 1])[:6]) or "—"
        print(
            f"{name:<14} {len(R):>4} {int(far.sum()):>10} {int((far & right).sum()):>14} "
            f"{'/'.join(f'{x:.2f}' for x in fit):>28} {wrong:>22} {limits[name]:>6g} "
            f"{int((right & (R[:, 1] > limits[name])).sum()):>14}"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
