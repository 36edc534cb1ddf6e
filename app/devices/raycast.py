"""The range finder's view of the true scene: the first surface a beam meets, by trimesh ray casting.

Each body's mesh (``body.model.triangles()``, object frame) and its trimesh intersector are built
once; a beam is brought into each body's frame with the body's true pose at the asked time
(``Body.pose_at``), so moving bodies cost no rebuild. Static bodies' poses are computed once.
"""

from __future__ import annotations

from typing import Iterable

import numpy as np
import trimesh

from app.scene import Body, Scene
from core.transforms import invert_T

__all__ = ["SceneRaycaster"]


class SceneRaycaster:
    """First hit of a beam against the scene's true meshes.

    bodies : the scene's bodies (``Scene.bodies``) or a Scene. Bodies are ray cast as closed
    triangle meshes in their own frame.
    """

    def __init__(self, bodies: Scene | Iterable[Body]):
        if isinstance(bodies, Scene):
            bodies = bodies.bodies
        self._items = []
        for body in bodies:
            V, F = body.model.triangles()
            mesh = trimesh.Trimesh(np.asarray(V, dtype=float), np.asarray(F, dtype=np.int64), process=False)
            intersector = trimesh.ray.ray_triangle.RayMeshIntersector(mesh)
            T_obj_world = None if body.moves else invert_T(body.pose_at(0.0))
            self._items.append((body, intersector, T_obj_world))
        if not self._items:
            raise ValueError("a scene with no bodies has nothing to measure; add at least a table")

    @property
    def names(self) -> list[str]:
        return [b.name for b, _, _ in self._items]

    def cast(self, origin_world: np.ndarray, direction_world: np.ndarray, t_s: float = 0.0) -> tuple[float, str | None]:
        """Distance (metres) along the beam to the first surface, and the body hit.

        origin_world : array, shape (3,), world frame. direction_world : array, shape (3,), any
        non-zero length (normalised here). t_s : scene time (seconds) for moving bodies.
        Returns (inf, None) when the beam meets nothing.
        """
        o = np.asarray(origin_world, dtype=float).reshape(3)
        d = np.asarray(direction_world, dtype=float).reshape(3)
        norm = float(np.linalg.norm(d))
        if not (np.all(np.isfinite(o)) and np.isfinite(norm) and norm > 0):
            raise ValueError(f"a beam needs a finite origin and a non-zero direction, got {o}, {d}")
        d = d / norm
        best, hit = np.inf, None
        for body, intersector, T_obj_world in self._items:
            T = T_obj_world if T_obj_world is not None else invert_T(body.pose_at(t_s))
            o_obj = T[:3, :3] @ o + T[:3, 3]
            d_obj = T[:3, :3] @ d
            locations, _, _ = intersector.intersects_location(o_obj[None], d_obj[None], multiple_hits=False)
            if len(locations):
                dist = float(np.min(np.linalg.norm(locations - o_obj, axis=1)))
                if dist < best:
                    best, hit = dist, body.name
        return best, hit
