"""The database overlay shared by every client: one scene node per object, redrawn only when it changes.

Each object is drawn as ``/overlay/db/<object id>`` (its wireframe through C, line segments) and
``/overlay/db_labels/<object id>`` (its name), kept with its projection (the segments the operator
sees, used to pick an object by clicking). ``sync(camera, objects)`` compares each object's
(version, status, name) with what was drawn: an unchanged object sends nothing, a changed one
updates its nodes in place (``handle.points``/``colors``, ``text``/``position``), a new one gets
its nodes, a removed one loses them. Every object is redrawn only when the camera calibration C
changes. It runs on the interface's database thread, never in the video frame's path.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable
from contextlib import AbstractContextManager, nullcontext
from dataclasses import dataclass
from typing import Any

import numpy as np

from app.overlay import PixelWorld, nearest_segment
from app.workflows.site import SiteObject
from core.camera import Camera

from .drawing import draw_object

__all__ = ["DatabaseOverlay"]

SEND_CHUNK = 100  # objects sent per atomic group (a full redraw never holds viser's buffer for long)
MAX_OUTLINE_SHARE = 0.25  # an outline larger than this share of the image is not picked by a click inside it


@dataclass
class _Drawn:
    key: tuple  # (version, status, name)
    name: str
    seg_uv: np.ndarray  # (K, 2, 2) the visible segments drawn, pixels (for picking)
    outline: np.ndarray | None = None  # (H, 2) its drawn outline's convex hull, pixels: a click inside picks it
    depth: float = np.inf  # its centre's depth from the camera (the nearest of several outlines is picked)
    lines: Any = None  # viser handle of /overlay/db/<id>, or None when nothing is in view
    label: Any = None  # viser handle of /overlay/db_labels/<id>, or None


class DatabaseOverlay:
    """Per-object nodes of the database overlay.

    Parameters
    ----------
    scene : viser.SceneApi (or anything with ``add_line_segments``, ``add_label``)
    pixel_world : PixelWorld (the camera's image, where it lies)
    z : the overlay plane (world units, in front of the image)
    line_px : line thickness, screen pixels
    atomic : callable returning a context manager that groups messages (``server.atomic``)
    prefix : the start of the nodes' names ("/overlay": ``/overlay/db/<id>``)
    """

    def __init__(
        self,
        scene: Any,
        pixel_world: PixelWorld,
        z: float,
        line_px: float,
        atomic: Callable[[], AbstractContextManager] | None = None,
        prefix: str = "/overlay",
    ):
        self.scene = scene
        self.prefix = prefix  # the nodes' names start so (each camera's overlay has its own)
        self.pixel_world = pixel_world
        self.z = float(z)
        self.line_px = float(line_px)
        self.atomic = atomic or nullcontext
        self._drawn: dict[Any, _Drawn] = {}
        self._camera_key: Any = None
        self._pick: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 2, 2)), np.zeros(0, dtype=object))
        self._lock = threading.Lock()  # one sync at a time
        self.redrawn: list[Any] = []  # ids drawn by the last sync (new, changed, or all on a new C)
        self.removed: list[Any] = []  # ids whose nodes the last sync removed

    @staticmethod
    def node_name(obj_id: Any, prefix: str = "/overlay") -> str:
        return f"{prefix}/db/{obj_id}"

    @staticmethod
    def label_name(obj_id: Any, prefix: str = "/overlay") -> str:
        return f"{prefix}/db_labels/{obj_id}"

    # ------------------------------------------------------------------ sync
    def sync(self, camera: Camera, objects: Iterable[SiteObject]) -> int:
        """Bring the nodes up to date with ``objects`` seen through ``camera``; returns how many
        objects were redrawn (0 when nothing changed)."""
        with self._lock:
            objects = list(objects)
            ckey = (camera.C.tobytes(), int(camera.width), int(camera.height))
            full = ckey != self._camera_key
            self._camera_key = ckey
            pw = self.pixel_world
            todo = []
            for obj in objects:
                key = (int(obj.version), obj.status, obj.name)
                old = self._drawn.get(obj.id)
                if full or old is None or old.key != key:
                    batch, label, wire = draw_object(camera, obj, pw.width, pw.height)
                    todo.append((obj, key, batch, label, wire, _outline(camera, obj, wire)))
            live = {o.id for o in objects}
            gone = [i for i in self._drawn if i not in live]
            for k in range(0, max(len(todo), 1), SEND_CHUNK):
                with self.atomic():
                    for obj, key, batch, label, wire, outline in todo[k : k + SEND_CHUNK]:
                        self._send(obj, key, batch, label, wire)
                        self._drawn[obj.id].outline, self._drawn[obj.id].depth = outline
                    if k == 0:
                        for i in gone:
                            self._remove(self._drawn.pop(i))
            self.redrawn = [t[0].id for t in todo]
            self.removed = gone
            if todo or gone:
                order = [o.id for o in objects if o.id in self._drawn]
                segs = [self._drawn[i].seg_uv for i in order]
                owners = [np.full(len(s), self._drawn[i].name, dtype=object) for i, s in zip(order, segs)]
                self._pick = (
                    np.concatenate(segs) if segs else np.zeros((0, 2, 2)),
                    np.concatenate(owners) if owners else np.zeros(0, dtype=object),
                )
            return len(todo)

    def _send(self, obj: SiteObject, key: tuple, batch, label, wire) -> None:
        d = self._drawn.get(obj.id)
        if d is None:
            d = self._drawn[obj.id] = _Drawn(key, obj.name, np.zeros((0, 2, 2)))
        d.key, d.name = key, obj.name
        d.seg_uv = wire.seg_uv[wire.visible] if wire is not None else np.zeros((0, 2, 2))
        pw = self.pixel_world
        if len(batch):
            points, colors = batch.world(pw, self.z)
            points = points.astype(np.float32)
            if d.lines is None:
                d.lines = self.scene.add_line_segments(
                    self.node_name(obj.id, self.prefix),
                    points,
                    colors,
                    thickness=self.line_px,
                    thickness_units="screen",
                )
            else:
                d.lines.points = points
                d.lines.colors = colors
        elif d.lines is not None:
            d.lines.remove()
            d.lines = None
        if label is not None:
            uv, text = label
            position = tuple(float(v) for v in pw.to_world(uv, self.z))
            if d.label is None:
                d.label = self.scene.add_label(
                    self.label_name(obj.id, self.prefix),
                    text,
                    position=position,
                    anchor="bottom-center",
                    font_screen_scale=0.9,
                )
            else:
                if d.label.text != text:
                    d.label.text = text
                d.label.position = position
        elif d.label is not None:
            d.label.remove()
            d.label = None

    @staticmethod
    def _remove(d: _Drawn) -> None:
        for handle in (d.lines, d.label):
            if handle is not None:
                handle.remove()

    # ------------------------------------------------------------------ reading
    @property
    def drawn_ids(self) -> set:
        """Ids of the objects the overlay holds (drawn, or out of view)."""
        return set(self._drawn)

    def handles(self, obj_id: Any) -> tuple[Any, Any]:
        """(lines, label) handles of one object (None where nothing is drawn)."""
        d = self._drawn.get(obj_id)
        return (None, None) if d is None else (d.lines, d.label)

    def object_at(self, uv: np.ndarray, radius_px: float) -> str | None:
        """The name of the object whose drawn (visible) wireframe passes nearest to pixel ``uv`` (2,),
        within ``radius_px``; else the nearest object whose drawn outline holds ``uv`` (the table's
        excepted: a click on the table's top picks nothing); else the table (or another object with no
        outline) whose wireframe passes there; None if none does. Uses the projections already drawn (a
        new operator clicked on a box's face, and nothing was selected)."""
        import cv2

        segs, owners = self._pick
        i, dist = nearest_segment(segs, uv)
        near = str(owners[i]) if i >= 0 and dist < radius_px else None
        drawn = list(self._drawn.values())
        if near is not None and any(d.name == near and d.outline is not None for d in drawn):
            return near
        # inside an object's outline, before the table's wireframe (its back edge is drawn across the boxes
        # on it: a click on a box's top selected the table, in a new operator's run)
        p = (float(uv[0]), float(uv[1]))
        holding = [d for d in drawn if d.outline is not None and cv2.pointPolygonTest(d.outline, p, False) >= 0]
        return min(holding, key=lambda d: d.depth).name if holding else near


def _outline(camera: Camera, obj: SiteObject, wire) -> tuple[np.ndarray | None, float]:
    """(the convex hull (H, 2) float32 of an object's drawn wireframe, pixels, or None; its centre's depth)
    for picking by a click inside it. None for the table and for anything whose outline covers more
    than MAX_OUTLINE_SHARE of the image (a wall: they hold the other objects, and are picked by their
    wireframe), for an object not wholly in front of the camera, or drawn as fewer than 3 points."""
    import cv2

    X = obj.vertices_world()
    if len(X) == 0:  # a cylinder, a cone: no vertices, its origin on its axis
        X = obj.T_world_obj[:3, 3][None]
    if obj.kind == "table" or wire is None or len(wire.seg_uv) == 0 or not np.all(camera.depth(X) > 0):
        return None, float("inf")
    pts = wire.seg_uv.reshape(-1, 2).astype(np.float32)
    if len(np.unique(pts, axis=0)) < 3:
        return None, float("inf")
    hull = cv2.convexHull(pts).reshape(-1, 2)
    if cv2.contourArea(hull) > MAX_OUTLINE_SHARE * camera.width * camera.height:
        return None, float("inf")
    return hull, float(camera.depth(X.mean(axis=0)[None])[0])
