"""The demo's numbers: what the replayed session produced, compared with the scene's truth.

Everything here reads a finished ``Replay`` (its workflow objects and the site's database) and
the scene's ground truth; nothing writes. The measures are the paper's:

* Table III.1 — the modelled box's width, height, length (the paper's w × h × l = 9 × 14 × 9.4 cm
  is our size_x × size_z × size_y) and volume, each against the true body;
* Table III.2 / Figure III.6 — the cylinder's "depth": how far behind its front surface the
  estimated axis lies along the range finder's horizontal line of sight (5.1 cm for a perfect
  model), by each of the paper's three methods and our fused fit, all on the measurements the
  operator's run took (``core.modeling.model_cylinder`` with the same silhouettes and scans);
* Table V.1 / Figures V.1, V.2 — the pose error (rotation angle, translation distance) of each
  update against the true pose at that time: P3L alone (the candidate the workflow chose, or, for
  an update refined from the database pose, P3L on the same clicks) and after refinement; the
  noise-free P3L on the clicks' true positions (the script's truth) through the true camera.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from app.scene import Scene
from core.camera import Camera
from core.geometry import Line, distance_point_line
from core.modeling import METHODS, ModelResult, model_box, model_cylinder
from core.modeling.uncertainty import with_calibration_uncertainty
from core.pose import p3l_candidates, refine
from core.transforms import pose_error

from .replay import Replay, RunRecord

__all__ = [
    "PAPER_BOX_ORDER",
    "box_dims_paper_order",
    "cylinder_depth_m",
    "first_p3l",
    "CalibrationResults",
    "BoxResults",
    "CylinderResults",
    "PoseUpdate",
    "DemoResults",
    "calibration_results",
    "box_results",
    "cylinder_results",
    "pose_results",
    "demo_results",
]

# The paper's w × h × l of the box (Table III.1) in our object frame's axes: x, z, y.
PAPER_BOX_ORDER = (("width", 0), ("height", 2), ("length", 1))


def box_dims_paper_order(
    result: ModelResult, T_world_true: np.ndarray, dims_true_m: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A modelled box's sizes matched to the true box's axes, in the paper's (width, height,
    length) order.

    result : the modelled box (``dimensions`` size_x, size_y, size_z and their ``sigmas``).
    T_world_true : array, shape (4, 4), the true pose. dims_true_m : array, shape (3,), the true
    sizes along the true box's x, y, z (metres). Returns (estimate (3,), σ (3,), truth (3,)),
    metres, each ordered width, height, length.
    """
    R_est, R_true = result.T_world_obj[:3, :3], np.asarray(T_world_true, float)[:3, :3]
    match = np.argmax(np.abs(R_est.T @ R_true), axis=0)  # for each true axis, the estimated axis along it
    if len(set(match.tolist())) != 3:
        raise ValueError("the modelled box's axes do not match the true box's one to one (more than 45° off)")
    est = np.array([result.dimensions[k] for k in ("size_x", "size_y", "size_z")])[match]
    sig = np.array([result.sigmas.get(k, np.nan) for k in ("size_x", "size_y", "size_z")])[match]
    order = [a for _, a in PAPER_BOX_ORDER]
    return est[order], sig[order], np.asarray(dims_true_m, float)[order]


def cylinder_depth_m(result: ModelResult, origin_world: np.ndarray, front_distance_m: float) -> float:
    """The paper's "depth" of a modelled cylinder (metres; its radius for a perfect model).

    Horizontal distance from ``origin_world`` (3,) (the range finder) to the estimated axis at
    mid-height, minus ``front_distance_m``, the true horizontal distance from it to the cylinder's
    front surface.
    """
    mid = result.axis.point + 0.5 * result.dimensions["height"] * result.axis.direction
    return float(np.linalg.norm((mid - np.asarray(origin_world, float))[:2]) - front_distance_m)


def first_p3l(
    camera: Camera, segs_uv: np.ndarray, edges_obj: np.ndarray
) -> tuple[list[np.ndarray], tuple[int, ...] | None]:
    """P3L on the first workable triple of clicked edges, in click order (the paper's large-motion step,
    ``core.pose.p3l_candidates`` with ``first_only``). Returns (candidates, best first; the triple's
    indices), or ([], None)."""
    if len(segs_uv) < 3:
        return [], None
    try:
        res = p3l_candidates(camera, segs_uv, edges_obj, first_only=True, max_triples=10**6)
    except ValueError:  # clicks no line goes through (two coinciding pixels): no candidate
        return [], None
    return (res.poses, res.triples[0]) if res.poses else ([], None)


# ---------------------------------------------------------------------- calibrations
@dataclass(frozen=True)
class CalibrationResults:
    """Camera: RMS of the DLT (px) over ``camera_points`` points; the calibrated C against the true
    one: reprojection difference (px) at every body's corners (RMS, max) and the optical centre's
    distance (m). Turret: RMS of the measured points to their surfaces (mm) and the pose error
    (°, m) against the true turret. NaN when the script has no such run."""

    camera_rms_px: float = float("nan")
    camera_points: int = 0
    camera_reprojection_rms_px: float = float("nan")
    camera_reprojection_max_px: float = float("nan")
    camera_centre_error_m: float = float("nan")
    turret_rms_mm: float = float("nan")
    turret_points: int = 0
    turret_error_deg: float = float("nan")
    turret_error_m: float = float("nan")


def _body_corners(scene: Scene, t_s: float) -> np.ndarray:
    """Every non-scenery body's corners (or axis ends ± radius for solids) in the world at t_s, (N, 3)."""
    out = []
    for b in scene.bodies:
        if b.status == "scenery":
            continue
        T = b.pose_at(t_s)
        V = b.model.vertices
        if not len(V):
            lo, hi = b.model.bounds()
            V = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        out.append(V @ T[:3, :3].T + T[:3, 3])
    return np.vstack(out)


def calibration_results(replay: Replay, scene: Scene) -> CalibrationResults:
    """The camera and turret calibrations of the run against the scene's true camera and turret."""
    out: dict[str, Any] = {}
    cams = replay.runs_of("calibrate_camera")
    if cams:
        run = cams[-1]
        wf = run.workflow
        X = _body_corners(scene, run.t_end)
        X = X[(scene.camera.depth(X) > 0) & (run.camera.depth(X) > 0)]
        d = np.linalg.norm(run.camera.project(X) - scene.camera.project(X), axis=1)
        out.update(
            camera_rms_px=float(wf.result.rms_px),
            camera_points=len(wf.uv),
            camera_reprojection_rms_px=float(np.sqrt(np.mean(d**2))),
            camera_reprojection_max_px=float(d.max()),
            camera_centre_error_m=float(np.linalg.norm(run.camera.center - scene.camera.center)),
        )
    turrets = replay.runs_of("calibrate_turret")
    if turrets:
        run = turrets[-1]
        s = run.workflow.summary()
        deg, m = pose_error(run.T_world_turret, scene.turret.T_world_turret)
        out.update(
            turret_rms_mm=float(s["rms_mm"]),
            turret_points=len(s.get("points", [])),
            turret_error_deg=float(deg),
            turret_error_m=float(m),
        )
    return CalibrationResults(**out)


# ---------------------------------------------------------------------- the box (Table III.1)
@dataclass(frozen=True)
class BoxResults:
    """The modelled box against the truth, in the paper's order (width, height, length), metres.

    estimate, sigma, truth : (3,). volume_m3, volume_true_m3. method : the workflow's.
    distance_turret_m, distance_camera_m : from the range finder / the camera to the box's centre.
    points : range points per measured face. fused : the same measurements by the fused fit
    (estimate (3,), sigma (3,)). true_camera : the same clicks and points through the true camera
    instead of the calibrated one (estimate (3,), sigma (3,)) — a diagnostic of how much of the
    error the camera calibration causes (an operator never has the true camera).
    sigma_parts : source → (3,) σ in the paper's order: "measurements" (clicks and range noise),
    "camera calibration", "turret calibration" (the calibrations' share; absent when the run's
    site had no calibration covariance).
    """

    name: str
    method: str
    estimate: np.ndarray
    sigma: np.ndarray
    truth: np.ndarray
    volume_m3: float
    volume_true_m3: float
    distance_turret_m: float
    distance_camera_m: float
    points: tuple[int, ...]
    fused: tuple[np.ndarray, np.ndarray]
    true_camera: tuple[np.ndarray, np.ndarray]
    sigma_parts: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        return self.estimate - self.truth


def _with_calibrations(run: RunRecord, build) -> ModelResult:
    """``build(camera, T_world_turret)`` through the run's calibrations, σ with their share."""
    camera_cov, turret_cov = run.calibration_covs
    return with_calibration_uncertainty(
        build, run.camera, run.T_world_turret, camera_cov=camera_cov, turret_cov=turret_cov
    )


def box_results(run: RunRecord, scene: Scene) -> BoxResults:
    """Table III.1's measures for one accepted ``model_object`` run of a box."""
    wf = run.workflow
    body = scene.body(run.object_name)
    T_true = body.pose_at(run.t_end)
    lo, hi = body.model.bounds()
    dims_true = hi - lo
    r = wf.result
    est, sig, truth = box_dims_paper_order(r, T_true, dims_true)
    faces = wf.box_faces()
    alt = {}
    fused = _with_calibrations(run, lambda cam, T: model_box(cam, wf.box_faces(T), wf.support, method="fused"))
    alt["fused"] = box_dims_paper_order(fused, T_true, dims_true)[:2]
    # The diagnostic through the true camera: the same construction, its measurement σ only.
    alt["true_camera"] = box_dims_paper_order(
        model_box(scene.camera, faces, wf.support, method=r.method), T_true, dims_true
    )[:2]
    parts = {}
    for source, sig_d in r.details.get("sigma_parts", {}).items():
        tmp = replace(r, sigmas={k: sig_d.get(k, float("nan")) for k in ("size_x", "size_y", "size_z")})
        parts[source] = box_dims_paper_order(tmp, T_true, dims_true)[1]
    centre = T_true[:3, :3] @ ((lo + hi) / 2) + T_true[:3, 3]
    return BoxResults(
        run.object_name,
        r.method,
        est,
        sig,
        truth,
        float(np.prod(est)),
        float(np.prod(dims_true)),
        float(np.linalg.norm(centre - scene.turret.T_world_turret[:3, 3])),
        float(np.linalg.norm(centre - scene.camera.center)),
        tuple(len(f.points_world) for f in faces),
        alt["fused"],
        alt["true_camera"],
        parts,
    )


# ---------------------------------------------------------------------- the cylinder (Table III.2)
@dataclass(frozen=True)
class CylinderResults:
    """Every method on the run's measurements (``METHODS`` order), against the truth.

    by_method : method → {"radius", "height", "sigma_radius", "sigma_height", "axis_error",
    "sigma_axis", "depth"} (metres; NaN when the method failed) and "error" (the failure's
    message or ""); every σ includes the calibrations' share when the run's site had their
    covariances, and "sigma_parts" splits them by source (``ModelResult.details``).
    radius_true, height_true, depth_true (= the radius) : metres. distance_turret_m,
    distance_camera_m : from the range finder / the camera to the axis at mid-height. method : the
    one the workflow used.
    beams, hits : per scan.
    """

    name: str
    method: str
    by_method: dict[str, dict[str, Any]]
    radius_true: float
    height_true: float
    distance_turret_m: float
    distance_camera_m: float
    beams: tuple[int, ...]
    hits: tuple[int, ...]

    @property
    def depth_true(self) -> float:
        return self.radius_true


def cylinder_results(run: RunRecord, scene: Scene) -> CylinderResults:
    """Table III.2's measures for one accepted ``model_object`` run of a cylinder: the paper's three
    methods and the fused fit, on the same silhouettes and scans."""
    wf = run.workflow
    body = scene.body(run.object_name)
    T_true = body.pose_at(run.t_end)
    solid = body.model.solids[0]
    p0 = T_true[:3, :3] @ solid.p0 + T_true[:3, 3]
    axis = T_true[:3, :3] @ solid.axis
    mid_true = p0 + 0.5 * solid.height * axis
    O_rf = scene.turret.T_world_turret[:3, 3]
    front = float(np.linalg.norm((mid_true - O_rf)[:2]) - solid.r0)
    by_method: dict[str, dict[str, Any]] = {}
    for m in METHODS:
        try:
            res = (
                wf.result
                if m == wf.result.method
                else _with_calibrations(
                    run,
                    lambda cam, T, m=m: model_cylinder(
                        cam,
                        m,
                        silhouettes_uv=np.array(wf.silhouettes),
                        scans=wf.scans,
                        T_world_turret=T,
                        spec=scene.rangefinder,
                        support=wf.support,
                        cone=wf.shape == "cone",
                    ),
                )
            )
        except ValueError as exc:
            by_method[m] = {
                k: float("nan")
                for k in ("radius", "height", "sigma_radius", "sigma_height", "axis_error", "sigma_axis", "depth")
            }
            by_method[m]["error"] = str(exc)
            continue
        mid = res.axis.point + 0.5 * res.dimensions["height"] * res.axis.direction
        by_method[m] = {
            "radius": res.dimensions["radius"],
            "height": res.dimensions["height"],
            "sigma_radius": res.sigmas.get("radius", float("nan")),
            "sigma_height": res.sigmas.get("height", float("nan")),
            "axis_error": float(distance_point_line(mid, Line(p0, axis))),
            "sigma_axis": res.sigmas.get("axis_position", float("nan")),
            "depth": cylinder_depth_m(res, O_rf, front),
            "error": "",
            "sigma_parts": res.details.get("sigma_parts", {}),
        }
    return CylinderResults(
        run.object_name,
        wf.result.method,
        by_method,
        float(solid.r0),
        float(solid.height),
        float(np.linalg.norm(mid_true - O_rf)),
        float(np.linalg.norm(mid_true - scene.camera.center)),
        tuple(len(s) for s in wf.scans),
        tuple(int(s.hits.sum()) for s in wf.scans),
    )


# ---------------------------------------------------------------------- pose updates (Table V.1)
@dataclass(frozen=True)
class PoseUpdate:
    """One update_pose run against the true pose at its end.

    motion_deg, motion_m : the object's true motion since the previous update (or t = 0).
    p3l_source : "workflow" (the operator's Solve, the candidate chosen) or "same clicks" (P3L run
    by the report on the run's clicks: the operator refined from the database pose). p3l_error,
    refined_error : (degrees, metres), NaN without a P3L solution. noise_free_error : P3L on the
    clicks without their noise (``_true_segments``) through the true camera, its first-ranked
    candidate (degrees, metres), NaN without truth; noise_free_nearest : its candidate nearest the
    truth. refined_true_camera : the same refinement (same start, same clicks) through the true
    camera instead of the calibrated one (degrees, metres): how much of the error the camera
    calibration causes. rms_px : the refinement's RMS. std_deg, std_m : its predicted σ of the rotation angle (RSS of
    the three axes) and of the position. edges : clicked edges. candidates : P3L's count.
    """

    name: str
    t_s: float
    motion: str
    motion_deg: float
    motion_m: float
    p3l_source: str
    p3l_error: tuple[float, float]
    refined_error: tuple[float, float]
    noise_free_error: tuple[float, float]
    noise_free_nearest: tuple[float, float]
    refined_true_camera: tuple[float, float]
    rms_px: float
    std_deg: float
    std_m: float
    edges: int
    candidates: int


def _true_segments(run: RunRecord, scene: Scene, T_true: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The run's clicks without their noise: each clicked 3D point of the script's truth, moved
    onto its model edge's line at the true pose and projected through the true camera — exact to
    round-off, where the script's stored ``uv_true`` is rounded to 1e-4 px. Returns (segments
    (S, 2, 2) pixels, model edges (S, 2, 3) object frame) in click order, or None without truth."""
    model = scene.body(run.object_name).model
    pts, edge_ids = [], []
    for a in run.script_actions:
        if a.action != "click":
            continue
        t = a.truth or {}
        if "X_world" not in t or "edge" not in t:
            return None
        E = model.vertices[model.edges[int(t["edge"])]] @ T_true[:3, :3].T + T_true[:3, 3]
        d = (E[1] - E[0]) / np.linalg.norm(E[1] - E[0])
        X = np.asarray(t["X_world"], float)
        pts.append(E[0] + ((X - E[0]) @ d) * d)
        edge_ids.append(int(t["edge"]))
    if not pts or len(pts) % 2 or edge_ids[0::2] != edge_ids[1::2]:
        return None
    segs = scene.camera.project(np.array(pts)).reshape(-1, 2, 2)
    return segs, np.array([model.vertices[model.edges[e]] for e in edge_ids[0::2]])


def pose_update(
    run: RunRecord, scene: Scene, T_before: np.ndarray, large_deg: float = 18.0, large_m: float = 0.05
) -> PoseUpdate:
    """One accepted update_pose run, compared with the true pose at its end.

    T_before : (4, 4) the true pose before the motion. large_deg, large_m : the paper's limit of
    the small-motion method (§IV.3): a true motion beyond either is "large".
    """
    wf = run.workflow
    T_true = scene.body(run.object_name).pose_at(run.t_end)
    motion_deg, motion_m = pose_error(T_before, T_true)
    model = wf.obj.model
    pairs = [(s, e) for s, e in zip(wf.segs, wf.edge_ids) if e is not None]
    segs = np.array([s for s, _ in pairs])
    edges = np.array([model.vertices[model.edges[e]] for _, e in pairs])
    nan2 = (float("nan"), float("nan"))
    if wf.candidates:
        source, cands = "workflow", wf.candidates
        T_p3l = cands[wf.chosen if wf.chosen is not None else 0]
    else:
        source = "same clicks"
        cands, _ = first_p3l(run.camera, segs, edges)
        T_p3l = cands[0] if cands else None
    p3l_err = pose_error(T_p3l, T_true) if T_p3l is not None else nan2
    truth = _true_segments(run, scene, T_true)
    noise_free = nearest = nan2
    if truth is not None:
        nf, _ = first_p3l(scene.camera, *truth)
        if nf:
            errs = [pose_error(T, T_true) for T in nf]
            noise_free, nearest = errs[0], min(errs, key=lambda e: e[0])
    r = wf.refined
    start = wf.candidates[wf.chosen] if wf.chosen is not None else wf.obj.T_world_obj
    try:
        diag = refine(scene.camera, start, segs_uv=segs, edges_obj=edges, loss=wf.loss)
        true_cam = tuple(map(float, pose_error(diag.T_world_obj, T_true)))
    except ValueError:
        true_cam = nan2
    return PoseUpdate(
        run.object_name,
        run.t_end,
        "large" if (motion_deg > large_deg or motion_m > large_m) else "small",
        float(motion_deg),
        float(motion_m),
        source,
        tuple(map(float, p3l_err)),
        tuple(map(float, pose_error(r.T_world_obj, T_true))),
        tuple(map(float, noise_free)),
        tuple(map(float, nearest)),
        true_cam,
        float(r.rms_px),
        float(np.linalg.norm(r.std_r_deg)),
        float(np.linalg.norm(r.std_t_m)),
        len(pairs),
        len(cands),
    )


def pose_results(replay: Replay, scene: Scene) -> list[PoseUpdate]:
    """Every update_pose run, in order. An update's true motion is the object's, from where it
    truly was at the previous update of it (or at t = 0) to where it is at this one."""
    out, last_t = [], {}
    for run in replay.runs_of("update_pose"):
        body = scene.body(run.object_name)
        out.append(pose_update(run, scene, body.pose_at(last_t.get(run.object_name, 0.0))))
        last_t[run.object_name] = run.t_end
    return out


# ---------------------------------------------------------------------- everything
@dataclass(frozen=True)
class DemoResults:
    """All of the run's numbers (see the module docstring)."""

    calibration: CalibrationResults
    boxes: list[BoxResults] = field(default_factory=list)
    cylinders: list[CylinderResults] = field(default_factory=list)
    poses: list[PoseUpdate] = field(default_factory=list)


def demo_results(replay: Replay, scene: Scene) -> DemoResults:
    """Compute every comparison the report shows from a finished replay."""
    boxes, cylinders = [], []
    for run in replay.runs_of("model_object"):
        shape = run.workflow.shape
        if shape == "box":
            boxes.append(box_results(run, scene))
        elif shape == "cylinder":
            cylinders.append(cylinder_results(run, scene))
    return DemoResults(calibration_results(replay, scene), boxes, cylinders, pose_results(replay, scene))
