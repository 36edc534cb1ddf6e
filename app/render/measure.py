"""Where do rendered edges lie? Measurements of a frame against the scene's true edges.

Used by the renderer's tests and ``bench/render.py``: project a true model edge through C, then
find the edge in the image across it, as the first moment of the gradient magnitude along the
normal (the image bilinearly interpolated). For a box-filtered step edge this centroid is exactly
the edge's position (the interpolated ramp's derivative is centred on it), so any offset is the
renderer's (or a blur's, or a shading gradient's) doing.
"""

from __future__ import annotations

from collections.abc import Iterator

import numpy as np
from scipy.ndimage import map_coordinates

from app.scene import Scene

from .renderer import Renderer

__all__ = ["edge_offsets", "visible_edges", "polygon_coverage", "top_down_scene"]


def edge_offsets(
    image: np.ndarray, seg_uv: np.ndarray, *, half_px: float = 2.0, step_px: float = 0.25, n: int = 9
) -> np.ndarray:
    """Signed offsets (n,), pixels, of the image's edge from the line of ``seg_uv`` (2, 2).

    At n places spread over the middle half of the segment, the profile across it (±half_px,
    every step_px) gives the gradient-weighted centroid, measured along the normal (−t_v, t_u)
    with t the unit direction p0 → p1.
    """
    img = np.asarray(image, dtype=float)
    p0, p1 = np.asarray(seg_uv, dtype=float).reshape(2, 2)
    length = float(np.linalg.norm(p1 - p0))
    if length <= 0:
        raise ValueError(f"seg_uv must have two distinct endpoints, got {p0.tolist()} twice")
    t = (p1 - p0) / length
    normal = np.array([-t[1], t[0]])
    s = np.arange(-half_px, half_px + 1e-9, step_px)
    out = np.empty(n)
    for i, a in enumerate(np.linspace(0.25, 0.75, n)):
        pts = p0 + a * (p1 - p0) + s[:, None] * normal
        prof = map_coordinates(img, [pts[:, 1], pts[:, 0]], order=1, mode="nearest")
        g = np.abs(np.gradient(prof, step_px))
        total = float(g.sum())
        out[i] = float(g @ s) / total if total > 0 else np.nan
    return out


def visible_edges(
    scene: Scene, renderer: Renderer, t_s: float, kinds: tuple[str, ...] = ("edge",), min_px: float = 25.0
) -> Iterator[tuple[str, int, np.ndarray]]:
    """The non-scenery bodies' edges (or silhouettes) seen unoccluded at t_s: (body name, wireframe
    index, projected segment (2, 2)), for those at least ``min_px`` long and 4 px inside the image."""
    caster = renderer.caster(t_s)
    cam = renderer.camera
    for bi, body in enumerate(scene.bodies):
        if body.status == "scenery":
            continue
        wire = body.model.wireframe(cam.center, body.pose_at(t_s))
        for k in np.flatnonzero(wire.visible):
            if wire.kind[k] not in kinds:
                continue
            seg = wire.segments[k]
            uv = cam.project(seg)
            if np.linalg.norm(uv[1] - uv[0]) < min_px or not cam.in_image(uv, 4.0).all():
                continue
            P = seg[0] + np.linspace(0.2, 0.8, 13)[:, None] * (seg[1] - seg[0])
            if caster.occluded(cam.center, P, body=bi, tol_m=1e-6).any():
                continue
            yield body.name, int(k), uv


def _clip(poly: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Sutherland–Hodgman: a convex polygon (K, 2) clipped to the box [lo, hi]."""
    for axis in (0, 1):
        for bound, keep_below in ((hi[axis], True), (lo[axis], False)):
            out = []
            for a, b in zip(poly, np.roll(poly, -1, axis=0)):
                ina = a[axis] <= bound if keep_below else a[axis] >= bound
                inb = b[axis] <= bound if keep_below else b[axis] >= bound
                if ina:
                    out.append(a)
                if ina != inb:
                    out.append(a + (bound - a[axis]) / (b[axis] - a[axis]) * (b - a))
            poly = np.array(out).reshape(-1, 2)
            if not len(poly):
                return poly
    return poly


def _area(poly: np.ndarray) -> float:
    if len(poly) < 3:
        return 0.0
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * abs(float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def polygon_coverage(poly_uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Exact share (H, W) of each pixel's square [u ± ½] × [v ± ½] covered by a convex polygon
    (K, 2) of pixel coordinates (any orientation): the reference for anti-aliased edges."""
    from scipy.spatial import ConvexHull

    P = np.asarray(poly_uv, dtype=float).reshape(-1, 2)
    hull = P[ConvexHull(P).vertices]
    out = np.zeros((height, width))
    u0, v0 = np.floor(hull.min(axis=0) + 0.5).astype(int)
    u1, v1 = np.floor(hull.max(axis=0) + 0.5).astype(int)
    for v in range(max(v0, 0), min(v1, height - 1) + 1):
        for u in range(max(u0, 0), min(u1, width - 1) + 1):
            out[v, u] = _area(_clip(hull, np.array([u - 0.5, v - 0.5]), np.array([u + 0.5, v + 0.5])))
    return out


def top_down_scene(yaw_deg: float, x_edge: float = -0.0031) -> dict:
    """The renderers' edge test (``mcit-scene/1`` dict): a 40×30 camera looking straight down at a 1 m box whose
    left edge is at world x = ``x_edge`` at yaw 0 (a third of a pixel off the image's middle column by default),
    turned by ``yaw_deg``; flat light, no noise, no blur: the edge's grey levels are its coverage alone."""
    return {
        "format": "mcit-scene/1",
        "camera": {
            "width": 40,
            "height": 30,
            "K": [[100, 0, 19.5], [0, 100, 14.5], [0, 0, 1]],
            "T_world_cam": {"xyz": [0, 0, 2.0], "rpy_deg": [180, 0, 0]},
        },
        "turret": {"T_world_turret": {"xyz": [0.2, 0, 2.0]}},
        "bodies": [
            {
                "name": "box",
                "model": {"box": [1.0, 1.0, 0.1]},
                "pose": {"xyz": [x_edge + 0.5, 0, 0], "rpy_deg": [0, 0, yaw_deg]},
                "appearance": {"albedo": 0.8},
            }
        ],
        "render": {"ambient": 1.0, "sky": 0.1, "gain": 200.0, "noise_sigma": 0.0, "blur_sigma_px": 0.0},
    }
