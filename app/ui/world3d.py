"""The virtual world in 3D: the database's objects, the camera's frustum, the turret and its beam.

It lives under ``/world3d`` in the same viser scene as the video plane, far to its side (``offset``),
with the site's axes (z up, viser's default up direction). Units are metres. A client switched to
the "3D world" view orbits it freely.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import viser

from app.overlay import COLORS, STATUS_COLORS
from app.workflows.site import Site
from core.transforms import invert_T

__all__ = ["World3D"]

R_VIEWER_WORLD = np.eye(3)  # the site's frame is the viewer's (z up), shifted by the offset


def _wxyz(R: np.ndarray) -> np.ndarray:
    return viser.transforms.SO3.from_matrix(R).wxyz


class World3D:
    """Scene nodes of the virtual world; ``draw(site)`` refreshes them."""

    def __init__(self, scene: viser.SceneApi, offset: np.ndarray):
        self.scene = scene
        self.offset = np.asarray(offset, float)
        self.root = scene.add_frame("/world3d", show_axes=False, position=tuple(self.offset), wxyz=_wxyz(R_VIEWER_WORLD))
        scene.add_grid("/world3d/grid", width=4.0, height=4.0, plane="xy", cell_size=0.1, section_size=0.5)
        self._objects: dict[str, Any] = {}

    def to_viewer(self, X_world: np.ndarray) -> np.ndarray:
        """Viewer coordinates of site points (..., 3)."""
        return np.asarray(X_world, float) @ R_VIEWER_WORLD.T + self.offset

    def draw(self, site: Site) -> None:
        seen = set()
        for obj in site.objects():
            seen.add(obj.name)
            V, F = obj.model.triangles(n_circle=32)
            Vw = V @ obj.T_world_obj[:3, :3].T + obj.T_world_obj[:3, 3]
            color = STATUS_COLORS.get(obj.status, STATUS_COLORS["known"])
            name = f"/world3d/objects/{obj.name}"
            self.scene.add_mesh_simple(name, Vw.astype(np.float32), F.astype(np.uint32), color=color,
                                       opacity=0.35 if obj.kind == "table" else 0.75, flat_shading=True, side="double")
            E = obj.model.edge_segments(obj.T_world_obj)
            if len(E):
                self.scene.add_line_segments(f"{name}_edges", E.astype(np.float32), (20, 20, 20), thickness=1.5,
                                             thickness_units="screen")
            self._objects[obj.name] = name
        for gone in set(self._objects) - seen:
            name = self._objects.pop(gone)
            self.scene.remove_by_name(name)
            self.scene.remove_by_name(f"{name}_edges")
        self._draw_sensors(site)

    def _draw_sensors(self, site: Site) -> None:
        cam = site.camera
        K, T_cam_world = cam.decompose()
        T_world_cam = invert_T(T_cam_world)
        fov = 2.0 * np.arctan2(cam.height / 2.0, abs(K[1, 1]))
        self.scene.add_camera_frustum("/world3d/camera", fov=float(fov), aspect=cam.width / cam.height, scale=0.1,
                                      color=(40, 40, 200), thickness=2.0, thickness_units="screen",
                                      position=tuple(T_world_cam[:3, 3]), wxyz=_wxyz(T_world_cam[:3, :3]))
        T = site.T_world_turret
        self.scene.add_frame("/world3d/turret", axes_length=0.12, axes_radius=0.006,
                             position=tuple(T[:3, 3]), wxyz=_wxyz(T[:3, :3]))
        self.draw_beam(site)

    def draw_beam(self, site: Site) -> None:
        X = getattr(site, "beam_X_world", None)
        T = site.T_world_turret
        if X is None or not np.all(np.isfinite(X)):
            self.scene.remove_by_name("/world3d/beam")
            return
        seg = np.array([[T[:3, 3], np.asarray(X, float)]], dtype=np.float32)
        self.scene.add_line_segments("/world3d/beam", seg, COLORS["beam"], thickness=2.5, thickness_units="screen")

    def default_view(self, site: Site) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(position, look_at, up) in viewer coordinates: behind and above the camera, at the objects."""
        objs = [o for o in site.objects() if o.kind != "table"] or list(site.objects())
        look = np.mean([o.T_world_obj[:3, 3] for o in objs], axis=0) if objs else np.zeros(3)
        c = site.camera.center
        eye = look + 1.1 * (c - look) + np.array([0.6, 0.0, 0.5])
        return self.to_viewer(eye), self.to_viewer(look), np.array([0.0, 0.0, 1.0])
