"""Rendered frames with known truth for the tests and benchmarks of snapping, matching and tracking.

A thin layer over the project's renderer (``app.render.Renderer``: exact ray casting, area-coverage
anti-aliasing at edges, so an edge lies where C projects it): one model seen by a given camera,
at one pose per frame, over a dark background, with a light that gives adjacent faces different
grey levels.
"""

from __future__ import annotations

import numpy as np

from app.scene import Scene, scene_from_dict
from core.brep import BRep
from core.camera import Camera

__all__ = ["one_body_scene", "render_poses", "edge_contrast"]

LIGHT_DIR = (0.3, -0.6, -1.0)  # towards the light, world frame: from behind a camera looking along +z
AMBIENT = 0.3
GAIN = 235.0
SKY = 0.15


def one_body_scene(
    camera: Camera,
    model: BRep,
    poses: list[np.ndarray] | np.ndarray,
    *,
    albedo: float = 0.85,
    noise_sigma: float = 2.0,
    blur_sigma_px: float = 0.5,
    seed: int = 0,
) -> Scene:
    """A scene holding ``model`` at ``poses[k]`` at time k seconds (k = 0, 1, …), seen by ``camera``.

    poses : list of arrays, shape (4, 4), T_world_obj per frame. noise_sigma : sensor noise (grey
    levels); blur_sigma_px : optical blur (pixels); seed : the noise's seed.
    """
    poses = [
        np.asarray(T, dtype=float)
        for T in (poses if isinstance(poses, (list, tuple)) else list(np.asarray(poses).reshape(-1, 4, 4)))
    ]
    if not poses:
        raise ValueError("give at least one pose")
    d = {
        "format": "mcit-scene/1",
        "name": "synthetic",
        "camera": {"width": camera.width, "height": camera.height, "C": camera.C.tolist()},
        "turret": {"T_world_turret": np.eye(4).tolist()},
        "bodies": [
            {
                "name": "object",
                "kind": "object",
                "model": {"brep": model.to_dict()},
                "pose": poses[0].tolist(),
                "motion": [{"t": float(k), "pose": T.tolist()} for k, T in enumerate(poses) if k > 0],
                "appearance": {"albedo": albedo},
            }
        ],
        "render": {
            "light_dir": list(LIGHT_DIR),
            "ambient": AMBIENT,
            "gain": GAIN,
            "sky": SKY,
            "noise_sigma": noise_sigma,
            "blur_sigma_px": blur_sigma_px,
            "seed": seed,
        },
    }
    return scene_from_dict(d, ".")


def render_poses(camera: Camera, model: BRep, poses: list[np.ndarray] | np.ndarray, **kw) -> list[np.ndarray]:
    """Grey uint8 frames (H, W), one per pose, rendered by ``app.render`` (see ``one_body_scene``)."""
    from app.render.renderer import Renderer

    scene = one_body_scene(camera, model, poses, **kw)
    r = Renderer(scene, camera)
    return [r.render(float(k), k) for k in range(len(scene.bodies[0].motion) + 1)]


def edge_contrast(camera: Camera, model: BRep, T_world_obj: np.ndarray, *, albedo: float = 0.85) -> np.ndarray:
    """Grey-level step across each model edge (E,) in a ``one_body_scene`` frame (NaN when hidden).

    An edge between two visible faces steps between their Lambert shades; an edge of one visible
    face (the outline) steps between that face and the background. Two faces turned away from
    the light have the same shade: the edge between them cannot be seen, nor snapped.
    """
    T = np.asarray(T_world_obj, dtype=float)
    light = np.asarray(LIGHT_DIR) / np.linalg.norm(LIGHT_DIR)
    n_world = model.face_normals() @ T[:3, :3].T
    shade = GAIN * albedo * (AMBIENT + (1.0 - AMBIENT) * np.clip(n_world @ light, 0.0, None))
    c_obj = (camera.center - T[:3, 3]) @ T[:3, :3]
    facing = np.einsum("ij,ij->i", model.face_normals(), c_obj - model.face_centroids()) > 0
    out = np.full(len(model.edges), np.nan)
    for k in range(len(model.edges)):
        seen = [f for f in model.edge_faces(k) if facing[f]]
        if len(seen) == 2:
            out[k] = abs(shade[seen[0]] - shade[seen[1]])
        elif len(seen) == 1:
            out[k] = abs(shade[seen[0]] - GAIN * SKY)
    return out
