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

from .node_groups import NodeGroups

__all__ = ["World3D"]

R_VIEWER_WORLD = np.eye(3)  # the site's frame is the viewer's (z up), shifted by the offset
GROUP_SIZE = 64  # objects per mesh node (app/ui/node_groups.py)


def _wxyz(R: np.ndarray) -> np.ndarray:
    return viser.transforms.SO3.from_matrix(R).wxyz


class World3D:
    """Scene nodes of the virtual world; ``sync(site)`` refreshes what changed.

    The objects are packed by colour (status) and opacity (the table's) in groups of up to GROUP_SIZE
    (``app.ui.node_groups``): ``/world3d/objects/<status>_<k>`` is one mesh of its objects' triangles placed
    at their ``T_world_obj``, with their edges as a child. A change to an object resends its group (and the
    group it left, when its status changed); a removed object leaves its group. The camera and the turret
    are redrawn only when their calibrations change."""

    def __init__(self, scene: viser.SceneApi, offset: np.ndarray, group_size: int = GROUP_SIZE):
        self.scene = scene
        self.offset = np.asarray(offset, float)
        self.root = scene.add_frame(
            "/world3d", show_axes=False, position=tuple(self.offset), wxyz=_wxyz(R_VIEWER_WORLD)
        )
        scene.add_grid("/world3d/grid", width=4.0, height=4.0, plane="xy", cell_size=0.1, section_size=0.5)
        # id → ((version, status, name), (V (N, 3), F (M, 3), E (K, 2, 3)) in the site's frame)
        self._objects: dict[Any, tuple[tuple, tuple]] = {}
        self._groups = NodeGroups(group_size)
        self._group_nodes: set[tuple] = set()  # the groups sent
        self._resend = False  # a sync failed part way: send every group at the next
        self._sensors_key: Any = None
        self.redrawn: list[Any] = []  # ids the last sync drew or moved

    def to_viewer(self, X_world: np.ndarray) -> np.ndarray:
        """Viewer coordinates of site points (..., 3)."""
        return np.asarray(X_world, float) @ R_VIEWER_WORLD.T + self.offset

    def draw(self, site: Site) -> None:
        """Same as ``sync(site)``."""
        self.sync(site)

    @staticmethod
    def group_name(group: tuple) -> str:
        (status, table), index = group
        return f"/world3d/objects/{status}{'_table' if table else ''}_{index}"

    def node_of(self, obj_id: Any) -> str | None:
        """The name of the mesh node that holds an object, or None."""
        group = self._groups.group_of(obj_id)
        return None if group is None else self.group_name(group)

    def sync(self, site: Site, objects: Any = None) -> int:
        """Bring the objects' nodes (and the sensors) up to date; returns how many objects were drawn."""
        objects = site.objects() if objects is None else objects
        seen = set()
        self.redrawn = []
        dirty: set[tuple] = set()
        for obj in objects:
            seen.add(obj.id)
            key = (int(obj.version), obj.status, obj.name)
            old = self._objects.get(obj.id)
            if old is not None and old[0] == key:
                continue
            self.redrawn.append(obj.id)
            T = obj.T_world_obj
            V, F = obj.model.triangles(n_circle=32)
            V = V @ T[:3, :3].T + T[:3, 3]
            E = obj.model.edge_segments(T)
            self._objects[obj.id] = (key, (V.astype(np.float32), F.astype(np.uint32), E.astype(np.float32)))
            dirty |= self._groups.place(obj.id, (obj.status, obj.kind == "table"))
        for gone in set(self._objects) - seen:
            del self._objects[gone]
            dirty.add(self._groups.drop(gone))
        if self._resend:
            dirty |= self._group_nodes | self._groups.groups()
            self._resend = False
        try:
            for group in sorted((g for g in dirty if g is not None), key=str):
                self._send_group(group)
        except BaseException:  # part of it sent (a message viser failed to queue): every group again at the next sync
            self._resend = True
            raise
        cams = [site.camera_of(v) for v in site.views]
        sensors = (*((c.C.tobytes(), c.width, c.height) for c in cams), site.T_world_turret.tobytes())
        if sensors != self._sensors_key:
            self._sensors_key = sensors
            self._draw_sensors(site)
        return len(self.redrawn)

    def _send_group(self, group: tuple) -> None:
        """One group's objects as one mesh (and its edges), replaced whole; removed when empty."""
        name = self.group_name(group)
        parts = [self._objects[i][1] for i in self._groups.members(group)]
        parts = [p for p in parts if len(p[1])]
        if not parts:
            if group in self._group_nodes:
                self._group_nodes.discard(group)
                self.scene.remove_by_name(name)
            return
        first = np.cumsum([0] + [len(V) for V, _, _ in parts])[:-1]
        V = np.concatenate([V for V, _, _ in parts])
        F = np.concatenate([F + k for (_, F, _), k in zip(parts, first)]).astype(np.uint32)
        (status, table), _ = group
        self.scene.add_mesh_simple(
            name,
            V,
            F,
            color=STATUS_COLORS.get(status, STATUS_COLORS["known"]),
            opacity=0.35 if table else 0.75,
            flat_shading=True,
            side="double",
        )
        E = [E for _, _, E in parts if len(E)]
        if E:
            self.scene.add_line_segments(
                f"{name}/edges", np.concatenate(E), (20, 20, 20), thickness=1.5, thickness_units="screen"
            )
        elif group in self._group_nodes:  # its objects with edges left it
            self.scene.remove_by_name(f"{name}/edges")
        self._group_nodes.add(group)

    def _draw_sensors(self, site: Site) -> None:
        for i, name in enumerate(site.views):  # every camera's frustum, named when there are several
            cam = site.camera_of(name)
            K, T_cam_world = cam.decompose()
            T_world_cam = invert_T(T_cam_world)
            fov = 2.0 * np.arctan2(cam.height / 2.0, abs(K[1, 1]))
            node = "/world3d/camera" if i == 0 else f"/world3d/cameras/{name}"
            self.scene.add_camera_frustum(
                node,
                fov=float(fov),
                aspect=cam.width / cam.height,
                scale=0.1,
                color=(40, 40, 200),
                thickness=2.0,
                thickness_units="screen",
                position=tuple(T_world_cam[:3, 3]),
                wxyz=_wxyz(T_world_cam[:3, :3]),
            )
            if len(site.views) > 1:
                self.scene.add_label(f"{node}_label", name, position=tuple(T_world_cam[:3, 3]))
        if not getattr(site, "has_turret", True):  # a camera-only site: no turret, no beam
            return
        T = site.T_world_turret
        self.scene.add_frame(
            "/world3d/turret", axes_length=0.12, axes_radius=0.006, position=tuple(T[:3, 3]), wxyz=_wxyz(T[:3, :3])
        )
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
