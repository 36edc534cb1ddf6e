"""Benchmark of Calibrate robot's automatic edge matching: how often a clicked edge is taken for the wrong robot
feature, beside the rule it replaced.

Run: .venv/bin/python bench/robot_match.py [--sessions 40]

Set-up: the bundled workcell's arm at the scene's three base-calibration poses, the front camera, a new
database's base (the drawing's: 2.5 cm and 2° from the truth). A session visits the poses in order; at each it
clicks a random subset (3 or more) of the edges an operator can click (``clickable_edges``: seen, 25 px or
longer), in random order, two pixels each 0.7 px off the edge. Each click is matched as the workflow does:
candidates are the features not yet assigned, drawn at the current estimate; the estimate follows the assigned
edges as the workflow's does (``app.workflows.calibrate_robot.estimate_from_clicks``). An edge not matched is
assigned by hand (rightly: the operator clicks it on the white robot).

* **ours** — ``match_segment``: the only feature whose χ² against the estimate's covariance (carried to the
  image) passes; no automatic match while the base has no covariance (nominal, not yet followed).
* **nearest** (the rule before, the anchor) — the nearest feature within 20 px and 10° of the click and along
  30 % of it, taken when the next is at least twice and 4 px farther, at any estimate.

Printed per rule: wrong automatic matches (the defect: silently wrong), automatic ones, asked ones.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from app.robot.urdf import load_scene_robot  # noqa: E402
from app.scene import default_scene_path, load_scene  # noqa: E402
from app.workflows.calibrate_robot import estimate_from_clicks  # noqa: E402
from core.robot.calibration import BaseClick, features_at, match_segment  # noqa: E402
from tests.app.robot.calibration_truth import clickable_edges, operator_segment  # noqa: E402

SIGMA_PX = 0.7


def nearest(seg, proj, max_px=20.0, max_deg=10.0, min_overlap=0.3, ratio=2.0, min_gap_px=4.0):
    """The rule before: the nearest fitting projected feature when the next is ratio× and min_gap_px farther."""
    a, b = proj[:, 0], proj[:, 1]
    L = np.linalg.norm(b - a, axis=1)
    u = (b - a) / np.maximum(L, 1e-12)[:, None]
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    dist = 0.5 * (np.abs(np.einsum("fj,fj->f", seg[0] - a, n)) + np.abs(np.einsum("fj,fj->f", seg[1] - a, n)))
    s = seg[1] - seg[0]
    ls = max(float(np.linalg.norm(s)), 1e-12)
    angle = np.degrees(np.arccos(np.clip(np.abs(u @ (s / ls)), 0.0, 1.0)))
    t0, t1 = np.einsum("fj,fj->f", seg[0] - a, u), np.einsum("fj,fj->f", seg[1] - a, u)
    overlap = np.clip(np.minimum(np.maximum(t0, t1), L) - np.maximum(np.minimum(t0, t1), 0.0), 0.0, None) / ls
    score = np.where((angle <= max_deg) & (overlap >= min_overlap) & (dist <= max_px), dist, np.inf)
    order = np.argsort(score)
    if not len(order) or not np.isfinite(score[order[0]]):
        return None
    second = score[order[1]] if len(order) > 1 else np.inf
    return int(order[0]) if second >= max(ratio * score[order[0]], score[order[0]] + min_gap_px) else None


class Site:
    def __init__(self):
        self.scene = load_scene(default_scene_path())
        self.model, _ = load_scene_robot(self.scene.robot)
        self.cam = self.scene.camera
        self.T_true, self.T_nom = self.scene.robot.T_world_base, self.scene.robot.nominal_base
        self.qs = self.scene.robot.calibration_qs(self.model, "base")
        self.edges = [
            clickable_edges(self.scene, self.model, q, k, self.cam, None, self.T_true) for k, q in enumerate(self.qs)
        ]

    def follow(self, assigned):
        """The workflow's estimate from the assigned (segment, feature) pairs: (T, cov), cov None when not followed."""
        clicks = [BaseClick(s, f, SIGMA_PX, 0) for s, f in assigned]
        fit = estimate_from_clicks(self.model, self.qs, clicks, self.cam, self.T_nom)
        return (self.T_nom, None) if fit is None else (fit.T_world_base, fit.cov)

    def session(self, seed: int, rule: str) -> np.ndarray:
        """(wrong, automatic, asked) over one session."""
        rng = np.random.default_rng(seed)
        assigned, out = [], np.zeros(3, int)
        T, cov = self.T_nom, None
        for k, q in enumerate(self.qs):
            edges = self.edges[k]
            for i in rng.permutation(len(edges))[: rng.integers(3, len(edges) + 1)]:
                f, a, b = edges[i]
                seg = operator_segment(a, b, rng, SIGMA_PX)
                used = {g for _, g in assigned}
                cands = [
                    (g, s)
                    for g, s, v in features_at(self.model, q, T, self.cam.center, k)
                    if v and g not in used and np.all(self.cam.depth(s) > 0)
                ]
                feats, W = [g for g, _ in cands], np.array([s for _, s in cands])
                if rule == "nearest":
                    j = nearest(seg, self.cam.project(W.reshape(-1, 3)).reshape(-1, 2, 2))
                else:
                    j = None if cov is None else match_segment(seg, W, self.cam, T, cov, sigma_px=SIGMA_PX)[0]
                g = f if j is None else feats[j]
                out += [j is not None and g != f, j is not None, j is None]
                assigned.append((seg, g))
                T, cov = self.follow(assigned)
        return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=40)
    args = ap.parse_args(argv)
    site = Site()
    print(__doc__.split("\n\n")[0])
    print(f"{args.sessions} sessions; clickable edges per pose: {[len(e) for e in site.edges]}\n")
    print(f"{'rule':34s}{'wrong':>8s}{'automatic':>11s}{'asked':>8s}{'sessions with a wrong one':>28s}")
    for rule, label in (("ours", "ours (χ² against the covariance)"), ("nearest", "nearest (the rule before)")):
        per = np.array([site.session(s, rule) for s in range(args.sessions)])
        tot = per.sum(axis=0)
        print(f"{label:34s}{tot[0]:8d}{tot[1]:11d}{tot[2]:8d}{int(np.sum(per[:, 0] > 0)):28d}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
