"""The database overlay shared by every client: the objects' wireframes in a few shared nodes, redrawn
only where they change.

The wireframes (line segments, coloured per vertex by status) are packed in groups of up to
GROUP_SIZE objects, one node each: ``/overlay/db/group_<k>`` (``app.ui.node_groups``); each object's
name is its own label ``/overlay/db_labels/<object id>``. Each object's projection is kept (the
segments the operator sees, used to pick an object by clicking: picking needs no node of its own).
``sync(camera, objects)`` compares each object's (version, status, name) with what was drawn: an
unchanged object sends nothing, a changed one sends its group's node again (one message, both arrays)
and updates its label in place, a new one joins a group, a removed one leaves it. Every object is
redrawn only when the camera calibration C changes. It runs on the interface's database thread, never
in the video frame's path, and never inside viser's ``atomic()``, which would hold every browser's
video while it lasts (on a loaded machine a thread can be descheduled for 100 ms and more inside it).
"""

from __future__ import annotations

import threading
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from app.overlay import PixelWorld, nearest_segment
from app.workflows.site import SiteObject
from core.camera import Camera

from .drawing import draw_objects
from .node_groups import NodeGroups

__all__ = ["DatabaseOverlay"]

GROUP_SIZE = 64  # objects per wireframe node: a full draw of 2,000 objects is 32 nodes, a change resends ~64 objects
MAX_OUTLINE_SHARE = 0.25  # an outline larger than this share of the image is not picked by a click inside it


@dataclass
class _Drawn:
    key: tuple  # (version, status, name)
    name: str
    seg_uv: np.ndarray  # (K, 2, 2) the visible segments drawn, pixels (for picking)
    outline: np.ndarray | None = None  # (H, 2) its drawn outline's convex hull, pixels: a click inside picks it
    depth: float = np.inf  # its centre's depth from the camera (the nearest of several outlines is picked)
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3), np.float32))  # its part of its group's node
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 3), np.uint8))
    label: Any = None  # viser handle of /overlay/db_labels/<id>, or None


class DatabaseOverlay:
    """The database overlay's nodes: grouped wireframes, one label per object.

    Parameters
    ----------
    scene : viser.SceneApi (or anything with ``add_line_segments``, ``add_label``)
    pixel_world : PixelWorld (the camera's image, where it lies)
    z : the overlay plane (world units, in front of the image)
    line_px : line thickness, screen pixels
    prefix : the start of the nodes' names ("/overlay": ``/overlay/db/group_<k>``)
    group_size : objects per wireframe node
    """

    def __init__(
        self,
        scene: Any,
        pixel_world: PixelWorld,
        z: float,
        line_px: float,
        prefix: str = "/overlay",
        group_size: int = GROUP_SIZE,
    ):
        self.scene = scene
        self.prefix = prefix  # the nodes' names start so (each camera's overlay has its own)
        self.pixel_world = pixel_world
        self.z = float(z)
        self.line_px = float(line_px)
        self._drawn: dict[Any, _Drawn] = {}
        self._groups = NodeGroups(group_size)
        self._group_nodes: dict[tuple, Any] = {}  # group → its viser handle
        self._offsets: dict[Any, tuple[int, int]] = {}  # object id → (first, end) of its segments in its group's node
        self._camera_key: Any = None
        self._pick: tuple[np.ndarray, np.ndarray] = (np.zeros((0, 2, 2)), np.zeros(0, dtype=object))
        self._lock = threading.Lock()  # one sync at a time
        self.redrawn: list[Any] = []  # ids drawn by the last sync (new, changed, or all on a new C)
        self.removed: list[Any] = []  # ids whose nodes the last sync removed

    def group_name(self, group: tuple) -> str:
        return f"{self.prefix}/db/group_{group[1]}"

    @staticmethod
    def label_name(obj_id: Any, prefix: str = "/overlay") -> str:
        return f"{prefix}/db_labels/{obj_id}"

    def node_of(self, obj_id: Any) -> str | None:
        """The name of the node that holds an object's wireframe, or None."""
        group = self._groups.group_of(obj_id)
        return None if group is None else self.group_name(group)

    # ------------------------------------------------------------------ sync
    def sync(self, camera: Camera, objects: Iterable[SiteObject]) -> int:
        """Bring the nodes up to date with ``objects`` seen through ``camera``; returns how many
        objects were redrawn (0 when nothing changed)."""
        with self._lock:
            try:
                return self._sync(camera, list(objects))
            except BaseException:
                # part of it sent (a message viser failed to queue): the next sync draws every object again
                self._camera_key = None
                raise

    def _sync(self, camera: Camera, objects: list[SiteObject]) -> int:
        ckey = (camera.C.tobytes(), int(camera.width), int(camera.height))
        full = ckey != self._camera_key
        self._camera_key = ckey
        changed: dict[tuple, list[tuple[SiteObject, tuple]]] = {}  # group → its objects to draw (and their keys)
        dirty: set[tuple] = set()
        for obj in objects:
            key = (int(obj.version), obj.status, obj.name)
            old = self._drawn.get(obj.id)
            if full or old is None or old.key != key:
                for group in self._groups.place(obj.id, 0):
                    changed.setdefault(group, [])
                changed[self._groups.group_of(obj.id)].append((obj, key))
        live = {o.id for o in objects}
        gone = [i for i in self._drawn if i not in live]
        for i in gone:
            d = self._drawn.pop(i)
            if d.label is not None:
                d.label.remove()
            dirty.add(self._groups.drop(i))
            self._offsets.pop(i, None)
        # Drawn and sent one group at a time: a new C moves every label, and 2,000 label messages queued at once
        # sit ahead of the video frame queued after them in every browser's stream (viser sends its buffer in
        # order, 128 messages a window): the watching browser's video stopped 0.14-0.27 s (load 5) while they
        # went out. A group's 64 labels and one node are about a window, queued while the next group is drawn.
        redrawn, wires = [], []
        for group in sorted(set(changed) | {g for g in dirty if g is not None}):
            todo = changed.get(group, [])
            if todo:  # the group's changed objects projected, dashed and placed in the pixel world at once
                objs = [obj for obj, _ in todo]
                seg, colors, bounds, labels, projections = draw_objects(
                    camera, objs, self.pixel_world.width, self.pixel_world.height
                )
                points = self.pixel_world.to_world(seg, self.z).astype(np.float32)
                colors = np.repeat(colors[:, None, :], 2, axis=1)
                anchors = [label[0] for label in labels if label is not None]
                where = iter(self.pixel_world.to_world(np.reshape(anchors, (-1, 2)), self.z).tolist())
                for (obj, key), label, wire, a, b in zip(todo, labels, projections, bounds[:-1], bounds[1:]):
                    self._store(obj, key, wire, points[a:b], colors[a:b])
                    # never inside viser's atomic(): it holds every browser's video
                    self._send_label(obj.id, None if label is None else (tuple(next(where)), label[1]))
                    redrawn.append(obj.id)
                    wires.append((obj, wire))
            self._send_group(group)
        # the outlines a click inside picks: after the drawing (they are not drawn)
        for (obj, _), (outline, depth) in zip(wires, _outlines(camera, wires)):
            d = self._drawn[obj.id]
            d.outline, d.depth = outline, depth
        self.redrawn = redrawn
        self.removed = gone
        if redrawn or gone:
            order = [o.id for o in objects if o.id in self._drawn]
            segs = [self._drawn[i].seg_uv for i in order]
            owners = [np.full(len(s), self._drawn[i].name, dtype=object) for i, s in zip(order, segs)]
            self._pick = (
                np.concatenate(segs) if segs else np.zeros((0, 2, 2)),
                np.concatenate(owners) if owners else np.zeros(0, dtype=object),
            )
        return len(redrawn)

    def _store(self, obj: SiteObject, key: tuple, wire, points: np.ndarray, colors: np.ndarray) -> None:
        """Keep one object's projection (for picking) and its part of its group's arrays: points (K, 2, 3)
        float32 in the pixel world, colours (K, 2, 3) uint8."""
        d = self._drawn.get(obj.id)
        if d is None:
            d = self._drawn[obj.id] = _Drawn(key, obj.name, np.zeros((0, 2, 2)))
        d.key, d.name = key, obj.name
        d.seg_uv = wire.seg_uv[wire.visible]
        d.points, d.colors = points, colors

    def _send_group(self, group: tuple) -> None:
        """Send one group's wireframes as one node (created, updated in place, or removed when empty)."""
        members = self._groups.members(group)
        parts = [self._drawn[i] for i in members]
        n = np.cumsum([0] + [len(d.points) for d in parts])
        for i, a, b in zip(members, n[:-1], n[1:]):
            self._offsets[i] = (int(a), int(b))
        handle = self._group_nodes.get(group)
        if n[-1] == 0:
            if handle is not None:
                handle.remove()
                del self._group_nodes[group]
            return
        # the node sent again whole: one message with both arrays (a browser never draws new points with old
        # colours) and no atomic() (it holds every browser's video while it lasts)
        self._group_nodes[group] = self.scene.add_line_segments(
            self.group_name(group),
            np.concatenate([d.points for d in parts]),
            np.concatenate([d.colors for d in parts]),
            thickness=self.line_px,
            thickness_units="screen",
        )

    def _send_label(self, obj_id: Any, label: tuple[tuple[float, float, float], str] | None) -> None:
        """Create, move or remove one object's label: (its position in the pixel world, its text) or None."""
        d = self._drawn[obj_id]
        if label is None:
            if d.label is not None:
                d.label.remove()
                d.label = None
            return
        position, text = label
        if d.label is None:
            d.label = self.scene.add_label(
                self.label_name(obj_id, self.prefix),
                text,
                position=position,
                anchor="bottom-center",
                font_screen_scale=0.9,
            )
            return
        if d.label.text != text:
            d.label.text = text
        d.label.position = position

    # ------------------------------------------------------------------ reading
    @property
    def drawn_ids(self) -> set:
        """Ids of the objects the overlay holds (drawn, or out of view)."""
        return set(self._drawn)

    @property
    def node_count(self) -> int:
        """How many scene nodes the overlay holds (its wireframe groups and labels)."""
        return len(self._group_nodes) + sum(d.label is not None for d in self._drawn.values())

    def handles(self, obj_id: Any) -> tuple[Any, Any]:
        """(its group's lines, its label) handles of one object (None where nothing is drawn)."""
        d = self._drawn.get(obj_id)
        if d is None:
            return None, None
        group = self._groups.group_of(obj_id)
        return self._group_nodes.get(group) if len(d.points) else None, d.label

    def points_sent(self, obj_id: Any) -> np.ndarray:
        """The segments (K, 2, 3) of one object in its group's node, as viser holds them."""
        lines, _ = self.handles(obj_id)
        if lines is None:
            return np.zeros((0, 2, 3), np.float32)
        a, b = self._offsets[obj_id]
        return np.asarray(lines.points).reshape(-1, 2, 3)[a:b]

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


def _outlines(camera: Camera, drawn: list[tuple[SiteObject, Any]]) -> list[tuple[np.ndarray | None, float]]:
    """Per (object, its drawn projection): (the convex hull (H, 2) float32 of its drawn wireframe, pixels,
    or None; its centre's depth) for picking by a click inside it. None for the table and for anything
    whose outline covers more than MAX_OUTLINE_SHARE of the image (a wall: they hold the other objects,
    and are picked by their wireframe), for an object not wholly in front of the camera, or drawn as
    fewer than 3 points. Whether they are in front is told for all their points at once."""
    import cv2

    points = []
    for obj, _ in drawn:
        X = obj.vertices_world()
        points.append(X if len(X) else obj.T_world_obj[:3, 3][None])  # a cylinder, a cone: its origin, on its axis
    if not points:
        return []
    counts = np.array([len(X) for X in points])
    ahead = np.minimum.reduceat(camera.depth(np.concatenate(points)), np.cumsum(counts) - counts) > 0
    out: list[tuple[np.ndarray | None, float]] = []
    for (obj, wire), in_front, X in zip(drawn, ahead, points):
        hull = None
        if obj.kind != "table" and wire is not None and len(wire.seg_uv) and in_front:
            hull = cv2.convexHull(wire.seg_uv.reshape(-1, 2).astype(np.float32)).reshape(-1, 2)
            if len(hull) < 3 or cv2.contourArea(hull) > MAX_OUTLINE_SHARE * camera.width * camera.height:
                hull = None  # fewer than 3 distinct points drawn, or a wall
        # each centre's depth alone: in one product with the others', its last bit could differ
        out.append((hull, float(camera.depth(X.mean(axis=0)[None])[0])) if hull is not None else (None, float("inf")))
    return out
