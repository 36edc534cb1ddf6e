"""The operator's clicks for one object's pose, in every view, and which model feature each one is.

Pure bookkeeping, no geometry beyond indexing: each clicked image segment (two pixels along an image
edge) with the view (camera name) it was clicked in, its noise σ (pixels) and the model edge it is
(assigned by hand, by automatic matching, or not yet); each clicked image point with its view, σ and
model vertex; the click under way (the first pixel of a segment, or a model vertex waiting for its
image point); and what "remove last" undoes. ``view_clicks`` gives them to the pose pipeline
(``refine.ViewClicks`` per camera, in the clicks' order), ``solve_view`` the camera P3L works in.

A model edge is assigned once per view: the same edge clicked in another view is another measurement
of it. ``note`` beside each click is the caller's (the interface keeps its snap record there).
``pipeline.Refused`` (a ValueError), nothing changed, for a click that cannot be taken: its message is for
the operator.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from ..camera import Camera
from .pipeline import Refused
from .refine import ViewClicks

__all__ = ["PoseClicks"]


class PoseClicks:
    """Clicks on one object (module docstring). ``edges`` (E, 2): the model's edges as vertex indices;
    ``vertices`` (V, 3): its vertices (object frame, metres). The parallel lists — ``segs`` (2, 2),
    ``edge_ids``, ``seg_views``, ``seg_sigmas``, ``seg_snaps`` (notes); ``points_uv`` (2,),
    ``vertex_ids``, ``point_views``, ``point_sigmas``, ``point_snaps`` — are in click order. ``name``: the
    object, as the messages say it."""

    def __init__(self, edges: np.ndarray, vertices: np.ndarray, name: str = "the object"):
        self.name = name  # the object, as messages say it
        self.edges = np.asarray(edges, dtype=int).reshape(-1, 2)
        self.vertices = np.asarray(vertices, dtype=float).reshape(-1, 3)
        self.segs: list[np.ndarray] = []
        self.edge_ids: list[int | None] = []
        self.seg_views: list[str] = []
        self.seg_sigmas: list[float] = []
        self.seg_snaps: list[Any] = []
        self.points_uv: list[np.ndarray] = []
        self.vertex_ids: list[int] = []
        self.point_views: list[str] = []
        self.point_sigmas: list[float] = []
        self.point_snaps: list[Any] = []
        self.pending: np.ndarray | None = None  # a segment's first pixel, waiting for its second
        self.pending_view: str | None = None
        self.mode = "edge"  # "point": the next clicks are a model vertex, then its image point
        self.pending_vertex: int | None = None
        self.auto = False  # automatic assignment: clicked segments wait for the matcher, not a model edge
        self._done: list[str] = []  # "segment", "assign", "point", "match": what remove_last undoes, last first
        self._match_undo: list[list] = []  # edge_ids before each assign_all

    # ------------------------------------------------------------------ adding
    @property
    def empty(self) -> bool:
        """No segment and no point clicked (a pending pixel aside)."""
        return not self.segs and not self.points_uv

    def undoable(self) -> bool:
        """Something for ``remove_last`` to undo besides a click under way."""
        return bool(self._done)

    def scripted(self, seg_uv: Any, auto: bool) -> np.ndarray:
        """A segment given whole (a script's two clicks [[u1, v1], [u2, v2]]) as a finite (2, 2) array, to be
        clicked; ``auto``: it waits for the matcher (automatic assignment on). Refused for anything else
        than two pixels, or while an edge is under way."""
        seg = np.asarray(seg_uv, dtype=float)
        if seg.shape != (2, 2) or not np.all(np.isfinite(seg)):
            raise Refused(f"a segment is two pixels [[u1, v1], [u2, v2]], got {seg_uv!r}")
        self.check_idle()
        self.auto |= auto
        return seg

    def check_idle(self) -> None:
        """Refused while an edge is under way (its second pixel, or its model edge, awaited)."""
        if self.pending is not None or self.waiting_for_edge():
            raise Refused("finish the edge under way first (or Remove last)")

    def click(
        self, uv: np.ndarray, view: str, camera: Camera, T_world_obj: np.ndarray, pick_px: float, replace: bool = False
    ) -> tuple[str, Any]:
        """A click at pixel uv (2,) in ``view``, as the click flow reads it: in vertex mode, the model vertex
        nearest the click (through ``camera`` at pose T_world_obj), then its image point; with a segment
        waiting for its model edge, the model edge nearest the click; else a segment's first pixel (``replace``:
        a new one replaces one waiting — only for a model without straight edges, whose one click waits for a
        search —), then its second. Returns what it was: ("vertex", k), ("assign", k) or
        ("pending", None), taken; ("point", vertex) or ("segment", (2, 2) pixels) for the caller to snap and
        add (``add_point``, ``add_segment``). Refused when the vertex or edge picked lies farther than
        ``pick_px``, or for a segment of a model with no straight edges."""
        if self.mode == "point" and self.pending_vertex is not None:
            return "point", self.pending_vertex
        if self.mode == "point":
            k, dist = self.nearest_vertex(camera, T_world_obj, uv)
            if dist > pick_px:
                raise Refused(
                    f"no vertex of {self.name} within {pick_px:.0f} px (nearest {dist:.0f} px); click a corner of its "
                    "wireframe"
                )
            self.pending_vertex = k
            return "vertex", k
        if self.waiting_for_edge():
            k, dist = self.nearest_edge(camera, T_world_obj, uv, self.seg_views[-1])
            if dist > pick_px:
                raise Refused(
                    f"no edge of {self.name} within {pick_px:.0f} px of the click (nearest {dist:.0f} px); click on "
                    "its wireframe in the overlay"
                )
            self.assign(k)
            return "assign", k
        if self.pending is None or (replace and not len(self.edges)):
            self.pending, self.pending_view = np.asarray(uv, dtype=float).reshape(2), view
            return "pending", None
        if not len(self.edges):
            raise Refused(
                f"{self.name} has no straight edges to click: Accept the found pose, pick another, or Remove last "
                "and double-click it again"
            )
        return "segment", np.array([self.pending, uv], dtype=float)

    def add_segment(self, seg: np.ndarray, view: str, sigma_px: float, note: Any = None) -> None:
        """A finished segment (2, 2) clicked in ``view``, waiting for its model edge."""
        self.segs.append(np.asarray(seg, dtype=float).reshape(2, 2))
        self.edge_ids.append(None)
        self.seg_views.append(view)
        self.seg_sigmas.append(float(sigma_px))
        self.seg_snaps.append(note)
        self.pending, self.pending_view = None, None
        self._done.append("segment")

    def waiting_for_edge(self) -> bool:
        """The last clicked segment waits for its model edge (hand assignment)."""
        return not self.auto and bool(self.edge_ids) and self.edge_ids[-1] is None

    def assign(self, k: int) -> None:
        """Model edge k is the last clicked segment (ValueError: no such edge, none waiting, or k is
        another segment's in the same view)."""
        if not self.edge_ids or self.edge_ids[-1] is not None:
            raise Refused("no clicked segment is waiting for its model edge: click two points on an image edge first")
        if not 0 <= k < len(self.edges):
            raise Refused(f"{self.name} has edges 0..{len(self.edges) - 1}, not {k}")
        view = self.seg_views[-1]
        taken = [i for i, (e, v) in enumerate(zip(self.edge_ids, self.seg_views)) if e == k and v == view]
        if taken:
            raise Refused(f"model edge {k} is already assigned to segment {taken[0] + 1}; click another model edge")
        self.edge_ids[-1] = int(k)
        self._done.append("assign")

    def set_auto(self, on: bool) -> None:
        """Automatic assignment on (segments wait for the matcher) or off (Refused while segments
        other than the last are unassigned)."""
        if not on and any(e is None for e in self.edge_ids[:-1]):
            raise Refused(
                "some clicked edges are not assigned: Auto match them, or Remove last, before assigning by hand"
            )
        self.auto = bool(on)

    def assign_all(self, edge_ids: list[int]) -> None:
        """Every segment's model edge at once (an automatic match); ``remove_last`` restores the assignment before."""
        self._match_undo.append(list(self.edge_ids))
        self.edge_ids = [int(e) for e in edge_ids]
        self._done.append("match")

    def check_vertex(self, vertex: int) -> None:
        """ValueError unless model vertex ``vertex`` exists and has no clicked point yet."""
        if not 0 <= vertex < len(self.vertices):
            raise Refused(f"{self.name} has vertices 0..{len(self.vertices) - 1}, not {vertex}")
        if vertex in self.vertex_ids:
            raise Refused(f"vertex {vertex} already has a clicked point; click another vertex")

    def check_view(self, view: str) -> None:
        """ValueError when a click in ``view`` would split a click under way across two views."""
        if self.pending is not None and self.pending_view not in (None, view):
            raise Refused(
                f"the edge under way was started in camera {self.pending_view}: click its second point there "
                "(or Remove last)"
            )
        if self.waiting_for_edge() and self.seg_views[-1] != view:
            raise Refused(
                f"edge {len(self.segs)} was clicked in camera {self.seg_views[-1]}: say which model edge it is "
                "there (or Remove last)"
            )

    def add_point(self, uv: np.ndarray, vertex: int, view: str, sigma_px: float, note: Any = None) -> None:
        """An image point of model vertex ``vertex`` clicked in ``view`` (ValueError: ``check_vertex``)."""
        self.check_vertex(vertex)
        self.points_uv.append(np.asarray(uv, dtype=float).reshape(2))
        self.vertex_ids.append(int(vertex))
        self.point_views.append(view)
        self.point_sigmas.append(float(sigma_px))
        self.point_snaps.append(note)
        self.mode, self.pending_vertex = "edge", None
        self._done.append("point")

    # ------------------------------------------------------------------ undoing
    def remove_last(self) -> str:
        """Undo the last click: a vertex mode, a pending pixel, an assignment, a match, a segment or a point.
        Returns what was undone ("point mode", "pending", "assign", "match", "segment", "point", "")."""
        last = ""
        if self.mode == "point":
            self.mode, self.pending_vertex, last = "edge", None, "point mode"
        elif self.pending is not None:
            self.pending, self.pending_view, last = None, None, "pending"
        elif self._done:
            last = self._done.pop()
            if last == "assign":
                self.edge_ids[max(i for i, e in enumerate(self.edge_ids) if e is not None)] = None
            elif last == "match":
                self.edge_ids = self._match_undo.pop()
            elif last == "segment":
                for lst in (self.segs, self.edge_ids, self.seg_views, self.seg_sigmas, self.seg_snaps):
                    lst.pop()
            else:
                for lst in (self.points_uv, self.vertex_ids, self.point_views, self.point_sigmas, self.point_snaps):
                    lst.pop()
        return last

    def rows(self) -> list[tuple[str, int]]:
        """Every click that can be deleted: ("segment", j) for each segment, then ("point", j)."""
        return [("segment", j) for j in range(len(self.segs))] + [("point", j) for j in range(len(self.points_uv))]

    def remove(self, index: int) -> str:
        """Delete click ``index`` of ``rows()``; returns what it was ("Edge 2", "Point 1"). ValueError when
        there is no such click or a click is under way. What ``remove_last`` undoes is rebuilt in click
        order (a match's undo is dropped)."""
        rows = self.rows()
        if not 0 <= index < len(rows):
            raise Refused(f"there is no click {index + 1}: {len(rows)} were made")
        if self.pending is not None or self.mode == "point":
            raise Refused("finish the click under way first (or Remove last)")
        kind, j = rows[index]
        if kind == "segment":
            for lst in (self.segs, self.edge_ids, self.seg_views, self.seg_sigmas, self.seg_snaps):
                del lst[j]
        else:
            for lst in (self.points_uv, self.vertex_ids, self.point_views, self.point_sigmas, self.point_snaps):
                del lst[j]
        self._done = [d for e in self.edge_ids for d in (("segment", "assign") if e is not None else ("segment",))]
        self._done += ["point"] * len(self.points_uv)
        self._match_undo = []
        return f"{'Edge' if kind == 'segment' else 'Point'} {j + 1}"

    def last_click(self) -> tuple[str, int] | None:
        """The last segment or point clicked (("segment", j) or ("point", j)), None before any."""
        for last in reversed(self._done):
            if last == "segment":
                return "segment", len(self.segs) - 1
            if last == "point":
                return "point", len(self.points_uv) - 1
        return None

    def note(self, kind: str, j: int) -> Any:
        """The note kept beside click j of ``kind`` ("segment" or "point")."""
        return (self.seg_snaps if kind == "segment" else self.point_snaps)[j]

    def drop_pending(self, uv: np.ndarray) -> bool:
        """Drop the pending pixel if it is ``uv`` (a click a search used and found nothing at); True if dropped."""
        if self.pending is None or not np.allclose(self.pending, uv):
            return False
        self.pending, self.pending_view = None, None
        return True

    def replace(self, kind: str, j: int, uv: np.ndarray, sigma_px: float) -> None:
        """Click j of ``kind`` moved to ``uv`` with noise ``sigma_px`` (a snap refused: the raw click)."""
        if kind == "segment":
            self.segs[j], self.seg_sigmas[j] = np.asarray(uv, float).reshape(2, 2), float(sigma_px)
        else:
            self.points_uv[j], self.point_sigmas[j] = np.asarray(uv, float).reshape(2), float(sigma_px)

    # ------------------------------------------------------------------ picking
    def nearest_edge(self, camera: Camera, T_world_obj: np.ndarray, uv: np.ndarray, view: str) -> tuple[int, float]:
        """The model edge not yet assigned in ``view`` whose projection through ``camera`` at pose
        T_world_obj (both ends in front) lies nearest pixel uv, and its distance (pixels); (−1, inf) if none."""
        T = np.asarray(T_world_obj, dtype=float)
        X = (self.vertices @ T[:3, :3].T + T[:3, 3])[self.edges]  # (E, 2, 3)
        front = np.all(camera.depth(X.reshape(-1, 3)).reshape(-1, 2) > 0, axis=1)
        used = {e for e, v in zip(self.edge_ids, self.seg_views) if v == view}
        idx = [k for k in range(len(self.edges)) if front[k] and k not in used]
        if not idx:
            return -1, float("inf")
        a, b = camera.project(X[idx].reshape(-1, 3)).reshape(-1, 2, 2).transpose(1, 0, 2)
        d = b - a
        t = np.clip(np.einsum("ij,ij->i", uv - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-12), 0.0, 1.0)
        dist = np.linalg.norm(a + t[:, None] * d - uv, axis=1)
        i = int(np.argmin(dist))
        return idx[i], float(dist[i])

    def nearest_vertex(self, camera: Camera, T_world_obj: np.ndarray, uv: np.ndarray) -> tuple[int, float]:
        """The model vertex in front of ``camera`` at pose T_world_obj whose projection lies nearest pixel
        uv, and its distance (pixels)."""
        T = np.asarray(T_world_obj, dtype=float)
        V = self.vertices @ T[:3, :3].T + T[:3, 3]
        d = np.linalg.norm(camera.project(V) - uv, axis=1)
        d[camera.depth(V) <= 0] = np.inf
        k = int(np.argmin(d))
        return k, float(d[k])

    # ------------------------------------------------------------------ reading
    def assigned(self) -> list[int]:
        """Indices of the segments with a model edge, in click order."""
        return [j for j, e in enumerate(self.edge_ids) if e is not None]

    def arrays(self, views: set[str] | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(segs_uv (S, 2, 2), edges_obj (S, 2, 3), points_uv (P, 2), points_obj (P, 3)) of the assigned
        segments and the points, in click order (only those clicked in ``views``, when given)."""
        si = [j for j in self.assigned() if views is None or self.seg_views[j] in views]
        pi = [j for j in range(len(self.points_uv)) if views is None or self.point_views[j] in views]
        segs = np.array([self.segs[j] for j in si]).reshape(-1, 2, 2)
        edges = self.vertices[self.edges[[self.edge_ids[j] for j in si]]].reshape(-1, 2, 3)
        pts = np.array([self.points_uv[j] for j in pi]).reshape(-1, 2)
        return segs, edges, pts, self.vertices[[self.vertex_ids[j] for j in pi]].reshape(-1, 3)

    def refine_args(self) -> dict[str, np.ndarray | None]:
        """``core.pose.refine``'s click arguments (segs_uv, edges_obj, points_uv, points_obj) of the
        assigned segments and the points, None for none."""
        segs, edges, pts, pobj = self.arrays()
        return {
            "segs_uv": segs if len(segs) else None,
            "edges_obj": edges if len(segs) else None,
            "points_uv": pts if len(pts) else None,
            "points_obj": pobj if len(pts) else None,
        }

    def click_views(self) -> tuple[list[str], list[str]]:
        """The view of each assigned segment and of each point, in the pipeline's order."""
        return [self.seg_views[j] for j in self.assigned()], list(self.point_views)

    def fitted_views(self) -> list[str]:
        """The views with an assigned segment or a point, in ``view_clicks``' order (one ViewClicks each)."""
        seg_views, pt_views = self.click_views()
        return list(dict.fromkeys(seg_views + pt_views))

    def sigmas(self) -> np.ndarray:
        """σ (pixels) of each assigned segment, then of each point."""
        return np.array([self.seg_sigmas[j] for j in self.assigned()] + self.point_sigmas, dtype=float)

    def all_views(self) -> list[str]:
        """Every view clicked in, in order of first use."""
        return list(dict.fromkeys(self.seg_views + self.point_views))

    def view_clicks(self, cameras: Mapping[str, Camera]) -> list[ViewClicks]:
        """The assigned segments and the points per view, for ``refine_views``: one ViewClicks per view
        clicked in (``cameras`` maps each to its Camera), each click placed at its click order, so the
        result's per-click arrays follow ``click_views()``."""
        seg_views, pt_views = self.click_views()
        si, pi = self.assigned(), range(len(self.points_uv))
        out = []
        for view in self.fitted_views():
            s = [k for k, v in enumerate(seg_views) if v == view]
            p = [k for k, v in enumerate(pt_views) if v == view]
            segs = np.array([self.segs[si[k]] for k in s]).reshape(-1, 2, 2)
            edges = self.vertices[self.edges[[self.edge_ids[si[k]] for k in s]]].reshape(-1, 2, 3)
            sig = [self.seg_sigmas[si[k]] for k in s] + [self.point_sigmas[pi[k]] for k in p]
            out.append(
                ViewClicks(
                    cameras[view],
                    segs if s else None,
                    edges if s else None,
                    np.array([self.points_uv[k] for k in p]) if p else None,
                    self.vertices[[self.vertex_ids[k] for k in p]] if p else None,
                    sigma_px=np.array(sig),
                    seg_index=s,
                    point_index=p,
                )
            )
        return out

    def views_clicks(self, camera_of, own: str) -> tuple[list[str], list[ViewClicks]]:
        """The views to fit (``own`` first, then every view clicked in) and their ``view_clicks``;
        ``camera_of(view)`` gives each view's Camera."""
        views = list(dict.fromkeys([own, *self.all_views()]))
        return views, self.view_clicks({v: camera_of(v) for v in views})

    def solve_clicks(self, own: str) -> tuple[str, tuple[np.ndarray, ...]]:
        """The view P3L works in (``solve_view``) and its clicks, as ``arrays`` (points None when none);
        Refused with fewer than 3 assigned segments there."""
        view = self.solve_view(own)
        segs, edges, pts, pobj = self.arrays({view})
        if len(segs) < 3:
            where = f" in camera {view}" if len(set(self.click_views()[0])) > 1 else ""
            raise Refused(
                f"{len(segs)} edges assigned{where}; the three-line solver needs 3{' in one camera' if where else ''} "
                "(click more edges)"
            )
        return view, (segs, edges, pts if len(pts) else None, pobj if len(pts) else None)

    def solve_view(self, own: str) -> str:
        """The view P3L works in: the one with the most assigned segments (``own`` first on a tie)."""
        seg_views = self.click_views()[0]
        return max(dict.fromkeys([own, *seg_views]), key=seg_views.count)

    def most_in_one_view(self) -> int:
        """The most assigned segments clicked in one view."""
        views = self.click_views()[0]
        return max((views.count(v) for v in set(views)), default=0)

    def one_corner(self) -> list[int] | None:
        """The segments (indices) when exactly three are assigned, in one camera, and their model edges share
        a vertex (P3L cannot fix the distance from them, ``core.pose.p3l``), else None. Seen from two cameras
        the corner is triangulated: its distance is fixed."""
        assigned = self.assigned()
        if len(assigned) != 3 or len({self.seg_views[j] for j in assigned}) != 1:
            return None
        ends = [set(self.edges[self.edge_ids[j]].tolist()) for j in assigned]
        return assigned if ends[0] & ends[1] & ends[2] else None
