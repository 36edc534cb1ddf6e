"""The robot's base pose in the world from image edges of its links clicked at known joint configurations.

The robot at joint configuration q_k is a rigid model in its base frame: its link shapes placed by the
forward kinematics, ``T_base_shape(q_k)``. An image segment clicked on one of its straight features — a
polyhedral edge of a link (a box's), or a silhouette generator of a link's cylinder or cone — is a
measurement of that feature's 3D line in the base frame, and every click, whatever the configuration,
shares one unknown: ``T_world_base``. So the base pose is the pose of one "object", the base frame, from
clicked edges, and the pose pipeline's refinement (``core.pose.refine_views``: the pixel distances of the
clicked points to the projected lines, each click weighted by its σ) solves it, with its covariance.

A silhouette generator depends on where the camera is: it is the generator whose tangent plane passes
through the optical centre. ``refine_base`` holds each silhouette's generator fixed (computed at the
current estimate), refines, and computes the generators again at the new estimate until the base stops
moving: at the fixed point each clicked line's interpretation plane is tangent to its solid, which is the
condition the silhouette imposes (a generator slides along its surface to first order, so the iteration
converges in a few rounds).

``features_at`` lists the straight features of the robot seen from an optical centre (the polyhedral
edges with their convex visibility, both silhouette generators of every solid of revolution);
``feature_line`` gives one feature in the base frame; ``match_segment`` finds which projected feature a
clicked segment lies on, when only one fits (automatic assignment); ``tip_corners`` are the corners of the
tool's end (the closed gripper's fingertips), the known points that calibrate a camera from the robot.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from ..camera import Camera
from ..pose.refine import RefineResult, ViewClicks, refine_views
from ..pose.uncertainty import with_views_camera_uncertainty
from ..primitives import Revolution
from ..transforms import check_T, invert_T, pose_error, transform_points
from .model import RobotModel

__all__ = [
    "RobotFeature",
    "BaseClick",
    "BaseFit",
    "features_at",
    "feature_line",
    "refine_base",
    "match_segment",
    "tip_corners",
    "FEATURE_KINDS",
]

FEATURE_KINDS = ("edge", "silhouette")
MAX_ROUNDS = 12  # silhouettes recomputed at most this many times
ROUND_TOL_M = 1e-7  # the base moved less than this (and the rotation likewise, in radians × 1 m): converged


@dataclass(frozen=True)
class RobotFeature:
    """A straight feature of the robot at one configuration.

    config : index of the joint configuration. shape : index into ``RobotModel.link_breps(q)`` (every link's
    drawn shapes, in the model's link order). kind : "edge" (a polyhedral edge, ``index`` into the shape's
    edges) or "silhouette" (``index`` = 2 · solid + side: side 0 and 1 the two generators of the shape's
    solid of revolution, as ``Revolution.silhouette`` orders them).
    """

    config: int
    shape: int
    kind: str
    index: int

    def __post_init__(self):
        if self.kind not in FEATURE_KINDS:
            raise ValueError(f"a robot feature's kind is one of {FEATURE_KINDS}, got {self.kind!r}")

    def label(self, links: Sequence[str]) -> str:
        """ "gripper_link edge 3", "forearm_link silhouette 1" (``links``: the shapes' links, in shape order)."""
        return f"{links[self.shape]} {self.kind} {self.index}"


@dataclass(frozen=True)
class BaseClick:
    """One clicked image segment on a robot feature: ``seg_uv`` (2, 2) two pixels along it, ``feature``,
    ``sigma_px`` its noise, ``view`` the index of the camera it was clicked in (into ``refine_base``'s cameras)."""

    seg_uv: np.ndarray
    feature: RobotFeature
    sigma_px: float = 1.0
    view: int = 0


@dataclass(frozen=True)
class BaseFit:
    """``refine_base``'s answer.

    T_world_base : (4, 4). cov : (6, 6) of (δt (m), δr (rad)) in the world frame about the base's origin
    (``core.pose.refine``'s convention), the camera calibrations' share included when given. result : the
    last refinement (``RefineResult``: residuals per click in the clicks' order, RMS, σ). rounds : how many
    times the silhouettes were recomputed. lines_base : (S, 2, 3) each click's feature in the base frame at
    the solution.
    """

    T_world_base: np.ndarray
    cov: np.ndarray
    result: RefineResult
    rounds: int
    lines_base: np.ndarray = field(repr=False)

    @property
    def rms_px(self) -> float:
        return self.result.rms_px

    @property
    def std_position_m(self) -> float:
        """The largest standard deviation of the base's position along a world axis (metres)."""
        return float(np.sqrt(np.max(np.diag(self.cov)[:3])))

    @property
    def std_angle_rad(self) -> float:
        """The largest standard deviation of the base's rotation about a world axis (radians)."""
        return float(np.sqrt(np.max(np.diag(self.cov)[3:])))


def _shapes_base(model: RobotModel, q) -> list[tuple[str, object, np.ndarray]]:
    """(link, BRep, T_base_shape) of every drawn shape at q, in ``link_breps`` order."""
    return model.link_breps(q)


def _silhouette(brep, index: int, T_base_shape: np.ndarray, center_base: np.ndarray) -> np.ndarray | None:
    """Generator ``index % 2`` of solid ``index // 2`` seen from ``center_base`` (3,), in the base frame (2, 3);
    None when the solid is no solid of revolution or the centre is inside its extension."""
    j = index // 2
    if not 0 <= j < len(brep.solids) or not isinstance(brep.solids[j], Revolution):
        return None
    c_shape = transform_points(invert_T(T_base_shape), center_base[None])[0]
    sil = brep.solids[j].silhouette(c_shape)
    if not len(sil):
        return None
    return transform_points(T_base_shape, sil[index % 2])


def features_at(
    model: RobotModel, q, T_world_base: np.ndarray, center_world: np.ndarray, config: int = 0
) -> list[tuple[RobotFeature, np.ndarray, bool]]:
    """Every straight feature of the robot at joint configuration q seen from ``center_world`` (3,): a list of
    (RobotFeature, its segment in the world (2, 3), visible). A polyhedral edge is visible when one of its
    shape's faces bordering it faces the centre (each shape on its own: other links may hide it); both
    silhouette generators of every solid of revolution are listed, visible."""
    T_wb = check_T(T_world_base, "T_world_base")
    c = np.asarray(center_world, float).reshape(3)
    c_base = transform_points(invert_T(T_wb), c[None])[0]
    out = []
    for k, (_link, brep, T_bs) in enumerate(_shapes_base(model, q)):
        if len(brep.edges):
            wf = brep.wireframe(c, T_wb @ T_bs)
            for seg, vis, e, kind in zip(wf.segments, wf.visible, wf.edge_index, wf.kind):
                if kind == "edge" and e >= 0:
                    out.append((RobotFeature(config, k, "edge", int(e)), seg.copy(), bool(vis)))
        for j in range(len(brep.solids)):
            for side in (0, 1):
                line = _silhouette(brep, 2 * j + side, T_bs, c_base)
                if line is not None:
                    out.append(
                        (RobotFeature(config, k, "silhouette", 2 * j + side), transform_points(T_wb, line), True)
                    )
    return out


def feature_line(model: RobotModel, q, feature: RobotFeature, center_base: np.ndarray) -> np.ndarray:
    """The feature's segment (2, 3) in the base frame at joint configuration q, a silhouette's seen from the
    optical centre ``center_base`` (3,) (base frame). ValueError for a feature the model does not have there."""
    shapes = _shapes_base(model, q)
    if not 0 <= feature.shape < len(shapes):
        raise ValueError(f"the robot has shapes 0..{len(shapes) - 1}, not {feature.shape}")
    _link, brep, T_bs = shapes[feature.shape]
    if feature.kind == "edge":
        if not 0 <= feature.index < len(brep.edges):
            raise ValueError(f"shape {feature.shape} ({_link}) has no edge {feature.index}")
        return transform_points(T_bs, brep.vertices[brep.edges[feature.index]])
    line = _silhouette(brep, feature.index, T_bs, np.asarray(center_base, float).reshape(3))
    if line is None:
        raise ValueError(f"shape {feature.shape} ({_link}) shows no silhouette {feature.index} from the camera")
    return line


def _lines(model, configs, clicks, cameras, T_world_base) -> np.ndarray:
    """Every click's feature in the base frame (S, 2, 3), silhouettes seen from its camera at T_world_base."""
    T_bw = invert_T(T_world_base)
    centers = [transform_points(T_bw, cam.center[None])[0] for cam in cameras]
    return np.array([feature_line(model, configs[c.feature.config], c.feature, centers[c.view]) for c in clicks])


def _views(clicks, cameras, lines) -> list[ViewClicks]:
    """The clicks as ``refine_views`` takes them: one ViewClicks per camera clicked in, in click order."""
    out = []
    for v in sorted({c.view for c in clicks}):
        idx = [i for i, c in enumerate(clicks) if c.view == v]
        out.append(
            ViewClicks(
                cameras[v],
                np.array([clicks[i].seg_uv for i in idx], float).reshape(-1, 2, 2),
                lines[idx],
                sigma_px=np.array([clicks[i].sigma_px for i in idx], float),
                seg_index=idx,
            )
        )
    return out


def refine_base(
    model: RobotModel,
    configs,
    clicks: Sequence[BaseClick],
    cameras: Sequence[Camera],
    T_world_base0: np.ndarray,
    *,
    loss: str = "l2",
    huber_px: float = 3.0,
    camera_covs: Sequence[np.ndarray | None] | None = None,
) -> BaseFit:
    """The base pose T_world_base from clicked segments on the robot's features (module docstring).

    model : the robot. configs : (K, n) the joint configurations the clicks were made at (``feature.config``
    indexes them). clicks : the clicked segments. cameras : the cameras (``BaseClick.view`` indexes them).
    T_world_base0 : (4, 4) where to start (the base's nominal or last calibrated pose). loss, huber_px : as
    ``core.pose.refine``. camera_covs : optional, per camera its C's covariance (12, 12) or None: the
    calibrations' share joins ``cov``.

    ValueError (one line) for too few clicks, clicks that leave the base free (the refinement names the
    direction), or a feature the model does not have.
    """
    configs = np.atleast_2d(np.asarray(configs, float))
    clicks = list(clicks)
    if not clicks:
        raise ValueError("no clicked edges: click edges of the robot's links")
    for c in clicks:
        if not 0 <= c.feature.config < len(configs):
            raise ValueError(f"a click names configuration {c.feature.config}; there are {len(configs)}")
        if not 0 <= c.view < len(cameras):
            raise ValueError(f"a click names camera {c.view}; there are {len(cameras)}")
    T = check_T(T_world_base0, "T_world_base0").copy()
    res, lines, rounds = None, None, 0
    for _ in range(MAX_ROUNDS):
        rounds += 1
        lines = _lines(model, configs, clicks, cameras, T)
        res = refine_views(_views(clicks, cameras, lines), T, loss=loss, huber_px=huber_px)
        moved_deg, moved_m = pose_error(res.T_world_obj, T)
        T = res.T_world_obj
        if moved_m < ROUND_TOL_M and np.radians(moved_deg) < ROUND_TOL_M:
            break
    if not any(c.feature.kind == "silhouette" for c in clicks):
        rounds = 1
    if camera_covs is not None and any(cv is not None for cv in camera_covs):
        views = _views(clicks, cameras, lines)
        covs = [camera_covs[v] for v in sorted({c.view for c in clicks})]
        res = with_views_camera_uncertainty(res, views, covs, huber_px=huber_px)
    return BaseFit(res.T_world_obj.copy(), res.cov.copy(), res, rounds, lines)


MATCH_GATE = 13.8  # χ² of 2 degrees of freedom at 0.999: a click farther than this from a feature is not it
MODEL_PX = 1.0  # the robot model's own error on the image (link lengths, joint offsets), added to the click's
OVERLAP_SIGMAS = 3.0  # a feature's ends may lie this many σ farther along its line
MIN_FEATURE_PX = 2.0  # a feature drawn shorter than this (end-on) has no direction to match a click by


def _click_distances(seg_uv: np.ndarray, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For a clicked segment (2, 2) and projected features (..., F, 2, 2): (the signed distances of the two
    clicked pixels to each feature's line (..., F, 2), the features' unit directions (..., F, 2), their lengths
    (..., F))."""
    d = uv[..., 1, :] - uv[..., 0, :]
    L = np.linalg.norm(d, axis=-1)
    u = d / np.maximum(L, 1e-12)[..., None]
    n = np.stack([-u[..., 1], u[..., 0]], axis=-1)
    r = np.einsum("...fj,...fij->...fi", n, seg_uv[None] - uv[..., :1, :])
    return r, u, L


def match_segment(
    seg_uv: np.ndarray,
    segs_world: np.ndarray,
    camera: Camera,
    T_world_base: np.ndarray,
    cov: np.ndarray,
    *,
    sigma_px: float = 1.0,
    gate: float = MATCH_GATE,
    min_overlap: float = 0.3,
) -> tuple[int | None, np.ndarray]:
    """Which robot feature a clicked segment lies on, when only one can be it given how well the base is known.

    seg_uv : (2, 2) the clicked pixels. segs_world : (F, 2, 3) the candidate features at the base estimate
    ``T_world_base`` (in front of the camera). cov : (6, 6) the estimate's covariance, (δt (m), δr (rad)) in the
    world frame about the base's origin (``refine_base``'s convention; a stated prior for a base not yet
    calibrated).

    Each feature's innovation is the two clicked pixels' signed distances to its projected line; its
    covariance S = J cov Jᵀ + (σ² + MODEL_PX²) I, with J the distances' derivative with respect to the base's
    pose (the data-association test of a Kalman filter). A feature is compatible when νᵀ S⁻¹ ν ≤ ``gate`` and
    at least ``min_overlap`` of the clicked segment lies alongside it, its ends allowed ``OVERLAP_SIGMAS`` of
    their own σ farther. Returns (the index of the only compatible feature, else None — none, or several: the
    operator says which; every feature's νᵀ S⁻¹ ν (F,), inf where the click is not alongside it)."""
    seg = np.asarray(seg_uv, float).reshape(2, 2)
    X = np.asarray(segs_world, float).reshape(-1, 2, 3)
    if not len(X):
        return None, np.zeros(0)
    o = np.asarray(T_world_base, float)[:3, 3]
    h = 1e-5
    steps = []  # the features moved with the base by ±h along each of the 6 coordinates: (12, F, 2, 3)
    for i in range(6):
        for sgn in (1.0, -1.0):
            e = np.zeros(6)
            e[i] = sgn * h
            steps.append(X + e[:3] + np.cross(e[3:], X - o))
    uv = camera.project(np.concatenate([X[None], np.array(steps)]).reshape(-1, 3)).reshape(13, -1, 2, 2)
    r, u, L = _click_distances(seg, uv)
    J = (r[1::2] - r[2::2]).transpose(1, 2, 0) / (2 * h)  # (F, 2, 6) distances per unit of the base's pose
    Je = (uv[1::2] - uv[2::2]).transpose(1, 2, 3, 0) / (2 * h)  # (F, 2 ends, 2, 6)
    C = np.asarray(cov, float).reshape(6, 6)
    S = J @ C @ J.transpose(0, 2, 1) + (sigma_px**2 + MODEL_PX**2) * np.eye(2)
    nu = r[0]
    d2 = np.einsum("fi,fi->f", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    # along each feature's line: the click's extent against the feature's, its ends' σ allowed
    u0, a = u[0], uv[0, :, 0]
    end_var = np.einsum("fj,fejk,kl,feml,fm->fe", u0, Je, C, Je, u0)
    slack = OVERLAP_SIGMAS * np.sqrt(np.maximum(end_var, 0.0) + sigma_px**2 + MODEL_PX**2)
    t = np.einsum("fj,ifj->fi", u0, seg[:, None] - a[None])  # (F, 2) the clicks along each feature
    lo, hi = t.min(axis=1), t.max(axis=1)
    ls = max(float(np.linalg.norm(seg[1] - seg[0])), 1e-12)
    overlap = np.clip(np.minimum(hi, L[0] + slack[:, 1]) - np.maximum(lo, -slack[:, 0]), 0.0, None) / ls
    d2 = np.where((overlap >= min_overlap) & (L[0] >= MIN_FEATURE_PX), d2, np.inf)
    fits = np.flatnonzero(d2 <= gate)
    return (int(fits[0]) if len(fits) == 1 else None), d2


def tip_corners(model: RobotModel, q, tol_m: float = 1e-4) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The corners of the tool's end at q: of the polyhedral shapes the tool's last moving joint carries (a
    gripper and its fingers), the vertices at the far end along the tool's z axis (within ``tol_m``) that lie
    at a corner of their bounding rectangle across it — with a closed gripper, the corners of the fingertips'
    end face. Returns (X_base (M, 3) in the base frame, shape (M,) each one's index into
    ``RobotModel.link_breps(q)``, vertex (M,) its index among that shape's vertices); empty arrays when the
    tool carries no polyhedral shape."""
    none = (np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64))
    moving = [i for i in model.chain(model.tool) if model.joints[i].moves]
    if not moving:
        return none
    carried = {link for link in model.links if moving[-1] in model.chain(link)}
    T_base_tool = model.tool_pose(q)
    T_tool_base = invert_T(T_base_tool)
    V, shape, vertex = [], [], []
    for k, (link, brep, T_bs) in enumerate(_shapes_base(model, q)):
        if link in carried and len(brep.vertices):
            V.append(transform_points(T_tool_base @ T_bs, brep.vertices))
            shape += [k] * len(brep.vertices)
            vertex += list(range(len(brep.vertices)))
    if not V:
        return none
    V, shape, vertex = np.vstack(V), np.array(shape), np.array(vertex)
    end = V[:, 2] >= V[:, 2].max() - tol_m
    lo, hi = V[end, :2].min(axis=0), V[end, :2].max(axis=0)
    at_x = (np.abs(V[:, 0] - lo[0]) <= tol_m) | (np.abs(V[:, 0] - hi[0]) <= tol_m)
    at_y = (np.abs(V[:, 1] - lo[1]) <= tol_m) | (np.abs(V[:, 1] - hi[1]) <= tol_m)
    keep = np.flatnonzero(end & at_x & at_y)
    _, first = np.unique(np.round(V[keep], 9), axis=0, return_index=True)  # a corner two shapes share: once
    keep = keep[np.sort(first)]
    return transform_points(T_base_tool, V[keep]), shape[keep], vertex[keep]
