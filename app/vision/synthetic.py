"""Rendered frames with known edges, for the tests and benchmarks of snapping, matching and tracking.

A convex polyhedral model is drawn as flat-shaded faces (each face's grey level from its normal)
over a uniform background, supersampled ``k`` times and averaged down by k × k block means: each
pixel gets the area fraction of the faces that cover it, so an edge's position in the image is
exact to a small fraction of a pixel (its true projection through C). Optional Gaussian noise,
then rounding to uint8 as a camera would.

The fine grid keeps the pixel convention (pixel centres at integers): coarse pixel u covers fine
pixels k·u … k·u + k − 1, so a point at u maps to ``k(u + 0.5) − 0.5`` on the fine grid.
"""

from __future__ import annotations

import numpy as np

from core.brep import BRep
from core.camera import Camera

__all__ = ["render_model"]



def _fill_convex(canvas: np.ndarray, P: np.ndarray, value: int) -> None:
    """Set the fine pixels whose centres lie inside the convex polygon P (n, 2) (either winding).

    Exact point-in-polygon sampling (OpenCV's fillConvexPoly includes its boundary pixels, which
    would grow every face by half a fine pixel and bias the edges outwards).
    """
    h, w = canvas.shape
    lo = np.maximum(np.floor(P.min(axis=0)).astype(int), 0)
    hi = np.minimum(np.ceil(P.max(axis=0)).astype(int), [w - 1, h - 1])
    if np.any(hi < lo):
        return
    u = np.arange(lo[0], hi[0] + 1, dtype=float)[None, :]
    v = np.arange(lo[1], hi[1] + 1, dtype=float)[:, None]
    area2 = np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    sign = 1.0 if area2 > 0 else -1.0
    inside = np.ones((len(v), u.shape[1]), bool)
    for a, b in zip(P, np.roll(P, -1, axis=0)):
        inside &= sign * ((b[0] - a[0]) * (v - a[1]) - (b[1] - a[1]) * (u - a[0])) > 0
    canvas[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1][inside] = value


def render_model(
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    background: float = 50.0,
    light_obj: np.ndarray | None = None,
    supersample: int = 8,
    noise_sigma: float = 0.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Grey uint8 image (H, W) of the model's faces that face the camera, flat-shaded.

    Parameters
    ----------
    camera : Camera; model : BRep with faces (convex); T_world_obj : array, shape (4, 4).
    background : grey level of the background.
    light_obj : array, shape (3,), direction to the light in the object frame (default a fixed
        oblique one); a face's grey level is 60 + 75·(1 + n·light), so adjacent faces differ.
    supersample : fine pixels per pixel along each axis.
    noise_sigma : standard deviation (grey levels) of additive Gaussian noise; needs ``rng``.
    """
    if not model.faces:
        raise ValueError("render_model draws faces; the model has none")
    if noise_sigma > 0 and rng is None:
        raise ValueError("noise_sigma > 0 needs rng (a numpy Generator) for reproducible noise")
    k = int(supersample)
    if k < 1:
        raise ValueError(f"supersample must be a positive integer, got {supersample}")
    light = np.array([0.3, -0.5, 0.8]) if light_obj is None else np.asarray(light_obj, dtype=float)
    light = light / np.linalg.norm(light)
    W, H = camera.width, camera.height
    canvas = np.full((H * k, W * k), int(round(background)), np.uint8)
    T = np.asarray(T_world_obj, dtype=float)
    c_obj = (camera.center - T[:3, 3]) @ T[:3, :3]
    normals = model.face_normals()
    cents = model.face_centroids()
    for f, nrm, cen in zip(model.faces, normals, cents):
        if nrm @ (c_obj - cen) <= 0:
            continue
        X = model.vertices[list(f)]
        if np.any(camera.depth(X @ T[:3, :3].T + T[:3, 3]) <= 0):
            raise ValueError("a visible face crosses the camera's principal plane; move the object in front")
        uv = camera.project_obj(T, X)
        grey = int(round(60 + 150 * (0.5 + 0.5 * float(nrm @ light))))
        _fill_convex(canvas, k * (uv + 0.5) - 0.5, grey)
    img = canvas.reshape(H, k, W, k).mean(axis=(1, 3), dtype=np.float32)  # exact area averages
    if noise_sigma > 0:
        img = img + rng.normal(0.0, noise_sigma, img.shape).astype(np.float32)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)
