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
* ``auto_match()``: which model edge each clicked edge is, found automatically
  (app/workflows/pose_matching.py); then Refine and Accept as usual;
* ``find()``: the pose from one click on the object (app/workflows/pose_search.py); clicked edges then
  refine together with the found pose;
* edges and points clicked in another camera join the refinement (``core.pose.refine_views``);
* a refined pose is offered only if it is plausible: RMS at most 3 σ_px, the object in front of
  the camera and its projection in the image; otherwise the next candidate is refined instead
  (and the operator told), and when none fits the operator is told what to do.

The workflow is a state machine over composed parts, each with one job: the clicks and their assignment
(``core.pose.PoseClicks``), the pose pipeline (``core.pose.p3l_candidates``, ``core.pose.pipeline``), the
one-click search (``OneClickSearch``), automatic matching (``AutoMatch``), snapping (``Snapper``) and what
is shown (app/workflows/pose_presentation.py). Solve, Refine, Find and Auto match take a snapshot under
the lock, compute outside it (the overlay keeps drawing) and commit only if the clicks did not change.
"""

from __future__ import annotations

import functools
import logging
import threading
from contextlib import contextmanager

import numpy as np

from core.pose import PoseClicks, Refused, nearest_twin, p3l_candidates, plausibility
from core.pose.pipeline import Estimates, refine_starts

from . import pose_presentation as show
from .base import AS_CLICK, Workflow, WorkflowError, as_pixel, pick_radius_px
from .pose_matching import AutoMatch, Match
from .pose_search import NothingFound, OneClickSearch
from .snapping import Snapper, segment_of
from .writing import write_pose

__all__ = ["UpdatePose", "Match", "plausibility", "nearest_twin"]

MIN_SEGMENT_PX = 3.0
MAX_VIEW_GAP_S = 0.5  # clicks in two cameras are of one moment when their frames arrived this close
MAX_TRIPLES = 20  # Solve tries at most this many triples of the assigned edges (6 edges: all 20)
MAX_CANDIDATES = 8


@contextmanager
def said():
    """A click the clicks' bookkeeping refuses (``core.pose.Refused``) said to the operator (WorkflowError)."""
    try:
        yield
    except Refused as exc:
        raise WorkflowError(str(exc)) from None


def action(method):
    """An operator action: under the workflow's lock, refused once it is closed, refusals ``said``."""

    @functools.wraps(method)
    def run(self, *args, **kwargs):
        with self.lock, said():
            self._check_open()
            return method(self, *args, **kwargs)

    return run


def shown(present):
    """What the workflow shows (a function of app/workflows/pose_presentation.py), read under its lock."""

    @functools.wraps(present)
    def method(self, *args):
        with self.lock:
            return present(self, *args)

    return method


class _Of:
    """A part's attribute read (and set) as the workflow's own: ``wf.segs`` is ``wf.clicks.segs``."""

    def __init__(self, part: str, name: str = ""):
        self.part, self.name = part, name

    def __set_name__(self, owner, name: str) -> None:
        self.name = self.name or name

    def __get__(self, wf, owner=None):
        return self if wf is None else getattr(getattr(wf, self.part), self.name)

    def __set__(self, wf, value) -> None:
        setattr(getattr(wf, self.part), self.name, value)


class UpdatePose(Workflow):
    name = "update_pose"
    title = "Update pose"
    options = ("object_name",)
    actions, controls = show.ACTIONS, show.CONTROLS
    snapping = True  # Session.start passes its "Snap clicks" setting as snap=
    # the parts' state, read as the workflow's (the panel, scripts, the demo)
    segs, edge_ids, seg_views, seg_snaps, points_uv, point_snaps, pending, pending_vertex, auto = (
        _Of("clicks") for _ in range(9)
    )
    candidates, chosen, refined, last_refined = (_Of("estimates") for _ in range(4))
    T_current = _Of("estimates", "current")  # the pose the overlay assigns against (refined, last, chosen, database)
    found, search_only, progress, progress_text = (_Of("search") for _ in range(4))
    search_click, match_info = _Of("search", "click"), _Of("match", "info")
    matches, snap = _Of("match"), _Of("snapper", "on")

    def __init__(self, site, client="operator", view=None, object_name=None, loss="l2", snap=True, sigma_px=1.0):
        super().__init__(site, client, view)
        self.obj = _object(site, object_name, sigma_px)
        self.object_name, self.loss, self.sigma_px = object_name, loss, float(sigma_px)
        self.clicks = PoseClicks(self.obj.model.edges, self.obj.model.vertices, object_name)
        self.search, self.match = OneClickSearch(object_name, self.obj.model), AutoMatch(object_name)
        self.snapper, self.estimates = Snapper(self, snap), Estimates(self.obj.T_world_obj)
        self.refined_unseen = ""  # why the refined pose's outline is suspect, if it is
        self.state = "click_edge"

    # ------------------------------------------------------------------ the state
    def _offer(self, candidates: list | None = None, state: str = "review") -> None:
        """New candidates ([] none; None the same): refined poses and automatic assignments shown go."""
        self.estimates.offer(candidates)
        self.match.matches = None if candidates is not None else self.match.matches
        self.state = state

    def _clicks_changed(self, state: str | None = None) -> None:
        """A click changed: the refined pose (kept as the last refined) and automatic assignments shown go."""
        self.estimates.clicks_changed()
        if self.match.matches is not None:  # the automatic assignments shown go, with their poses
            self._offer([])
        self.state = state or ("assign_edge" if self.clicks.waiting_for_edge() else "click_edge")

    @contextmanager
    def _commit(self, generation: int, again: str):
        """Commit what was computed outside the lock, unless the workflow closed or its clicks changed since."""
        with self.lock:
            self._check_open()
            if self.estimates.generation != generation:
                raise WorkflowError(f"the clicks changed while solving: {again} again")
            yield

    # ------------------------------------------------------------------ clicks
    @action
    def click_in(self, view: str, uv) -> None:
        """A click in camera ``view``: clicks in several cameras fit one pose (``core.pose.refine_views``)."""
        try:
            view = self.site.view_name(view)
        except ValueError as exc:
            raise WorkflowError(str(exc)) from None
        self.search.check_camera(view, self.view, self.search.alone(self.clicks, self.refined))
        same_moment(self.frame_in(view) if view != self.view else None, view, self.view)
        self.clicks.check_view(view)
        self.click_view = view
        try:
            self.click(uv)
        finally:
            self.click_view = None

    @action
    def click(self, uv) -> None:
        """A click on the video; what it means depends on the step (``core.pose.PoseClicks.click``)."""
        p, view, c = as_pixel(uv), self.click_view or self.view, self.clicks
        # with no edges to click, a click replaces the one waiting for Find
        kind, what = c.click(p, view, self._click_camera(), self.T_current, pick_radius_px(self), not self.found)
        if kind == "point":
            return self.add_point(p, what)
        if kind == "segment":
            self.message = self.snapper.add_segment(c, segment_of(*what, MIN_SEGMENT_PX), view, self.sigma_px)
        self.state = {"vertex": "click_point_image", "pending": "click_edge_end"}.get(kind, self.state)
        if kind in ("segment", "assign"):
            self._clicks_changed()

    @action
    def assign_edge(self, edge: int) -> None:
        """Say which model edge (index into the model's edges) the last clicked segment is."""
        self.clicks.assign(int(edge))
        self._clicks_changed()

    @action
    def add_segment(self, seg_uv, edge: int | None = None) -> None:
        """A clicked segment (2, 2) and its model edge (for scripts); None: left for ``auto_match``."""
        for p in self.clicks.scripted(seg_uv, auto=edge is None):
            self.click(p)
        if edge is not None:
            self.assign_edge(edge)

    @action
    def start_point(self) -> None:
        """Next clicks: a model vertex in the overlay, then where it is in the video."""
        self.clicks.check_idle()
        self.clicks.mode, self.clicks.pending_vertex, self.state = "point", None, "click_point_model"

    @action
    def add_point(self, uv, vertex: int) -> None:
        """A clicked image point of model vertex ``vertex``, snapped to the image's corner."""
        view, model, T = self.click_view or self.view, self.obj.model, self.T_current
        self.message = self.snapper.add_point(self.clicks, as_pixel(uv), int(vertex), view, self.sigma_px, model, T)
        self._clicks_changed()

    @action
    def remove_last(self) -> None:
        """Undo the last click, the automatic assignments shown, or the found poses alone (and their click)."""
        c = self.clicks
        if self.search.alone(c, self.refined):
            self.search.clear(c)
            return self._offer([], "click_edge")
        if (c.mode == "point" or c.pending is not None or self.match.matches is None) and c.remove_last() == "match":
            self.match.info = None
        self._clicks_changed()

    @action
    def remove_click(self, index: int) -> None:
        """Delete click ``index`` (a row of the residual table: clicked edges, then points)."""
        what = self.clicks.remove(int(index))
        self._clicks_changed()
        self.message = f"{what} deleted; {'Refine' if self.candidates else 'click or Refine'} again."

    @action
    def refuse_snap(self) -> None:
        """Use the last click as clicked, not snapped (its raw pixels come back)."""
        self.message = self.snapper.refuse(self.clicks, self.sigma_px)
        self._clicks_changed(self.state)

    @action
    def set_snap(self, on: bool = True) -> None:
        """Snap the next clicks to the image's edges and corners (on), or use them as clicked (off)."""
        self.message = self.snapper.set(on)

    # ------------------------------------------------------------------ the pose pipeline
    def solve(self) -> list[np.ndarray]:
        """The paper's three-line solver on the assigned edges of one camera (``core.pose.p3l_candidates``)."""
        with self.lock, said():  # snapshot
            self._check_open()
            view, clicks = self.clicks.solve_clicks(self.view)
            camera, generation = self.site.camera_of(view), self.estimates.generation
        try:  # compute, outside the lock: the overlay keeps drawing
            res = p3l_candidates(camera, *clicks, max_triples=MAX_TRIPLES, max_candidates=MAX_CANDIDATES)
        except ValueError as exc:
            raise WorkflowError(f"Solve: {exc}") from None
        if not res.poses:
            raise WorkflowError(show.no_pose_fits(self.object_name, res))
        with self._commit(generation, "Solve"):
            self._offer(res.poses)
            self.message = show.solve_message(len(res.poses), len(res.triples), len(clicks[0]))
            return self.candidates

    @action
    def choose_candidate(self, index: int) -> None:
        """Use candidate ``index`` (0 = best) as the estimate."""
        self.estimates.choose(int(index))

    def refine(self):
        """Every click of every camera fitted from the pipeline's starts (``core.pose.pipeline.refine_starts``)."""
        with self.lock:  # snapshot
            self._check_open()
            self.match.check_confirmed()
            views, clicks = self.clicks.views_clicks(self.site.camera_of, self.view)
            starts = self.estimates.starts(self.search.start(self.chosen or 0, views))  # the found pose alone, if any
            generation = self.estimates.generation
            fit = dict(model=self.obj.model, camera=self.camera, max_rms_px=3 * self.sigma_px, loss=self.loss)
            fit.update(self.site.pose_priors(self.clicks.fitted_views(), self.obj))  # the views as ``clicks``
        out = refine_starts(clicks, starts, **fit)
        if out.result is None:
            raise WorkflowError(show.no_plausible(starts, out.failures))
        unseen = show.unseen_outline(self.snapper.frame(), self.camera, self.obj.model, out.result.T_world_obj)
        with self._commit(generation, "Refine"):
            self.estimates.adopt(out.result, starts[out.start])
            self.refined_unseen, self.state = unseen, "review"
            self.message = show.refine_message(self, out.result, starts[out.start], out.failures, unseen, views)
            return out.result

    def accept(self):
        """Write the refined pose (refining first if needed), or the found pose alone, in one transaction."""
        with self.lock:
            self._check_open()
            unrefined = self.refined is None and not self.search.alone(self.clicks, self.refined)
        if unrefined:
            self.refine()  # outside the lock, as Refine is
        with self.lock:
            self._check_open()
            if self.refined is None and not self.search.alone(self.clicks, self.refined):
                raise WorkflowError("the clicks changed while solving: Accept again")
            rec, todo = show.history_record(self), "Cancel, and update the pose again from its new one."
            written, self.obj = write_pose(self, self.obj, rec.pop("T_world_obj"), rec.pop("cov"), todo=todo, **rec)
            self.accepted, self.state = True, "accepted"
            self.message = show.accepted_words(self, written.version)
            return written

    # ------------------------------------------------------------------ one click, automatic matching
    def find(self, uv=None):
        """The object's pose from one click on it: the pending first click, or ``uv`` (``OneClickSearch``)."""
        with self.lock:  # snapshot
            self._check_open()
            p = self.search.click_for(uv, self.clicks, self.view)
            job, generation = self.search.job(self.site, self.view, self.obj), self.estimates.generation
            self.cancel_event.clear()  # a search stopped before (stop_measurement) does not stop this one
        try:
            res = self.search.run(job, p, self.snapper, self.cancel_event.is_set)
        except NothingFound:
            with self.lock:  # the click found nothing: it goes (the next click or double click starts afresh)
                if self.estimates.generation == generation and self.clicks.drop_pending(p):
                    self._offer(state="click_edge")
            raise
        moving = self.search.moving_at(res.candidates[0].T_world_obj, job, self.frame)
        with self._commit(generation, "Find"):
            self.clicks.pending = None  # the click was the search's, not an edge's start
            self.message = self.search.adopt(res, p, moving)
            self._offer([c.T_world_obj for c in res.candidates], "found")
            return self.search.found

    @action
    def search_again(self, uv) -> None:
        """A double click at ``uv`` once poses are found: they go, and ``uv`` waits for Find."""
        self.search.again(self.clicks, as_pixel(uv))
        self._offer([], "click_edge_end")

    @action
    def auto_assign(self, on: bool = True) -> None:
        """Automatic assignment on: clicked edges wait for ``auto_match`` (off: each is assigned by hand)."""
        self.clicks.set_auto(on)
        if not on or (self.clicks.mode == "edge" and self.clicks.pending is None):
            self.state = "assign_edge" if self.clicks.waiting_for_edge() else "click_edge"
        self.message = show.AUTO_ASSIGN_WORDS[bool(on)]

    def auto_match(self):
        """Which model edge is each clicked edge (``AutoMatch``)? With fewer than 3: automatic assignment on."""
        with self.lock:  # snapshot
            self._check_open()
            if not self.match.check(self.clicks, self.view):
                return self.auto_assign(True)
            job = self.match.job(self.clicks, self.camera, self.obj, self.sigma_px)
            generation = self.estimates.generation
        kept, message = self.match.run(job, self.snapper.frame())
        with self._commit(generation, "Auto match"):
            self._offer([m.T_world_obj for m in kept], "match")
            self.match.matches, self.message = kept, message
            return kept

    @action
    def confirm_match(self) -> None:
        """Adopt the shown automatic assignment (the chosen candidate's): then Refine and Accept."""
        edges, self.message = self.match.confirm(self.chosen or 0)
        self.clicks.assign_all(edges)
        self._offer(state="review")

    def on_double_click(self, view: str, uv) -> str | None:
        """A double click on the moved object finds its pose from there (Find; found poses: again, from there)."""
        if self.search.double_click(view, self.view):  # poses found: search again from this point
            self.search_again(uv)
        return "find" if "find" in self.current_step().enabled else AS_CLICK

    def use_frame(self, frame) -> None:
        """Work on ``frame``; its oriented edges (auto match and the search read them) are readied meanwhile."""
        super().use_frame(frame)
        ready_edges(frame)

    # ------------------------------------------------------------------ what is shown (pose_presentation)
    _step, summary, weaknesses = shown(show.step), shown(show.summary), shown(show.weaknesses)
    choices, choice_value = shown(show.choices), shown(show.choice_value)
    candidate_labels = shown(show.candidate_labels)
    marks = marks_in = shown(show.marks)


def _object(site, object_name: str | None, sigma_px: float):
    """The object to update (the site's snapshot of it); WorkflowError when none is selected, it is not in
    the database, or it has neither straight edges to click nor an outline to find, or for a click noise
    ``sigma_px`` (pixels) that is not positive."""
    if not sigma_px > 0:
        raise WorkflowError(f"sigma_px (the clicks' noise, pixels) must be positive, got {sigma_px}")
    if object_name is None:
        raise WorkflowError("Update pose: select the object first")
    try:
        obj = site.object(object_name)
    except KeyError as exc:
        raise WorkflowError(str(exc.args[0])) from None
    if not len(obj.model.edges) and not obj.model.solids:
        raise WorkflowError(f"{object_name} has neither straight edges nor an outline to find: model it again instead")
    return obj


def same_moment(ref, view: str, own: str) -> None:
    """WorkflowError when camera ``view``'s frame (``ref``: its FrameRef frozen with camera ``own``'s, or
    None) arrived more than ``MAX_VIEW_GAP_S`` from the frozen one: an object that moved would be in two places."""
    if ref is not None and abs(ref.gap_s) > MAX_VIEW_GAP_S:
        raise WorkflowError(
            f"camera {view}'s frame nearest the frozen one arrived {abs(ref.gap_s):.1f} s "
            f"{'after' if ref.gap_s > 0 else 'before'} it: an object that moved would be in two places. "
            f"Freeze again (F) while both cameras show the video, or click in camera {own} alone"
        )


def ready_edges(frame) -> None:
    """Compute ``frame``'s oriented edges in the background (``app.vision.evaluate.prepare_frame``): auto match
    and the search read them, and the operator's first Auto match or double click then need not wait."""
    if frame is not None:
        threading.Thread(target=_prepare_frame, args=(frame.image,), daemon=True, name="mcit-frame-edges").start()


def _prepare_frame(image) -> None:
    try:
        from app.vision.evaluate import prepare_frame

        prepare_frame(image)
    except Exception:  # noqa: BLE001 - only a head start: the workflow computes them when it needs them
        logging.getLogger("mcit.workflows").debug("could not prepare the frame's edges", exc_info=True)
