"""Model a cylinder or cone: the paper's three methods (§III.2) and a fused maximum-likelihood fit.

Inputs: the two clicked silhouettes (contour generators, each clicked from its bottom end to its
top end), horizontal range scans across the solid (misses kept), the operator's hints (axis
direction, the support it stands on).

* "tangential" (a), camera + range finder: the two silhouette interpretation planes P1, P2 and
  the front tangent plane P3 of the range profile; in each cross-section the axis is the centre
  of the circle tangent to the three lines.
* "bisecting" (b), camera + range finder: the axis is the intersection of the bisecting plane of
  P1, P2 with the bisecting plane of the range finder's own lateral tangent planes P_RF1, P_RF2
  (from the last hit / first miss of each scan); the radius is the distance to P_RF1, P_RF2.
* "rf_tangential" (c), range finder alone: the circle tangent to P_RF1, P_RF2 and P3.
* "fused" (d): every measurement at once (each scan return, each tangent beam, both silhouettes'
  clicked ends, the support), weighted by its sensor's noise (core/modeling/fused.py).

Cones (two radii) need the axis direction (the "vertical" hint or the support) and two scans at
different heights: each cross-section gives a centre and a radius, the radius varies linearly.
The height comes from the silhouettes' clicked ends (and the support for the base).
Uncertainties of the paper's methods are propagated to first order from the clicks (σ_px), the
tangent-beam angles and the front plane's fit.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..brep import BRep, Revolution
from ..camera import Camera, as_segment
from ..geometry import Line, Plane, bisecting_planes, make_plane
from ..rangefinder import RangeFinderSpec, RangeScan
from ..transforms import check_T, make_T
from .lm import numeric_jacobian
from .profile import ProfileFit, axis_basis, fit_profile, front_plane, front_plane_jacobian
from .result import ModelResult
from .returns import Returns, concat_returns
from .scans import segment_scan
from .small import image_line, interp_plane, interp_plane_jacobian

__all__ = ["METHODS", "CylinderData", "reduce_cylinder_data", "model_paper"]

METHODS = ("tangential", "bisecting", "rf_tangential", "fused")


@dataclass(frozen=True)
class CylinderData:
    """The measurements of a cylinder or cone, reduced once and shared by every method.

    camera, T_world_turret, spec : the sensors. silhouettes_uv : (2, 2, 2) or None.
    segments : list of ScanSegment (object returns, tangent beams per scan).
    support : Plane (normal up) or None. axis_hint : unit (3,) or None. cone : bool.
    """

    camera: Camera
    T_world_turret: np.ndarray
    spec: RangeFinderSpec
    silhouettes_uv: np.ndarray | None
    segments: list
    support: Plane | None
    axis_hint: np.ndarray | None
    cone: bool

    @property
    def hits(self) -> np.ndarray:
        """The object's returns of every scan, world points (N, 3)."""
        return np.vstack([s.hits_world for s in self.segments])

    @property
    def returns(self) -> Returns:
        """The same returns with their beams (for the likelihood fits)."""
        return concat_returns([s.returns for s in self.segments])

    @property
    def groups(self) -> np.ndarray:
        """Which scan each return comes from, (N,) int."""
        return np.concatenate([np.full(len(s.hits_world), k) for k, s in enumerate(self.segments)])

    @property
    def tangents(self) -> list:
        return [tb for s in self.segments for tb in s.tangents]

    @property
    def rf_origin(self) -> np.ndarray:
        return self.T_world_turret[:3, 3]


def _orient_up(a: np.ndarray, support: Plane | None) -> np.ndarray:
    ref = support.n if support is not None else np.array([0.0, 0.0, 1.0])
    s = a @ ref
    if abs(s) < 1e-9:
        s = a @ np.array([1.0, 1e-3, 1e-6])
    return a if s > 0 else -a


def _silhouette_planes(camera: Camera, sil: np.ndarray) -> tuple[Plane, Plane]:
    """Interpretation planes of the two silhouettes, positive on the object's side."""
    inside = sil.reshape(-1, 2).mean(axis=0)
    X_in = camera.backproject(inside[None], 1.0)[0]
    out = []
    for s in sil:
        v = interp_plane(camera.C, s)
        if v[:3] @ X_in + v[3] < 0:
            v = -v
        out.append(Plane(v[:3], float(v[3])))
    return out[0], out[1]


def reduce_cylinder_data(
    camera: Camera,
    *,
    silhouettes_uv: np.ndarray | None,
    scans: Sequence[RangeScan],
    T_world_turret: np.ndarray | None,
    spec: RangeFinderSpec,
    support: Plane | None,
    axis_dir: np.ndarray | None,
    cone: bool,
    jump_m: float,
) -> CylinderData:
    """Validate the inputs, find the object in each scan and its tangent beams."""
    if not isinstance(camera, Camera):
        raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
    sil = None
    if silhouettes_uv is not None:
        sil = np.asarray(silhouettes_uv, dtype=float)
        if sil.shape != (2, 2, 2):
            raise ValueError(f"silhouettes_uv must have shape (2, 2, 2) (two segments of two pixels), got {sil.shape}")
        for k in range(2):
            as_segment(sil[k], f"silhouettes_uv[{k}]")
        p1 = camera.interpretation_plane(sil[0])
        p2 = camera.interpretation_plane(sil[1])
        if np.linalg.norm(np.cross(p1.n, p2.n)) < np.sin(np.radians(0.05)):
            raise ValueError(
                "the two silhouettes are the same image line: they do not bound a cylinder; "
                "click the left and the right contour of the object"
            )
    if support is not None:
        if not isinstance(support, Plane):
            raise ValueError(f"support must be a core.geometry.Plane, got {type(support).__name__}")
        support = make_plane(support.n, support.d)
        if support.n @ camera.center + support.d < 0:
            support = support.flipped()
    hint = None
    if axis_dir is not None:
        hint = np.asarray(axis_dir, dtype=float).reshape(-1)
        if hint.shape != (3,) or not np.all(np.isfinite(hint)) or np.linalg.norm(hint) < 1e-12:
            raise ValueError(f"axis_dir must be a non-zero 3-vector, got {axis_dir}")
        hint = hint / np.linalg.norm(hint)
    elif support is not None:
        hint = support.n.copy()
    if hint is not None:
        hint = _orient_up(hint, support)
    scans = list(scans)
    if not scans:
        raise ValueError("every method needs at least one range scan across the object")
    if T_world_turret is None:
        raise ValueError("range scans need T_world_turret (the turret's calibrated pose)")
    T = check_T(T_world_turret, "T_world_turret")
    keep = None
    if sil is not None:
        P1, P2 = _silhouette_planes(camera, sil)
        tol = 0.02  # points up to 2 cm outside the wedge still count (noise, parallax)
        keep = lambda X: (X @ P1.n + P1.d > -tol) & (X @ P2.n + P2.d > -tol)  # noqa: E731

    segs = [segment_scan(s, T, spec, jump_m=jump_m, scan_index=k, keep=keep) for k, s in enumerate(scans)]
    if keep is not None:
        inside = np.concatenate([keep(sg.hits_world) for sg in segs])
        if inside.mean() < 0.5:
            raise ValueError(
                f"only {inside.mean():.0%} of the object's range returns lie between the two silhouettes: "
                "the clicked contours do not bound the scanned object (click its left and right contours)"
            )
    if cone and hint is None:
        raise ValueError(
            "a cone needs its axis direction: say it stands on the support (support=...) or give axis_dir; "
            "the paper's methods cannot find an oblique cone's axis"
        )
    return CylinderData(camera, T, spec, sil, segs, support, hint, cone)


# --------------------------------------------------------------------------- the paper's methods
@dataclass
class _Ctx:
    data: CylinderData
    method: str
    profile: ProfileFit | None
    t_sections: np.ndarray  # axial coordinates of the cross-sections, relative to X0 along a0
    X0: np.ndarray
    a0: np.ndarray
    centroid: np.ndarray


def _lateral_plane(ctx: _Ctx, beams, angles: np.ndarray, a: np.ndarray | None) -> Plane:
    """Plane through the range finder's origin containing the tangent beams (and the axis direction)."""
    T = ctx.data.T_world_turret
    D = [tb.direction(T, angles[2 * i], angles[2 * i + 1]) for i, tb in enumerate(beams)]
    if a is not None and not ctx.data.cone:
        D.append(a)
    if len(D) < 2:
        raise ValueError(
            "a lateral tangent plane of the range finder needs two scans, or one scan and the axis "
            "direction (a 'vertical' hint or the support)"
        )
    _, _, Vt = np.linalg.svd(np.array(D))
    n = Vt[-1]
    o = ctx.data.rf_origin
    p = Plane(n, float(-n @ o))
    return p if p.n @ ctx.centroid + p.d > 0 else p.flipped()


def _section_line(p: Plane, X0, a, e1, e2, t) -> tuple[np.ndarray, float]:
    u = np.array([p.n @ e1, p.n @ e2])
    s = np.linalg.norm(u)
    if s < 1e-6:
        raise ValueError("a tangent plane is perpendicular to the axis: it does not bound the cross-section")
    return u / s, float(p.n @ X0 + t * (p.n @ a) + p.d) / s


def _incircle(lines) -> tuple[np.ndarray, float]:
    A = np.array([[u[0], u[1], -1.0] for u, _ in lines])
    b = -np.array([g for _, g in lines])
    sol, *_ = np.linalg.lstsq(A, b, rcond=None)
    return sol[:2], float(sol[2])


def _unpack(z: np.ndarray, ctx: _Ctx):
    d = ctx.data
    i = 0
    sil = None
    if d.silhouettes_uv is not None:
        sil = z[:8].reshape(2, 2, 2)
        i = 8
    nb = len(d.tangents)
    angles = z[i : i + 2 * nb]
    i += 2 * nb
    p3 = None
    if ctx.profile is not None:
        v = z[i : i + 4]
        p3 = make_plane(v[:3], v[3])
    return sil, angles, p3


def _axis_from_sections(ctx, a, e1, e2, centres, radii):
    """Axis point at the first section's height, direction a, and radius function r(t) = r_ref + k t."""
    t = ctx.t_sections
    y = np.mean(centres, axis=0)
    if ctx.data.cone:
        k, r_ref = np.polyfit(t, radii, 1)
    else:
        k, r_ref = 0.0, float(np.mean(radii))
    Xa = ctx.X0 + y[0] * e1 + y[1] * e2
    return Xa, float(r_ref), float(k)


def _generators(camera: Camera, Xa, a, r_ref, k, t_lo, t_hi):
    """The two contour generators (as lines, point (3,) and direction (3,)) seen by the camera."""
    r_lo, r_hi = r_ref + k * t_lo, r_ref + k * t_hi
    if min(r_lo, r_hi) <= 0:
        raise ValueError("the modelled cone's radius vanishes within the object: the data do not bound a cone")
    sol = Revolution(Xa + t_lo * a, Xa + t_hi * a, r_lo, r_hi)
    sil = sol.silhouette(camera.center)
    if len(sil) != 2:
        raise ValueError("the camera is inside the modelled solid: the silhouettes do not bound a cylinder")
    return [(g[0], (g[1] - g[0]) / np.linalg.norm(g[1] - g[0])) for g in sil]


def _click_heights(camera, sil_uv, gens, Xa, a):
    """Axial coordinates (2 silhouettes × (low end, high end)) of the clicked ends on the generators."""
    c = camera.center
    Minv = np.linalg.inv(camera.C[:, :3])
    lines = []
    for P, u in gens:
        uv = camera.project(np.array([P, P + 0.1 * u]))
        lines.append(image_line(uv[0], uv[1]))
    out = []
    for seg in sil_uv:
        # Match the clicked line with the nearer projected generator.
        H = np.column_stack([seg, np.ones(2)])
        g = int(np.argmin([np.abs(H @ l).sum() for l in lines]))
        P, u = gens[g]
        rays = H @ Minv.T
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        w = P - c
        b = rays @ u
        den = np.maximum(1 - b * b, 1e-12)
        s_g = (b * (rays @ w) - (w @ u)) / den  # closest point on the generator to each click's ray
        ts = (P - Xa) @ a + s_g * (u @ a)
        out.append(np.sort(ts))
    return np.array(out)


def _solve_paper(z: np.ndarray, ctx: _Ctx) -> dict:
    """The paper's construction from the reduced measurements z; returns the solid."""
    d = ctx.data
    sil, angles, p3 = _unpack(z, ctx)
    cam = d.camera
    P1 = P2 = None
    if sil is not None:
        P1, P2 = _silhouette_planes(cam, sil)
    beams = d.tangents
    sides = {}
    for i, tb in enumerate(beams):
        sides.setdefault(tb.side, []).append(i)
    a = d.axis_hint
    lat = {}
    if ctx.method in ("bisecting", "rf_tangential"):
        if set(sides) != {-1, 1}:
            raise ValueError(
                "the scans do not pass the object on both sides: the range finder's lateral tangent planes "
                "need a miss (or background) beyond each edge; widen the scans"
            )
        for s, idx in sides.items():
            ang = np.concatenate([angles[2 * i : 2 * i + 2] for i in idx])
            lat[s] = _lateral_plane(ctx, [beams[i] for i in idx], ang, a)
    if a is None:  # an oblique cylinder: the direction from the planes parallel to the axis
        if ctx.method == "tangential":
            a = np.cross(P1.n, P2.n)
        elif ctx.method == "rf_tangential":
            a = np.cross(lat[-1].n, lat[1].n)
        else:
            a = np.cross(bisecting_planes(P1, P2)[0].n, bisecting_planes(lat[-1], lat[1])[0].n)
        a = _orient_up(a / np.linalg.norm(a), d.support)
    e1, e2 = axis_basis(a)
    centres, radii = [], []
    for t in ctx.t_sections:

        def L(p):
            return _section_line(p, ctx.X0, a, e1, e2, t)

        if ctx.method == "tangential":
            y, r = _incircle([L(P1), L(P2), L(p3)])
        elif ctx.method == "rf_tangential":
            y, r = _incircle([L(lat[-1]), L(lat[1]), L(p3)])
        else:
            (u1, g1), (u2, g2) = L(bisecting_planes(P1, P2)[0]), L(bisecting_planes(lat[-1], lat[1])[0])
            A = np.array([u1, u2])
            if abs(np.linalg.det(A)) < np.sin(np.radians(0.2)):
                raise ValueError(
                    "the camera's and the range finder's bisecting planes are parallel: the axis is not "
                    "fixed (the two sensors see the object from the same direction)"
                )
            y = np.linalg.solve(A, -np.array([g1, g2]))
            r = float(np.mean([u @ y + g for u, g in (L(lat[-1]), L(lat[1]))]))
        if not r > 0:
            raise ValueError(
                f"the tangent planes give a radius of {r * 1000:.1f} mm: the silhouettes and scans do not "
                "bound a cylinder (check which contours were clicked and that the scans cross the object)"
            )
        centres.append(y)
        radii.append(r)
    Xa, r_ref, k = _axis_from_sections(ctx, a, e1, e2, centres, radii)
    return _finish(ctx, sil, Xa, a, r_ref, k)


def _finish(ctx: _Ctx, sil, Xa, a, r_ref, k) -> dict:
    """Base and top along the axis (support, silhouette ends) → the solid's parameters."""
    d = ctx.data
    t_lo, t_hi = float(ctx.t_sections.min()), float(ctx.t_sections.max())
    t_base = t_top = None
    if sil is not None:
        span = max(t_hi - t_lo, 0.05)
        gens = _generators(d.camera, Xa, a, r_ref, k, t_lo - 0.1 * span, t_hi + 0.1 * span)
        th = _click_heights(d.camera, sil, gens, Xa, a)
        t_top = float(th[:, 1].mean())
        t_base = float(th[:, 0].mean())
    if d.support is not None:
        den = d.support.n @ a
        if abs(den) < 1e-6:
            raise ValueError("the axis is parallel to the support: the solid cannot stand on it")
        t_base = float(-(d.support.n @ Xa + d.support.d) / den)
    if t_top is None or t_base is None:
        raise ValueError(
            "the height needs the silhouettes clicked from end to end (and the support, or both ends, for the base)"
        )
    h = t_top - t_base
    if not h > 0:
        raise ValueError(
            f"the clicked silhouette ends give a height of {h * 1000:.1f} mm: "
            "click each contour from its bottom end to its top end"
        )
    r0, r1 = r_ref + k * t_base, r_ref + k * t_top
    if min(r0, r1) < 0:
        raise ValueError("the fitted cone's radius is negative at an end: the data do not bound a cone")
    return {"p0": Xa + t_base * a, "a": a, "r0": r0, "r1": r1, "h": h}


# ---------------------------------------------------------------- its derivative (known axis direction)
# Each quantity travels with its derivative with respect to z, an array (..., len(z)).


def _unit_plane_jacobian(v: np.ndarray, dv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``make_plane(v[:3], v[3]).as_vector()`` and its derivative from v (4,) and dv (4, n)."""
    nu = np.linalg.norm(v[:3])
    return v / nu, dv / nu - np.outer(v, v[:3] @ dv[:3]) / nu**3


def _lateral_plane_jacobian(ctx: _Ctx, idx, angles, a, i_ang: int, n: int):
    """A lateral tangent plane (4,) and its derivative: the plane's normal is the direction least
    along the beams (and the axis), the eigenvector of M = DᵀD of its smallest eigenvalue λ₀, so
    dn = −Σⱼ vⱼ vⱼᵀ dM n / (λⱼ − λ₀) over the other eigenvectors; the plane holds the origin."""
    d = ctx.data
    beams = d.tangents
    ang = np.concatenate([angles[2 * i : 2 * i + 2] for i in idx])
    plane = _lateral_plane(ctx, [beams[i] for i in idx], ang, a)
    R = d.T_world_turret[:3, :3]
    rows, drows = [], []
    for i in idx:
        pan, tilt = angles[2 * i], angles[2 * i + 1]
        cp, sp, ct, st = np.cos(pan), np.sin(pan), np.cos(tilt), np.sin(tilt)
        dD = np.zeros((3, n))
        dD[:, i_ang + 2 * i] = R @ [-ct * sp, ct * cp, 0.0]
        dD[:, i_ang + 2 * i + 1] = R @ [-st * cp, -st * sp, ct]
        rows.append(R @ [ct * cp, ct * sp, st])
        drows.append(dD)
    if not d.cone:
        rows.append(a)
        drows.append(np.zeros((3, n)))
    D, dD = np.array(rows), np.array(drows)
    nv = plane.n
    Dn, dDn = D @ nv, np.einsum("kin,i->kn", dD, nv)
    dMn = np.einsum("kin,k->in", dD, Dn) + D.T @ dDn  # (dDᵀ D + Dᵀ dD) n
    lam, V = np.linalg.eigh(D.T @ D)
    lam0 = float(Dn @ Dn)
    dnv = np.zeros((3, n))
    for j in range(3):
        if abs(V[:, j] @ nv) < 0.5:  # not the plane's normal
            dnv -= np.outer(V[:, j], V[:, j] @ dMn) / (lam[j] - lam0)
    o = d.rf_origin
    return plane.as_vector(), np.vstack([dnv, -(o @ dnv)])


def _paper_jacobian(z: np.ndarray, ctx: _Ctx, sol: dict) -> np.ndarray | None:
    """d q / d z of ``_solid_vector(_solve_paper(z, ctx))`` (analytic) when the axis direction is
    known (a hint or the support); None when the construction finds it (then differences)."""
    d = ctx.data
    a = d.axis_hint
    if a is None:
        return None
    n = len(z)
    sil, angles, _ = _unpack(z, ctx)
    planes = _planes_jacobian(z, ctx, sil, angles, a)
    e1, e2 = axis_basis(a)
    sections = [_section_jacobian(ctx, planes, a, e1, e2, t) for t in ctx.t_sections]
    Xa, dXa, r_ref, dr_ref, k, dk = _axis_jacobian(ctx, sections, e1, e2, n)
    # _finish: the generators seen from the camera, the clicked ends' heights on them, the support.
    dt_base = dt_top = None
    if sil is not None:
        dt_base, dt_top = _end_heights_jacobian(ctx, sil, Xa, dXa, a, r_ref, dr_ref, k, dk, n)
    if d.support is not None:
        dt_base = -(d.support.n @ dXa) / (d.support.n @ a)
    if dt_top is None or dt_base is None:
        return None
    t_base_v = (sol["p0"] - Xa) @ a
    h = sol["h"]
    dh = dt_top - dt_base
    dr0, dr1 = dr_ref + t_base_v * dk + k * dt_base, dr_ref + (t_base_v + h) * dk + k * dt_top
    dp0 = dXa + np.outer(a, dt_base)
    dmid = dp0 + 0.5 * np.outer(a, dh)
    dradii = [dr0, dr1] if d.cone else [0.5 * (dr0 + dr1)]
    return np.vstack([*dradii, dh, dmid, np.zeros((3, n))])


def _planes_jacobian(z: np.ndarray, ctx: _Ctx, sil, angles: np.ndarray, a: np.ndarray) -> dict:
    """The planes the method cuts the cross-sections with, each (4,) with its derivative (4, n):
    "P1", "P2" (the silhouettes'), "p3" (the front plane), "lat-1", "lat1" (the range finder's
    lateral planes), and for "bisecting" "bis_cam", "bis_rf" (the two bisecting planes)."""
    d = ctx.data
    n = len(z)
    cam = d.camera
    i_ang = 8 if sil is not None else 0
    nb = len(d.tangents)
    planes = {}
    if sil is not None and ctx.method in ("tangential", "bisecting"):
        for k, P in enumerate(_silhouette_planes(cam, sil)):
            v, J = interp_plane_jacobian(cam.C, sil[k])
            dv = np.zeros((4, n))
            dv[:, 4 * k : 4 * k + 4] = J if v @ P.as_vector() > 0 else -J
            planes[f"P{k + 1}"] = (P.as_vector(), dv)
    if ctx.profile is not None:
        dv = np.zeros((4, n))
        dv[:, i_ang + 2 * nb :] = np.eye(4)
        planes["p3"] = _unit_plane_jacobian(z[i_ang + 2 * nb :], dv)
    if ctx.method in ("bisecting", "rf_tangential"):
        for s in (-1, 1):
            idx = [i for i, tb in enumerate(d.tangents) if tb.side == s]
            planes[f"lat{s}"] = _lateral_plane_jacobian(ctx, idx, angles, a, i_ang, n)
    if ctx.method == "bisecting":
        for pair, name in ((("P1", "P2"), "bis_cam"), (("lat-1", "lat1"), "bis_rf")):
            (v1, dv1), (v2, dv2) = planes[pair[0]], planes[pair[1]]
            planes[name] = _unit_plane_jacobian(v1 - v2, dv1 - dv2)
    return planes


def _section_line_jacobian(v: np.ndarray, dv: np.ndarray, X0, a, e1, e2, t):
    """``_section_line`` of the plane v (4,) and its derivatives: (u (2,), du (2, n), g, dg (n,))."""
    u_raw, du_raw = np.array([v[:3] @ e1, v[:3] @ e2]), np.array([e1 @ dv[:3], e2 @ dv[:3]])
    g_raw, dg_raw = v[:3] @ X0 + t * (v[:3] @ a) + v[3], (X0 + t * a) @ dv[:3] + dv[3]
    s_ = np.linalg.norm(u_raw)
    ds = u_raw @ du_raw / s_
    return u_raw / s_, du_raw / s_ - np.outer(u_raw, ds) / s_**2, g_raw / s_, dg_raw / s_ - g_raw * ds / s_**2


def _section_jacobian(ctx: _Ctx, planes: dict, a, e1, e2, t: float):
    """The cross-section at t: its centre y (2,) and radius r with their derivatives (dy (2, n), dr (n,))."""

    def line(name):
        return _section_line_jacobian(*planes[name], ctx.X0, a, e1, e2, t)

    if ctx.method == "bisecting":
        (u1, du1, g1, dg1), (u2, du2, g2, dg2) = line("bis_cam"), line("bis_rf")
        A = np.array([u1, u2])
        y = np.linalg.solve(A, -np.array([g1, g2]))
        dy = np.linalg.solve(A, -np.array([dg1, dg2]) - np.array([y @ du1, y @ du2]))
        ls = [line("lat-1"), line("lat1")]
        r = np.mean([u @ y + g for u, _, g, _ in ls])
        dr = np.mean([y @ du + u @ dy + dg for u, du, _, dg in ls], axis=0)
        return y, dy, r, dr
    names = ("P1", "P2", "p3") if ctx.method == "tangential" else ("lat-1", "lat1", "p3")
    ls = [line(nm) for nm in names]
    A = np.array([[u[0], u[1], -1.0] for u, _, _, _ in ls])
    x, *_ = np.linalg.lstsq(A, -np.array([g for _, _, g, _ in ls]), rcond=None)
    rhs = -np.array([dg for _, _, _, dg in ls]) - np.array([x[:2] @ du for _, du, _, _ in ls])
    dx = np.linalg.pinv(A) @ rhs
    return x[:2], dx[:2], x[2], dx[2]


def _axis_jacobian(ctx: _Ctx, sections: list, e1, e2, n: int):
    """``_axis_from_sections`` with derivatives: (Xa (3,), dXa (3, n), r_ref, dr_ref (n,), k, dk (n,))."""
    centres = [y for y, _, _, _ in sections]
    dcentres = [dy for _, dy, _, _ in sections]
    radii = [r for _, _, r, _ in sections]
    dradii = [dr for _, _, _, dr in sections]
    dy = np.mean(dcentres, axis=0)
    if ctx.data.cone:
        X = np.column_stack([ctx.t_sections, np.ones(len(ctx.t_sections))])
        dk, dr_ref = np.linalg.pinv(X) @ np.array(dradii)
        k, r_ref = np.linalg.pinv(X) @ np.array(radii)
    else:
        k, dk, r_ref, dr_ref = 0.0, np.zeros(n), float(np.mean(radii)), np.mean(dradii, axis=0)
    Xa = ctx.X0 + np.mean(centres, axis=0) @ np.array([e1, e2])
    dXa = np.outer(e1, dy[0]) + np.outer(e2, dy[1])
    return Xa, dXa, r_ref, dr_ref, k, dk


def _end_heights_jacobian(ctx: _Ctx, sil, Xa, dXa, a, r_ref, dr_ref, k, dk, n: int):
    """Derivatives (n,) of the base's and the top's axial coordinates from the clicked silhouette ends
    (``_finish``: the contour generators, then ``_click_heights``)."""
    cam = ctx.data.camera
    t_lo, t_hi = float(ctx.t_sections.min()), float(ctx.t_sections.max())
    span = max(t_hi - t_lo, 0.05)
    tl, th = t_lo - 0.1 * span, t_hi + 0.1 * span
    gens = _generators(cam, Xa, a, r_ref, k, tl, th)
    r_lo, r_hi, dr_lo, dr_hi = r_ref + k * tl, r_ref + k * th, dr_ref + tl * dk, dr_ref + th * dk
    dgens = _generators_jacobian(cam.center, Xa, dXa, a, tl, th, r_lo, r_hi, dr_lo, dr_hi)
    Minv = np.linalg.inv(cam.C[:, :3])
    lines = [image_line(*cam.project(np.array([P, P + 0.1 * u]))) for P, u in gens]
    ends = []
    for si, seg in enumerate(sil):
        H = np.column_stack([seg, np.ones(2)])
        g = int(np.argmin([np.abs(H @ l).sum() for l in lines]))
        ts, dts = [], []
        for j in range(2):
            dray_raw = np.zeros((3, n))
            dray_raw[:, 4 * si + 2 * j : 4 * si + 2 * j + 2] = Minv[:, :2]
            t, dt = _click_height_jacobian(cam.center, Minv @ H[j], dray_raw, *dgens[g], Xa, dXa, a)
            ts.append(t)
            dts.append(dt)
        lo = int(np.argmin(ts))
        ends.append((dts[lo], dts[1 - lo]))
    return np.mean([lo for lo, _ in ends], axis=0), np.mean([hi for _, hi in ends], axis=0)


def _generators_jacobian(c, Xa, dXa, a, tl, th, r_lo, r_hi, dr_lo, dr_hi) -> list:
    """The two contour generators seen from c with derivatives, as (P0, dP0, u, du): their base end and
    unit direction. ``Revolution.silhouette``: e = (κ/D) ŵ ± √(1 − (κ/D)²) (a × ŵ), the generator
    (p0 + r_lo e) → (p1 + r_hi e)."""
    q = c - (Xa + tl * a)
    q_a, dq_a = q @ a, -(a @ dXa)
    w, dw = q - q_a * a, -dXa - np.outer(a, dq_a)
    D = np.linalg.norm(w)
    w_hat = w / D
    dD = w_hat @ dw
    dw_hat = (dw - np.outer(w_hat, dD)) / D
    b_hat, db_hat = np.cross(a, w_hat), np.cross(a, dw_hat, axisa=0, axisb=0, axisc=0)
    kap = r_lo - (r_lo - r_hi) * q_a / (th - tl)
    dkap = dr_lo - ((dr_lo - dr_hi) * q_a + (r_lo - r_hi) * dq_a) / (th - tl)
    cc, dcc = kap / D, dkap / D - kap * dD / D**2
    sq = np.sqrt(max(0.0, 1.0 - cc * cc))
    dsq = -cc * dcc / sq
    dgens = []
    for sign in (1.0, -1.0):
        e = cc * w_hat + sign * sq * b_hat
        de = np.outer(w_hat, dcc) + cc * dw_hat + sign * (np.outer(b_hat, dsq) + sq * db_hat)
        P0, P1 = Xa + tl * a + r_lo * e, Xa + th * a + r_hi * e
        dP0 = dXa + np.outer(e, dr_lo) + r_lo * de
        dP1 = dXa + np.outer(e, dr_hi) + r_hi * de
        L = np.linalg.norm(P1 - P0)
        u = (P1 - P0) / L
        dgens.append((P0, dP0, u, (np.eye(3) - np.outer(u, u)) @ (dP1 - dP0) / L))
    return dgens


def _click_height_jacobian(c, ray_raw, dray_raw, P, dP, u, du, Xa, dXa, a):
    """The axial coordinate of a clicked end (its ray ray_raw from c, unnormalised, with derivative
    dray_raw (3, n)) on the generator (P, u): the generator's point closest to the ray; with its derivative."""
    nr = np.linalg.norm(ray_raw)
    ray = ray_raw / nr
    dray = (dray_raw - np.outer(ray, ray @ dray_raw)) / nr
    wv, dwv = P - c, dP
    b, db = ray @ u, u @ dray + ray @ du
    rw, drw = ray @ wv, wv @ dray + ray @ dwv
    wu, dwu = wv @ u, u @ dwv + wv @ du
    den = 1 - b * b
    dden = -2 * b * db if den > 1e-12 else np.zeros(len(db))
    den = max(den, 1e-12)
    num, dnum = b * rw - wu, db * rw + b * drw - dwu
    s_g, ds_g = num / den, dnum / den - num * dden / den**2
    return (P - Xa) @ a + s_g * (u @ a), a @ (dP - dXa) + ds_g * (u @ a) + s_g * (a @ du)


def _solid_vector(s: dict, cone: bool) -> np.ndarray:
    mid = s["p0"] + 0.5 * s["h"] * s["a"]
    radii = [s["r0"], s["r1"]] if cone else [0.5 * (s["r0"] + s["r1"])]
    return np.concatenate([radii, [s["h"]], mid, s["a"]])


def _stage_one(data: CylinderData, method: str) -> _Ctx:
    """Directions, cross-sections and (for the tangential methods) the profile's front plane."""
    hits = data.hits
    centroid = hits.mean(axis=0)
    a0 = data.axis_hint
    if a0 is None:
        if data.silhouettes_uv is not None and method in ("tangential", "bisecting"):
            P1, P2 = _silhouette_planes(data.camera, data.silhouettes_uv)
            a0 = np.cross(P1.n, P2.n)
        else:
            ctx0 = _Ctx(data, method, None, np.zeros(1), centroid, np.zeros(3), centroid)
            beams = data.tangents
            lat = []
            for s in (-1, 1):
                idx = [i for i, tb in enumerate(beams) if tb.side == s]
                ang = np.concatenate([[beams[i].pan_rad, beams[i].tilt_rad] for i in idx]) if idx else np.zeros(0)
                lat.append(_lateral_plane(ctx0, [beams[i] for i in idx], ang, None))
            a0 = np.cross(lat[0].n, lat[1].n)
        a0 = _orient_up(a0 / np.linalg.norm(a0), data.support)
    profile = None
    if method in ("tangential", "rf_tangential"):
        profile = fit_profile(data.returns, a0, cone=data.cone, groups=data.groups)
    t_sec = np.array(sorted({float(np.median((s.hits_world - centroid) @ a0)) for s in data.segments}))
    if not data.cone:
        t_sec = np.array([float(np.mean(t_sec))])
    return _Ctx(data, method, profile, t_sec, centroid, a0, centroid)


def solve_paper(data: CylinderData, method: str) -> dict:
    """The paper's construction alone (no covariance): {"p0", "a", "r0", "r1", "h"} in the world."""
    ctx = _stage_one(data, method)
    z_parts = []
    if data.silhouettes_uv is not None:
        z_parts.append(data.silhouettes_uv.reshape(-1))
    for tb in data.tangents:
        z_parts.append([tb.pan_rad, tb.tilt_rad])
    if ctx.profile is not None:
        z_parts.append(front_plane(ctx.profile, data.rf_origin, float(np.mean(ctx.t_sections))).as_vector())
    return _solve_paper(np.concatenate([np.asarray(p, dtype=float).reshape(-1) for p in z_parts]), ctx)


def model_paper(data: CylinderData, method: str, sigma_px: float) -> ModelResult:
    ctx = _stage_one(data, method)
    z_parts, var_parts = [], []
    if data.silhouettes_uv is not None:
        z_parts.append(data.silhouettes_uv.reshape(-1))
        var_parts.append(np.full(8, sigma_px**2))
    for tb in data.tangents:
        z_parts.append([tb.pan_rad, tb.tilt_rad])
        var_parts.append([tb.sigma_pan_rad**2, tb.sigma_tilt_rad**2])
    Sz_blocks = [np.diag(np.concatenate(var_parts))] if var_parts else []
    if ctx.profile is not None:
        prof = ctx.profile
        t_ref = float(np.mean(ctx.t_sections))

        v0 = front_plane(prof, data.rf_origin, t_ref).as_vector()
        Jp = front_plane_jacobian(prof, data.rf_origin, t_ref)
        z_parts.append(v0)
        Sz_blocks.append(Jp @ prof.cov @ Jp.T)
    z = np.concatenate([np.asarray(p, dtype=float).reshape(-1) for p in z_parts])
    Sz = np.zeros((len(z), len(z)))
    i = 0
    for B in Sz_blocks:
        Sz[i : i + len(B), i : i + len(B)] = B
        i += len(B)
    sol = _solve_paper(z, ctx)
    q0 = _solid_vector(sol, data.cone)
    scale = np.sqrt(np.maximum(np.diag(Sz), 1e-30))
    # Forward differences (the construction has no derivative at hand): the map is smooth on the
    # scale of σ; an input with no spread gets no column.
    J = _paper_jacobian(z, ctx, sol)
    if J is None:
        step = np.where(scale <= 1e-15, 0.0, 1e-4 * scale)
        J = numeric_jacobian(lambda x: _solid_vector(_solve_paper(x, ctx), data.cone), z, step, f0=q0)
    cov_q = J @ Sz @ J.T
    residuals = {}
    if ctx.profile is not None:
        residuals["profile_sigma"] = ctx.profile.residuals
    details = {"profile": ctx.profile, "sections_t": ctx.t_sections, "segments": data.segments}
    return build_result(data, method, sol, cov_q, residuals, details)


def build_result(
    data: CylinderData, method: str, sol: dict, cov_q: np.ndarray, residuals: dict, details: dict, notes=()
) -> ModelResult:
    """Assemble the ModelResult from the solid and the covariance of (radii, h, mid-point, a)."""
    a = sol["a"]
    cone = data.cone
    nr = 2 if cone else 1
    if cone:
        dims = {"radius_bottom": sol["r0"], "radius_top": sol["r1"], "height": sol["h"]}
    else:
        dims = {"radius": 0.5 * (sol["r0"] + sol["r1"]), "height": sol["h"]}
    sig = {k: float(np.sqrt(max(cov_q[i, i], 0.0))) for i, k in enumerate(dims)}
    Pp = np.eye(3) - np.outer(a, a)
    cm = cov_q[nr + 1 : nr + 4, nr + 1 : nr + 4]
    sig["axis_position"] = float(np.sqrt(max(np.trace(Pp @ cm @ Pp), 0.0)))
    e1, e2 = axis_basis(a)
    R = np.column_stack([e1, e2, a])
    T = make_T(R, sol["p0"])
    model = BRep.cone(sol["r0"], sol["r1"], sol["h"]) if cone else BRep.cylinder(dims["radius"], sol["h"])
    names = tuple(dims) + ("mid_x", "mid_y", "mid_z", "axis_x", "axis_y", "axis_z")
    # Residuals of the silhouette clicks to the model's contours (pixels).
    if data.silhouettes_uv is not None:
        sol_w = Revolution(sol["p0"], sol["p0"] + sol["h"] * a, sol["r0"], sol["r1"])
        gens = sol_w.silhouette(data.camera.center)
        res = []
        for seg in data.silhouettes_uv:
            best = None
            for g in gens:
                uv = data.camera.project(g)
                l = image_line(uv[0], uv[1])
                r = np.column_stack([seg, np.ones(2)]) @ l
                if best is None or np.abs(r).sum() < np.abs(best).sum():
                    best = r
            res.append(best)
        residuals["silhouettes_px"] = np.concatenate(res) if res else np.zeros(0)
    return ModelResult(
        kind="cone" if cone else "cylinder",
        method=method,
        model=model,
        T_world_obj=T,
        dimensions={k: float(v) for k, v in dims.items()},
        sigmas=sig,
        cov=cov_q,
        cov_names=names,
        vertices_world=np.array([sol["p0"], sol["p0"] + sol["h"] * a]),
        axis=Line(sol["p0"].copy(), a.copy()),
        residuals=residuals,
        details=details,
        notes=tuple(notes),
    )
