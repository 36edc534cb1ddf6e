"""Update a known object's pose from clicked image edges (source paper §IV).

The operator selects the object, then for each image edge: two clicks along it in the video, then
a click on the model edge it is (in the overlay: the nearest projected edge of the object at its
current estimate — the database pose, or the chosen candidate once solved). With three edges,
``solve()`` runs the paper's three-line solver (``core.pose.p3l``) and shows every candidate as a
ghost, the best pre-selected; ``choose_candidate(i)`` picks another. More edges and clicked points
(``start_point()``: a model vertex, then its image) can be added at any time; ``refine()`` runs
the iterated small-motion least squares (``core.pose.refine``) from the chosen candidate — or,
without a solve, from the database pose (the paper's small motion) — and shows the RMS, each
click's residual and the pose's standard deviations. ``accept()`` writes the pose and its
covariance in one transaction (refining first if needed); a version conflict writes nothing.
"""

from __future__ import annotations

import itertools
from typing import Any

import numpy as np

from core.pose import p3l, refine
from core.transforms import pose_error

from .base import Ghost, Marks, Workflow, WorkflowError, as_pixel

__all__ = ["UpdatePose"]

PICK_RADIUS_PX = 25.0
MIN_SEGMENT_PX = 3.0


class UpdatePose(Workflow):
    name = "update_pose"
    title = "Update pose"
    options = ("object_name",)
    actions = ("click", "assign_edge", "add_segment", "add_point", "start_point", "remove_last", "solve",
               "choose_candidate", "refine", "accept", "cancel")

    def __init__(self, site, client: str = "operator", object_name: str | None = None, loss: str = "l2"):
        super().__init__(site, client)
        if object_name is None:
            raise WorkflowError("Update pose: select the object first")
        try:
            self.obj = site.object(object_name)
        except KeyError as exc:
            raise WorkflowError(str(exc.args[0])) from None
        if not len(self.obj.model.edges):
            raise WorkflowError(f"{object_name} has no straight edges (a cylinder or cone): its pose cannot come from edges; "
                                "model it again instead")
        self.object_name = object_name
        self.loss = loss
        self.segs: list[np.ndarray] = []
        self.edge_ids: list[int | None] = []
        self.points_uv: list[np.ndarray] = []
        self.vertex_ids: list[int] = []
        self.pending: np.ndarray | None = None
        self.mode = "edge"
        self.pending_vertex: int | None = None
        self.candidates: list[np.ndarray] = []
        self.chosen: int | None = None
        self.refined = None
        self._done: list[str] = []  # "segment", "assign", "point": what remove_last undoes, last first
        self.state = "click_edge"

    # ------------------------------------------------------------------ estimate in use
    @property
    def T_current(self) -> np.ndarray:
        """The pose the overlay assigns against: refined, else the chosen candidate, else the database's."""
        if self.refined is not None:
            return self.refined.T_world_obj
        if self.chosen is not None:
            return self.candidates[self.chosen]
        return self.obj.T_world_obj

    def _invalidate(self) -> None:
        self.refined = None

    # ------------------------------------------------------------------ actions
    def click(self, uv) -> None:
        """A click on the video; what it means depends on the step (see ``next_step``)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.mode == "point":
                if self.pending_vertex is None:
                    k, dist = self._nearest_vertex(p)
                    if dist > PICK_RADIUS_PX:
                        raise WorkflowError(f"no vertex of {self.object_name} within {PICK_RADIUS_PX:.0f} px "
                                            f"(nearest {dist:.0f} px); click a corner of its wireframe")
                    self.pending_vertex = k
                    self.state = "click_point_image"
                else:
                    self._add_point(p, self.pending_vertex)
                return
            if self.edge_ids and self.edge_ids[-1] is None:
                k, dist = self._nearest_edge(p)
                if dist > PICK_RADIUS_PX:
                    raise WorkflowError(f"no edge of {self.object_name} within {PICK_RADIUS_PX:.0f} px of the click "
                                        f"(nearest {dist:.0f} px); click on its wireframe in the overlay")
                self._assign(k)
                return
            if self.pending is None:
                self.pending = p
                self.state = "click_edge_end"
                return
            seg = np.array([self.pending, p])
            if np.linalg.norm(seg[1] - seg[0]) < MIN_SEGMENT_PX:
                raise WorkflowError(f"the two clicks are {np.linalg.norm(seg[1] - seg[0]):.1f} px apart: click two points "
                                    f"at least {MIN_SEGMENT_PX:.0f} px apart along the edge (second click again)")
            self.pending = None
            self.segs.append(seg)
            self.edge_ids.append(None)
            self._done.append("segment")
            self._invalidate()
            self.state = "assign_edge"

    def assign_edge(self, edge: int) -> None:
        """Say which model edge (index into the model's edges) the last clicked segment is."""
        with self.lock:
            self._check_open()
            if not self.edge_ids or self.edge_ids[-1] is not None:
                raise WorkflowError("no clicked segment is waiting for its model edge: click two points on an image edge first")
            self._assign(int(edge))

    def add_segment(self, seg_uv, edge: int) -> None:
        """A clicked segment (2, 2) and its model edge at once (for scripts)."""
        seg = np.asarray(seg_uv, dtype=float)
        if seg.shape != (2, 2) or not np.all(np.isfinite(seg)):
            raise WorkflowError(f"a segment is two pixels [[u1, v1], [u2, v2]], got {seg_uv!r}")
        with self.lock:
            self._check_open()
            if self.pending is not None or (self.edge_ids and self.edge_ids[-1] is None):
                raise WorkflowError("finish the edge under way first (or Remove last)")
            self.click(seg[0])
            self.click(seg[1])
            self.assign_edge(edge)

    def start_point(self) -> None:
        """Next clicks: a model vertex in the overlay, then where it is in the video."""
        with self.lock:
            self._check_open()
            if self.pending is not None or (self.edge_ids and self.edge_ids[-1] is None):
                raise WorkflowError("finish the edge under way first (or Remove last)")
            self.mode = "point"
            self.pending_vertex = None
            self.state = "click_point_model"

    def add_point(self, uv, vertex: int) -> None:
        """A clicked image point and its model vertex at once (for scripts)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if not 0 <= int(vertex) < len(self.obj.model.vertices):
                raise WorkflowError(f"{self.object_name} has vertices 0..{len(self.obj.model.vertices) - 1}, not {vertex}")
            self._add_point(p, int(vertex))

    def remove_last(self) -> None:
        """Undo the last click (a pending end, an assignment, a segment or a point)."""
        with self.lock:
            self._check_open()
            if self.mode == "point":
                self.mode, self.pending_vertex = "edge", None
            elif self.pending is not None:
                self.pending = None
            elif self._done:
                last = self._done.pop()
                if last == "assign":
                    self.edge_ids[self._last_assigned()] = None
                elif last == "segment":
                    self.segs.pop()
                    self.edge_ids.pop()
                else:
                    self.points_uv.pop()
                    self.vertex_ids.pop()
            self._invalidate()
            self.state = "assign_edge" if (self.edge_ids and self.edge_ids[-1] is None) else "click_edge"

    def _last_assigned(self) -> int:
        return max(i for i, e in enumerate(self.edge_ids) if e is not None)

    def solve(self) -> list[np.ndarray]:
        """The paper's three-line solver on the first workable triple of assigned edges."""
        with self.lock:
            self._check_open()
            segs, edges = self._assigned()
            if len(segs) < 3:
                raise WorkflowError(f"{len(segs)} edges assigned; the three-line solver needs 3 (click more edges)")
            pts_uv, pts_obj = self._points()
            errors = []
            for triple in itertools.combinations(range(len(segs)), 3):
                idx = list(triple)
                try:
                    cands = p3l(self.site.camera, segs[idx], edges[idx], pts_uv if len(pts_uv) else None,
                                pts_obj if len(pts_obj) else None)
                except (ValueError, ArithmeticError, np.linalg.LinAlgError) as exc:
                    # a degenerate triple (or a numerical failure in it): try the next triple
                    errors.append(f"edges {[i + 1 for i in idx]}: {exc}")
                    continue
                if cands:
                    self.candidates = [np.asarray(T, float) for T in cands]
                    self.chosen = 0
                    self._invalidate()
                    self.state = "review"
                    self.message = (f"{len(cands)} candidate pose{'s' if len(cands) > 1 else ''} from edges "
                                    f"{[i + 1 for i in idx]}; the best (fewest pixels off) is selected")
                    return self.candidates
                errors.append(f"edges {[i + 1 for i in idx]}: no pose puts the object in front of the camera")
            raise WorkflowError("no pose fits these edges: " + "; ".join(errors[:3]) +
                                ". Check the edge assignments (Remove last) or click other edges")

    def choose_candidate(self, index: int) -> None:
        """Use candidate ``index`` (0 = best) as the estimate."""
        with self.lock:
            self._check_open()
            if not self.candidates:
                raise WorkflowError("no candidates: Solve first")
            if not 0 <= int(index) < len(self.candidates):
                raise WorkflowError(f"there are candidates 1..{len(self.candidates)}, not {int(index) + 1}")
            self.chosen = int(index)
            self._invalidate()

    def refine(self):
        """Least squares on every click from the chosen candidate (or the database pose)."""
        with self.lock:
            self._check_open()
            segs, edges = self._assigned()
            pts_uv, pts_obj = self._points()
            start = self.candidates[self.chosen] if self.chosen is not None else self.obj.T_world_obj
            try:
                result = refine(self.site.camera, start,
                                segs_uv=segs if len(segs) else None, edges_obj=edges if len(edges) else None,
                                points_uv=pts_uv if len(pts_uv) else None, points_obj=pts_obj if len(pts_obj) else None,
                                loss=self.loss)
            except ValueError as exc:
                raise WorkflowError(f"refinement failed: {exc}. Click more edges or points") from None
            if not np.all(np.isfinite(result.T_world_obj)):
                raise WorkflowError("refinement diverged: choose another candidate or click more edges")
            self.refined = result
            self.state = "review"
            deg, m = pose_error(result.T_world_obj, self.obj.T_world_obj)
            self.message = (f"RMS {result.rms_px:.2f} px over {len(result.kinds)} clicks; moved {deg:.2f}° and "
                            f"{100 * m:.1f} cm from the database pose")
            return result

    def accept(self):
        """Write the refined pose and covariance (one transaction); ConflictError → nothing written."""
        from app.db import ConflictError

        with self.lock:
            self._check_open()
            if self.refined is None:
                self.refine()
            r = self.refined
            segs, edges = self._assigned()
            pts_uv, _ = self._points()
            clicks = {"segs_uv": segs, "edge_ids": [e for e in self.edge_ids if e is not None],
                      "points_uv": pts_uv, "vertex_ids": list(self.vertex_ids),
                      "candidates": len(self.candidates), "chosen": self.chosen}
            residuals = {"rms_px": r.rms_px, "click_residuals_px": r.click_residuals_px, "kinds": list(r.kinds)}
            method = "p3l+refine" if self.chosen is not None else "refine"
            try:
                rec = self.site.write(lambda db: db.update_pose(
                    self.obj.id, r.T_world_obj, r.cov, expected_version=self.obj.version, method=method,
                    client=self.client, clicks=clicks, residuals=residuals))
            except ConflictError as exc:
                raise WorkflowError(f"{exc}. Cancel, and update the pose again from the new one") from None
            except ValueError as exc:
                raise WorkflowError(f"the database refused the pose: {exc}") from None
            self.accepted = True
            self.state = "accepted"
            self.message = f"{self.object_name} updated (version {rec.version}): RMS {r.rms_px:.2f} px"
            return rec

    # ------------------------------------------------------------------ helpers
    def _assign(self, k: int) -> None:
        E = len(self.obj.model.edges)
        if not 0 <= k < E:
            raise WorkflowError(f"{self.object_name} has edges 0..{E - 1}, not {k}")
        if k in self.edge_ids:
            raise WorkflowError(f"model edge {k} is already assigned to segment {self.edge_ids.index(k) + 1}; "
                                "click another model edge")
        self.edge_ids[-1] = k
        self._done.append("assign")
        self._invalidate()
        self.state = "click_edge"

    def _add_point(self, p: np.ndarray, vertex: int) -> None:
        if vertex in self.vertex_ids:
            raise WorkflowError(f"vertex {vertex} already has a clicked point; click another vertex")
        self.points_uv.append(p)
        self.vertex_ids.append(vertex)
        self.mode, self.pending_vertex = "edge", None
        self._done.append("point")
        self._invalidate()
        self.state = "click_edge"

    def _assigned(self) -> tuple[np.ndarray, np.ndarray]:
        pairs = [(s, e) for s, e in zip(self.segs, self.edge_ids) if e is not None]
        if not pairs:
            return np.zeros((0, 2, 2)), np.zeros((0, 2, 3))
        model = self.obj.model
        return np.array([s for s, _ in pairs]), np.array([model.vertices[model.edges[e]] for _, e in pairs])

    def _points(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.points_uv:
            return np.zeros((0, 2)), np.zeros((0, 3))
        return np.array(self.points_uv), self.obj.model.vertices[self.vertex_ids]

    def _projected_edges(self) -> np.ndarray:
        cam = self.site.camera
        S = self.obj.model.edge_segments(self.T_current)
        uv = cam.project(S.reshape(-1, 3)).reshape(-1, 2, 2)
        behind = np.any(cam.depth(S.reshape(-1, 3)).reshape(-1, 2) <= 0, axis=1)
        uv[behind] = np.inf
        return uv

    def _nearest_edge(self, p: np.ndarray) -> tuple[int, float]:
        from app.overlay import nearest_segment

        uv = self._projected_edges()
        ok = np.all(np.isfinite(uv.reshape(len(uv), -1)), axis=1)
        free = np.array([k not in self.edge_ids for k in range(len(uv))])
        idx = np.nonzero(ok & free)[0]
        if not len(idx):
            return -1, float("inf")
        i, d = nearest_segment(uv[idx], p)
        return int(idx[i]), d

    def _nearest_vertex(self, p: np.ndarray) -> tuple[int, float]:
        cam = self.site.camera
        T = self.T_current
        V = self.obj.model.vertices @ T[:3, :3].T + T[:3, 3]
        d = np.linalg.norm(cam.project(V) - p, axis=1)
        d[cam.depth(V) <= 0] = np.inf
        k = int(np.argmin(d))
        return k, float(d[k])

    # ------------------------------------------------------------------ display
    @property
    def next_step(self) -> str:
        if self.accepted:
            return f"Done: {self.object_name}'s pose is updated."
        if self.cancelled:
            return "Cancelled: nothing was written."
        n = sum(e is not None for e in self.edge_ids)
        where = "on the white ghost" if self.chosen is not None else "on its wireframe"
        if self.mode == "point":
            if self.pending_vertex is None:
                return f"Click a corner of {self.object_name} {where} (the model vertex)."
            return f"Now click where vertex {self.pending_vertex} really is in the video."
        if self.pending is not None:
            return f"Click a second point on the same image edge (edge {len(self.segs) + 1})."
        if self.edge_ids and self.edge_ids[-1] is None:
            return f"Which model edge is it? Click that edge of {self.object_name} {where}."
        if n < 3:
            return f"Click two points along an edge of {self.object_name} in the video (edge {n + 1} of 3)."
        if not self.candidates and self.refined is None:
            return "Solve (P3L) for a large motion, or Refine from the database pose for a small one; or click more edges."
        if self.refined is None:
            return f"Candidate {self.chosen + 1} of {len(self.candidates)} shown in white: pick another if it is wrong, add edges, then Refine."
        return f"RMS {self.refined.rms_px:.2f} px: Accept, or add clicks and Refine again."

    def candidate_labels(self) -> list[str]:
        """One label per candidate for a chooser: "#1 (best)", "#2", ..."""
        return [f"#{i + 1}" + (" (best)" if i == 0 else "") for i in range(len(self.candidates))]

    def marks(self) -> Marks:
        with self.lock:
            m = Marks(selected=self.object_name)
            if self.segs:
                m.segments = np.array(self.segs)
                m.labels = [((s[0] + s[1]) / 2, f"{i + 1}" + (f"→e{e}" if e is not None else "?"))
                            for i, (s, e) in enumerate(zip(self.segs, self.edge_ids))]
            if self.pending is not None:
                m.pending = self.pending.reshape(1, 2)
            if self.points_uv:
                m.points = np.array(self.points_uv)
                m.labels += [(p, f"v{k}") for p, k in zip(self.points_uv, self.vertex_ids)]
            m.highlight = [(self.object_name, e) for e in self.edge_ids if e is not None]
            model = self.obj.model
            if self.refined is not None:
                m.ghosts = [Ghost(model, self.refined.T_world_obj, "refined", chosen=True)]
            else:
                m.ghosts = [Ghost(model, T, f"#{i + 1}", chosen=(i == self.chosen)) for i, T in enumerate(self.candidates)]
            if self.mode == "point" and self.pending_vertex is not None:
                T = self.T_current
                X = T[:3, :3] @ model.vertices[self.pending_vertex] + T[:3, 3]
                m.pending = self.site.camera.project(X.reshape(1, 3))
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {"object": self.object_name, "edges": sum(e is not None for e in self.edge_ids),
                                   "points": len(self.points_uv)}
            if self.candidates:
                out["candidates"] = len(self.candidates)
                out["chosen"] = (self.chosen or 0) + 1
            r = self.refined
            if r is not None:
                out["rms_px"] = r.rms_px
                out["std_t_mm"] = [float(v) for v in 1000 * r.std_t_m]
                out["std_r_deg"] = [float(v) for v in r.std_r_deg]
                deg, m = pose_error(r.T_world_obj, self.obj.T_world_obj)
                out["change"] = {"deg": float(deg), "cm": float(100 * m)}
                names = [f"edge {i + 1}" for i in range(r.kinds.count("segment"))] + \
                        [f"point {i + 1}" for i in range(r.kinds.count("point"))]
                out["clicks"] = [{"click": n, "residual_px": float(v), "weight": float(w)}
                                 for n, v, w in zip(names, r.click_residuals_px, r.weights)]
            return out
