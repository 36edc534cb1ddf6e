"""Update pose's one-click path (issue 17): one click on the moved object, Find, Accept.

The operator's first click in Update pose (on the object where it is now, in the frozen frame) can
start an edge or, with **Find**, be the whole input: ``app.vision.search.search_pose`` searches the
poses consistent with the click — on the table (x, y, heading) when the database pose rests on the
database's table, else the full pose near the old one — scores them on the frame's edges, settles the
best on the image with the edge tracker and returns every pose that fits, ranked by fit with σ. They
are shown as ghosts (the best in white, a chooser for the others); Accept writes the chosen one with
method "search" and the click in the history. Edges clicked afterwards are assigned on the found pose
and Refine fits them together with it (the found pose and its covariance as the prior: one edge already
helps; method "search+refine").

The search runs outside the workflow's lock (the overlay keeps drawing), reports its progress
(``progress``, ``progress_text``) and stops when the workflow is cancelled; it commits only if the
clicks did not change meanwhile. A mixin of ``UpdatePose`` (app/workflows/update_pose.py).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.transforms import pose_error

from .base import MOTION_GAP_S, Step, WorkflowError, as_pixel, sigma_over
from .writing import write_pose

__all__ = ["OneClickMixin", "WEAK_FOUND_SIGMA_DEG", "WEAK_FOUND_SIGMA_MM", "WEAK_FOUND_MATCH", "NEAR_TIE_MISMATCH"]

# A found pose is weak (Accept asks once more) above these σ: the accuracy a one-click update is held to
# (bench/search.py: within 1° and 5 mm). Its σ then says the image alone does not pin the pose (a small
# box half hidden: its heading); one clicked edge and Refine usually does (refine_with_prior).
WEAK_FOUND_SIGMA_DEG = 1.0
WEAK_FOUND_SIGMA_MM = 5.0
# ... and when less than this share of its visible outline matches the image (1 − mismatch): the pose then
# rests on a small part of the object, and a pose turned behind an occluder can fit that part as well.
# Measured on bench/search.py (b), 150 placements: the right top poses matched 34-78 % (5th percentile 49 %;
# 2 of 138 below 40 %, asked once more); of the 11 wrong ones, 4 matched 33-38 % (a parallelepiped turned 90°
# behind a board, one 4° off), the others are near-ties or σ above 1°. Raised to 45 %: the box's model
# double-clicked on the cylinder (its vertical edges on the cylinder's outline) matched 41-44 % on all 5 frames
# of the workcell video, said before only as a near-tie on 3; of the 289 right top poses of seeds 0 and 1, 6
# (2 %) match less than 45 % and are asked once more.
WEAK_FOUND_MATCH = 0.45
# Found poses whose mismatch (app.vision.search._check) is within this of the best's are near-ties: said to
# the operator. Measured on bench/search.py (b), the 90 × 94 mm box: its 90° twin, when found, scored 0.01-0.26
# worse than the right pose, and where it came first 0.03-0.04 better (so it is said as a near-tie).
NEAR_TIE_MISMATCH = 0.10
MANY_TIES = 4  # this many other poses or more fitting almost as well: the click may not be on the object at all
# (bench/search.py (b), seed 0: right poses had at most 3 such; the box's model clicked on the cylinder, 5)


class OneClickMixin:
    """Find from one click (see the module docstring)."""

    found: list | None
    search_click: np.ndarray | None
    search_info: dict[str, Any] | None

    def _init_found(self) -> None:
        self.found = None  # the search's candidates (app.vision.search.SearchCandidate), best first
        self.search_click = None  # the pixel the search used
        self.search_info = None  # what the history keeps of the search
        self.found_moving = ""  # said when the object was moving in the frame the pose was found in

    # ------------------------------------------------------------------ action
    def find(self, uv=None):
        """Find the object's pose from one click on it: the pending first click (or ``uv``).

        Searches outside the lock on the workflow's frame; WorkflowError, nothing changed, when no
        pose fits ("no pose of the parallelepiped fits the image near your click"), when cancelled,
        or when the clicks changed meanwhile. Returns the candidates (best first).
        """
        from app.vision.search import Cancelled, NoPoseFits, rests_on, search_pose

        from .model_object import table_support

        with self.lock:  # snapshot
            self._check_open()
            if uv is not None:
                p = as_pixel(uv)
                if self.pending is not None or self.segs or self.points_uv or self.mode != "edge":
                    raise WorkflowError("Find uses one click on the object and no others: Remove last first")
            elif self.pending is not None and not self.segs and not self.points_uv and self.mode == "edge":
                if getattr(self, "pending_view", None) not in (None, self.view):
                    raise WorkflowError(
                        f"Find searches camera {self.view}'s frame: click {self.object_name} there (Remove last)"
                    )
                p = self.pending.copy()
            else:
                raise WorkflowError(
                    f"click once on {self.object_name} where it is now in the video, then Find "
                    "(Find uses that one click, before any edge)"
                )
            camera, model, T_db, generation = self.camera, self.obj.model, self.obj.T_world_obj, self._generation
            camera_cov = self.site.camera_cov(self.view)  # a camera calibrated in this database: its σ joins the pose's
            table = table_support(self.site)
            if table is not None and not rests_on(model, T_db, table):
                table = None  # it did not lie on the table: the full pose is searched near the old one
        image = self._frame()  # compute, outside the lock: the overlay keeps drawing
        if image is None:
            raise WorkflowError(
                f"no video frame to search in ({self._no_frame_reason()}); check the video, then Find again"
            )

        def progress(frac: float, what: str) -> None:
            self.progress, self.progress_text = float(frac), what

        if not self.finished:
            self.cancel_event.clear()  # a search stopped before (stop_measurement) does not stop this one
        # under way from now (its step refuses clicks: one made before the first progress report had become an
        # edge's point, and the found poses could then not be accepted: a new operator's second double click)
        self.progress, self.progress_text = 0.0, "searching"
        try:
            res = search_pose(
                camera,
                model,
                T_db,
                p,
                image,
                table=table,
                name=self.object_name,
                cancel=self.cancel_event.is_set,
                progress=progress,
                camera_cov=camera_cov,
            )
        except Cancelled:
            raise WorkflowError("Find cancelled: nothing was written") from None
        except NoPoseFits as exc:
            with self.lock:  # the click found nothing: it goes (the next click or double click starts afresh)
                if self._generation == generation and self.pending is not None and np.allclose(self.pending, p):
                    self.pending = None
                    self._invalidate()
                    self.state = "click_edge"
            advice = "" if self.search_only else ", or update it by clicking its edges"
            raise WorkflowError(f"{exc}{advice}. Nothing was written, and the click was dropped") from None
        except ValueError as exc:
            raise WorkflowError(f"Find failed: {exc}") from None
        finally:
            self.progress, self.progress_text = None, ""
        moving = self._moving_at(res.candidates[0].T_world_obj, camera, model)
        with self.lock:  # commit
            self._unchanged_since(generation, "Find")
            self.found_moving = moving
            self.pending = None  # the click was the search's, not an edge's start
            self.search_click = p
            self.found = list(res.candidates)
            self.candidates = [c.T_world_obj for c in res.candidates]
            self.chosen = 0
            self.matches = None
            self._invalidate()
            self.state = "found"
            where = "on the table" if res.mode == "table" else "near its old pose"
            self.search_info = {
                "click_uv": [float(p[0]), float(p[1])],
                "mode": res.mode,
                "candidates": len(res.candidates),
                "seconds": round(res.total_s, 3),
            }
            best = res.candidates[0]
            n, ties = len(res.candidates), self._near_ties()
            self.message = (
                f"{n} pose{'s' if n > 1 else ''} of {self.object_name} fit{'' if n > 1 else 's'} your click "
                f"(searched {where} in {res.total_s:.1f} s); the best fits the image's edges within "
                f"{best.fit_px:.1f} px"
                + (
                    f": {ties} other{'s' if ties > 1 else ''} fit{'' if ties > 1 else 's'} "
                    "almost as well, check the white ghost"
                    if ties
                    else (
                        (": the others fit clearly worse" if n > 2 else ": the other fits clearly worse")
                        if n > 1
                        else ""
                    )
                )
            )
            if best.beside_click:
                self.message += (
                    f". ⚠ The best lies beside your click, not under it: {self.object_name} fits the image "
                    "there far better than any pose under the click (check the white ghost)"
                )
            if moving:
                self.message += f". ⚠ {moving}"
            return self.found

    def _moving_at(self, T: np.ndarray, camera, model) -> str:
        """ "" unless the object at pose T changed between the frozen frame and the one shown just before
        it (``Workflow.moving_share``): then it was moving, and the pose found there is where it passed,
        not where it stays. The pixels: its bounding box's corners, projected, taken inside
        (``app.vision.change.inside``)."""
        from app.vision.change import CHANGED_SHARE, inside

        lo, hi = model.bounds()
        box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        X = box @ T[:3, :3].T + T[:3, 3]
        uv = camera.project(X[camera.depth(X) > 0])
        if not len(uv):
            return ""
        share = self.moving_share(inside(uv))
        if share is None or share <= CHANGED_SHARE:
            return ""
        return (
            f"{self.object_name} was moving in this frame (it differs from the frame {MOTION_GAP_S:.1f} s before): "
            "the pose found is where it passed, not where it stays; once it has stopped, "
            "press Remove last, freeze a frame (F; Seconds back reaches one where it had "
            "stopped before) and double-click it again, or Accept if it stopped there"
        )

    def _near_ties(self) -> int:
        """How many found poses besides the best match the image almost as well (mismatch within
        ``NEAR_TIE_MISMATCH`` of the best's): the ambiguity the operator is told of."""
        if not self.found:
            return 0
        m0 = self.found[0].mismatch
        return sum(c.mismatch <= m0 + NEAR_TIE_MISMATCH for c in self.found[1:])

    # ------------------------------------------------------------------ hooks for UpdatePose
    def _found_pending(self) -> bool:
        """Only the found pose is in use (no edge or point clicked since): Accept writes it."""
        return (
            self.found is not None
            and self.pending is None
            and not self.segs
            and not self.points_uv
            and self.mode == "edge"
            and self.refined is None
        )

    def _first_click_pending(self) -> bool:
        """One click made, nothing else: it can be Find's."""
        return (
            self.found is None
            and self.pending is not None
            and not self.segs
            and not self.points_uv
            and self.mode == "edge"
            and self.matches is None
        )

    def search_again(self, uv) -> None:
        """A double click at ``uv`` once poses are found: they go (with the double click's first click, an
        edge's first point by then), and ``uv`` waits for Find, as the first click of a new search (a new
        operator double-clicked again to retry at a better point: it was split into two edge points).
        WorkflowError, nothing changed, once edges or points were clicked after the search."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.found is None or self.segs or self.points_uv or self.mode != "edge":
                raise WorkflowError(
                    "a double click searches again only while no edge has been clicked since the search: "
                    "Remove last the edges first, then double-click"
                )
            self.found, self.search_info, self.found_moving = None, None, ""
            self.search_click, self.candidates, self.chosen, self.matches = None, [], None, None
            self.pending, self.pending_view = p, None
            self._invalidate()
            self.state = "click_edge_end"

    def _drop_found(self) -> bool:
        """Remove last on the found poses alone: they go, and the click (or double click) they came from
        with them — back to the start, as one Remove last undoes one double click. True if dropped."""
        if not self._found_pending():
            return False
        self.found, self.search_info, self.found_moving = None, None, ""
        self.pending, self.search_click = None, None
        self.candidates, self.chosen = [], None
        self._invalidate()
        self.state = "click_edge"
        return True

    def _found_step(self, base: set) -> Step | None:
        if not self._found_pending():
            return None
        i = self.chosen or 0
        c = self.found[i]
        n = len(self.found)
        sd = (
            f"σ {np.max(c.std_t_mm):.1f} mm, {np.max(c.std_r_deg):.2f}°"
            if np.all(np.isfinite(c.std_t_mm))
            else "σ unknown"
        )
        enabled = set(base) | {"accept", "remove_last"} | (set() if self.search_only else {"start_point"})
        choose = ""
        if n > 1:
            enabled.add("choose_candidate")
            ties = self._near_ties()
            if i > 0:
                choose = (
                    f" Pose 1 matches the image best ({100 * (1 - self.found[0].mismatch):.0f} % against "
                    f"{100 * (1 - c.mismatch):.0f} %): "
                    + "pick it back {choose_candidate} unless this one is plainly on the object."
                )
            elif ties:
                choose = (
                    f" {ties + 1} poses fit almost equally (e.g. a box of "
                    "nearly square footprint turned 90°): look closely, "
                    "pick another {choose_candidate} if the white one is not on the object."
                )
            else:
                choose = (
                    f" {n - 1} other pose{'s' if n > 2 else ''} fit{'' if n > 2 else 's'} clearly worse "
                    + "({choose_candidate})."
                )
        tail = " {accept} to write it" + (
            "." if self.search_only else f", or click edges of {self.object_name} to refine it."
        )
        return Step(
            "found",
            f"Pose {i + 1} of {n} drawn in white: the model's edges {c.fit_px:.1f} px from the image's, "
            f"{sd}." + choose + tail,
            frozenset(enabled),
        )

    def _found_labels(self) -> list[str]:
        return [
            f"#{i + 1} · {100 * (1 - c.mismatch):.0f} % matched" + (" (best)" if i == 0 else "")
            for i, c in enumerate(self.found)
        ]

    def _found_weaknesses(self) -> list[str]:
        c = self.found[self.chosen or 0]
        out = [self.found_moving] if self.found_moving else []
        sd, st = float(np.max(c.std_r_deg)), float(np.max(c.std_t_mm))
        if not (np.isfinite(sd) and np.isfinite(st)):
            out.append("the pose's uncertainty is unknown; click edges and Refine")
        elif sd > WEAK_FOUND_SIGMA_DEG or st > WEAK_FOUND_SIGMA_MM:
            out.append(
                f"the pose is uncertain ({sigma_over(sd, st, WEAK_FOUND_SIGMA_DEG, WEAK_FOUND_SIGMA_MM)}); "
                "click an edge of it and Refine"
            )
        if getattr(c, "beside_click", False):
            out.append(
                f"this pose lies beside your click, not under it (there {self.object_name} fits the image far "
                "better): check that the white ghost is on the object"
            )
        ties = self._near_ties()
        if ties >= MANY_TIES:
            out.append(
                f"{ties} other poses fit about as well: the image near your click does not single out one pose "
                f"of {self.object_name} (is the click on {self.object_name}, not on another object?); click an edge "
                "of it and Refine"
            )
        if 1.0 - c.mismatch < WEAK_FOUND_MATCH:
            out.append(
                f"only {100 * (1 - c.mismatch):.0f} % of its outline matches the image (the rest hidden, or not "
                "there): check the white ghost where the object is hidden, or click an edge of it and Refine"
            )
        return out

    def _accept_found(self):
        """Write the chosen found pose (method "search", the click in the history); None when Accept is
        for a refined pose instead."""
        with self.lock:
            self._check_open()
            if not self._found_pending():
                return None
            i = self.chosen or 0
            c = self.found[i]
            clicks = dict(self.search_info or {})
            clicks.update({"chosen": i, "frame": self.frame_record()})
            residuals = {"fit_px": c.fit_px, "support_px": c.support_px, "confidence": c.confidence}
            rec, self.obj = write_pose(
                self,
                self.obj,
                c.T_world_obj,
                c.cov,
                method="search",
                clicks=clicks,
                residuals=residuals,
                todo="Cancel, and update the pose again from its new one.",
            )
            self.accepted = True
            self.state = "accepted"
            self.message = (
                f"{self.object_name} updated (version {rec.version}): found from one click, edges {c.fit_px:.1f} px off"
            )
            return rec

    def _refine_found(self, prior, camera, clicks: dict, sigmas, generation: int):
        """Refine: the found pose and the clicks since, together (``core.pose.refine_with_prior``: the
        found pose with its covariance as the prior, so one clicked edge already helps; on the table
        its height and tilt stay as the table has them). The camera calibration's share of the found
        pose's σ (``SearchCandidate.cov_camera``) is common to the found pose and the clicks: it is taken
        out of the prior and added to the result. Runs outside the lock; WorkflowError, nothing changed,
        when the result is not plausible."""
        from dataclasses import replace

        from core.pose import plausibility, refine_with_prior

        i, T, cov, cov_camera = prior
        try:
            # the camera calibration's share is an error common to the found pose and the clicks (both
            # measured through C): the two are combined on the image's share alone, and it is added after
            result = refine_with_prior(
                camera, T, cov if cov_camera is None else cov - cov_camera, **clicks, sigma_px=sigmas
            )
        except ValueError as exc:
            raise WorkflowError(f"Refine failed: {exc}") from None
        if cov_camera is not None:
            result = replace(
                result,
                cov=result.cov + cov_camera,
                cov_parts={"found pose and clicks": result.cov, "camera calibration": cov_camera},
            )
        why = plausibility(camera, self.obj.model, result.T_world_obj, result.rms_px, 3.0 * self.sigma_px)
        if why:
            raise WorkflowError(
                f"the clicks do not agree with the found pose ({why}): check the edge assignments, or "
                "pick another found pose"
            )
        with self.lock:  # commit
            self._unchanged_since(generation, "Refine")
            self.refined = result
            self.state = "review"
            deg, m = pose_error(result.T_world_obj, T)
            sig_deg, sig_mm = float(np.max(result.std_r_deg)), 1000 * float(np.max(result.std_t_m))
            n_e, n_p = result.kinds.count("segment"), result.kinds.count("point")
            what = " and ".join(
                x
                for x in (
                    f"{n_e} edge{'s' if n_e != 1 else ''}" if n_e else "",
                    f"{n_p} point{'s' if n_p != 1 else ''}" if n_p else "",
                )
                if x
            )
            self.message = (
                f"found pose {i + 1} refined with {what}: RMS {result.rms_px:.2f} px, moved {deg:.2f}° and "
                f"{1000 * m:.1f} mm from the found pose; σ up to {sig_deg:.2f}° and {sig_mm:.1f} mm"
                + (" (camera calibration included)" if result.cov_parts else "")
            )
            return result

    def _found_summary(self, out: dict[str, Any]) -> None:
        if self.found is None:
            return
        c = self.found[self.chosen or 0]
        out["found"] = {
            "candidates": len(self.found),
            "chosen": (self.chosen or 0) + 1,
            "fit_px": round(c.fit_px, 1),
            # an axis the table holds has σ 0: said as held, not as "0" (read as certain)
            "std_t_mm": [round(float(v), 1) if v > 0 else "held by the table" for v in c.std_t_mm],
            "std_r_deg": [round(float(v), 2) if v > 0 else "held" for v in c.std_r_deg],
        }
        deg, m = pose_error(c.T_world_obj, self.obj.T_world_obj)
        out["found"]["change"] = {"deg": round(float(deg), 2), "mm": round(float(1000 * m), 1)}
