"""Benchmark of a pose from two views (core.pose.refine_views): the error along camera 1's line of sight.

Run: .venv/bin/python bench/views.py [--n 200] [--seed 0]

Set-ups: "paper" (``core.pose.synthetic``): camera 1 is the paper's camera (``paper_camera``, 512 × 256
px, f = 500 px, 1.45 m behind the table, 25° down), camera 2 a side view of the same table
(``side_camera``, the same lens 2.0 m to the right, looking across camera 1's line of sight);
"workcell": the bundled scene's front and side cameras (scenes/workcell/scene.json). The paper's box 35
× 23.1 × 13.2 cm lies on the table with a random yaw, ~2 m from each camera. Every visible edge (whole
in the image) is clicked twice in each view, at random points along it, with Gaussian noise σ on each
pixel coordinate. Refinement starts from the truth moved 2 cm (σ per axis).

Rows, on the same placements and clicks:
* one view: camera 1's clicks alone (``refine_views`` with one view is ``refine``);
* two views: camera 1's and camera 2's clicks in one refinement;
* two views, half: as many clicked edges as one view, split (the first half of camera 1's edges, then
  as many of camera 2's as make the count): what a second view brings without more clicking.

Columns: the clicked edges (mean); along camera 1's line of sight (its optical centre to the box's
origin), the RMS error and the median σ the refinement states (``RefineResult.cov``), the Cramér–Rao
bound (the anchor: σ at the true pose from exact clicks, σ² (JᵀJ)⁻¹, RMS over placements) and the share
of errors within 2σ (95 % for a σ that is right); across the line of sight, the RMS error of the two
other directions (mm); the rotation error (°, RMS).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from core.pose import ViewClicks, refine_views  # noqa: E402
from core.pose.synthetic import PAPER_BOX_M, box_problem, paper_box_pose, paper_camera, side_camera  # noqa: E402
from core.transforms import pose_error  # noqa: E402

SIGMAS_PX = (0.5, 1.0, 2.0)
ROWS = ("one view", "two views", "two views, half")


def cameras(site: str) -> tuple:
    """(camera 1, camera 2) of a set-up: "paper" (``paper_camera`` and ``side_camera``) or "workcell" (the
    bundled scene's front and side cameras, scenes/workcell/scene.json)."""
    if site == "paper":
        return paper_camera(), side_camera()
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    return scene.view("front").camera, scene.view("side").camera


def placements(rng: np.random.Generator, n: int, sigma_px: float, cams: tuple) -> list:
    """n placements clicked in both views: (T_true, camera 1's problem, camera 2's), the same random
    fractions along the edges noisy and exact (the exact ones for the bound)."""
    out = []
    while len(out) < n:
        T = paper_box_pose(rng)
        try:
            a = box_problem(rng, cams[0], T, PAPER_BOX_M, sigma_px)
            b = box_problem(rng, cams[1], T, PAPER_BOX_M, sigma_px)
        except ValueError:  # not whole in one of the images
            continue
        out.append((T, a, b))
    return out


def views_of(row: str, a, b, exact: bool = False) -> list[ViewClicks]:
    sa, sb = (a.segs_true_uv, b.segs_true_uv) if exact else (a.segs_uv, b.segs_uv)
    sig = (a.sigma_px or 1.0, b.sigma_px or 1.0)
    if row == "one view":
        return [ViewClicks(a.camera, sa, a.edges_obj, sigma_px=sig[0])]
    if row == "two views":
        return [
            ViewClicks(a.camera, sa, a.edges_obj, sigma_px=sig[0]),
            ViewClicks(b.camera, sb, b.edges_obj, sigma_px=sig[1]),
        ]
    ka = (len(sa) + 1) // 2
    kb = len(sa) - ka
    return [
        ViewClicks(a.camera, sa[:ka], a.edges_obj[:ka], sigma_px=sig[0]),
        ViewClicks(b.camera, sb[:kb], b.edges_obj[:kb], sigma_px=sig[1]),
    ]


def run(rng: np.random.Generator, n: int, sigma_px: float, cams: tuple) -> dict:
    cam1 = cams[0]
    out = {row: {"los": [], "sd": [], "crb": [], "across": [], "deg": [], "edges": []} for row in ROWS}
    for T, a, b in placements(rng, n, sigma_px, cams):
        d = T[:3, 3] - cam1.center
        d /= np.linalg.norm(d)
        across = np.linalg.svd(d[None])[2][1:]  # two unit directions across the line of sight
        T0 = T.copy()
        T0[:3, 3] += rng.normal(0.0, 0.02, 3)
        for row in ROWS:
            res = refine_views(views_of(row, a, b), T0)
            bound = refine_views(views_of(row, a, b, exact=True), T)  # cov at the truth: the CRB
            e = res.T_world_obj[:3, 3] - T[:3, 3]
            r = out[row]
            r["los"].append(float(d @ e))
            r["sd"].append(float(np.sqrt(d @ res.cov[:3, :3] @ d)))
            r["crb"].append(float(d @ bound.cov[:3, :3] @ d))
            r["across"].append(float(np.sum((across @ e) ** 2) / 2))
            r["deg"].append(pose_error(res.T_world_obj, T)[0])
            r["edges"].append(len(res.kinds))
    return {row: {k: np.asarray(v) for k, v in r.items()} for row, r in out.items()}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--n", type=int, default=200, help="placements per noise level (default 200)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--site", choices=("paper", "workcell", "both"), default="both", help="the cameras (default: both set-ups)"
    )
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed)
    print(__doc__.split("\n\n")[1].replace("\n", " "))
    print(f"{args.n} placements per σ, seed {args.seed}; load average {os.getloadavg()[0]:.2f}.\n")
    head = (
        f"{'σ px':>4} {'clicks in':<16} {'edges':>5} | {'line of sight: RMS mm':>21} {'σ med':>6} {'CRB':>6} "
        f"{'≤2σ':>5} | {'across RMS mm':>13} | {'rot RMS °':>9}"
    )
    for site in ("paper", "workcell") if args.site == "both" else (args.site,):
        print(f"\n{site}: " + ("paper_camera + side_camera" if site == "paper" else "the scene's front + side cameras"))
        table(rng, args.n, cameras(site), head)
    return 0


def table(rng: np.random.Generator, n: int, cams: tuple, head: str) -> None:
    print(head)
    print("-" * len(head))
    for sigma in SIGMAS_PX:
        res = run(rng, n, sigma, cams)
        base = np.sqrt(np.mean(res["one view"]["los"] ** 2))
        for row in ROWS:
            r = res[row]
            rms = np.sqrt(np.mean(r["los"] ** 2))
            edges = f"{np.mean(r['edges']):.1f}"
            ratio = "" if row == "one view" else f" ({base / rms:.0f}× less)"
            los = f"{1000 * rms:.2f}{ratio}"
            print(
                f"{sigma:>4.1f} {row:<16} {edges:>5} | {los:>21} {1000 * np.median(r['sd']):>6.2f} "
                f"{1000 * np.sqrt(np.mean(r['crb'])):>6.2f} {100 * np.mean(np.abs(r['los']) <= 2 * r['sd']):>4.0f}% | "
                f"{1000 * np.sqrt(np.mean(r['across'])):>13.2f} | {np.sqrt(np.mean(r['deg'] ** 2)):>9.3f}"
            )


if __name__ == "__main__":
    raise SystemExit(main())
