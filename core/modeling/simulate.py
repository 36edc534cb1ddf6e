"""Synthetic observations of unknown objects, for tests, benchmarks and the headless demo.

Ray casting is analytic (boxes by slabs, solids of revolution by their quadric, the table as a
plane), so this stays pure numpy. The sensor model is the paper's (DESIGN.md §Simulation):

* camera: clicks are the true image points plus N(0, σ_px²) on each coordinate;
* turret: angles are commanded in whole steps (``spec.step_rad``) and reported as commanded;
  the beam actually leaves at the commanded angle plus a uniform error of ±½ step
  (σ = step/√12, the ``RangeFinderSpec.sigma_angle`` default) on pan and on tilt;
* range finder: true range plus N(0, σ_ρ²); NaN (no return) outside [min, max] range or when
  the beam hits nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brep import Revolution
from ..camera import Camera
from ..geometry import Plane
from ..rangefinder import RangeFinderSpec, RangeScan, aim, beam_direction, beam_point_cov, quantize_angle
from ..transforms import make_T, rot_z, transform_points
from .box import BoxFace
from .box_scans import box_entry

__all__ = [
    "look_at_setup",
    "ray_box",
    "ray_plane",
    "ray_revolution",
    "SimWorld",
    "simulate_box",
    "simulate_box_scans",
    "simulate_revolution",
    "ray_convex",
    "simulate_polyhedron",
]


def look_at_setup(
    target_world: np.ndarray,
    distance_m: float,
    *,
    elevation_deg: float = 30.0,
    azimuth_deg: float = 90.0,
    baseline_m: float = 0.2,
    f_px: float = 500.0,
    width: int = 512,
    height: int = 256,
) -> tuple[Camera, np.ndarray]:
    """A camera looking at a target from ``distance_m`` and a turret ``baseline_m`` to its right.

    azimuth_deg : direction from the camera to the target in the table plane (90° = along +y);
    elevation_deg : how far the camera looks down. The turret's z is world z, its x the
    camera's horizontal viewing direction. Returns (camera, T_world_turret (4, 4)).
    """
    target = np.asarray(target_world, dtype=float)
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    fwd = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), -np.sin(el)])
    centre = target - distance_m * fwd
    z_cam = fwd
    x_cam = np.cross(z_cam, [0.0, 0.0, 1.0])
    x_cam /= np.linalg.norm(x_cam)
    y_cam = np.cross(z_cam, x_cam)
    R_cam_world = np.vstack([x_cam, y_cam, z_cam])
    K = np.array([[f_px, 0.0, (width - 1) / 2.0], [0.0, f_px, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
    cam = Camera.from_intrinsics(K, make_T(R_cam_world, -R_cam_world @ centre), width, height)
    T_world_turret = make_T(rot_z(az), centre + baseline_m * x_cam)
    return cam, T_world_turret


def ray_plane(origin: np.ndarray, dirs: np.ndarray, plane: Plane) -> np.ndarray:
    """Distance (N,) along unit rays to a plane, NaN when parallel or behind."""
    n, d = plane
    den = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        s = -(origin @ n + d) / den
    return np.where((np.abs(den) > 1e-12) & (s > 1e-9), s, np.nan)


def ray_box(origin: np.ndarray, dirs: np.ndarray, T_world_obj: np.ndarray, size) -> np.ndarray:
    """Distance (N,) along unit rays to a box ``BRep.box(*size)`` at ``T_world_obj``; NaN for a miss."""
    return box_entry(origin, dirs, T_world_obj[:3, :3], T_world_obj[:3, 3], size)[0]


def ray_revolution(origin: np.ndarray, dirs: np.ndarray, solid: Revolution) -> np.ndarray:
    """Distance (N,) along unit rays to a closed cylinder/cone (lateral surface and caps); NaN for a miss."""
    t = solid.ray_cast(origin, dirs)[0]
    return np.where(np.isfinite(t) & (t > 1e-9), t, np.nan)


def ray_convex(origin: np.ndarray, dirs: np.ndarray, brep_world) -> np.ndarray:
    """Distance (N,) along unit rays to a convex polyhedron (a BRep in world coordinates); NaN for a miss."""
    t = brep_world.polyhedron.ray_cast(origin, dirs)[0]
    return np.where(np.isfinite(t) & (t > 1e-9), t, np.nan)


@dataclass
class SimWorld:
    """A simulated site: the table plane, boxes and solids of revolution, and the sensors' noise.

    boxes : list of (T_world_obj (4, 4), size (3,)). solids : list of Revolution in the world.
    polyhedra : list of convex BRep in world coordinates. table : Plane or None (z = 0 by default).
    """

    T_world_turret: np.ndarray
    spec: RangeFinderSpec = RangeFinderSpec()
    boxes: tuple = ()
    solids: tuple = ()
    polyhedra: tuple = ()
    table: Plane | None = Plane(np.array([0.0, 0.0, 1.0]), 0.0)

    def cast(self, origin: np.ndarray, dirs: np.ndarray) -> np.ndarray:
        """True distance (N,) along unit world rays to the nearest surface, NaN if none."""
        best = np.full(len(dirs), np.inf)
        hits = [ray_box(origin, dirs, T, s) for T, s in self.boxes]
        hits += [ray_revolution(origin, dirs, s) for s in self.solids]
        hits += [ray_convex(origin, dirs, b) for b in self.polyhedra]
        if self.table is not None:
            hits.append(ray_plane(origin, dirs, self.table))
        for h in hits:
            best = np.where(np.isfinite(h) & (h < best), h, best)
        return np.where(np.isfinite(best), best, np.nan)

    def measure(self, pan_rad, tilt_rad, rng: np.random.Generator | None) -> np.ndarray:
        """Ranges (N,) for commanded angles (already whole steps); noise-free when rng is None."""
        pan = np.atleast_1d(np.asarray(pan_rad, dtype=float))
        tilt = np.atleast_1d(np.asarray(tilt_rad, dtype=float))
        if rng is not None:
            half = self.spec.step_rad / 2
            pan = pan + rng.uniform(-half, half, pan.shape)
            tilt = tilt + rng.uniform(-half, half, tilt.shape)
        T = self.T_world_turret
        dirs = beam_direction(pan, tilt) @ T[:3, :3].T
        rho = self.cast(T[:3, 3], dirs)
        if rng is not None:
            rho = rho + rng.normal(0.0, self.spec.sigma_range_m, rho.shape)
        ok = (rho >= self.spec.min_range_m) & (rho <= self.spec.max_range_m)
        return np.where(ok, rho, np.nan)


def _click(camera: Camera, X: np.ndarray, rng, sigma_px: float) -> np.ndarray:
    uv = camera.project(X)
    if rng is not None and sigma_px > 0:
        uv = uv + rng.normal(0.0, sigma_px, uv.shape)
    return uv


def simulate_box(
    camera: Camera,
    world: SimWorld,
    T_world_obj: np.ndarray,
    size,
    rng: np.random.Generator | None,
    *,
    sigma_px: float = 1.0,
    grid: int = 4,
    inset: float = 0.2,
    click_span: tuple[float, float] = (0.1, 0.9),
    step_quantize: bool = True,
) -> list[BoxFace]:
    """Operator's measurements of a box: visible faces, range points on a grid, clicked sides.

    For every face that both the camera and the turret see, the beam is aimed at a ``grid`` ×
    ``grid`` lattice of points inset by ``inset`` of the face's size (the beam may still land on
    another face or the table through the turret error), and every side of the face is clicked
    at ``click_span`` of its length (a side shared with a face listed earlier is clicked once).
    rng None: noise-free (and ``step_quantize`` False aims exactly). Returns a list of BoxFace.
    """
    sx, sy, sz = size
    R, t = T_world_obj[:3, :3], T_world_obj[:3, 3]
    s = np.array([[1 if v & 1 else -1, 1 if v & 2 else -1, 1 if v & 4 else -1] for v in range(8)])
    corners = t + np.column_stack([s[:, 0] * sx / 2, s[:, 1] * sy / 2, (s[:, 2] + 1) / 2 * sz]) @ R.T
    o_turret = world.T_world_turret[:3, 3]
    faces, clicked = [], set()
    for ax in range(3):
        for sg in (1, -1):
            n = R[:, ax] * sg
            idx = np.flatnonzero(s[:, ax] == sg)
            cen = corners[idx].mean(axis=0)
            if n @ (camera.center - cen) <= 0 or n @ (o_turret - cen) <= 0:
                continue
            u_ax, v_ax = [a for a in range(3) if a != ax]
            span = np.array([sx, sy, sz])
            g = (np.arange(grid) + 0.5) / grid * (1 - 2 * inset) + inset - 0.5
            gu, gv = np.meshgrid(g, g)
            P = cen + gu.reshape(-1, 1) * span[u_ax] * R[:, u_ax] + gv.reshape(-1, 1) * span[v_ax] * R[:, v_ax]
            pan, tilt, _ = aim(world.T_world_turret, P)
            if step_quantize:
                pan, tilt = quantize_angle(pan, world.spec.step_rad), quantize_angle(tilt, world.spec.step_rad)
            rho = world.measure(pan, tilt, rng)
            ok = np.isfinite(rho)
            Xw = transform_points(world.T_world_turret, beam_direction(pan[ok], tilt[ok]) * rho[ok, None])
            covs = beam_point_cov(world.T_world_turret, pan[ok], tilt[ok], rho[ok], world.spec)
            segs = []
            for m in (u_ax, v_ax):
                q = 3 - ax - m
                for sq in (-1, 1):
                    e = tuple(np.flatnonzero((s[:, ax] == sg) & (s[:, q] == sq)))
                    if e in clicked:
                        continue
                    clicked.add(e)
                    A, B = corners[e[0]], corners[e[1]]
                    X = np.array([A + click_span[0] * (B - A), A + click_span[1] * (B - A)])
                    segs.append(_click(camera, X, rng, sigma_px))
            faces.append(BoxFace(Xw, np.array(segs).reshape(-1, 2, 2), covs))
    return faces


def simulate_revolution(
    camera: Camera,
    world: SimWorld,
    solid: Revolution,
    rng: np.random.Generator | None,
    *,
    sigma_px: float = 1.0,
    scan_fractions: tuple[float, ...] = (1 / 3, 2 / 3),
    step_multiple: int = 1,
    margin_m: float = 0.03,
    exact_edges: bool = False,
) -> tuple[np.ndarray, list[RangeScan]]:
    """Operator's measurements of a cylinder or cone: two clicked silhouettes and horizontal scans.

    Silhouettes: each contour generator clicked at its two ends (bottom rim, top rim), shape
    (2, 2, 2). Scans: for each fraction f of the height, a pan sweep at the tilt that aims at
    the axis point at height f·h, from ``margin_m`` left of the solid to ``margin_m`` right of
    it, every ``step_multiple`` turret steps (angles in whole steps, reported as commanded).
    exact_edges : add, at each end of the object's run, a pair of beams 1e-12 rad either side of
    the exact grazing angle (found by bisection): with rng None the tangent beams are then exact,
    for tests of the methods' exactness.
    Returns (silhouettes_uv (2, 2, 2), list of RangeScan).
    """
    sil = solid.silhouette(camera.center)
    if len(sil) != 2:
        raise ValueError("the camera is inside the solid's extension: no silhouette")
    sil_uv = np.array([_click(camera, g, rng, sigma_px) for g in sil])
    step = world.spec.step_rad
    scans = []
    for f in scan_fractions:
        P = solid.p0 + f * (solid.p1 - solid.p0)
        pan0, tilt0, rho0 = aim(world.T_world_turret, P)
        r = solid.r0 + f * (solid.r1 - solid.r0)
        half = np.arctan((r + margin_m) / rho0)
        k0 = int(np.floor((pan0 - half) / step))
        k1 = int(np.ceil((pan0 + half) / step))
        pan = np.arange(k0, k1 + 1, step_multiple) * step
        tilt = np.full_like(pan, float(quantize_angle(tilt0, step)))
        rho = world.measure(pan, tilt, rng)
        if exact_edges:
            pan, tilt, rho = _add_exact_edges(world, lambda o, d: ray_revolution(o, d, solid), pan, tilt)
        scans.append(RangeScan(pan, tilt, rho, meta={"fraction": f}))
    return sil_uv, scans


def simulate_box_scans(
    world: SimWorld,
    T_world_obj: np.ndarray,
    size,
    rng: np.random.Generator | None,
    *,
    scan_fractions: tuple[float, ...] = (0.5, 0.75),
    step_multiple: int = 1,
    margin_m: float = 0.03,
    exact_edges: bool = False,
) -> list[RangeScan]:
    """Horizontal profile scans across a box ``BRep.box(*size)`` at ``T_world_obj`` (misses kept).

    For each fraction f of the height, a pan sweep at the tilt (whole steps) that aims at the
    point of the box's vertical axis at height f·h, from ``margin_m`` beyond the box's extreme
    corners on one side to ``margin_m`` beyond them on the other, every ``step_multiple`` turret
    steps (angles reported as commanded; ``world.measure`` adds the turret's and range's noise).
    exact_edges : add, at each end of the box's run, beams 1e-12 rad either side of the exact
    grazing pan (bisection): with rng None the transitions are then exact, for exactness tests.
    Returns a list of RangeScan (meta {"fraction": f}).

    The default heights are above the middle: along a sweep at one tilt the beam crosses the far
    silhouette edge lower than the near one, and the jump from the box's last return to the table
    behind it is (crossing height) / sin(depression); at half height and above it stays ≥ 9.6 cm
    for the benchmark's set-ups (1.3–1.6 m, any yaw), well over ``jump_m`` = 5 cm — at a third of
    the height it falls to 4.6 cm and the box's run would run on into the table.
    """
    size = np.asarray(size, dtype=float)
    R, t = T_world_obj[:3, :3], T_world_obj[:3, 3]
    T = world.T_world_turret
    step = world.spec.step_rad
    s = np.array([[1 if v & 1 else -1, 1 if v & 2 else -1, 1 if v & 4 else -1] for v in range(8)])
    corners = t + np.column_stack([s[:, 0] * size[0] / 2, s[:, 1] * size[1] / 2, (s[:, 2] + 1) / 2 * size[2]]) @ R.T
    scans = []
    for f in scan_fractions:
        pan0, tilt0, rho0 = aim(T, t + f * size[2] * R[:, 2])
        pans = aim(T, corners)[0]
        rel = (pans - pan0 + np.pi) % (2 * np.pi) - np.pi
        pad = np.arctan(margin_m / rho0)
        k0 = int(np.floor((pan0 + rel.min() - pad) / step))
        k1 = int(np.ceil((pan0 + rel.max() + pad) / step))
        pan = np.arange(k0, k1 + 1, step_multiple) * step
        tilt = np.full_like(pan, float(quantize_angle(tilt0, step)))
        rho = world.measure(pan, tilt, rng)
        if exact_edges:
            pan, tilt, rho = _add_exact_edges(world, lambda o, d: ray_box(o, d, T_world_obj, size), pan, tilt)
        scans.append(RangeScan(pan, tilt, rho, meta={"fraction": f}))
    return scans


def _add_exact_edges(world: SimWorld, cast_object, pan, tilt):
    """Add beams 1e-12 rad either side of the exact ends of the object's run (noise-free ranges).

    cast_object(origin (3,), dirs (N, 3)) → distances (N,), NaN where the object is missed.
    """
    T = world.T_world_turret

    def on(p):
        d = beam_direction(np.array([p]), np.array([tilt[0]])) @ T[:3, :3].T
        return bool(np.isfinite(cast_object(T[:3, 3], d))[0])

    hit = np.array([on(p) for p in pan])
    idx = np.flatnonzero(hit)
    extra = []
    for lo, hi in ((idx[0] - 1, idx[0]), (idx[-1], idx[-1] + 1)):
        a, b = pan[lo], pan[hi]  # hit state differs between a and b
        ha = on(a)
        for _ in range(200):
            m = 0.5 * (a + b)
            if on(m) == ha:
                a = m
            else:
                b = m
            if abs(b - a) < 1e-13:
                break
        m = 0.5 * (a + b)
        extra += [m - 1e-12, m + 1e-12]
    pan2 = np.sort(np.concatenate([pan, extra]))
    tilt2 = np.full_like(pan2, tilt[0])
    return pan2, tilt2, world.measure(pan2, tilt2, None)


def simulate_polyhedron(
    camera: Camera,
    world: SimWorld,
    brep_world,
    rng: np.random.Generator | None,
    *,
    sigma_px: float = 1.0,
    rings: tuple[float, ...] = (0.3, 0.6),
    click_span: tuple[float, float] = (0.1, 0.9),
) -> tuple[dict, dict, dict]:
    """Operator's measurements of a convex polyhedron (a BRep in world coordinates).

    Faces seen by both sensors get range points at ``rings`` of the way from their centroid to
    each vertex and to each side's midpoint; every side of those faces is clicked once.
    Returns (face_points {face: (N, 3)}, face_point_covs {face: (N, 3, 3)}, edge_segments {(i, j): (2, 2)}).
    """
    V = brep_world.vertices
    N = brep_world.face_normals()
    C = brep_world.face_centroids()
    o_t = world.T_world_turret[:3, 3]
    pts, covs, segs = {}, {}, {}
    for f, loop in enumerate(brep_world.faces):
        if N[f] @ (camera.center - C[f]) <= 0 or N[f] @ (o_t - C[f]) <= 0:
            continue
        P = V[list(loop)]
        M = 0.5 * (P + np.roll(P, -1, axis=0))
        targets = np.vstack([C[f] + s * (Q - C[f]) for s in rings for Q in (P, M)] + [C[f][None]])
        pan, tilt, _ = aim(world.T_world_turret, targets)
        pan, tilt = quantize_angle(pan, world.spec.step_rad), quantize_angle(tilt, world.spec.step_rad)
        rho = world.measure(pan, tilt, rng)
        ok = np.isfinite(rho)
        pts[f] = transform_points(world.T_world_turret, beam_direction(pan[ok], tilt[ok]) * rho[ok, None])
        covs[f] = beam_point_cov(world.T_world_turret, pan[ok], tilt[ok], rho[ok], world.spec)
        for a, b in zip(loop, loop[1:] + loop[:1]):
            e = (min(a, b), max(a, b))
            if e in segs:
                continue
            A, B = V[e[0]], V[e[1]]
            X = np.array([A + click_span[0] * (B - A), A + click_span[1] * (B - A)])
            segs[e] = _click(camera, X, rng, sigma_px)
    return pts, covs, segs
