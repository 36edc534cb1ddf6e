"""Track a known object in the video and write its tracked pose (beyond the paper: docs/beyond.md).

Started on a known object (``object_name``, default: the selection), the workflow follows it from
its database pose, frame by frame, on the image's edges (``app.vision.track.EdgeTracker``: the
"moving edges" tracker with the robust small-motion pose step). Each ``step`` takes the frame at
the scene time (``Site.frame_at``) or the frame given — the interface feeds it every new video
frame from a worker thread — and updates the tracked pose, its confidence and the edge points
that support it (``marks``).

When the tracker is lost (too few edges found, a jump, a failed step) it stops and says so:
nothing is written while lost. The operator then clicks three or more of the object's image edges
(two clicks each, snapped to the image) and ``reinit()`` finds the pose from them on the current
frame (automatic matching, ``app.vision.matching.match_edges``: no need to say which edge is
which) and tracking resumes; or ``restart()`` resumes from the last good pose. ``pause()`` stops
following (clicks are then accepted too), ``resume()`` goes on.

``accept()`` writes the tracked pose (one transaction, version check, method "tracking", the
frames tracked, the last confidence and residual, any re-initialisation's clicks in the history).
"""

from __future__ import annotations

import copy
from typing import Any

import numpy as np

from core.pose import nearest_twin, plausibility
from core.pose.uncertainty import Priors
from core.transforms import pose_error

from .base import CANCEL, Control, Ghost, Marks, Step, Workflow, WorkflowError, as_pixel
from .pose_matching import SNAPPED_SIGMA_PX
from .snapping import ClickSnap, SnapMixin, snap_marks
from .update_pose import MIN_SEGMENT_PX
from .writing import write_pose

__all__ = ["TrackObject"]


class TrackObject(SnapMixin, Workflow):
    name = "track"
    title = "Track"
    follows_video = True
    options = ("object_name",)
    actions = (
        "step",
        "pause",
        "resume",
        "restart",
        "click",
        "add_segment",
        "remove_last",
        "reinit",
        "accept",
        "cancel",
        "refuse_snap",
        "set_snap",
    )
    controls = (
        Control("pause", "Pause", "space", hint="Stop following the video (the tracked pose stays)"),
        Control("resume", "Resume", "space", hint="Follow the video again"),
        Control(
            "reinit",
            "Re-initialise",
            "I",
            kind="long",
            color="blue",
            hint="Find the pose from the clicked edges on this frame, then track on",
        ),
        Control("restart", "Restart", "T", hint="Track on from the last good pose"),
        Control("accept", "Accept", "enter", color="green", hint="Write the tracked pose to the database"),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last edge as clicked, not moved onto the image's edge"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click"),
        CANCEL,
    )

    def __init__(
        self,
        site,
        client: str = "operator",
        view: str | None = None,
        object_name: str | None = None,
        snap: bool = True,
        sigma_px: float = 1.0,
        **tracker_options: Any,
    ):
        from app.vision.track import EdgeTracker

        super().__init__(site, client, view)
        self._init_snap(snap)
        if object_name is None:
            raise WorkflowError("Track: select the object first")
        try:
            self.obj = site.object(object_name)
        except KeyError as exc:
            raise WorkflowError(str(exc.args[0])) from None
        self.object_name = object_name
        self.sigma_px = float(sigma_px)
        try:
            self.tracker = EdgeTracker(self.camera, self.obj.model, self.obj.T_world_obj, **tracker_options)
        except (TypeError, ValueError) as exc:
            raise WorkflowError(f"Track: cannot track {object_name}: {exc}") from None
        # each frame's σ holds the camera's calibration (or its file's prior) and the model's prior (issue 27)
        self.tracker.priors = Priors(site.pose_camera_cov(view), self.obj.model_sigma_m)
        self.T_world_obj = self.obj.T_world_obj.copy()  # the last good pose
        self.cov: np.ndarray | None = None
        self.confidence: float | None = None
        self.rms_px = float("nan")
        self.diagnostics = None
        self.diagnostics_good = None  # the last good frame's (what Accept writes is that frame's)
        self.frames = 0
        self.t_first: float | None = None
        self.t_last: float | None = None
        self.t_good: float | None = None  # the scene time of the last good pose (T_world_obj), None before one
        self.confidence_good: float | None = None
        self.t_lost: float | None = None
        self.lost = False
        self.lost_count = 0  # how many times it was lost (the interface notifies on each)
        self.reason = ""
        self.paused = False
        self.segs: list[np.ndarray] = []  # re-initialisation clicks
        self._generation = 0  # moves whenever the tracker's state is set: a step computed meanwhile is dropped
        self.seg_snaps: list[ClickSnap | None] = []
        self.pending: np.ndarray | None = None
        self.reinits: list[dict[str, Any]] = []
        self.stamp_good: float | None = None  # when the image of the last good pose was taken (unix seconds)
        # the video frame (its index) whose pose the tracker holds after a re-initialisation on a frozen frame: the
        # interface tracks on through the frames kept after it, not from the newest (the video moved on)
        self.resume_index: int | None = None
        self.state = "tracking"

    # ------------------------------------------------------------------ tracking
    @property
    def following(self) -> bool:
        """True while frames are followed (not paused, not lost, not finished)."""
        return not (self.paused or self.lost or self.finished)

    def follows_live(self) -> str:
        return f"{self.title} follows the live video: nothing to freeze (Pause it first)" if self.following else ""

    def step(self, frame=None, t_s: float | None = None, stamp: float | None = None, ref=None):
        """Follow the object into one frame: ``frame`` (an image of the camera's size, taken at ``stamp``, unix
        seconds, when known) or the site's frame at ``t_s`` (default: the scene time now); ``ref``: the caller's
        frame it is (kept as ``stepped_on`` with the step: lost or paused, the frame frozen is the one it stopped on,
        not the newest). Returns
        ``app.vision.track.TrackResult``; when it is lost the result says so (and the message what to do).

        The tracking itself runs outside the workflow's lock (on a copy of the tracker), so that
        the overlay's ``marks()`` never waits for it; its result is kept only if nothing reset the
        tracker meanwhile (Restart, Re-initialise, Pause, another step, Accept or Cancel), else
        dropped (the result is returned, nothing is changed)."""
        with self.lock:  # snapshot
            self._check_open()
            if self.lost:
                raise WorkflowError(
                    f"tracking is lost ({self.reason}): click three or more edges of {self.object_name} "
                    "and Re-initialise, or Restart from the last good pose"
                )
            if self.paused:
                raise WorkflowError("tracking is paused: Resume first")
            generation = self._generation
            worker = copy.copy(self.tracker)  # track() replaces its state (pose, polarities), never mutates it
        t = self.site.time_s() if t_s is None else float(t_s)
        image = self.site.frame_at(t, self.view) if frame is None else np.asarray(frame)
        if image is None:
            raise WorkflowError(f"no video frame at t = {t:.2f} s: tracking needs the video")
        try:  # compute, unlocked
            res = worker.track(image)
        except ValueError as exc:
            raise WorkflowError(f"cannot track on this frame: {exc}") from None
        with self.lock:  # commit
            if generation != self._generation or self.finished or self.paused or self.lost:
                return res
            self._generation += 1
            self.tracker = worker
            self.stepped_on = ref
            self.frames += 1
            self.diagnostics = self.tracker.diagnostics
            self.confidence = float(res.confidence)
            jumped = self.t_last is not None and t < self.t_last - 0.5  # before the last frame: the video restarted
            self.t_first = t if self.t_first is None else self.t_first
            self.t_last = t
            if res.lost:
                self.lost = True
                self.lost_count += 1
                self.reason = self.diagnostics.reason if self.diagnostics is not None else "lost"
                if jumped:
                    self.reason += (
                        " — the video jumped back in time (a recording restarting, or a stream that "
                        "reconnected): the object is where that frame shows it"
                    )
                self.state = "lost"
                self.t_lost = t
                # the reason and what to do are the instruction's (said three times, it filled 20 lines)
                self.message = f"Lost at t = {t:.2f} s. Nothing is written while lost."
            else:
                self.t_good, self.confidence_good = t, float(res.confidence)
                self.stamp_good = stamp if stamp is not None else self.seen_at()
                self.T_world_obj = res.T_world_obj.copy()
                self.cov = None if self.diagnostics.cov is None else self.diagnostics.cov.copy()
                self.rms_px = float(self.diagnostics.rms_px)
                self.diagnostics_good = self.diagnostics
                self.state = "tracking"
            return res

    def pause(self) -> None:
        """Stop following frames (the tracked pose stays; clicks for a re-initialisation are taken)."""
        with self.lock:
            self._check_open()
            self.paused = True
            self._generation += 1
            self.state = "paused"
            self.message = "Paused: Resume, Accept the tracked pose, or click edges and Re-initialise."

    def resume(self) -> None:
        """Follow frames again from the tracked pose."""
        with self.lock:
            self._check_open()
            if self.lost:
                raise WorkflowError("tracking is lost: Re-initialise (click edges) or Restart")
            self.paused = False
            self.state = "tracking"
            self.message = ""

    def restart(self) -> None:
        """Resume from the last good pose (e.g. after an occlusion has passed)."""
        with self.lock:
            self._check_open()
            self.tracker.reset(self.T_world_obj)
            self._generation += 1
            self.lost = self.paused = False
            self.reason = ""
            self.state = "tracking"
            self.message = "Restarted from the last good pose."

    # ------------------------------------------------------------------ re-initialisation
    def click(self, uv) -> None:
        """First or second end of an image edge of the object (while lost or paused)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.following:
                raise WorkflowError("clicks re-initialise a lost track: Pause first to click edges")
            if self.pending is None:
                self.pending = p
                return
            seg, snap = self._finish_segment(self.pending, p, MIN_SEGMENT_PX)
            self.pending = None
            self.segs.append(seg)
            self.seg_snaps.append(snap)
            self.message = self._snap_message(f"Edge {len(self.segs)}", snap)

    def add_segment(self, seg_uv) -> None:
        """A clicked segment (2, 2) at once (for scripts)."""
        self._click_segment(seg_uv)

    def remove_last(self) -> None:
        """Drop the pending click, or else the last clicked edge."""
        with self.lock:
            self._check_open()
            if self.pending is not None:
                self.pending = None
            elif self.segs:
                self.segs.pop()
                self.seg_snaps.pop()

    def _last_snap(self):
        if not self.segs:
            return None, None
        i = len(self.segs) - 1
        return self.seg_snaps[i], lambda raw: self.segs.__setitem__(i, raw)

    def reinit(self):
        """The pose from the clicked edges on the current frame (every assignment tried), then track on."""
        from app.vision.matching import match_edges

        with self.lock:
            self._check_open()
            if len(self.segs) < 3:
                raise WorkflowError(
                    f"{len(self.segs)} edges clicked: click three or more edges of {self.object_name} "
                    "(4 is best), two clicks each, then Re-initialise"
                )
            image = self._frame()
            snapped = all(s is not None and s.applied for s in self.seg_snaps)
            try:
                res = match_edges(
                    self.camera,
                    self.obj.model,
                    np.array(self.segs),
                    image=image,
                    sigma_px=SNAPPED_SIGMA_PX if snapped else self.sigma_px,
                )
            except ValueError as exc:
                raise WorkflowError(f"cannot re-initialise: {exc}") from None
            for c in res.candidates:
                twin = nearest_twin(self.obj.model, c.T_world_obj, c.edges, self.T_world_obj)
                if twin is not None and not plausibility(self.camera, self.obj.model, twin[0]):
                    break
            else:
                raise WorkflowError(
                    f"no pose of {self.object_name} fits the {len(self.segs)} clicked edges: check them "
                    "(Remove last), click another edge (4 or more, not all through one point)"
                )
            T, edges = twin
            at = self.frame  # the frozen frame the edges were clicked on (None: the site's frame now)
            self.reinits.append(
                {
                    "t_s": self.site.time_s() if at is None else float(at.t_s),
                    "segs_uv": np.array(self.segs).tolist(),
                    "edges": [int(e) for e in edges],
                    "rms_px": float(c.rms_px),
                    "snaps": [None if s is None else s.record() for s in self.seg_snaps],
                }
            )
            self.tracker.reset(T)
            self._generation += 1
            self.T_world_obj = T.copy()
            self.t_good = self.reinits[-1]["t_s"]
            self.resume_index = None if at is None or at.index < 0 else int(at.index)
            self.segs, self.seg_snaps, self.pending = [], [], None
            self.lost = self.paused = False
            self.reason = ""
            self.state = "tracking"
            self.message = (
                f"Re-initialised from {len(edges)} edges (model edges {', '.join(f'e{e}' for e in edges)}, "
                f"RMS {c.rms_px:.2f} px): tracking again."
            )
            return T

    # ------------------------------------------------------------------ accept
    def accept(self):
        """Write the tracked pose (one transaction, method "tracking"). While lost, its last good pose
        (the panel asks once more: ``weaknesses``; a run lost at a recording's restart had tracked the
        object to its rest first), with the loss recorded; refused when none was tracked before the loss."""
        with self.lock:
            self._check_open()
            if self.lost and self.t_good is None:
                raise WorkflowError(
                    f"the track is lost ({self.reason}) and no frame was tracked before: nothing written. "
                    "Re-initialise (click edges) or Restart, or Cancel"
                )
            if self.frames == 0:
                raise WorkflowError("no frame has been tracked yet: wait for the video (or step), then Accept")
            clicks = {"reinit": self.reinits} if self.reinits else None
            measurements = {"frames": self.frames, "t_first_s": self.t_first, "t_last_s": self.t_good}
            if self.lost:
                measurements.update(lost_at_s=self.t_lost, lost_reason=self.reason)
            residuals = {"confidence": self.confidence_good, "rms_px": self.rms_px}
            d = self.diagnostics_good  # the written pose's frame's, not a lost frame's after it
            if d is not None:
                residuals.update(n_samples=int(d.n_samples), n_inliers=int(d.n_inliers))
            T, cov = self.T_world_obj.copy(), None if self.cov is None else self.cov.copy()
            rec, self.obj = write_pose(
                self,
                self.obj,
                T,
                cov,
                method="tracking",
                seen_at=self.stamp_good,
                clicks=clicks,
                measurements=measurements,
                residuals=residuals,
                todo="Cancel, and Track again from its new pose.",
            )
            self.accepted = True
            self.state = "accepted"
            self.message = (
                f"{self.object_name} updated from tracking (version {rec.version}): {self.frames} frames, "
                f"confidence {100 * (self.confidence_good or 0):.0f} %"
                + (f"; its last good pose, at t = {self.t_good:.2f} s (lost after)" if self.lost else "")
            )
            return rec

    def weaknesses(self) -> list[str]:
        with self.lock:
            if self.lost and self.t_good is not None and not self.finished:
                return [
                    f"the track was lost at t = {self.t_lost:.2f} s ({self.reason}): Accept writes its last good "
                    f"pose, tracked at t = {self.t_good:.2f} s; where {self.object_name} is since, the track cannot say"
                ]
            return []

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        base = {"cancel"} | ({"remove_last"} if (self.pending is not None or self.segs) else set())
        snap, _ = self._last_snap()
        if snap is not None and snap.applied and self.pending is None:
            base.add("refuse_snap")
        if self.pending is not None:
            return Step("click_end", "Click the other end of that edge.", frozenset(base))
        n = len(self.segs)
        reinit = {"reinit"} if n >= 3 else set()
        # named before its button shows (the third edge brings it): said so, not looked for in vain
        later = "Re-initialise (its button comes with the third edge)"
        then = "then {reinit}" if reinit else f"then {later}"
        if self.lost:
            more = f" ({n} clicked)" if n else ""
            acc = {"accept"} if self.t_good is not None else set()
            last = (
                " from the last good pose, or {accept} that pose" + f" (t = {self.t_good:.2f} s)."
                if acc
                else " from the last good pose."
            )
            return Step(
                "lost",
                f"Lost: {self.reason}. Click three or more edges of {self.object_name}, two clicks each{more}, "
                f"{then}; or " + "{restart}" + last,
                frozenset(base | reinit | acc | {"restart"}),
            )
        if self.paused:
            acc = {"accept"} if self.frames else set()
            return Step(
                "paused",
                "Paused: {resume}, "
                + ("{accept} the tracked pose, " if acc else "")
                + f"or click three or more edges and {'{reinit}' if reinit else later}.",
                frozenset(base | acc | reinit | {"resume"}),
            )
        if self.frames == 0:
            return Step(
                "waiting",
                f"Tracking {self.object_name} from its database pose: waiting for the next frame ({{pause}} stops).",
                frozenset(base | {"pause"}),
                clicks=False,
            )
        return Step(
            "tracking",
            f"Tracking {self.object_name}: confidence {100 * (self.confidence or 0):.0f} %{self._fit_text()}. "
            "A tracked pose can be wrong where the image does not show it: check the wireframe, then "
            "{accept} writes the tracked pose; {pause} to stop.",
            frozenset(base | {"accept", "pause"}),
            clicks=False,
        )

    def _fit_text(self) -> str:
        """How well the last tracked pose fits the frame: its edges' mean distance from the image's and
        the pose's σ (largest axis), e.g. ", edges 0.6 px off, σ 1.2 mm / 0.10°"; "" before a frame."""
        d = self.diagnostics
        if d is None or not np.isfinite(getattr(d, "edge_distance_px", np.nan)):
            return ""
        text = f", edges {d.edge_distance_px:.1f} px off"
        if self.cov is not None and np.all(np.isfinite(self.cov)):
            s_t = float(np.sqrt(max(np.linalg.eigvalsh(self.cov[:3, :3]).max(), 0.0)))
            s_r = float(np.degrees(np.sqrt(max(np.linalg.eigvalsh(self.cov[3:, 3:]).max(), 0.0))))
            text += f", σ {1000 * s_t:.1f} mm / {s_r:.2f}°"
        return text

    def marks(self) -> Marks:
        with self.lock:
            m = Marks(selected=self.object_name)
            label = "LOST" if self.lost else (f"{100 * self.confidence:.0f} %" if self.confidence is not None else "")
            m.tracked = [
                Ghost(self.obj.model, self.T_world_obj, f"{self.object_name} {label}".strip(), chosen=not self.lost)
            ]
            d = self.diagnostics
            if d is not None and len(d.matched_uv):
                found = np.all(np.isfinite(d.matched_uv), axis=1)
                m.found_points = d.matched_uv[found & (d.weights >= 0.5)]
                m.rejected_points = d.matched_uv[found & (d.weights < 0.5)]
            cam = self.camera
            X = (
                self.obj.model.vertices @ self.T_world_obj[:3, :3].T + self.T_world_obj[:3, 3]
                if len(self.obj.model.vertices)
                else self.T_world_obj[:3, 3].reshape(1, 3)
            )
            X = X[cam.depth(X) > 0]
            if len(X) and label:
                uv = cam.project(X)
                m.labels = [(np.array([uv[:, 0].mean(), uv[:, 1].max() + 14.0]), f"tracked {label}")]
            if self.segs:
                m.segments = np.array(self.segs)
                m.labels += [((s[0] + s[1]) / 2, str(i + 1)) for i, s in enumerate(self.segs)]
            if self.pending is not None:
                m.pending = self.pending.reshape(1, 2)
            m.raw_segments, _, _, snap_labels = snap_marks(self.seg_snaps)
            m.labels += snap_labels
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {
                "object": self.object_name,
                "state": (
                    "accepted"
                    if self.accepted
                    else "cancelled"
                    if self.cancelled
                    else "lost"
                    if self.lost
                    else "paused"
                    if self.paused
                    else "tracking"
                ),
                "frames": self.frames,
            }
            if self.confidence is not None:
                out["confidence"] = self.confidence
            if np.isfinite(self.rms_px):
                out["rms_px"] = self.rms_px
            d = self.diagnostics
            if d is not None:
                out["edge points"] = f"{d.n_inliers} kept of {d.n_samples}"
            if self.lost:
                out["reason"] = self.reason
            deg, m = pose_error(self.T_world_obj, self.obj.T_world_obj)
            out["change"] = {"deg": float(deg), "mm": float(1000 * m)}
            if self.reinits:
                out["re-initialised"] = len(self.reinits)
            return out
