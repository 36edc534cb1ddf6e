"""The robot drawn at its joint states, for every operator: over each camera's image and in the 3D world.

Over the video: ``<prefix>/robot`` per camera (its links' wireframes through that camera's C, each
link hiding its own back edges), in the robot's colour, with a label at its base. In the 3D world:
``/world3d/robot/<k>`` one mesh per link shape, moved on each joint state. Both are redrawn by the
frame loop when the robot's joint state or a camera's calibration changed since the last draw
(``sync``), never more often than the frame loop runs.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.overlay import COLORS, LineBatch, PixelWorld, project_wireframe

__all__ = ["RobotOverlay", "robot_batch"]


def robot_batch(camera, links, width: int, height: int, color=COLORS["robot"]) -> LineBatch:
    """The wireframes of ``links`` [(link, BRep, T_world)] through ``camera``, back edges removed."""
    batch = LineBatch()
    for _link, brep, T in links:
        batch.add_wireframe(project_wireframe(camera, brep, T, width=width, height=height), color, hidden="removed")
    return batch


def link_meshes(scene, prefix: str, links, color, opacity: float, offset=(0.0, 0.0, 0.0)) -> list:
    """One mesh node per link shape, ``<prefix>/<k>``, at its pose (shifted by ``offset``); their handles."""
    from .world3d import _wxyz

    out = []
    for k, (_link, brep, T) in enumerate(links):
        V, F = brep.triangles(n_circle=24)
        out.append(
            scene.add_mesh_simple(
                f"{prefix}/{k}",
                V.astype(np.float32),
                F.astype(np.uint32),
                color=color,
                opacity=opacity,
                flat_shading=True,
                position=tuple(T[:3, 3] + np.asarray(offset, float)),
                wxyz=_wxyz(T[:3, :3]),
            )
        )
    return out


class RobotOverlay:
    """The robot's shared drawing (see the module docstring).

    send_lines : ``InterfaceServer._send_lines``-like callable (scene, name, batch, z, pixel_world).
    views : {camera name: (PixelWorld, node prefix)}. z : the overlay plane. world3d : the World3D.
    """

    def __init__(self, scene: Any, send_lines, views: dict[str, tuple[PixelWorld, str]], z: float, world3d):
        self.scene = scene
        self.send_lines = send_lines
        self.views = views
        self.z = float(z)
        self.world3d = world3d
        self._key: Any = None
        self._meshes: list = []
        self._labels: dict[str, Any] = {}

    def sync(self, site) -> bool:
        """Redraw when the robot moved or a camera was calibrated since the last draw; True when it drew."""
        cell = site.robot
        if cell is None:
            return False
        cams = {name: site.camera_of(name) for name in self.views}
        key = (cell.revision, cell.T_world_base.tobytes(), *(c.C.tobytes() for c in cams.values()))
        if key == self._key:
            return False
        self._key = key
        links = cell.link_breps() if _heard(cell) else []  # a robot not heard from yet is not drawn anywhere
        base = cell.T_world_base[:3, 3]
        for name, (pw, prefix) in self.views.items():
            cam = cams[name]
            self.send_lines(self.scene, f"{prefix}/robot", robot_batch(cam, links, pw.width, pw.height), self.z, pw)
            if cam.depth(base[None])[0] > 0 and f"{prefix}/robot_label" not in self._labels:
                uv = cam.project(base[None])[0] + [-40.0, 0.0]  # beside the base: not over what stands by it
                self._labels[f"{prefix}/robot_label"] = self.scene.add_label(
                    f"{prefix}/robot_label",
                    cell.model.name,
                    position=tuple(float(v) for v in pw.to_world(uv, self.z)),
                    anchor="top-right",
                    font_screen_scale=0.8,
                )
        self._draw_3d(links)
        return True

    def _draw_3d(self, links) -> None:
        from .world3d import _wxyz

        if len(self._meshes) != len(links):
            for h in self._meshes:
                h.remove()
            self._meshes = link_meshes(self.scene, "/world3d/robot", links, COLORS["robot"], 1.0)
            return
        for h, (_link, _brep, T) in zip(self._meshes, links):
            h.position = tuple(T[:3, 3])
            h.wxyz = _wxyz(T[:3, :3])


def _heard(cell) -> bool:
    """Whether the robot's joints are known (a real robot's driver may not have spoken yet)."""
    from app.robot.controller import ControllerError

    if cell.last_state() is not None:
        return True
    try:
        cell.state()
    except ControllerError:
        return False
    return True


class RobotGhost3D:
    """One operator's ghost robot in the 3D world (client-scoped ``/robot_ghost3d/<k>``): where a previewed
    motion ends, translucent; removed when there is none. ``offset`` is the 3D world's place in the scene."""

    def __init__(self, scene: Any, offset: np.ndarray):
        self.scene = scene
        self.offset = np.asarray(offset, float)
        self._handles: list = []
        self._key: Any = None

    def show(self, links) -> None:
        key = tuple(np.round(T, 6).tobytes() for _l, _b, T in links)
        if key == self._key:
            return
        self._key = key
        for h in self._handles:
            h.remove()
        self._handles = link_meshes(self.scene, "/robot_ghost3d", links, COLORS["robot_ghost_3d"], 0.6, self.offset)
