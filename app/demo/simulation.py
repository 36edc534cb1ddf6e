"""Simulated sweeps for the parts of the paper's tables that one run cannot cover.

The paper's Table III.1 and Table III.2 / Figure III.6 sweep the object/sensor distance (1–1.6 m)
and its Table V.1 gives statistics over many pose updates; one replayed session has one box, one
cylinder and four updates. These sweeps repeat the same measurements on simulated data
(``core.modeling.simulate``: analytic ray casting, clicks σ px, range σ_ρ, whole turret steps with
a ±½-step pointing error; ``core.pose.synthetic``: the paper's box seen at ~2 m) with the same
solvers, so the report can show them — always labelled "simulation", never as measured.

The set-up copies the scene's: its camera's image size, focal length and downward angle, and the
range finder's horizontal offset from the camera.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from app.scene import Scene
from core.brep import Revolution
from core.geometry import Line, Plane, distance_point_line
from core.modeling import METHODS, model_box, model_cylinder
from core.modeling.simulate import SimWorld, look_at_setup, simulate_box, simulate_revolution
from core.pose import refine
from core.pose.synthetic import paper_problems
from core.transforms import make_T, pose_error, rot_z

from .results import box_dims_paper_order, cylinder_depth_m, first_p3l

__all__ = [
    "SimSetup",
    "sim_setup",
    "BoxSweep",
    "box_sweep",
    "CylinderSweep",
    "cylinder_sweep",
    "PoseSweep",
    "pose_sweep",
    "operator_order",
]

TABLE = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
BOX_METHODS = ("planes", "fused")
GOOD_FIT = 3.0  # a refined pose whose RMS is within this many σ of the clicks fits them: the operator accepts it


@dataclass(frozen=True)
class SimSetup:
    """The simulated sensors: camera downward angle (°), range finder offset to the camera's
    right (m), focal length (px), image size, click σ (px)."""

    elevation_deg: float
    baseline_m: float
    f_px: float
    width: int
    height: int
    sigma_px: float = 1.0

    def sensors(self, target_world: np.ndarray, distance_m: float):
        """(camera, T_world_turret (4, 4)) looking at ``target_world`` from ``distance_m``."""
        return look_at_setup(
            np.asarray(target_world, float),
            distance_m,
            elevation_deg=self.elevation_deg,
            baseline_m=self.baseline_m,
            f_px=self.f_px,
            width=self.width,
            height=self.height,
        )


def sim_setup(scene: Scene, sigma_px: float = 1.0) -> SimSetup:
    """The scene's camera and turret geometry as a SimSetup (angle from the camera's optical axis,
    offset = horizontal distance from the optical centre to the turret's origin)."""
    C = scene.camera.C
    axis = C[2, :3] / np.linalg.norm(C[2, :3])  # towards the scene (s > 0 in front)
    K = scene.camera.decompose()[0]
    offset = scene.turret.T_world_turret[:3, 3] - scene.camera.center
    return SimSetup(
        float(np.degrees(np.arcsin(-axis[2]))),
        float(np.linalg.norm(offset[:2])),
        float(abs(K[0, 0])),
        scene.camera.width,
        scene.camera.height,
        sigma_px,
    )


# ---------------------------------------------------------------------- Table III.1
@dataclass(frozen=True)
class BoxSweep:
    """Box errors per distance: ``errors[method]`` (D, N, 4) — width, height, length (m) and volume
    (m³), estimate − truth; ``sigmas[method]`` (D, N, 3) the predicted σ (m)."""

    distances_m: tuple[float, ...]
    trials: int
    size_m: tuple[float, float, float]
    errors: dict[str, np.ndarray]
    sigmas: dict[str, np.ndarray]

    def rms(self, method: str) -> np.ndarray:
        """(D, 4) RMS errors over the trials."""
        return np.sqrt(np.mean(self.errors[method] ** 2, axis=1))


def box_sweep(
    setup: SimSetup,
    size_m,
    distances_m,
    trials: int,
    rng: np.random.Generator,
    progress: Callable[[], None] | None = None,
) -> BoxSweep:
    """The paper's box (size_m = x, y, z sizes) on the table, turned U(20°, 70°) so that two sides
    show, jittered ±5 mm; every visible face gets a 4 × 4 lattice of range points and each of its
    sides is clicked once (``simulate_box``); ``model_box`` by both methods on the same data."""
    size = np.asarray(size_m, float)
    errs = {m: np.zeros((len(distances_m), trials, 4)) for m in BOX_METHODS}
    sigs = {m: np.zeros((len(distances_m), trials, 3)) for m in BOX_METHODS}
    for i, d in enumerate(distances_m):
        cam, T_wt = setup.sensors([0.0, 0.0, size[2] / 2], d)
        for k in range(trials):
            T_obj = make_T(rot_z(np.radians(rng.uniform(20.0, 70.0))), [*rng.uniform(-0.005, 0.005, 2), 0.0])
            faces = simulate_box(
                cam, SimWorld(T_wt, boxes=((T_obj, tuple(size)),)), T_obj, size, rng, sigma_px=setup.sigma_px
            )
            for m in BOX_METHODS:
                res = model_box(cam, faces, TABLE, sigma_px=setup.sigma_px, support_sigma_m=1e-6, method=m)
                est, sig, truth = box_dims_paper_order(res, T_obj, size)
                errs[m][i, k] = [*(est - truth), np.prod(est) - np.prod(truth)]
                sigs[m][i, k] = sig
            if progress:
                progress()
    return BoxSweep(tuple(distances_m), trials, tuple(size), errs, sigs)


# ---------------------------------------------------------------------- Table III.2 / Figure III.6
@dataclass(frozen=True)
class CylinderSweep:
    """Per distance and method: ``values[method]`` (D, N, 4) — depth, radius error, axis position
    error, height error (m) — over N trials."""

    distances_m: tuple[float, ...]
    trials: int
    radius_m: float
    height_m: float
    values: dict[str, np.ndarray]

    def mean_depth(self, method: str) -> np.ndarray:
        return self.values[method][:, :, 0].mean(axis=1)

    def rms(self, method: str, column: int) -> np.ndarray:
        """(D,) RMS of a column (1 radius, 2 axis, 3 height error; 0 depth − radius)."""
        v = self.values[method][:, :, column] - (self.radius_m if column == 0 else 0.0)
        return np.sqrt(np.mean(v**2, axis=1))


def cylinder_sweep(
    setup: SimSetup,
    radius_m: float,
    height_m: float,
    distances_m,
    trials: int,
    rng: np.random.Generator,
    progress: Callable[[], None] | None = None,
) -> CylinderSweep:
    """A vertical cylinder on the table, jittered ±5 mm: both silhouettes clicked at their ends, two
    horizontal scans at ⅓ and ⅔ of the height at the turret's finest step (``simulate_revolution``);
    every method of ``core.modeling.model_cylinder`` on the same data."""
    vals = {m: np.zeros((len(distances_m), trials, 4)) for m in METHODS}
    for i, d in enumerate(distances_m):
        cam, T_wt = setup.sensors([0.0, 0.0, height_m / 2], d)
        O = T_wt[:3, 3]
        for k in range(trials):
            p0 = np.array([*rng.uniform(-0.005, 0.005, 2), 0.0])
            sol = Revolution(p0, p0 + [0.0, 0.0, height_m], radius_m, radius_m)
            sil, scans = simulate_revolution(cam, SimWorld(T_wt, solids=(sol,)), sol, rng, sigma_px=setup.sigma_px)
            mid_true = p0 + [0.0, 0.0, height_m / 2]
            front = float(np.linalg.norm((mid_true - O)[:2]) - radius_m)
            for m in METHODS:
                res = model_cylinder(
                    cam, m, silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE, sigma_px=setup.sigma_px
                )
                mid = res.axis.point + 0.5 * res.dimensions["height"] * res.axis.direction
                vals[m][i, k] = [
                    cylinder_depth_m(res, O, front),
                    res.dimensions["radius"] - radius_m,
                    distance_point_line(mid, Line(sol.p0, sol.axis)),
                    res.dimensions["height"] - height_m,
                ]
            if progress:
                progress()
    return CylinderSweep(tuple(distances_m), trials, float(radius_m), float(height_m), vals)


# ---------------------------------------------------------------------- Table V.1 / Figures V.1, V.2
@dataclass(frozen=True)
class PoseSweep:
    """Pose errors (degrees, metres) on ``core.pose.synthetic.paper_problems`` (9 visible edges
    clicked twice): ``p3l`` (N, 2) P3L's first-ranked candidate on the first workable triple in
    the operator's click order, ``refined`` (N, 2) the refinement from it with every edge, both with click noise
    σ px; ``noise_free`` (N, 2) P3L without noise. ``failed``: problems where P3L found nothing;
    ``refine_failed``: where no candidate could be refined (each put a clicked edge behind the
    camera). The refinement starts from the first-ranked candidate; when its RMS exceeds
    ``GOOD_FIT`` σ (the ghost visibly off the clicks) the next candidate is refined, as an
    operator would choose another, and the best fit is kept: ``candidates_tried`` (N,) how many."""

    trials: int
    sigma_px: float
    p3l: np.ndarray
    refined: np.ndarray
    noise_free: np.ndarray
    failed: int
    refine_failed: int
    candidates_tried: np.ndarray


def operator_order(edges_obj: np.ndarray) -> np.ndarray:
    """A click order (E,) of model edges (E, 2, 3) that begins, as the recorded operator's does,
    with three edges pairwise non-parallel and not all through one vertex; ValueError if none."""
    E = np.asarray(edges_obj, float)
    d = E[:, 1] - E[:, 0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    ends = [{tuple(np.round(p, 9)) for p in e} for e in E]
    for tri in itertools.combinations(range(len(E)), 3):
        if any(abs(d[a] @ d[b]) > 0.99 for a, b in itertools.combinations(tri, 2)):
            continue
        if ends[tri[0]] & ends[tri[1]] & ends[tri[2]]:
            continue
        return np.array(list(tri) + [k for k in range(len(E)) if k not in tri])
    raise ValueError("no three edges are pairwise non-parallel and not concurrent")


def pose_sweep(
    trials: int, sigma_px: float, rng: np.random.Generator, progress: Callable[[], None] | None = None
) -> PoseSweep:
    """P3L then refinement on the paper's box at ~2 m (the large-motion update's Solve, then Refine
    from the candidate it ranks first), the clicks in the operator's order (``operator_order``)."""
    p3l_e, ref_e, free_e, failed, refine_failed, candidates_tried = [], [], [], 0, 0, []
    for pb in paper_problems(rng, trials, sigma_px):
        order = operator_order(pb.edges_obj)
        segs, edges = pb.segs_uv[order], pb.edges_obj[order]
        cands, _ = first_p3l(pb.camera, segs, edges)
        exact, _ = first_p3l(pb.camera, pb.segs_true_uv[order], edges)
        if exact:
            free_e.append(pose_error(exact[0], pb.T_world_obj))
        if not cands:
            failed += 1
            continue
        p3l_e.append(pose_error(cands[0], pb.T_world_obj))
        best, tried = None, 0
        for T in cands:  # the operator refines the candidate shown first, and another while the fit is poor
            tried += 1
            try:
                r = refine(pb.camera, T, segs_uv=segs, edges_obj=edges, sigma_px=max(sigma_px, 1e-3))
            except ValueError:  # the candidate puts another clicked edge behind the camera
                continue
            if best is None or r.rms_px < best.rms_px:
                best = r
            if r.rms_px <= GOOD_FIT * max(sigma_px, 1e-3):
                break
        if best is None:
            refine_failed += 1
            continue
        candidates_tried.append(tried)
        ref_e.append(pose_error(best.T_world_obj, pb.T_world_obj))
        if progress:
            progress()
    arr = lambda v: np.array(v, float).reshape(-1, 2)  # noqa: E731
    return PoseSweep(
        trials,
        float(sigma_px),
        arr(p3l_e),
        arr(ref_e),
        arr(free_e),
        failed,
        refine_failed,
        np.array(candidates_tried, int),
    )
