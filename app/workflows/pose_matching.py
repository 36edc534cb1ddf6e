"""Update pose's automatic matching: which model edge is each clicked image edge (beyond the paper).

``auto_match()``: with three or more (four is best) clicked edges not assigned by hand, every
assignment to model edges is tried (``app.vision.matching.match_edges`` on the frozen frame) and
the plausible ones ranked; the best is shown with its edge labels, the others as ghosts
(``choose_candidate``); ``confirm_match()`` adopts the shown assignment, then Refine and Accept as
usual. The first ``auto_match()`` with fewer than three edges switches to automatic assignment
(``auto_assign()``): clicked edges then wait for the match instead of a model edge. Of the
assignments that draw the same picture (a symmetric model) the one nearest the database pose is
kept (``core.pose.nearest_twin``).

A mixin of ``UpdatePose`` (app/workflows/update_pose.py): it uses its clicks (``segs``,
``edge_ids``, ``seg_snaps``), its candidates and its snapshot/commit discipline.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from core.pose import nearest_twin, plausibility

from .base import WorkflowError

__all__ = ["AutoMatchMixin", "Match", "SNAPPED_SIGMA_PX", "IMAGE_GATE_PX"]

SNAPPED_SIGMA_PX = 0.3  # the click noise automatic matching assumes when every segment is snapped
IMAGE_GATE_PX = 3.0  # a matched pose whose edges lie farther than this from the image's (mean) fits the clicks only


@dataclass(frozen=True)
class Match:
    """One automatic assignment: ``T_world_obj`` (4, 4) refined on the clicks, ``edges`` (S,) the
    model edge of each clicked segment, ``rms_px`` of the clicks to their edges, ``image_px`` mean
    distance of the whole projected model to the image's edges (NaN without a frame)."""

    T_world_obj: np.ndarray
    edges: np.ndarray
    rms_px: float
    image_px: float


class AutoMatchMixin:
    """Automatic assignment for Update pose (see the module docstring)."""

    matches: list[Match] | None
    match_info: dict[str, Any] | None

    # ------------------------------------------------------------------ automatic matching
    def auto_assign(self, on: bool = True) -> None:
        """Automatic assignment on: clicked edges wait for ``auto_match`` instead of a model edge
        (off: back to assigning each by hand)."""
        with self.lock:
            self._check_open()
            if not on and sum(e is None for e in self.edge_ids[:-1]):
                raise WorkflowError(
                    "some clicked edges are not assigned: Auto match them, or Remove last, before assigning by hand"
                )
            self.auto = bool(on)
            if self.auto and self.mode == "edge" and self.pending is None:
                self.state = "click_edge"
            elif not self.auto:
                self.state = "assign_edge" if self._waiting_for_edge() else "click_edge"
            self.message = (
                "Automatic matching: click 3 or more image edges (4 is best), two points each, without "
                "assigning them; then Auto match."
                if self.auto
                else "Assign each clicked edge by hand."
            )

    def auto_match(self):
        """Which model edge is each clicked edge? Every assignment is tried on the frame and ranked.

        With fewer than 3 clicked edges: switches to automatic assignment (``auto_assign``) and
        says what to click. Otherwise ``app.vision.matching.match_edges`` on all clicked edges (hand
        assignments are kept: only assignments agreeing with them count) and the frame the operator
        clicked on; the plausible assignments become the candidates, the best shown; the operator
        confirms one (``confirm_match``). Returns the list of ``Match`` (or None when switching).
        """
        from app.vision.matching import match_edges

        with self.lock:
            self._check_open()
            if any(v != self.view for v in getattr(self, "seg_views", ())):
                raise WorkflowError(
                    f"automatic matching works on camera {self.view}'s frame alone: say which model edge each edge "
                    "clicked in another camera is (click it on the wireframe), or Remove last"
                )
            if self.pending is not None or self.mode == "point":
                raise WorkflowError("finish the click under way first (or Remove last)")
            if len(self.segs) < 3:
                if not self.auto:
                    self.auto_assign(True)
                    return None
                raise WorkflowError(
                    f"{len(self.segs)} edge{'s' if len(self.segs) != 1 else ''} clicked: automatic "
                    "matching needs 3 (4 or more is best); click more image edges"
                )
            if all(e is not None for e in self.edge_ids):
                raise WorkflowError("every clicked edge is assigned already: Solve or Refine")
            segs = np.array(self.segs)
            snapped = all(s is not None and s.applied for s in self.seg_snaps)
            sigma = SNAPPED_SIGMA_PX if snapped else self.sigma_px
            hand = {j: e for j, e in enumerate(self.edge_ids) if e is not None}  # kept: only agreeing assignments count
            camera, model, T_db, generation = self.camera, self.obj.model, self.obj.T_world_obj, self._generation
        image = self._frame()  # compute, outside the lock: the overlay keeps drawing
        try:
            res = match_edges(camera, model, segs, image=image, sigma_px=sigma)
        except ValueError as exc:
            raise WorkflowError(f"automatic matching failed: {exc}") from None
        kept: list[Match] = []
        for c in res.candidates:
            twin = nearest_twin(model, c.T_world_obj, np.asarray(c.edges), T_db, hand)
            if twin is None or plausibility(camera, model, twin[0]):
                continue
            kept.append(Match(twin[0], twin[1], float(c.rms_px), float(c.image_px)))
        if not kept:
            raise WorkflowError(
                f"no assignment of the {len(segs)} clicked edges to {self.object_name}'s edges fits "
                "(with your hand assignments): check the clicks (Remove last), click another edge "
                "(4 or more, not all through one point), or assign them by hand"
            )
        # With the frame, poses whose whole drawing misses the image's edges fit the clicks only: drop them,
        # unless nothing else is left (then they are shown, with a warning).
        on_image = [mt for mt in kept if mt.image_px <= IMAGE_GATE_PX]
        warning = ""
        if image is not None and on_image:
            kept = on_image
        elif image is not None:
            warning = (
                f" None lies on the image's edges (the best is {min(mt.image_px for mt in kept):.1f} px off on "
                "average): check the clicks and any hand assignment."
            )
        with self.lock:  # commit
            self._unchanged_since(generation, "Auto match")
            self.matches = kept
            self.candidates = [m.T_world_obj for m in kept]
            self.chosen = 0
            self._invalidate()
            self.state = "match"
            self._match_s = res.total_s
            self.message = (
                f"{len(kept)} way{'s' if len(kept) > 1 else ''} of pairing your edges with the model's "
                f"edges fit{'' if len(kept) > 1 else 's'} ({res.total_s:.1f} s); the best is drawn, each clicked "
                "edge labelled with its model edge: Confirm match, or choose another candidate" + warning
            )
            return kept

    def confirm_match(self) -> None:
        """Adopt the shown automatic assignment (the chosen candidate's): then Refine and Accept."""
        with self.lock:
            self._check_open()
            if not self.matches:
                raise WorkflowError("no automatic assignment to confirm: click 3 or more edges and Auto match first")
            i = self.chosen or 0
            m = self.matches[i]
            self._match_undo.append(list(self.edge_ids))
            self.edge_ids = [int(e) for e in m.edges]
            self._done.append("match")
            self.match_info = {
                "candidate": i + 1,
                "of": len(self.matches),
                "rms_px": m.rms_px,
                "image_px": None if not np.isfinite(m.image_px) else m.image_px,
                "edges": [int(e) for e in m.edges],
            }
            self.matches = None
            self._invalidate()
            self.state = "review"
            self.message = (
                f"Assignment {i + 1} confirmed: segments "
                f"{', '.join(f'{j + 1}→e{e}' for j, e in enumerate(self.edge_ids))}. Refine, then Accept."
            )
