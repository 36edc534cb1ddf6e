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

Beyond the paper (docs/beyond.md):

* every clicked segment is snapped to the image's edge, and every clicked image point of a vertex
  to the image's corner, on the frame the operator clicked on (``snapping``); ``refuse_snap()``
  keeps the last click as clicked; ``snap=False`` (or ``set_snap(False)``) turns snapping off;
* ``auto_match()``: which model edge each clicked edge is, found automatically (the mixin in
  app/workflows/pose_matching.py); then Refine and Accept as usual;
* a refined pose is offered only if it is plausible: RMS at most 3 σ_px, the object in front of
  the camera and its projection in the image; otherwise the next candidate is refined instead
  (and the operator told), and when none fits the operator is told what to do.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

import numpy as np

from core.pose import nearest_twin, p3l_candidates, plausibility, refine
from core.pose.uncertainty import with_camera_uncertainty
from core.transforms import pose_error

from .base import AS_CLICK, CANCEL, Control, Ghost, Marks, Step, Workflow, WorkflowError, as_pixel, sigma_over
from .pose_matching import AutoMatchMixin, Match
from .pose_search import OneClickMixin
from .snapping import SNAPPED_CORNER_SIGMA_PX, SNAPPED_SEGMENT_SIGMA_PX, ClickSnap, SnapMixin, snap_marks
from .writing import write_pose

__all__ = ["UpdatePose", "Match", "plausibility", "nearest_twin"]

PICK_RADIUS_PX = 25.0
MIN_SEGMENT_PX = 3.0
# A refined pose is weak (Accept asks once more) when its σ exceed these, a click lies more than 3σ
# off, a snap moved a click more than MAX_SNAP_MOVE_PX, or the clicks fix the 6 unknowns just barely.
WEAK_SIGMA_DEG = 2.0
WEAK_SIGMA_MM = 20.0
MAX_SNAP_MOVE_PX = 2.0
# A refined pose whose outline lies on the image's edges for less than this share is said suspect (its clicks
# may fit a wrong assignment): the one-click search's own floor (app.vision.search.MIN_NEAR), which the right
# poses of 150 rendered placements, a fifth to a third of them hidden, all passed.
MIN_OUTLINE_SEEN = 0.40
MAX_VIEW_GAP_S = 0.5  # clicks in two cameras are of one moment when their frames arrived this close
MAX_TRIPLES = 20  # Solve tries at most this many triples of the assigned edges (6 edges: all 20)
MAX_CANDIDATES = 8


def refine_in_views(cameras: dict, start: np.ndarray, clicks: dict, sigmas: np.ndarray, views: tuple, loss: str):
    """``core.pose.refine_views`` on clicks made in several cameras ({name: Camera}, in order): ``clicks``
    as ``refine`` takes them, ``sigmas`` one per click (segments, then points), ``views`` (segment
    cameras, point cameras). The result's per-click arrays follow the clicks' order, as ``refine``'s."""
    import dataclasses

    from core.pose import ViewClicks, refine_views

    seg_views, pt_views = views
    S = len(seg_views)
    segs, edges = clicks.get("segs_uv"), clicks.get("edges_obj")
    pts, pobj = clicks.get("points_uv"), clicks.get("points_obj")
    per_view, order_s, order_p = [], [], []
    for name, camera in cameras.items():
        si = [i for i, v in enumerate(seg_views) if v == name]
        pi = [i for i, v in enumerate(pt_views) if v == name]
        if not si and not pi:
            continue
        per_view.append(
            ViewClicks(
                camera,
                segs[si] if si else None,
                edges[si] if si else None,
                pts[pi] if pi else None,
                pobj[pi] if pi else None,
                sigma_px=np.concatenate([sigmas[si], sigmas[[S + i for i in pi]]]),
            )
        )
        order_s += si
        order_p += pi
    result = refine_views(per_view, start, loss=loss)
    perm = np.array(order_s + [S + i for i in order_p], int)  # result's click k is the clicks' perm[k]
    inv = np.empty_like(perm)
    inv[perm] = np.arange(len(perm))
    rows = np.stack([2 * inv, 2 * inv + 1], axis=1).reshape(-1)
    return dataclasses.replace(
        result,
        residuals_px=result.residuals_px[rows],
        kinds=tuple(result.kinds[k] for k in inv),
        click_residuals_px=result.click_residuals_px[inv],
        weights=result.weights[inv],
        downweighted=tuple(int(perm[k]) for k in result.downweighted),
        views=tuple(result.views[k] for k in inv),
        sigma_px=result.sigma_px if np.ndim(result.sigma_px) == 0 else np.asarray(result.sigma_px)[inv],
    )


def _counted(n_edges: int, n_points: int) -> str:
    """ "4 edges", "3 edges and 1 point", "no click": what a refinement used, or what was snapped."""
    parts = [f"{n} {w}{'s' if n != 1 else ''}" for n, w in ((n_edges, "edge"), (n_points, "point")) if n]
    return " and ".join(parts) or "no click"


class UpdatePose(OneClickMixin, AutoMatchMixin, SnapMixin, Workflow):
    name = "update_pose"
    title = "Update pose"
    options = ("object_name",)
    actions = (
        "click",
        "assign_edge",
        "add_segment",
        "add_point",
        "start_point",
        "remove_last",
        "remove_click",
        "solve",
        "choose_candidate",
        "refine",
        "accept",
        "cancel",
        "refuse_snap",
        "set_snap",
        "auto_assign",
        "auto_match",
        "confirm_match",
        "find",
    )
    controls = (
        Control(
            "find",
            "Find",
            "G",
            kind="long",
            color="blue",
            hint="Find the object's pose from your one click on it (where it is now in the video)",
        ),
        Control(
            "auto_match",
            "Auto match",
            "M",
            kind="long",
            color="blue",
            hint="Find which model edge each clicked image edge is (3 or more edges, 4 is best)",
        ),
        Control("confirm_match", "Confirm match", "C", color="blue", hint="Adopt the assignment shown"),
        Control("solve", "Solve", "P", color="blue", hint="Large motion: the three-line solver's candidate poses"),
        Control("choose_candidate", "Candidate", kind="choice", hint="The candidate pose drawn in white"),
        Control(
            "refine",
            "Refine",
            "R",
            color="blue",
            hint="Least squares on every click, from the candidate or the database pose",
        ),
        Control("accept", "Accept", "enter", color="green", hint="Write the refined pose to the database"),
        Control("start_point", "Add point", "V", hint="Next clicks: a model corner, then where it is in the video"),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last click as clicked, not moved onto the image's edge"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click or assignment"),
        Control("click_row", "Click", kind="choice", hint="A clicked edge or point (its residual after Refine)"),
        Control("remove_click", "Delete click", arg="click_row", hint="Delete the click chosen above"),
        CANCEL,
    )

    def __init__(
        self,
        site,
        client: str = "operator",
        view: str | None = None,
        object_name: str | None = None,
        loss: str = "l2",
        snap: bool = True,
        sigma_px: float = 1.0,
    ):
        super().__init__(site, client, view)
        self._init_snap(snap)
        if not sigma_px > 0:
            raise WorkflowError(f"sigma_px (the clicks' noise, pixels) must be positive, got {sigma_px}")
        self.sigma_px = float(sigma_px)
        if object_name is None:
            raise WorkflowError("Update pose: select the object first")
        try:
            self.obj = site.object(object_name)
        except KeyError as exc:
            raise WorkflowError(str(exc.args[0])) from None
        # no straight edges (a cylinder, a cone): its pose can only be found from one click (the search draws
        # its outline), not from clicked edges
        self.search_only = not len(self.obj.model.edges)
        if self.search_only and not self.obj.model.solids:
            raise WorkflowError(
                f"{object_name} has neither straight edges nor an outline to find: model it again instead"
            )
        self.object_name = object_name
        self.loss = loss
        self.segs: list[np.ndarray] = []
        self.edge_ids: list[int | None] = []
        self.points_uv: list[np.ndarray] = []
        self.vertex_ids: list[int] = []
        # the camera each segment and point was clicked in (the workflow's own, or another: one pose fits all)
        self.seg_views: list[str] = []
        self.point_views: list[str] = []
        self.pending: np.ndarray | None = None
        self.pending_view: str | None = None
        self.mode = "edge"
        self.pending_vertex: int | None = None
        self.candidates: list[np.ndarray] = []
        self.chosen: int | None = None
        self.refined = None
        self.seg_snaps: list[ClickSnap | None] = []  # beside segs: each segment's snap (None: snapping off)
        self.point_snaps: list[ClickSnap | None] = []  # beside points_uv
        self.auto = False  # automatic assignment: clicked edges wait for auto_match, not for a model edge
        self.matches: list[Match] | None = None  # automatic assignments awaiting confirm_match
        self.match_info: dict[str, Any] | None = None  # the confirmed automatic assignment (history)
        self._match_undo: list[list] = []  # edge_ids before each confirm_match (remove_last restores them)
        self._done: list[str] = []  # "segment", "assign", "point", "match": what remove_last undoes, last first
        # Bumped by every change of what the solvers read (clicks, assignments, the chosen candidate): a
        # solve that ran outside the lock commits only if it is unchanged (snapshot, compute, commit).
        self._generation = 0
        self.last_refined: np.ndarray | None = None  # the last refined pose, once a click changed it
        self._init_found()  # Find from one click (app/workflows/pose_search.py)
        self.state = "click_edge"

    # ------------------------------------------------------------------ estimate in use
    @property
    def T_current(self) -> np.ndarray:
        """The pose the overlay assigns against: refined, else the last refined one (a click added
        since), else the chosen candidate, else the database's."""
        if self.refined is not None:
            return self.refined.T_world_obj
        if self.last_refined is not None:
            return self.last_refined
        if self.chosen is not None:
            return self.candidates[self.chosen]
        return self.obj.T_world_obj

    def _invalidate(self) -> None:
        self.refined = None
        self.last_refined = None  # a new candidate or assignment: the old refinement is no guide
        self._generation += 1

    def _clicks_changed(self) -> None:
        """A click or an assignment changed: the refined pose and any automatic assignments shown go;
        the last refined pose stays the estimate new edges are assigned on (and Refine starts from)."""
        if self.refined is not None:
            self.last_refined = self.refined.T_world_obj.copy()
        self.refined = None
        self._generation += 1
        if self.matches is not None:
            self.matches = None
            self.candidates, self.chosen = [], None

    def _after_refuse(self) -> None:
        self._clicks_changed()

    # ------------------------------------------------------------------ actions
    def click_in(self, view: str, uv) -> None:
        """A click in camera ``view``: edges and points clicked in another camera than the workflow's
        join its own in one refinement (``core.pose.refine_views``): a second view fixes the distance
        along the first one's line of sight."""
        with self.lock:
            self._check_open()
            try:
                view = self.site.view_name(view)
            except ValueError as exc:
                raise WorkflowError(str(exc)) from None
            if view != self.view:
                if self.search_only or self._found_pending() or self.progress is not None:
                    raise WorkflowError(
                        f"the pose found from one click is camera {self.view}'s: click in camera {self.view}, or "
                        f"click edges of {self.object_name} in camera {self.view} first"
                    )
                if not len(self.obj.model.edges):
                    raise WorkflowError(f"{self.object_name} has no edges to click in camera {view}")
            ref = self.frame_in(view) if view != self.view else None
            if ref is not None and abs(ref.gap_s) > MAX_VIEW_GAP_S:
                raise WorkflowError(
                    f"camera {view}'s frame nearest the frozen one arrived {abs(ref.gap_s):.1f} s "
                    f"{'after' if ref.gap_s > 0 else 'before'} it: an object that moved would be in two places. "
                    f"Freeze again (F) while both cameras show the video, or click in camera {self.view} alone"
                )
            if self.pending is not None and self.pending_view not in (None, view):
                raise WorkflowError(
                    f"the edge under way was started in camera {self.pending_view}: click its second point there "
                    "(or Remove last)"
                )
            if self._waiting_for_edge() and self.seg_views[-1] != view:
                raise WorkflowError(
                    f"edge {len(self.segs)} was clicked in camera {self.seg_views[-1]}: say which model edge it is "
                    "there (or Remove last)"
                )
            self.click_view = view
            try:
                self.click(uv)
            finally:
                self.click_view = None

    def _in_view(self) -> str:
        return self.click_view or self.view

    def click(self, uv) -> None:
        """A click on the video; what it means depends on the step (see ``next_step``)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.mode == "point":
                if self.pending_vertex is None:
                    k, dist = self._nearest_vertex(p)
                    if dist > PICK_RADIUS_PX:
                        raise WorkflowError(
                            f"no vertex of {self.object_name} within {PICK_RADIUS_PX:.0f} px "
                            f"(nearest {dist:.0f} px); click a corner of its wireframe"
                        )
                    self.pending_vertex = k
                    self.state = "click_point_image"
                else:
                    self._add_point(p, self.pending_vertex)
                return
            if not self.auto and self.edge_ids and self.edge_ids[-1] is None:
                k, dist = self._nearest_edge(p)
                if dist > PICK_RADIUS_PX:
                    raise WorkflowError(
                        f"no edge of {self.object_name} within {PICK_RADIUS_PX:.0f} px of the click "
                        f"(nearest {dist:.0f} px); click on its wireframe in the overlay"
                    )
                self._assign(k)
                return
            if self.pending is None or (self.search_only and self.found is None):
                self.pending = p  # with no edges to click, a new click replaces the one waiting for Find
                self.pending_view = self._in_view()
                self.state = "click_edge_end"
                return
            if self.search_only:
                raise WorkflowError(
                    f"{self.object_name} has no straight edges to click: Accept the found pose, pick another, "
                    "or Remove last and double-click it again"
                )
            seg, snap = self._finish_segment(self.pending, p, MIN_SEGMENT_PX)
            self.pending = None
            self.segs.append(seg)
            self.seg_snaps.append(snap)
            self.edge_ids.append(None)
            self.seg_views.append(self._in_view())
            self._done.append("segment")
            self._clicks_changed()
            self.state = "click_edge" if self.auto else "assign_edge"
            self.message = self._snap_message(f"Edge {len(self.segs)}", snap)

    def assign_edge(self, edge: int) -> None:
        """Say which model edge (index into the model's edges) the last clicked segment is."""
        with self.lock:
            self._check_open()
            self._assign_last(int(edge))

    def add_segment(self, seg_uv, edge: int | None = None) -> None:
        """A clicked segment (2, 2) and its model edge at once (for scripts); ``edge=None`` leaves
        it for ``auto_match`` (and switches to automatic assignment)."""
        seg = np.asarray(seg_uv, dtype=float)
        if seg.shape != (2, 2) or not np.all(np.isfinite(seg)):
            raise WorkflowError(f"a segment is two pixels [[u1, v1], [u2, v2]], got {seg_uv!r}")
        with self.lock:
            self._check_open()
            if self.pending is not None or self._waiting_for_edge():
                raise WorkflowError("finish the edge under way first (or Remove last)")
            if edge is None:
                self.auto = True
            self.click(seg[0])
            self.click(seg[1])
            if edge is not None:
                self._assign_last(int(edge))

    def _waiting_for_edge(self) -> bool:
        """The last clicked segment waits for its model edge (hand assignment)."""
        return not self.auto and bool(self.edge_ids) and self.edge_ids[-1] is None

    def _assign_last(self, k: int) -> None:
        """Assign model edge k to the last clicked segment (hand assignment, also in automatic mode)."""
        if not self.edge_ids or self.edge_ids[-1] is not None:
            raise WorkflowError(
                "no clicked segment is waiting for its model edge: click two points on an image edge first"
            )
        self._assign(k)

    def start_point(self) -> None:
        """Next clicks: a model vertex in the overlay, then where it is in the video."""
        with self.lock:
            self._check_open()
            if self.pending is not None or self._waiting_for_edge():
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
                raise WorkflowError(
                    f"{self.object_name} has vertices 0..{len(self.obj.model.vertices) - 1}, not {vertex}"
                )
            self._add_point(p, int(vertex))

    def remove_last(self) -> None:
        """Undo the last click (a pending end, an assignment, a segment or a point)."""
        with self.lock:
            self._check_open()
            if self._drop_found():
                return
            if self.mode == "point":
                self.mode, self.pending_vertex = "edge", None
            elif self.pending is not None:
                self.pending = None
            elif self.matches is not None:
                self.matches = None  # the automatic assignments shown: dropped, the clicks stay
                self.candidates, self.chosen = [], None
            elif self._done:
                last = self._done.pop()
                if last == "assign":
                    self.edge_ids[self._last_assigned()] = None
                elif last == "match":
                    self.edge_ids = self._match_undo.pop()
                    self.match_info = None
                elif last == "segment":
                    self.segs.pop()
                    self.seg_snaps.pop()
                    self.edge_ids.pop()
                    self.seg_views.pop()
                else:
                    self.points_uv.pop()
                    self.point_snaps.pop()
                    self.vertex_ids.pop()
                    self.point_views.pop()
            self._clicks_changed()
            self.state = "assign_edge" if self._waiting_for_edge() else "click_edge"

    def _last_assigned(self) -> int:
        return max(i for i, e in enumerate(self.edge_ids) if e is not None)

    def solve(self) -> list[np.ndarray]:
        """The paper's three-line solver on every workable triple of the assigned edges (at most
        ``MAX_TRIPLES``), its candidates ranked by how far all the clicks (every edge and point, not
        only the triple's) lie from the projected model (``core.pose.residuals.pose_distance_cost``),
        near-duplicates merged, the best ``MAX_CANDIDATES`` kept."""
        with self.lock:  # snapshot
            self._check_open()
            segs, edges = self._assigned()
            pts_uv, pts_obj = self._points()
            seg_views, pt_views = self._click_views()
            # the three-line solver works in one camera: the one with the most assigned edges (its own first)
            view = max(dict.fromkeys([self.view, *seg_views]), key=seg_views.count)
            keep = np.array([v == view for v in seg_views], bool)
            segs, edges = segs[keep] if len(segs) else segs, edges[keep] if len(edges) else edges
            keep = np.array([v == view for v in pt_views], bool)
            pts_uv, pts_obj = (pts_uv[keep], pts_obj[keep]) if len(pts_uv) else (pts_uv, pts_obj)
            if len(segs) < 3:
                several = len(set(seg_views)) > 1
                raise WorkflowError(
                    f"{len(segs)} edges assigned{f' in camera {view}' if several else ''}; the three-line solver "
                    f"needs 3{' in one camera' if several else ''} (click more edges)"
                )
            camera, generation = self.site.camera_of(view), self._generation
        try:  # compute, outside the lock: the overlay keeps drawing
            res = p3l_candidates(
                camera,
                segs,
                edges,
                pts_uv if len(pts_uv) else None,
                pts_obj if len(pts_obj) else None,
                max_triples=MAX_TRIPLES,
                max_candidates=MAX_CANDIDATES,
            )
        except ValueError as exc:
            raise WorkflowError(f"Solve: {exc}") from None
        if not res.poses:
            raise WorkflowError(
                "no pose fits these edges: "
                + "; ".join(self._skipped_words(tri, kind, why) for tri, kind, why in res.skipped[:3])
                + ". Check the edge assignments (Remove last) or click other edges"
            )
        ranked, triples = res.poses, len(res.triples)
        with self.lock:  # commit
            self._unchanged_since(generation, "Solve")
            self.candidates = ranked
            self.chosen = 0
            self.matches = None
            self._invalidate()
            self.state = "review"
            every = f"all {len(segs)} edges" if len(segs) > 3 else "the 3 edges"
            self.message = (
                f"{len(ranked)} candidate pose{'s' if len(ranked) > 1 else ''} from {triples} triple"
                f"{'s' if triples > 1 else ''} of edges, ranked by how well each fits {every}; the best "
                "is selected"
            )
            return self.candidates

    def _skipped_words(self, triple: tuple, kind: str, why: str) -> str:
        """Why a triple of clicked edges gave no pose, as the operator reads it."""
        edges = ", ".join(str(i + 1) for i in triple)
        if kind == "concurrent":
            return (
                f"edges {edges} meet at one corner of {self.object_name}: they give its turn but not its distance; "
                "click a fourth edge that does not pass through that corner, or Add point on another corner"
            )
        return f"edges {edges}: {why}"

    def _unchanged_since(self, generation: int, again: str) -> None:
        """Before committing a result computed outside the lock (held): WorkflowError, nothing
        changed, if the workflow closed or its clicks changed meanwhile."""
        self._check_open()
        if self._generation != generation:
            raise WorkflowError(f"the clicks changed while solving: {again} again")

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
        """Least squares on every click from the chosen candidate (or the database pose).

        The refined pose is offered only when plausible (``plausibility``: RMS ≤ 3 σ_px, the object
        in front of the camera and in the image); otherwise the other candidates are refined in
        turn and the first plausible one is chosen (the message says so). WorkflowError, nothing
        changed, when none is.
        """
        with self.lock:  # snapshot
            self._check_open()
            if self.matches is not None:
                raise WorkflowError(
                    "confirm the automatic assignment first (Confirm match), or assign the edges by hand"
                )
            segs, edges = self._assigned()
            pts_uv, pts_obj = self._points()
            starts: list[tuple[int | None, np.ndarray]] = [(None, self.obj.T_world_obj)]
            if self.chosen is not None:
                order = [self.chosen] + [i for i in range(len(self.candidates)) if i != self.chosen]
                starts = [(i, self.candidates[i]) for i in order]
            if self.last_refined is not None:  # clicks added since the last Refine: go on from there
                starts = [(-1, self.last_refined)] + starts
            camera, camera_cov, sigmas = self.camera, self.site.camera_cov(self.view), self._click_sigmas()
            generation = self._generation
            views = self._click_views()
            several = any(v != self.view for v in views[0] + views[1])  # clicks in another camera too
            prior = None
            if self.found is not None and not several:  # found from one click: the clicks refine it, together
                c = self.found[self.chosen or 0]
                if c.cov is not None:
                    prior = (self.chosen or 0, c.T_world_obj, c.cov, c.cov_camera)
        clicks = dict(
            segs_uv=segs if len(segs) else None,
            edges_obj=edges if len(edges) else None,
            points_uv=pts_uv if len(pts_uv) else None,
            points_obj=pts_obj if len(pts_obj) else None,
        )
        if prior is not None:
            return self._refine_found(prior, camera, clicks, sigmas, generation)
        failures = []  # compute, outside the lock: the overlay keeps drawing
        for i, start in starts:
            what = (
                "from the database pose"
                if i is None
                else ("from the last refined pose" if i == -1 else f"candidate {i + 1}")
            )
            try:
                result = self._refine_at(start, clicks, sigmas, views)
            except ValueError as exc:
                failures.append(f"{what}: {exc}")
                continue
            if not np.all(np.isfinite(result.T_world_obj)):
                failures.append(f"{what}: the refinement diverged")
                continue
            why = plausibility(camera, self.obj.model, result.T_world_obj, result.rms_px, 3.0 * self.sigma_px)
            if why:
                failures.append(f"{what}: {why}")
                continue
            break
        else:
            advice = "Check the edge assignments (Remove last and assign again), or add clicks (another edge, a point)"
            if i is None:
                advice += "; for a large motion Solve first"
            raise WorkflowError("no plausible pose: " + "; ".join(failures) + f". {advice}")
        if camera_cov is not None and not several:  # the camera calibrated in this database: its share joins
            result = with_camera_uncertainty(result, camera, camera_cov, **clicks)
        unseen = self._unseen_outline(camera, result.T_world_obj)
        with self.lock:  # commit
            self._unchanged_since(generation, "Refine")
            self.refined_unseen = unseen
            note = ""
            if failures and i is not None and i >= 0:
                note = f"{'; '.join(failures)} — not offered; candidate {i + 1} refined instead. "
                self.chosen = i
            self.refined = result
            self.state = "review"
            deg, m = pose_error(result.T_world_obj, self.obj.T_world_obj)
            sig_deg, sig_mm = float(np.max(result.std_r_deg)), 1000 * float(np.max(result.std_t_m))
            used = _counted(list(result.kinds).count("segment"), list(result.kinds).count("point"))
            if several:
                used += f" in cameras {', '.join(dict.fromkeys([self.view, *views[0], *views[1]]))}"
            self.message = (
                f"{note}RMS {result.rms_px:.2f} px over {used}; moved {deg:.2f}° and "
                f"{1000 * m:.1f} mm from the database pose; σ up to {sig_deg:.2f}° and {sig_mm:.1f} mm"
                + (" (camera calibration included)" if result.cov_parts else "")
                + (
                    " (the cameras' calibration σ not included)"
                    if several and any(self.site.camera_cov(v) is not None for v in (*views[0], *views[1]))
                    else ""
                )
                + (f". ⚠ {unseen}" if unseen else "")
            )
            return result

    def _unseen_outline(self, camera, T: np.ndarray) -> str:
        """ "" unless little of the model's visible outline at pose T lies on the frame's edges (less
        than ``MIN_OUTLINE_SEEN``, samples within 1.5 px of an edge of their orientation): then why
        the pose is suspect. The clicks can fit a wrong pose exactly — edges assigned as in a mirror,
        4 edges for 6 unknowns — while its drawing misses the object (a new operator: RMS 0.45 px, the
        box 40 px off). Outside the lock; "" without a frame."""
        from app.vision.evaluate import edge_distance

        image = self._frame()
        if image is None:
            return ""
        d = edge_distance(image, camera, self.obj.model, T, max_px=10.0)
        if not len(d.distances_px):
            return ""
        seen = float(np.mean(d.distances_px <= 1.5))
        if seen >= MIN_OUTLINE_SEEN:
            return ""
        return (
            f"only {100 * seen:.0f} % of the refined pose's outline lies on the image's edges, though the clicks fit: "
            "an edge assigned to the wrong model edge (a mirror image)? Compare the white ghost with the video, "
            "and Remove last to assign again"
        )

    def accept(self):
        """Write the refined pose and covariance (one transaction); ConflictError → nothing written.
        A pose found from one click, with no click since, is written as found (method "search")."""
        rec = self._accept_found()
        if rec is not None:
            return rec
        with self.lock:
            self._check_open()
            unrefined = self.refined is None
        if unrefined:
            self.refine()  # outside the lock, as Refine is
        with self.lock:
            self._check_open()
            if self.refined is None:
                raise WorkflowError("the clicks changed while solving: Accept again")
            r = self.refined
            segs, edges = self._assigned()
            pts_uv, _ = self._points()
            used = [j for j, e in enumerate(self.edge_ids) if e is not None]
            clicks = {
                "segs_uv": segs,
                "edge_ids": [self.edge_ids[j] for j in used],
                "points_uv": pts_uv,
                "vertex_ids": list(self.vertex_ids),
                "candidates": len(self.candidates),
                "chosen": self.chosen,
                # raw and snapped pixels of each segment and point above (None: snapping was off)
                "snaps": [None if self.seg_snaps[j] is None else self.seg_snaps[j].record() for j in used],
                "point_snaps": [None if s is None else s.record() for s in self.point_snaps],
                "assignment": "automatic" if self.match_info is not None else "hand",
                "views": [self.seg_views[j] for j in used] + list(self.point_views),
                "frame": self.frame_record(),
                "view_frames": {
                    v: self.frame_in(v).record()
                    for v in dict.fromkeys(self.seg_views + self.point_views)
                    if v != self.view and self.frame_in(v) is not None
                },
            }  # the frozen frame the edges were clicked on
            if self.match_info is not None:
                clicks["match"] = self.match_info
            residuals = {"rms_px": r.rms_px, "click_residuals_px": r.click_residuals_px, "kinds": list(r.kinds)}
            method = (
                "match+refine"
                if self.match_info is not None
                else ("p3l+refine" if self.chosen is not None else "refine")
            )
            if self.found is not None:
                method = "search+refine"
                clicks["search"] = self.search_info
            rec, self.obj = write_pose(
                self,
                self.obj,
                r.T_world_obj,
                r.cov,
                method=method,
                clicks=clicks,
                residuals=residuals,
                todo="Cancel, and update the pose again from its new one.",
            )
            self.accepted = True
            self.state = "accepted"
            self.message = f"{self.object_name} updated (version {rec.version}): RMS {r.rms_px:.2f} px"
            return rec

    # ------------------------------------------------------------------ helpers
    def _assign(self, k: int) -> None:
        E = len(self.obj.model.edges)
        if not 0 <= k < E:
            raise WorkflowError(f"{self.object_name} has edges 0..{E - 1}, not {k}")
        view = self.seg_views[-1] if self.seg_views else self.view
        taken = [i for i, (e, v) in enumerate(zip(self.edge_ids, self.seg_views)) if e == k and v == view]
        if taken:  # in this camera (the same edge clicked in another camera is another measurement of it)
            raise WorkflowError(
                f"model edge {k} is already assigned to segment {taken[0] + 1}; click another model edge"
            )
        self.edge_ids[-1] = k
        self._done.append("assign")
        self._clicks_changed()
        self.state = "click_edge"

    def _add_point(self, p: np.ndarray, vertex: int) -> None:
        if vertex in self.vertex_ids:
            raise WorkflowError(f"vertex {vertex} already has a clicked point; click another vertex")
        snap = self._snap_corner(p, self.obj.model, self.T_current, vertex)
        self.points_uv.append(p if snap is None else snap.used)
        self.point_snaps.append(snap)
        self.vertex_ids.append(vertex)
        self.point_views.append(self._in_view())
        self.mode, self.pending_vertex = "edge", None
        self._done.append("point")
        self._clicks_changed()
        self.state = "click_edge"
        self.message = self._snap_message(f"Point v{vertex}", snap)

    def _last_snap(self):
        """The last clicked segment or image point, and how to put a click back in its place."""
        for last in reversed(self._done):
            if last == "segment":
                i = len(self.segs) - 1
                return self.seg_snaps[i], lambda raw: self.segs.__setitem__(i, raw)
            if last == "point":
                i = len(self.points_uv) - 1
                return self.point_snaps[i], lambda raw: self.points_uv.__setitem__(i, raw)
        return None, None

    def _assigned(self) -> tuple[np.ndarray, np.ndarray]:
        pairs = [(s, e) for s, e in zip(self.segs, self.edge_ids) if e is not None]
        if not pairs:
            return np.zeros((0, 2, 2)), np.zeros((0, 2, 3))
        model = self.obj.model
        return np.array([s for s, _ in pairs]), np.array([model.vertices[model.edges[e]] for _, e in pairs])

    def _click_views(self) -> tuple[list[str], list[str]]:
        """The camera of each assigned segment and of each point, in refine's order."""
        return [v for v, e in zip(self.seg_views, self.edge_ids) if e is not None], list(self.point_views)

    def _refine_at(self, start: np.ndarray, clicks: dict, sigmas: np.ndarray, views: tuple[list, list]):
        """``core.pose.refine`` from ``start`` on the clicks, or ``refine_views`` when some were made in
        another camera (its result's per-click arrays put back in the clicks' order)."""
        seg_views, pt_views = views
        if all(v == self.view for v in seg_views + pt_views):
            return refine(self.camera, start, **clicks, loss=self.loss, sigma_px=sigmas)
        return refine_in_views(
            {v: self.site.camera_of(v) for v in dict.fromkeys([self.view, *seg_views, *pt_views])},
            start,
            clicks,
            sigmas,
            views,
            self.loss,
        )

    def _click_sigmas(self) -> np.ndarray:
        """σ of each click in refine's order (assigned segments, then points), pixels: a click snapped
        to the image has the snap's measured precision, a raw or refused one the operator's σ."""

        def sigma(snap: ClickSnap | None, snapped_sigma: float) -> float:
            return snapped_sigma if snap is not None and snap.applied else self.sigma_px

        segs = [sigma(sn, SNAPPED_SEGMENT_SIGMA_PX) for sn, e in zip(self.seg_snaps, self.edge_ids) if e is not None]
        return np.array(segs + [sigma(sn, SNAPPED_CORNER_SIGMA_PX) for sn in self.point_snaps])

    def _points(self) -> tuple[np.ndarray, np.ndarray]:
        if not self.points_uv:
            return np.zeros((0, 2)), np.zeros((0, 3))
        return np.array(self.points_uv), self.obj.model.vertices[self.vertex_ids]

    def _projected_edges(self) -> np.ndarray:
        cam = self._click_camera()
        S = self.obj.model.edge_segments(self.T_current)
        uv = cam.project(S.reshape(-1, 3)).reshape(-1, 2, 2)
        behind = np.any(cam.depth(S.reshape(-1, 3)).reshape(-1, 2) <= 0, axis=1)
        uv[behind] = np.inf
        return uv

    def _nearest_edge(self, p: np.ndarray) -> tuple[int, float]:
        from app.overlay import nearest_segment

        uv = self._projected_edges()
        ok = np.all(np.isfinite(uv.reshape(len(uv), -1)), axis=1)
        view = self._in_view()
        used = {e for e, v in zip(self.edge_ids, self.seg_views) if v == view}
        free = np.array([k not in used for k in range(len(uv))])
        idx = np.nonzero(ok & free)[0]
        if not len(idx):
            return -1, float("inf")
        i, d = nearest_segment(uv[idx], p)
        return int(idx[i]), d

    def _nearest_vertex(self, p: np.ndarray) -> tuple[int, float]:
        cam = self._click_camera()
        T = self.T_current
        V = self.obj.model.vertices @ T[:3, :3].T + T[:3, 3]
        d = np.linalg.norm(cam.project(V) - p, axis=1)
        d[cam.depth(V) <= 0] = np.inf
        k = int(np.argmin(d))
        return k, float(d[k])

    def _click_rows(self) -> list[tuple[str, int]]:
        """Every click that can be deleted, in refine's order: ("segment", j) then ("point", j)."""
        return [("segment", j) for j in range(len(self.segs))] + [("point", j) for j in range(len(self.points_uv))]

    def remove_click(self, index: int) -> None:
        """Delete click ``index`` (a row of the residual table: clicked edges, then points)."""
        with self.lock:
            self._check_open()
            rows = self._click_rows()
            i = int(index)
            if not 0 <= i < len(rows):
                raise WorkflowError(f"there is no click {i + 1}: {len(rows)} were made")
            if self.pending is not None or self.mode == "point":
                raise WorkflowError("finish the click under way first (or Remove last)")
            kind, j = rows[i]
            if kind == "segment":
                del self.segs[j], self.seg_snaps[j], self.edge_ids[j], self.seg_views[j]
                what = f"Edge {j + 1}"
            else:
                del self.points_uv[j], self.point_snaps[j], self.vertex_ids[j], self.point_views[j]
                what = f"Point {j + 1}"
            # What Remove last undoes, rebuilt in click order (a confirmed match's undo is dropped).
            self._done = [
                d
                for j2, e in enumerate(self.edge_ids)
                for d in (("segment", "assign") if e is not None else ("segment",))
            ]
            self._done += ["point"] * len(self.points_uv)
            self._match_undo = []
            self._clicks_changed()
            self.state = "assign_edge" if self._waiting_for_edge() else "click_edge"
            self.message = (
                f"{what} deleted; {'Refine' if self.refined is None and self.candidates else 'click or Refine'} again."
            )

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if self.progress is not None:  # Find under way (its click was taken: not "click a second point")
            return Step(
                "searching",
                f"Searching for the pose of {self.object_name} from your click… " + "{cancel} stops the search.",
                frozenset({"cancel"}),
                clicks=False,
            )
        n = sum(e is not None for e in self.edge_ids)
        k = len(self.segs)
        where = (
            "on the white ghost" if (self.chosen is not None or self.last_refined is not None) else "on its wireframe"
        )
        base = {"cancel"}
        if self.pending is not None or self.mode == "point" or self._done or self.matches is not None:
            base.add("remove_last")
        snap, _ = self._last_snap()
        if snap is not None and snap.applied and self.pending is None and self.mode == "edge":
            base.add("refuse_snap")
        if self.mode == "point":
            if self.pending_vertex is None:
                return Step(
                    "click_point_model",
                    f"Click a corner of {self.object_name} {where} (the model vertex).",
                    frozenset(base),
                )
            return Step(
                "click_point_image",
                f"Now click where vertex {self.pending_vertex} (circled) really is in the video.",
                frozenset(base),
            )
        found = self._found_step(base)
        if found is not None:
            return found
        if self._first_click_pending():
            if self.search_only:
                return Step(
                    "click_edge_end",
                    "{find} the pose of " + f"{self.object_name} from this click (or double-click it).",
                    frozenset(base | {"find"}),
                )
            return Step(
                "click_edge_end",
                "{find} the pose of " + f"{self.object_name} from this one click (or double-click "
                f"it), or click a second point on the same image edge (edge {k + 1}).",
                frozenset(base | {"find"}),
            )
        if self.search_only:
            return Step(
                "click_edge",
                f"Double-click {self.object_name} where it is now in the video to find its pose "
                "(it has no straight edges to click).",
                frozenset(base),
            )
        if self.pending is not None:
            return Step(
                "click_edge_end", f"Click a second point on the same image edge (edge {k + 1}).", frozenset(base)
            )
        rows = {"click_row", "remove_click"} if self._click_rows() else set()
        if self.matches is not None:
            e0 = int(self.matches[self.chosen or 0].edges[0])
            return Step(
                "match",
                f"Assignment {(self.chosen or 0) + 1} of {len(self.matches)} shown (1→e{e0}: clicked edge 1 is "
                f"model edge {e0}): "
                + "{confirm_match}, choose another {choose_candidate}, or {remove_last} to assign "
                "by hand.",
                frozenset(base | {"confirm_match", "choose_candidate"}),
            )
        more = base | rows | {"start_point"}
        if self._waiting_for_edge():
            return Step(
                "assign_edge",
                f"Which model edge is it? Click that edge of {self.object_name} {where}.",
                frozenset(base | rows),
            )
        if self.auto and (n < k or not (self.segs or self.points_uv)):  # automatic assignment: say so from the start
            if k < 3:
                return Step(
                    "auto_click",
                    f"Automatic matching: click two points along an edge of {self.object_name} "
                    f"(edge {k + 1}; 3 or more, 4 is best).",
                    frozenset(base | rows),
                )
            return Step(
                "auto_ready",
                f"{k} edges clicked: " + "{auto_match}, or click another edge (4 or more is best).",
                frozenset(base | rows | {"auto_match"}),
            )
        constraints = 2 * (n + len(self.points_uv))
        if constraints >= 6 or (self.found is not None and constraints >= 2):  # with a found pose one edge is enough
            more.add("refine")
        if self._most_in_one_camera() >= 3:  # the three-line solver works in one camera
            more.add("solve")
        if not self.auto and k < 3:
            more.add("auto_match")
        if n < 3 and not self.refined:
            tail = " Or {refine} from the database pose (a small motion)." if "refine" in more else ""
            if self.found is not None and "refine" in more:
                tail = " Or {refine}: the clicks fit together with the found pose (one edge is enough)."
            one = (
                f"Double-click {self.object_name} where it is now in the video to find its pose from that point; or c"
                if not self.segs and not self.points_uv and self.found is None
                else "C"
            )
            spread = ", not all three through one corner" if n == 2 else ""
            return Step(
                "click_edge",
                one + f"lick two points along an edge of {self.object_name} in the video (edge {n + 1} of 3"
                f"{spread}), then click which model edge it is; "
                + "or {auto_match} to skip saying which is which."
                + tail
                if "auto_match" in more
                else f"Click two points along an edge of {self.object_name} in the video (edge {n + 1} of 3{spread})."
                + tail,
                frozenset(more),
            )
        if self.last_refined is not None and self.refined is None:
            return Step(
                "refine_again",
                "Clicks changed since Refine (the white ghost is the last refined pose): "
                "{refine} again to use them, then Accept.",
                frozenset(more - {"solve"} | {"refine"}),
            )
        if self.candidates and self.refined is None and len(self.candidates) == 1:  # no other to pick
            return Step(
                "candidates",
                "The pose is drawn in white: add edges if it looks off, then {refine} — it uses "
                "every click and often corrects a pose that looks off.",
                frozenset(more),
            )
        if self.candidates and self.refined is None:
            return Step(
                "candidates",
                f"Candidate {(self.chosen or 0) + 1} of {len(self.candidates)} is drawn in white: pick "
                "another {choose_candidate} if it is clearly wrong, add edges, then {refine} — it uses every click and "
                "often corrects a candidate that looks off.",
                frozenset(more | {"choose_candidate"}),
            )
        if self.refined is None:
            corner = self._one_corner()
            if corner is not None and not self.points_uv:  # said now, not after Solve
                return Step(
                    "ready",
                    f"Edges {', '.join(str(i + 1) for i in corner)} meet at one corner of "
                    f"{self.object_name}: they give its turn but not its distance. Click a fourth edge that does not "
                    "pass through that corner, or {start_point} on another corner; or {refine} from the database "
                    "pose for a small motion.",
                    frozenset(more - {"solve"}),
                )
            if "solve" not in more:  # edges in several cameras, fewer than 3 in any one
                return Step(
                    "ready",
                    "{refine} from the database pose fits every camera's edges at once (a small motion); for a "
                    "large one, click 3 edges in one camera, then Solve.",
                    frozenset(more),
                )
            return Step(
                "ready",
                "{solve} for a large motion, or {refine} from the database pose for a small one; or click more edges.",
                frozenset(more),
            )
        extra = {"choose_candidate"} if self.candidates else set()
        return Step(
            "review",
            f"Refined: RMS {self.refined.rms_px:.2f} px. " + "{accept} to write it, or add clicks and {refine} again.",
            frozenset(more | extra | {"accept"}),
        )

    def _most_in_one_camera(self) -> int:
        """The most assigned edges clicked in one camera."""
        views = self._click_views()[0]
        return max((views.count(v) for v in set(views)), default=0)

    def _one_corner(self) -> list[int] | None:
        """The clicked edges (indices) when exactly three are assigned and their model edges share one
        vertex (P3L cannot fix the distance from them, ``core.pose.p3l``), else None."""
        assigned = [(i, e) for i, e in enumerate(self.edge_ids) if e is not None]
        if len(assigned) != 3:
            return None
        E = self.obj.model.edges
        common = set(E[assigned[0][1]]) & set(E[assigned[1][1]]) & set(E[assigned[2][1]])
        return [i for i, _ in assigned] if common else None

    def choices(self, action: str) -> list[tuple[str, Any]]:
        with self.lock:
            if action == "choose_candidate":
                return [(label, i) for i, label in enumerate(self.candidate_labels())]
            if action != "click_row":
                return []
            res = None
            if self.refined is not None:
                res = list(self.refined.click_residuals_px)
            out, r = [], 0
            for kind, j in self._click_rows():
                several = len(set(self.seg_views + self.point_views)) > 1
                if kind == "segment":
                    e = self.edge_ids[j]
                    text = f"edge {j + 1}" + (f" → e{e}" if e is not None else " (unassigned)")
                    text += f" ({self.seg_views[j]})" if several else ""
                    used = e is not None
                else:
                    text = f"point {j + 1} (v{self.vertex_ids[j]}" + (f", {self.point_views[j]})" if several else ")")
                    used = True
                if res is not None and used and r < len(res):
                    text += f" · {res[r]:.1f} px"
                r += used
                out.append((text, len(out)))
            return out

    def choice_value(self, action: str) -> Any:
        return self.chosen if action == "choose_candidate" else None

    def weaknesses(self) -> list[str]:
        with self.lock:
            r = self.refined
            if r is None:
                return self._found_weaknesses() if self._found_pending() else []
            out = []
            sd, st = float(np.max(r.std_r_deg)), float(np.max(r.std_t_m)) * 1000
            if sd > WEAK_SIGMA_DEG or st > WEAK_SIGMA_MM:
                out.append(
                    f"the pose is uncertain ({sigma_over(sd, st, WEAK_SIGMA_DEG, WEAK_SIGMA_MM)}); click more edges"
                )
            sig = self._click_sigmas()
            names = [f"edge {j + 1}" for j, e in enumerate(self.edge_ids) if e is not None] + [
                f"point {j + 1}" for j in range(len(self.points_uv))
            ]
            for name, res, sg in zip(names, r.click_residuals_px, sig):
                if res > 3 * max(sg, 0.3):
                    out.append(
                        f"{name} is {res:.1f} px from the refined model (more than 3σ): a wrong click or assignment?"
                    )
            for j, sn in enumerate(self.seg_snaps):
                if sn is not None and sn.applied and sn.moved_px > MAX_SNAP_MOVE_PX:
                    out.append(
                        f"edge {j + 1}'s snap moved it {sn.moved_px:.1f} px (more than {MAX_SNAP_MOVE_PX:.0f} px)"
                    )
            for j, sn in enumerate(self.point_snaps):
                if sn is not None and sn.applied and sn.moved_px > MAX_SNAP_MOVE_PX:
                    out.append(
                        f"point {j + 1}'s snap moved it {sn.moved_px:.1f} px (more than {MAX_SNAP_MOVE_PX:.0f} px)"
                    )
            if getattr(self, "refined_unseen", ""):
                out.append(self.refined_unseen)
            if len(r.kinds) * 2 <= 6 and self.found is None:  # with a found pose the image's edges are the redundancy
                out.append(
                    "no redundant click: the clicks fix the pose's 6 unknowns exactly, so a wrong one cannot show; "
                    "click a fourth edge"
                )
            return out

    def candidate_labels(self) -> list[str]:
        """One label per candidate for a chooser: "#1 (best)", "#2", ..."""
        if self.found is not None and len(self.found) == len(self.candidates):
            return self._found_labels()
        return [f"#{i + 1}" + (" (best)" if i == 0 else "") for i in range(len(self.candidates))]

    def on_double_click(self, view: str, uv) -> str | None:
        """A double click on the moved object finds its pose from that point (Find); found poses there, a
        double click again (a better point) searches again from it; otherwise it is one more click."""
        if view != self.view:
            raise WorkflowError(
                f"a double click finds the pose in camera {self.view}, where {self.title} started: double-click there"
            )
        if self.found is not None:
            self.search_again(uv)
            return "find"
        return "find" if "find" in self.current_step().enabled else AS_CLICK

    def use_frame(self, frame) -> None:
        """Work on ``frame``; its oriented edges (auto match and search read them) are computed meanwhile."""
        super().use_frame(frame)
        if frame is not None:
            threading.Thread(target=_prepare_frame, args=(frame.image,), daemon=True, name="mcit-frame-edges").start()

    def marks_in(self, view: str) -> Marks:
        """What to draw on camera ``view``'s image: the clicks made in it, the estimate through its camera."""
        return self.marks(view)

    def marks(self, view: str | None = None) -> Marks:
        """What to draw on camera ``view``'s image (the workflow's own for None)."""
        with self.lock:
            view = view or self.view
            own = view == self.view
            m = Marks(selected=self.object_name)
            model = self.obj.model
            shown = None if self.matches is None else self.matches[self.chosen or 0]  # assignment awaiting confirmation
            here = [i for i, v in enumerate(self.seg_views) if v == view]  # the segments clicked in this camera
            pts_here = [i for i, v in enumerate(self.point_views) if v == view]
            if here:
                m.segments = np.array([self.segs[i] for i in here])
                ids = self.edge_ids if shown is None else [int(e) for e in shown.edges]
                m.labels = [
                    (
                        (self.segs[i][0] + self.segs[i][1]) / 2,
                        f"{i + 1}"
                        + (f"→e{ids[i]}" if ids[i] is not None else "?")
                        + ("?" if shown is not None else ""),
                    )
                    for i in here
                ]
            if self.pending is not None and (self.pending_view or self.view) == view:
                m.pending = self.pending.reshape(1, 2)
            if self.search_click is not None and own:  # the one click Find used
                m.circles = self.search_click.reshape(1, 2)
                m.labels.append((self.search_click + [8.0, -8.0], "click"))
            if pts_here:
                m.points = np.array([self.points_uv[i] for i in pts_here])
                m.labels += [(self.points_uv[i], f"v{self.vertex_ids[i]}") for i in pts_here]
            snaps = [self.seg_snaps[i] for i in here] + [self.point_snaps[i] for i in pts_here]
            m.raw_segments, m.raw_points, m.snap_lines, snap_labels = snap_marks(snaps)
            m.labels += snap_labels
            if shown is None:
                T = self.T_current  # the assigned model edges, orange, where the estimate draws them
                m.highlight = [(self.object_name, e, T) for e in self.edge_ids if e is not None]
            else:  # the matched model edges, labelled where the shown candidate draws them
                cam = self.site.camera_of(view)
                S = model.edge_segments(shown.T_world_obj)[shown.edges]
                front = np.all(cam.depth(S.reshape(-1, 3)).reshape(-1, 2) > 0, axis=1)
                mids = cam.project(S.reshape(-1, 3)).reshape(-1, 2, 2).mean(axis=1)
                m.labels += [(mid + [0.0, -10.0], f"e{int(e)}") for mid, e, f in zip(mids, shown.edges, front) if f]
            if self.refined is not None:
                m.ghosts = [Ghost(model, self.refined.T_world_obj, "refined", chosen=True)]
            elif self.last_refined is not None:  # clicks added since Refine: the estimate they are assigned on
                m.ghosts = [Ghost(model, self.last_refined, "last refined", chosen=True)]
            else:
                m.ghosts = [
                    Ghost(model, T, f"#{i + 1}", chosen=(i == self.chosen)) for i, T in enumerate(self.candidates)
                ]
            if self._waiting_for_edge() and self.seg_views[-1] == view:  # which model edge: each visible one labelled
                cam = self.site.camera_of(view)
                T = self.T_current
                wfm = model.wireframe(cam.center, T)
                vis = [int(k) for k, v, kind in zip(wfm.edge_index, wfm.visible, wfm.kind) if v and kind == "edge"]
                S = model.edge_segments(T)
                for k in vis:
                    if k not in self.edge_ids and np.all(cam.depth(S[k]) > 0):
                        m.labels.append((cam.project(S[k]).mean(axis=0) + [0.0, 8.0], f"e{k}"))
            if self.mode == "point" and self.pending_vertex is not None:
                T = self.T_current
                X = T[:3, :3] @ model.vertices[self.pending_vertex] + T[:3, 3]
                m.pending = self.site.camera_of(view).project(X.reshape(1, 3))
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            # edges clicked, and of them assigned to a model edge (an auto match assigns them all at once: it
            # showed "Edges: 0" beside "Clicked edges: 4")
            assigned = sum(e is not None for e in self.edge_ids)
            out: dict[str, Any] = {
                "object": self.object_name,
                "edges clicked": len(self.segs),
                "edges assigned": assigned,
                "points": len(self.points_uv),
            }
            snaps = [s for s in self.seg_snaps + self.point_snaps if s is not None]
            if snaps:
                n_seg = sum(1 for s in self.seg_snaps if s is not None)
                out["snapped"] = f"{sum(s.applied for s in snaps)} of {_counted(n_seg, len(snaps) - n_seg)}"
            self._found_summary(out)
            if self.candidates and self.found is None:  # the found poses' are in "found" (they were listed twice)
                out["candidates"] = len(self.candidates)
                out["chosen"] = (self.chosen or 0) + 1
            if self.matches is not None:
                out["assignments"] = [
                    {
                        "candidate": i + 1,
                        "edges": " ".join(f"e{int(e)}" for e in mt.edges),
                        "rms_px": mt.rms_px,
                        "image_px": mt.image_px,
                    }
                    for i, mt in enumerate(self.matches)
                ]
            r = self.refined
            if r is not None:
                out["rms_px"] = r.rms_px
                out["std_t_mm"] = [float(v) for v in 1000 * r.std_t_m]
                out["std_r_deg"] = [float(v) for v in r.std_r_deg]
                deg, m = pose_error(r.T_world_obj, self.obj.T_world_obj)
                out["change"] = {"deg": float(deg), "mm": float(1000 * m)}
                names = [f"edge {i + 1}" for i in range(r.kinds.count("segment"))] + [
                    f"point {i + 1}" for i in range(r.kinds.count("point"))
                ]
                out["clicks"] = [
                    {"click": n, "residual_px": float(v), "weight": float(w)}
                    for n, v, w in zip(names, r.click_residuals_px, r.weights)
                ]
            return out


def _prepare_frame(image) -> None:
    """The frame's oriented edges, computed in the background (app.vision.evaluate.prepare_frame)."""
    try:
        from app.vision.evaluate import prepare_frame

        prepare_frame(image)
    except Exception:  # noqa: BLE001 - only a head start: the workflow computes them when it needs them
        logging.getLogger("mcit.workflows").debug("could not prepare the frame's edges", exc_info=True)
