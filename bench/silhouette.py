"""Cost of drawing curved meshes by their silhouettes (issue 15, item 5), per object.

Run: .venv/bin/python bench/silhouette.py [--poses 30] [--repeat 3]

For each model: the smooth sides found once per model (``Polyhedron.smooth_sides``: what a new
or remodelled object costs once), the contour at one pose (``SmoothSides.contour``), and one
object's redraw on the database overlay's thread (``app.ui.drawing.draw_object``: wireframe,
silhouettes, projection, clipping, dashing), with the mesh silhouettes and without them (the same
edges with no faces: no smooth side, every edge drawn as visible), at
``--poses`` random poses in view of a 640×480, 800 px camera; medians over the poses, best of
``--repeat`` runs (the machine is shared: the anchor rows — a box and an analytic cylinder, which
have no smooth side — show the load in the same run). "First redraw" is one object's redraw with
a model just read from the database (``BRep.from_dict``): its face normals, centroids and smooth
sides are computed then, once per model.
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

from app.ui.drawing import draw_object  # noqa: E402
from app.workflows.site import SiteObject  # noqa: E402
from core.brep import BRep  # noqa: E402
from core.camera import Camera  # noqa: E402
from core.mesh_features import brep_from_mesh  # noqa: E402
from core.silhouette import SmoothSides  # noqa: E402
from core.transforms import invert_T, make_T, random_rotation  # noqa: E402


def _camera() -> Camera:
    K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])
    eye, target = np.array([0.6, -0.7, 0.45]), np.array([0.0, 0.0, 0.05])
    z = (target - eye) / np.linalg.norm(target - eye)
    x = np.cross(z, [0, 0, 1.0])
    x /= np.linalg.norm(x)
    return Camera.from_intrinsics(K, invert_T(make_T(np.column_stack([x, np.cross(z, x), z]), eye)), 640, 480)


def _models() -> dict[str, BRep]:
    def mesh(m):
        return brep_from_mesh(m.vertices, m.faces)

    return {
        "box (anchor)": BRep.box(0.05, 0.06, 0.07),
        "analytic cylinder (anchor)": BRep.cylinder(0.03, 0.1),
        "mesh cylinder, 2,000 faces": mesh(trimesh.creation.cylinder(0.05, 0.2, sections=500)),
        "mesh cone, 2,000 faces": mesh(trimesh.creation.cone(0.05, 0.2, sections=1000)),
        "mesh sphere, 5,120 faces": mesh(trimesh.creation.icosphere(4, 0.1)),
        "mesh capsule, 2,048 faces": mesh(trimesh.creation.capsule(0.2, 0.05, count=[32, 32])),
    }


def _median_ms(fn, items) -> float:
    out = []
    for it in items:
        t = time.perf_counter()
        fn(it)
        out.append(time.perf_counter() - t)
    return 1000.0 * float(np.median(out))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--poses", type=int, default=30)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    cam = _camera()
    rng = np.random.default_rng(0)
    poses = [make_T(random_rotation(rng), rng.uniform(-0.05, 0.05, 3)) for _ in range(args.poses)]
    rows = []
    for name, model in _models().items():
        objs = [SiteObject(1, "o", "mesh", "known", model, T, 1) for T in poses]
        centres = [(cam.center - T[:3, 3]) @ T[:3, :3] for T in poses]
        best = [np.inf] * 5
        for _ in range(args.repeat):
            fresh = SiteObject(1, "o", "mesh", "known", BRep.from_dict(model.to_dict()), poses[0], 1)
            t = time.perf_counter()
            draw_object(cam, fresh, 640, 480)
            first = 1000.0 * (time.perf_counter() - t)
            t = time.perf_counter()
            sides = SmoothSides.of(model.vertices, model.faces, model.edges)
            pre = 1000.0 * (time.perf_counter() - t)
            model.polyhedron.smooth_sides()
            contour = _median_ms(sides.contour, centres)
            with_sil = _median_ms(lambda o: draw_object(cam, o, 640, 480), objs)
            bare = BRep(model.vertices, model.edges, (), model.solids, model.circles)
            bare_objs = [replace(o, model=bare) for o in objs]
            without = _median_ms(lambda o: draw_object(cam, o, 640, 480), bare_objs)
            best = [min(a, b) for a, b in zip(best, (pre, contour, with_sil, without, first))]
        n_sil = int(np.median([len(sides.contour(c)) for c in centres]))
        rows.append((name, sum(len(f) == 3 for f in model.faces), len(sides), n_sil, *best))
    print(
        f"mesh silhouettes, per object — camera 640×480, 800 px; {args.poses} random poses, medians, best of "
        f"{args.repeat} runs; machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}"
    )
    print()
    print(
        "| model | triangles | smooth sides | silhouette sides (median) | smooth sides found, once per model (ms) "
        "| contour at one pose (ms) | one object's redraw (ms) | "
        "same without mesh silhouettes (ms) | first redraw (ms) |"
    )
    print("|---|---|---|---|---|---|---|---|---|")
    for name, tris, ns, nsil, pre, contour, with_sil, without, first in rows:
        print(
            f"| {name} | {tris} | {ns} | {nsil} | {pre:.2f} | "
            f"{contour:.3f} | {with_sil:.2f} | {without:.2f} | {first:.1f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
