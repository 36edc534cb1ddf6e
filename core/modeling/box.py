"""Model a box ("a box lying on the table") from its visible faces: the paper's §III.1.

Each visible face gives a plane from range-finder points aimed at it (least squares, robust to
points that miss the face); each clicked image edge gives an interpretation plane; a vertex is
the least-squares point of every plane that meets there (faces, interpretation planes, the
support). A box (pose and three sizes) is then fitted to those vertices by generalised least
squares with their joint covariance, which fills in the hidden vertex and yields the sizes'
standard deviations. ``method="fused"`` then fits the box by maximum likelihood to the raw
range points and clicks, and to horizontal profile scans when given (``box_scans``: their edge
transitions put the silhouette's vertical edges on the turret's tangent planes).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..brep import BRep
from ..camera import Camera, as_segment
from ..geometry import Plane, angle_between_planes
from ..rangefinder import RangeFinderSpec, RangeScan
from ..robust import huber_weights
from ..transforms import check_T, exp_so3, make_T, skew
from .box_scans import (
    BoxScans,
    assign_returns,
    associate_tangents,
    reduce_box_scans,
    tangent_distances,
    tangent_distances_jacobian,
)
from .lm import levenberg_marquardt
from .observations import PlaneObs, fit_face_plane, interpretation_plane_obs, support_obs
from .result import ModelResult
from .vertices import solve_vertices

__all__ = ["BoxFace", "model_box", "box_corner_signs"]

_AXES = "xyz"


@dataclass(frozen=True)
class BoxFace:
    """What the operator measured of one visible face of a box.

    points_world : array, shape (N, 3), range-finder points aimed at the face, metres.
    edges_uv : array, shape (K, 2, 2), clicked image segments of the face's sides (0 ≤ K ≤ 4,
        any order; an edge shared with another visible face may be clicked in either or both).
    point_covs : array, shape (N, 3, 3), optional covariance of each point (m²), e.g. from
        ``core.rangefinder.beam_point_cov``.
    """

    points_world: np.ndarray
    edges_uv: np.ndarray
    point_covs: np.ndarray | None = None


def box_corner_signs() -> np.ndarray:
    """Sign pattern (8, 3) of the box corners, index = (sx > 0) + 2 (sy > 0) + 4 (sz > 0)."""
    return np.array([[1 if v & 1 else -1, 1 if v & 2 else -1, 1 if v & 4 else -1] for v in range(8)])


_CORNER_UNIT = box_corner_signs() * [0.5, 0.5, 0.5] + [0.0, 0.0, 0.5]  # corner = (8, 3) ⊙ dims


def _corner_offsets(dims: np.ndarray) -> np.ndarray:
    """Corners (8, 3) in the box frame (origin at the centre of the bottom face)."""
    return _CORNER_UNIT * np.asarray(dims)


def _so3_right_jacobian(w: np.ndarray) -> np.ndarray:
    """J_r(w) (3, 3): exp(w + δ) ≈ exp(w) exp(J_r(w) δ) for a small δ."""
    th = float(np.linalg.norm(w))
    K = skew(w)
    if th < 1e-6:
        return np.eye(3) - 0.5 * K + K @ K / 6.0
    return np.eye(3) - (1 - np.cos(th)) / th**2 * K + (th - np.sin(th)) / th**3 * K @ K


def _box_axes(face_normals: list[np.ndarray], support: Plane | None) -> np.ndarray:
    """Box axes (3, 3) as columns, from the outward face normals and the support's upward normal."""
    normals = list(face_normals)
    if support is not None:
        z = support.n
        others = normals
    else:
        if len(normals) < 2:
            raise ValueError(
                "a box needs two measured faces, or one face and the support plane it lies on; "
                f"got {len(normals)} face(s) and no support"
            )
        k = int(np.argmax([abs(n[2]) for n in normals]))
        z = normals[k] * np.sign(normals[k][2] or 1.0)
        others = normals[:k] + normals[k + 1 :]
    if not others:
        raise ValueError("a box needs at least one measured side face besides the support")
    perp = [n - (n @ z) * z for n in others]
    k = int(np.argmax([np.linalg.norm(p) for p in perp]))
    if np.linalg.norm(perp[k]) < 0.5:
        raise ValueError("the measured faces are (nearly) parallel: they do not fix the box's orientation")
    x = perp[k] / np.linalg.norm(perp[k])
    return np.column_stack([x, np.cross(z, x), z])


def model_box(
    camera: Camera,
    faces: Sequence[BoxFace],
    support: Plane | None = None,
    *,
    sigma_px: float = 1.0,
    sigma_point_m: float | None = None,
    support_sigma_m: float = 1e-3,
    plane_fit: str = "tls",
    robust: bool = True,
    min_angle_deg: float = 5.0,
    method: str = "planes",
    scans: Sequence[RangeScan] | None = None,
    T_world_turret: np.ndarray | None = None,
    spec: RangeFinderSpec = RangeFinderSpec(),
    jump_m: float = 0.05,
    edge_margin_m: float = 0.005,
) -> ModelResult:
    """Build a box from its visible faces (range points + clicked edges) and an optional support.

    Parameters
    ----------
    camera : Camera
        The calibrated camera (global model C) the edges were clicked in.
    faces : sequence of BoxFace
        The visible faces (1 to 3), each with its range points and clicked sides.
    support : Plane, optional
        The plane the box lies on (the table top, normal pointing up): its bottom face.
    sigma_px : float
        Click noise, pixels (each coordinate). sigma_point_m : isotropic range-point noise when a
        face has no ``point_covs`` (estimated from the residuals when None).
    support_sigma_m : float
        Uncertainty of the support plane's offset, metres.
    plane_fit : "tls" or "ols"
        Face plane estimator (total least squares, or the paper's ``ax + by + z + d = 0``).
    robust : bool
        Drop range points off their face (RANSAC) before fitting.
    min_angle_deg : float
        An interpretation plane closer than this to its face plane (the face seen edge-on)
        raises ValueError: their intersection would be ill-conditioned.
    method : "planes" or "fused"
        "planes": the paper's construction (vertices from planes, then a box fitted to them).
        "fused": starting from it, the box (pose and sizes; standing on the support when given:
        z along its normal, the bottom face on it) fitted by maximum likelihood to every range
        point (its distance to its face over its σ along the face's current normal) and every
        clicked end (its pixel distance to the model edge's image), and to the scans if given.
    scans : sequence of RangeScan, optional ("fused" only)
        Horizontal profile scans across the box: pan sweeps at a fixed tilt, misses (NaN) kept,
        from beyond one side of the box to beyond the other (``core.modeling.box_scans``). Each
        return on the box joins its face's points (the face its beam enters on the current box;
        returns within ``edge_margin_m`` of a face's border are left out); at each end of the
        box's run, the last hit and the next beam put the silhouette's vertical edge on the
        turret's vertical plane at the mid pan (residual: the edge's signed distance to that
        plane over ρ_h σ_pan).
    T_world_turret : array, shape (4, 4)
        The turret's calibrated pose; needed with scans. spec : the range finder's noise and
        step. jump_m : a range jump that ends the object's run in a scan (the background).
        edge_margin_m : scan returns entering the box nearer than this to a face's border are
        not used (they could lie on either face).

    Returns
    -------
    ModelResult
        kind "box", method as asked, ``model = BRep.box(size_x, size_y, size_z)`` with its frame at
        the centre of the bottom face, z up; ``vertices_world`` (8, 3) the fitted corners
        (``details["constructed_vertices"]`` holds the plane-constructed ones, NaN where hidden).
    """
    faces = list(faces)
    scans, T_world_turret = _checked_inputs(faces, method, scans, T_world_turret)
    con = _construct(camera, faces, support, sigma_px, sigma_point_m, support_sigma_m, plane_fit, robust, min_angle_deg)
    R, t, dims, cov_p, details_fused = con.R, con.t, con.dims, con.cov_p, {}
    if method == "fused":
        box_scans = None
        if scans:
            box_scans = reduce_box_scans(scans, T_world_turret, spec, R, t, dims, jump_m=jump_m)
        R, t, dims, cov_p, details_fused = _fused_box(
            camera,
            faces,
            con.fits,
            con.labels,
            con.segments,
            None if con.sup is None else con.sup.plane,
            R,
            t,
            dims,
            sigma_px,
            box_scans,
            T_world_turret,
            edge_margin_m,
        )
    return _box_result(camera, method, con, R, t, dims, cov_p, details_fused)


def _checked_inputs(faces: list, method: str, scans, T_world_turret) -> tuple[list, np.ndarray | None]:
    """The method, that there are faces, and the scans with the turret's pose (``method="fused"`` only)."""
    if method not in ("planes", "fused"):
        raise ValueError(f"method must be 'planes' or 'fused', got {method!r}")
    if not faces:
        raise ValueError("model_box needs at least one measured face")
    scans = [] if scans is None else list(scans)
    if scans:
        if method != "fused":
            raise ValueError(f"profile scans are fused by method='fused' only, got method={method!r}")
        if T_world_turret is None:
            raise ValueError("range scans need T_world_turret (the turret's calibrated pose)")
        T_world_turret = check_T(T_world_turret, "T_world_turret")
        for k, sc in enumerate(scans):
            if not isinstance(sc, RangeScan):
                raise ValueError(f"scans[{k}] must be a core.rangefinder.RangeScan, got {type(sc).__name__}")
    return scans, T_world_turret


@dataclass(frozen=True)
class _Constructed:
    """The paper's construction: the faces' fits and (axis, side) labels, the support (normal up), every
    plane (faces, support, clicked sides), the clicked sides as (corner pair, segment), the corners the
    planes fix (``solvable``: their indices; Xv, cov_v, vres from ``solve_vertices``) and the box fitted
    to them (``_fit_box``)."""

    fits: list
    labels: list[tuple[int, int]]
    sup: PlaneObs | None
    planes: list[PlaneObs]
    segments: list
    solvable: list[int]
    Xv: np.ndarray
    cov_v: np.ndarray
    vres: list
    R: np.ndarray
    t: np.ndarray
    dims: np.ndarray
    cov_p: np.ndarray
    fit_res: np.ndarray


def _construct(
    camera, faces, support, sigma_px, sigma_point_m, support_sigma_m, plane_fit, robust, min_angle_deg
) -> _Constructed:
    """Face planes, then the clicked sides' planes, the corners where three of them cross, the box."""
    fits, centroids = _fit_faces(camera.center, faces, sigma_point_m, plane_fit, robust)
    sup = None
    if support is not None:
        sup = support_obs(support, support_sigma_m)
        if sup.plane.n @ camera.center + sup.plane.d < 0:  # normal up: towards the camera's side
            sup = PlaneObs(sup.plane.flipped(), sup.cov, sup.label)
    R0 = _box_axes([fit.obs.plane.n for fit in fits], None if sup is None else sup.plane)
    planes, face_plane, labels = _label_faces(fits, R0, sup)
    edge_planes, segments = _clicked_sides(camera, faces, fits, labels, centroids, R0, planes, sigma_px, min_angle_deg)
    incidence, solvable, names = _corner_incidence(planes, face_plane, edge_planes)
    Xv, cov_v, vres = solve_vertices(planes, incidence, names)
    R, t, dims, cov_p, fit_res = _fit_box(Xv, cov_v, np.array(solvable), R0)
    return _Constructed(fits, labels, sup, planes, segments, solvable, Xv, cov_v, vres, R, t, dims, cov_p, fit_res)


def _fit_faces(c: np.ndarray, faces, sigma_point_m, plane_fit, robust) -> tuple[list, list[np.ndarray]]:
    """Each face's plane fitted to its range points, its normal outward (towards the camera at c, which
    sees the face), and the centroid (3,) of its inliers."""
    fits, centroids = [], []
    for k, f in enumerate(faces):
        if not isinstance(f, BoxFace):
            raise ValueError(f"faces[{k}] must be a BoxFace, got {type(f).__name__}")
        fit = fit_face_plane(
            f.points_world,
            covs=f.point_covs,
            sigma_m=sigma_point_m,
            method=plane_fit,
            robust=robust,
            label=f"face {k + 1}",
        )
        cen = np.asarray(f.points_world, dtype=float)[fit.inliers].mean(axis=0)
        p = fit.obs.plane
        if p.n @ (c - cen) < 0:
            # (n, d) → (−n, −d): the covariance is unchanged.
            fit = type(fit)(PlaneObs(p.flipped(), fit.obs.cov, fit.obs.label), fit.fits, fit.inliers, fit.method)
        fits.append(fit)
        centroids.append(cen)
    return fits, centroids


def _label_faces(fits, R0: np.ndarray, sup: PlaneObs | None):
    """Label each face by the box axis and side it faces.

    Returns (planes: the faces' then the support's, face_plane {(axis, side): [plane index]}, the
    faces' labels (axis, side)).
    """
    planes: list[PlaneObs] = []
    face_plane: dict[tuple[int, int], list[int]] = {}
    labels = []
    for k, fit in enumerate(fits):
        a = R0.T @ fit.obs.plane.n
        ax = int(np.argmax(np.abs(a)))
        if abs(a[ax]) < np.cos(np.radians(30.0)):
            raise ValueError(
                f"face {k + 1} is {np.degrees(np.arccos(min(1.0, abs(a[ax])))):.0f}° from every box axis: "
                f"the measured faces are not those of a box, or face {k + 1}'s points are wrong (part of its patch on "
                "another surface: measure it again with all its visible sides clicked)"
            )
        key = (ax, int(np.sign(a[ax])))
        if key in face_plane:
            raise ValueError(f"faces {face_plane[key][0] + 1} and {k + 1} are the same side of the box")
        if key == (2, -1) and sup is not None:
            raise ValueError(f"face {k + 1} faces down, where the box lies on its support")
        face_plane[key] = [len(planes)]
        labels.append(key)
        planes.append(PlaneObs(fit.obs.plane, fit.obs.cov, f"face {_sgn(key)}"))
    if sup is not None:
        face_plane[(2, -1)] = [len(planes)]
        planes.append(PlaneObs(sup.plane, sup.cov, "support (bottom face)"))
    return planes, face_plane, labels


def _clicked_sides(camera, faces, fits, labels, centroids, R0, planes, sigma_px, min_angle_deg):
    """Appends each clicked side's interpretation plane to ``planes`` and says which box edge it is
    (from its line on the face plane).

    Returns (edge_planes {corner pair: [plane index]}, segments [(corner pair, segment (2, 2))]).
    """
    signs = box_corner_signs()
    edge_planes: dict[tuple[int, int], list[int]] = {}
    segments = []
    min_angle = np.radians(min_angle_deg)
    for k, f in enumerate(faces):
        E = np.asarray(f.edges_uv, dtype=float)
        if E.size == 0:
            continue
        if E.ndim != 3 or E.shape[1:] != (2, 2):
            raise ValueError(f"faces[{k}].edges_uv must have shape (K, 2, 2), got {E.shape}")
        ax, sg = labels[k]
        fp = fits[k].obs.plane
        for j, seg in enumerate(E):
            seg = as_segment(seg, f"faces[{k}].edges_uv[{j}]")
            ip = interpretation_plane_obs(camera, seg, sigma_px, f"edge click {k}.{j}")
            ang = angle_between_planes(ip.plane, fp)
            if ang < min_angle:
                raise ValueError(
                    f"side {j + 1} of face {k + 1}: its plane through the camera is {np.degrees(ang):.1f}° from "
                    f"the face's plane (< {min_angle_deg}°): the camera sees that face edge-on, so the side "
                    "cannot be placed on it; model it from another view or another face"
                )
            m, M = _side_axis(camera, seg, fp, ax, R0, j, k)
            q = 3 - ax - m
            sq = int(np.sign(R0[:, q] @ (M - centroids[k])) or 1)
            verts = tuple(int(v) for v in np.flatnonzero((signs[:, ax] == sg) & (signs[:, q] == sq)))
            edge_planes.setdefault(verts, []).append(len(planes))
            planes.append(ip)
            segments.append((verts, seg))
    return edge_planes, segments


def _side_axis(camera, seg: np.ndarray, fp: Plane, ax: int, R0: np.ndarray, j: int, k: int):
    """The box axis that side j of face k (plane fp, facing along axis ax) runs along, and the clicked
    segment's midpoint M (3,) on the face plane.

    The clicked direction in the image is compared with the two box axes of the face drawn through M
    (image angles are robust where a short, foreshortened edge has a poorly known 3D direction).
    """
    c_ray, r_mid = camera.rays(seg.mean(axis=0, keepdims=True))
    M = c_ray + (-(fp.n @ c_ray + fp.d) / (fp.n @ r_mid[0])) * r_mid[0]
    d_img = (seg[1] - seg[0]) / np.linalg.norm(seg[1] - seg[0])
    cand = [m for m in range(3) if m != ax]
    offs = []
    for m in cand:
        uv = camera.project(np.array([M - 0.01 * R0[:, m], M + 0.01 * R0[:, m]]))
        e_img = (uv[1] - uv[0]) / max(np.linalg.norm(uv[1] - uv[0]), 1e-12)
        offs.append(np.degrees(np.arccos(min(1.0, abs(float(d_img @ e_img))))))
    m = cand[int(np.argmin(offs))]
    if min(offs) > 30.0:
        raise ValueError(
            f"side {j + 1} of face {k + 1} does not run along a side of that face (in the image it is "
            f"{min(offs):.0f}° from the nearest side direction): check its clicks, or measure face {k + 1} "
            "again with all its visible sides clicked"
        )
    return m, M


def _corner_incidence(planes, face_plane, edge_planes) -> tuple[list[list[int]], list[int], list[str]]:
    """The corners fixed by the planes through them (three crossing well), each one's planes and name."""
    signs = box_corner_signs()
    incidence, solvable, names = [], [], []
    for v in range(8):
        idx = []
        for (ax, sg), pl in face_plane.items():
            if signs[v, ax] == sg:
                idx += pl
        for verts, pl in edge_planes.items():
            if v in verts:
                idx += pl
        if len(idx) >= 3:
            N = np.array([planes[i].plane.n for i in idx])
            sv = np.linalg.svd(N, compute_uv=False)
            if sv[-1] >= 0.05 * sv[0]:
                incidence.append(idx)
                solvable.append(v)
                names.append(_corner_name(signs[v]))
    if len(solvable) < 2:
        raise ValueError(
            f"only {len(solvable)} corner(s) of the box are fixed by the measured faces and clicked edges; "
            "click the edges of the visible faces"
        )
    return incidence, solvable, names


def _box_result(camera, method: str, con: _Constructed, R, t, dims, cov_p, details_fused: dict) -> ModelResult:
    """The ModelResult of the box (R, t, dims) with the covariance (9, 9) of (dims, t, small rotation)."""
    corners = t + _corner_offsets(dims) @ R.T
    constructed = np.full((8, 3), np.nan)
    constructed[con.solvable] = con.Xv
    names_p = ("size_x", "size_y", "size_z", "x", "y", "z", "rot_x", "rot_y", "rot_z")
    dims_d = {n: float(v) for n, v in zip(names_p[:3], dims)}
    sig = {n: float(np.sqrt(cov_p[i, i])) for i, n in enumerate(names_p[:3])}
    sig["position"] = float(np.sqrt(np.trace(cov_p[3:6, 3:6])))
    click_res = []
    for verts, seg in con.segments:
        uv = camera.project(corners[list(verts)])
        l = np.cross(np.append(uv[0], 1.0), np.append(uv[1], 1.0))
        l /= np.linalg.norm(l[:2])
        click_res += list(np.column_stack([seg, np.ones(2)]) @ l)
    residuals = {
        "clicks_px": np.array(click_res),
        "vertex_fit_m": con.fit_res,
        "vertex_planes_m": np.concatenate(con.vres),
    }
    for k, fit in enumerate(con.fits):
        residuals[f"face_{_sgn(con.labels[k])}_points_m"] = fit.fits[fit.method].residuals_m
    residuals.update(details_fused.pop("scan_residuals", {}))
    return ModelResult(
        kind="box",
        method=method,
        model=BRep.box(*dims),
        T_world_obj=make_T(R, t),
        dimensions=dims_d,
        sigmas=sig,
        cov=cov_p,
        cov_names=names_p,
        vertices_world=corners,
        residuals=residuals,
        details={
            "constructed_vertices": constructed,
            "constructed_cov": con.cov_v,
            "face_fits": [f.fits for f in con.fits],
            "face_inliers": [f.inliers for f in con.fits],
            "face_labels": [_sgn(l) for l in con.labels],
            "planes": con.planes,
            **details_fused,
        },
    ).check_finite()


def _sgn(key: tuple[int, int]) -> str:
    return ("+" if key[1] > 0 else "-") + _AXES[key[0]]


def _corner_name(s: np.ndarray) -> str:
    return "(" + ", ".join(("+" if v > 0 else "-") + a for v, a in zip(s, _AXES)) + ")"


def _fit_box(X: np.ndarray, cov: np.ndarray, which: np.ndarray, R0: np.ndarray):
    """GLS fit of a box (R, t, dims) to constructed corners X (M, 3) with joint covariance (3M, 3M).

    Returns R (3, 3), t (3,) (centre of the bottom face), dims (3,), the covariance (9, 9) of
    (dims, t, rotation vector in the box frame) and the residuals (M,) (corner distances, m).
    """
    s = box_corner_signs()[which].astype(float)
    S = np.column_stack([0.5 * s[:, 0], 0.5 * s[:, 1], 0.5 * (s[:, 2] + 1)])  # corner = t + R (S ⊙ dims)
    W = np.linalg.pinv(cov, rcond=1e-12, hermitian=True)
    M = len(which)
    # Linear start: with R fixed, X = t + R diag(S_k) dims is linear in (dims, t).
    A = np.zeros((3 * M, 6))
    for k in range(M):
        A[3 * k : 3 * k + 3, :3] = R0 * S[k]
        A[3 * k : 3 * k + 3, 3:] = np.eye(3)
    sol, *_ = np.linalg.lstsq(A, X.reshape(-1), rcond=None)
    dims, t, R = sol[:3], sol[3:], R0
    for _ in range(20):
        V = S * dims  # (M, 3) corners in the box frame
        r = (X - (t + V @ R.T)).reshape(-1)
        J = np.zeros((M, 3, 9))
        J[:, :, :3] = R[None] * S[:, None, :]
        J[:, :, 3:6] = np.eye(3)
        # R exp([δ]×) v ≈ R v − R [v]× δ
        Vx = np.zeros((M, 3, 3))
        Vx[:, 0, 1], Vx[:, 0, 2], Vx[:, 1, 2] = -V[:, 2], V[:, 1], -V[:, 0]
        Vx[:, 1, 0], Vx[:, 2, 0], Vx[:, 2, 1] = V[:, 2], -V[:, 1], V[:, 0]
        J[:, :, 6:] = -np.einsum("ij,mjk->mik", R, Vx)
        J = J.reshape(3 * M, 9)
        H = J.T @ W @ J
        dscale = 1.0 / np.sqrt(np.maximum(np.diag(H), 1e-300))
        if np.linalg.cond(H * np.outer(dscale, dscale)) > 1e12:
            raise ValueError(
                "the clicked sides and measured faces do not fix all three sizes and the pose of the box; "
                "click all four sides of each measured face, and measure at least two faces"
            )
        step = np.linalg.solve(H, J.T @ W @ r)
        dims = dims + step[:3]
        t = t + step[3:6]
        R = R @ exp_so3(step[6:])
        if np.linalg.norm(step) < 1e-12:
            break
    if np.any(dims <= 0):
        raise ValueError(f"the fitted box has a non-positive size {dims}: the clicked edges contradict the faces")
    cov_p = np.linalg.inv(H)
    res = np.linalg.norm((X - (t + (S * dims) @ R.T)), axis=1)
    return R, t, dims, 0.5 * (cov_p + cov_p.T), res


def _face_planes(R: np.ndarray, t: np.ndarray, dims: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The six faces' outward unit normals (6, 3) and offsets (6,) (n·X + d = 0), row 2 axis + (side > 0)."""
    N = np.repeat(R.T, 2, axis=0) * _FACE_SIDES
    far = np.array([dims[0] / 2, dims[0] / 2, dims[1] / 2, dims[1] / 2, 0.0, dims[2]])
    return N, -(N @ t) - far


_FACE_SIDES = np.array([-1.0, 1.0] * 3)[:, None]


def _face_index(key: tuple[int, int]) -> int:
    return 2 * key[0] + (key[1] > 0)


def _fused_box(
    camera,
    faces,
    fits,
    labels,
    segments,
    support,
    R0,
    t0,
    dims0,
    sigma_px,
    scans: BoxScans | None = None,
    T_world_turret=None,
    edge_margin_m: float = 0.005,
):
    """Maximum-likelihood box from the raw range points, clicks and profile scans, starting at the planes' box.

    With scans, which face each scan return lies on and which box edge each transition brackets
    are decided at the start and again after each fit, until they no longer change (at most 3 fits).
    """
    if support is not None:
        R0, t0 = _stand_on(support, R0, t0)
    box = _BoxParameters(R0, t0, support is not None)
    fit = _FusedBoxFit(
        camera, box, _face_points(faces, fits, labels), segments, sigma_px, scans, T_world_turret, edge_margin_m
    )
    th0 = np.concatenate([np.zeros(3), dims0]) if box.on_support else np.concatenate([np.zeros(6), dims0])
    th, it, passes = fit.fit(th0)
    r = fit.residuals(th)
    J = fit.jacobian(th)
    cov_th = np.linalg.inv(J.T @ (huber_weights(r, 3.0)[:, None] * J))
    R, t, dims = box.unpack(th)
    if np.any(dims <= 0):
        raise ValueError(f"the fused box fit gives a non-positive size {dims}: the clicks contradict the range points")
    G = box.covariance_map(th)
    cov = G @ cov_th @ G.T
    details = {"fused_iterations": it, "fused_residuals_sigma": r}
    if scans is not None:
        details.update(fit.scan_details(th, passes))
    return R, t, dims, 0.5 * (cov + cov.T), details


def _face_points(faces, fits, labels) -> dict:
    """The faces' inlier range points "X" (N, 3), their covariances "C" (N, 3, 3) (isotropic at the fit's
    σ when a face has none) and the index "k" (N,) of the box face each lies on (``_face_index``)."""
    X_faces, C_faces, k_faces = [], [], []
    for f, fit, key in zip(faces, fits, labels):
        X = np.asarray(f.points_world, dtype=float)[fit.inliers]
        if f.point_covs is not None:
            C = np.asarray(f.point_covs, dtype=float)[fit.inliers]
        else:
            C = np.broadcast_to(fit.fits[fit.method].sigma_m ** 2 * np.eye(3), (len(X), 3, 3))
        X_faces.append(X)
        C_faces.append(C)
        k_faces.append(np.full(len(X), _face_index(key)))
    return {"X": np.vstack(X_faces), "C": np.concatenate(C_faces), "k": np.concatenate(k_faces)}


def _stand_on(support: Plane, R0: np.ndarray, t0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The box (R0, t0) turned to stand on the support: z along its normal and the bottom face on it
    (the planes' GLS box has its own small tilt, from the clicks on the top corners)."""
    x = R0[:, 0] - (R0[:, 0] @ support.n) * support.n
    x /= np.linalg.norm(x)
    R0 = np.column_stack([x, np.cross(support.n, x), support.n])
    return R0, t0 - (support.n @ t0 + support.d) * support.n


@dataclass(frozen=True)
class _BoxParameters:
    """The fused fit's parameters θ about the box (R0, t0). On the support: (turn about z, shift along
    R0's x and y, dims); else (rotation vector w of R0 exp(w), t − t0, dims)."""

    R0: np.ndarray
    t0: np.ndarray
    on_support: bool

    def unpack(self, th: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(R (3, 3), t (3,), dims (3,)) at θ."""
        R0, t0 = self.R0, self.t0
        if self.on_support:
            c, s_ = np.cos(th[0]), np.sin(th[0])
            R = R0 @ np.array([[c, -s_, 0.0], [s_, c, 0.0], [0.0, 0.0, 1.0]])
            return R, t0 + th[1] * R0[:, 0] + th[2] * R0[:, 1], th[3:6]
        return R0 @ exp_so3(th[:3]), t0 + th[3:6], th[6:9]

    def unpack_jacobian(self, th: np.ndarray, R: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Derivatives dR (n, 3, 3), dt (n, 3), ddims (n, 3) with respect to θ (n,), at R = unpack(θ)[0]."""
        n_th = len(th)
        dR, dt, ddims = np.zeros((n_th, 3, 3)), np.zeros((n_th, 3)), np.zeros((n_th, 3))
        if self.on_support:
            dR[0] = R @ skew(np.array([0.0, 0.0, 1.0]))
            dt[1], dt[2] = self.R0[:, 0], self.R0[:, 1]
        else:
            Jr = _so3_right_jacobian(th[:3])
            for j in range(3):
                dR[j] = R @ skew(Jr[:, j])
            dt[3:6] = np.eye(3)
        ddims[-3:] = np.eye(3)
        return dR, dt, ddims

    def covariance_map(self, th: np.ndarray) -> np.ndarray:
        """G (9, n): the derivatives of (dims, t, small rotation in the box frame), the order of the
        planes' result, with respect to θ (analytic); off the support the small rotation
        log(Rᵀ R0 exp(w + δ)) ≈ J_r(w) δ (SO(3)'s right Jacobian)."""
        G = np.zeros((9, len(th)))
        G[0:3, -3:] = np.eye(3)
        if self.on_support:
            G[3:6, 1], G[3:6, 2], G[8, 0] = self.R0[:, 0], self.R0[:, 1], 1.0
        else:
            G[3:6, 3:6] = np.eye(3)
            G[6:9, 0:3] = _so3_right_jacobian(th[:3])
        return G


class _FusedBoxFit:
    """The fused box fit's residuals and their Jacobian at θ, over the range points and tangents of the
    current pass (``terms``: the faces' points, then the scan returns used, and the scan tangents).

    Each range point's residual is its distance to its face over its σ along the face's *current*
    normal, √(nᵀΣn): for a plane that is the exact likelihood of a point with covariance Σ (the true
    point profiled out). With σ held at the starting normal, the range noise — along the beam,
    oblique to the face — correlates a point's offset from the face with its lever arm in the face,
    and the sizes of a face seen obliquely came out biased (+0.3 mm at 1.6 m, yaw 22°, measured).
    """

    def __init__(
        self,
        camera,
        box: _BoxParameters,
        face_points: dict,
        segments,
        sigma_px: float,
        scans,
        T_world_turret,
        edge_margin_m,
    ):
        self.camera = camera
        self.box = box
        self.faces = face_points
        self.sigma_px = sigma_px
        self.scans: BoxScans | None = scans
        self.T_world_turret = T_world_turret
        self.edge_margin_m = edge_margin_m
        self.vi = np.array([v[0] for v, _ in segments], dtype=int)
        self.vj = np.array([v[1] for v, _ in segments], dtype=int)
        self.clicks = np.array([seg for _, seg in segments]).reshape(-1, 2, 2)
        self.terms = {**face_points, "assoc": [], "sig_t": np.zeros(0), "id": None}

    def fit(self, th0: np.ndarray) -> tuple[np.ndarray, int, int]:
        """Levenberg–Marquardt from th0; with scans, again while the returns' faces and the transitions'
        edges change (at most 3 fits). Returns θ, the iterations, the passes."""
        th, it, passes = th0, 0, 0
        for passes in range(1, 4):
            if self.scans is not None:
                new = self.scan_terms(th)
                if new["id"] == self.terms["id"]:
                    passes -= 1
                    break
                self.terms = new
            th, n_it = levenberg_marquardt(self.residuals, self.jacobian, th)
            it += n_it
            if self.scans is None:
                break
        return th, it, passes

    def scan_terms(self, th: np.ndarray) -> dict:
        """The range points and tangents with the scan returns' faces and the transitions' edges at the box th."""
        R, t, dims = self.box.unpack(th)
        scans, X_faces = self.scans, self.faces["X"]
        used, ax, sd = assign_returns(scans, R, t, dims, edge_margin_m=self.edge_margin_m)
        assoc = associate_tangents(scans, self.T_world_turret, t + _corner_offsets(dims) @ R.T, R)
        return {
            "X": np.vstack([X_faces, scans.points_world[used]]),
            "C": np.concatenate([self.faces["C"], scans.covs[used]]),
            "k": np.concatenate([self.faces["k"], 2 * ax[used] + (sd[used] > 0)]),
            "assoc": assoc,
            "sig_t": np.array([a.sigma_m for a in assoc]),
            "used": used,
            "id": (used.tobytes(), ax[used].tobytes(), sd[used].tobytes(), tuple(a.edge for a in assoc)),
        }

    def distances(self, th: np.ndarray):
        """Range points' distances to their faces (m), their σ along the normals (m), edges' distances
        to their tangent planes (m), clicked ends' distances to their model edges' images (px)."""
        pts = self.terms
        R, t, dims = self.box.unpack(th)
        corners = t + _corner_offsets(dims) @ R.T
        N6, d6 = _face_planes(R, t, dims)
        N, d = N6[pts["k"]], d6[pts["k"]]
        pts_m = np.einsum("ij,ij->i", pts["X"], N) + d
        sig = np.maximum(np.sqrt(np.einsum("ni,nij,nj->n", N, pts["C"], N)), 1e-7)
        if pts["assoc"]:
            edges_m = tangent_distances(pts["assoc"], corners, self.T_world_turret[:3, 3])
        else:
            edges_m = np.zeros(0)
        uv = self.camera.project(corners)
        a, b = uv[self.vi], uv[self.vj]  # each clicked edge's model image, (S, 2) ends
        l = np.column_stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])
        l /= np.hypot(l[:, 0], l[:, 1])[:, None]
        clicks = self.clicks
        dist = clicks[:, :, 0] * l[:, None, 0] + clicks[:, :, 1] * l[:, None, 1] + l[:, None, 2]
        return pts_m, sig, edges_m, dist.reshape(-1)

    def residuals(self, th: np.ndarray) -> np.ndarray:
        pts_m, sig, edges_m, click_px = self.distances(th)
        return np.concatenate([pts_m / sig, edges_m / self.terms["sig_t"], click_px / self.sigma_px])

    def jacobian(self, th: np.ndarray) -> np.ndarray:
        """d(residuals)/dθ (analytic): through the box's axes, origin and sizes to its faces (the
        range points' distances and their σ along the normals), its corners (the scan tangents'
        edges; the clicked edges' images through the camera)."""
        R, t, dims = self.box.unpack(th)
        dR, dt, ddims = self.box.unpack_jacobian(th, R)
        rows = [_point_rows(self.terms, R, t, dims, dR, dt, ddims)]
        # the corners: t + R (unit ⊙ dims)
        Cb = _corner_offsets(dims)
        corners = t + Cb @ R.T
        dcorners = dt[:, None, :] + np.einsum("nij,kj->nki", dR, Cb) + (_CORNER_UNIT[None] * ddims[:, None, :]) @ R.T
        if self.terms["assoc"]:
            dtan = tangent_distances_jacobian(self.terms["assoc"], corners, dcorners, self.T_world_turret[:3, 3])
            rows.append((dtan / self.terms["sig_t"][None]).T)
        else:
            rows.append(np.zeros((0, len(th))))
        ddist = _click_distance_jacobian(self.camera.C, corners, dcorners, self.vi, self.vj, self.clicks)
        rows.append(ddist.reshape(len(th), -1).T / self.sigma_px)
        return np.vstack(rows)

    def scan_details(self, th: np.ndarray, passes: int) -> dict:
        """The scans' residuals and what the last pass used: the returns, each tangent's edge and distance."""
        pts_m, _, edges_m, _ = self.distances(th)
        signs = box_corner_signs()
        tangents = [
            {
                "scan": a.tangent.scan_index,
                "side": a.tangent.side,
                "pan_rad": a.tangent.pan_rad,
                "edge": (_corner_name(signs[a.edge[0]]), _corner_name(signs[a.edge[1]])),
                "sigma_m": a.sigma_m,
                "distance_m": float(e),
            }
            for a, e in zip(self.terms["assoc"], edges_m)
        ]
        return {
            "scan_residuals": {"scan_points_m": pts_m[len(self.faces["X"]) :], "scan_edges_m": edges_m},
            "scans": {
                "segments": self.scans.segments,
                "points_used": self.terms["used"],
                "passes": passes,
                "tangents": tangents,
            },
        }


def _point_rows(pts: dict, R, t, dims, dR, dt, ddims) -> np.ndarray:
    """d(range points' distance / σ)/dθ (N, n): through the faces N6[f] = s_f R[:, f // 2],
    d6 = −N6·t − far(dims), and σ = √(nᵀΣn) along the current normal."""
    n_th = len(dR)
    N6, d6 = _face_planes(R, t, dims)
    dN6 = np.repeat(np.transpose(dR, (0, 2, 1)), 2, axis=1) * _FACE_SIDES[None]  # (n, 6, 3)
    dfar = np.column_stack(
        [ddims[:, 0] / 2, ddims[:, 0] / 2, ddims[:, 1] / 2, ddims[:, 1] / 2, np.zeros(n_th), ddims[:, 2]]
    )
    dd6 = -(dN6 @ t) - dt @ N6.T - dfar
    k = pts["k"]
    N, dN = N6[k], dN6[:, k]
    X, Cov = pts["X"], pts["C"]
    pts_m = np.einsum("ij,ij->i", X, N) + d6[k]
    sig_raw = np.sqrt(np.einsum("ni,nij,nj->n", N, Cov, N))
    sig = np.maximum(sig_raw, 1e-7)
    dpts = np.einsum("pi,npi->np", X, dN) + dd6[:, k]
    dsig = np.where(sig_raw > 1e-7, np.einsum("pi,pij,npj->np", N, Cov, dN) / sig, 0.0)
    return (dpts / sig - pts_m * dsig / sig**2).T


def _click_distance_jacobian(C, corners, dcorners, vi, vj, clicks) -> np.ndarray:
    """d(clicked ends' pixel distances to the lines through their edge's projected corners)/dθ (n, S, 2)."""
    P = corners @ C[:, :3].T + C[:, 3]
    uv = P[:, :2] / P[:, 2:3]
    duv = np.einsum(
        "kab,nkb->nka", (C[None, :2, :3] - uv[:, :, None] * C[None, 2:3, :3]) / P[:, 2, None, None], dcorners
    )
    a, b, da, db = uv[vi], uv[vj], duv[:, vi], duv[:, vj]
    l = np.column_stack([a[:, 1] - b[:, 1], b[:, 0] - a[:, 0], a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]])
    dl = np.stack(
        [
            da[..., 1] - db[..., 1],
            db[..., 0] - da[..., 0],
            da[..., 0] * b[:, 1] + a[:, 0] * db[..., 1] - da[..., 1] * b[:, 0] - a[:, 1] * db[..., 0],
        ],
        axis=-1,
    )
    nrm = np.hypot(l[:, 0], l[:, 1])
    dnrm = (l[:, 0] * dl[..., 0] + l[:, 1] * dl[..., 1]) / nrm
    dl = dl / nrm[:, None] - l[None] * (dnrm / nrm**2)[..., None]  # (n, S, 3)
    return clicks[None, :, :, 0] * dl[..., None, 0] + clicks[None, :, :, 1] * dl[..., None, 1] + dl[..., None, 2]
