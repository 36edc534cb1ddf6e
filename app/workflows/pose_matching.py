"""Update pose's automatic matching: which model edge is each clicked image edge (beyond the paper).

``auto_match()``: with three or more (four is best) clicked edges not assigned by hand, every
assignment to model edges is tried (``app.vision.matching.match_edges`` on the frozen frame) and
the plausible ones ranked; the best is shown with its edge labels, the others as ghosts
(``choose_candidate``); ``confirm_match()`` adopts the shown assignment, then Refine and Accept as
usual. The first ``auto_match()`` with fewer than three edges switches to automatic assignment
(``auto_assign()``): clicked edges then wait for the match instead of a model edge. Of the
assignments that draw the same picture (a symmetric model) the one nearest the database pose is
kept (``core.pose.nearest_twin``).

``AutoMatch`` is that session, a collaborator of ``UpdatePose`` (app/workflows/update_pose.py): it is given
the clicks (``core.pose.PoseClicks``) and the frame, runs the matcher (the pose pipeline's automatic-matching
source: P3L on every assignment's triples, refined with every click by ``core.pose.refine_many``) outside
the workflow's lock, keeps the assignments shown and says what it found; the workflow commits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from core.pose import nearest_twin, plausibility

from .base import WorkflowError

__all__ = ["AutoMatch", "Match", "SNAPPED_SIGMA_PX", "IMAGE_GATE_PX"]

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


class AutoMatch:
    """Automatic assignment for Update pose (see the module docstring)."""

    def __init__(self, object_name: str):
        self.object_name = object_name
        self.matches: list[Match] | None = None  # automatic assignments awaiting confirmation
        self.info: dict[str, Any] | None = None  # the confirmed one, for the history

    def check_confirmed(self) -> None:
        """WorkflowError while automatic assignments await confirmation (Refine needs one assignment)."""
        if self.matches is not None:
            raise WorkflowError("confirm the automatic assignment first (Confirm match), or assign the edges by hand")

    @staticmethod
    def check(clicks, view: str) -> bool:
        """Can the clicks be matched now? True: yes; False: fewer than 3 edges, automatic assignment is to
        be switched on; WorkflowError otherwise (an edge in another camera, a click under way, every edge
        assigned, too few edges with automatic assignment on)."""
        if any(v != view for v in clicks.seg_views):
            raise WorkflowError(
                f"automatic matching works on camera {view}'s frame alone: say which model edge each edge "
                "clicked in another camera is (click it on the wireframe), or Remove last"
            )
        if clicks.pending is not None or clicks.mode == "point":
            raise WorkflowError("finish the click under way first (or Remove last)")
        n = len(clicks.segs)
        if n < 3:
            if not clicks.auto:
                return False
            raise WorkflowError(
                f"{n} edge{'s' if n != 1 else ''} clicked: automatic matching needs 3 (4 or more is best); "
                "click more image edges"
            )
        if all(e is not None for e in clicks.edge_ids):
            raise WorkflowError("every clicked edge is assigned already: Solve or Refine")
        return True

    @staticmethod
    def job(clicks, camera, obj, sigma_px: float) -> dict[str, Any]:
        """What the matcher needs, taken under the workflow's lock: the clicked segments, the click noise
        (``SNAPPED_SIGMA_PX`` when every segment is snapped), the hand assignments (kept: only assignments
        agreeing with them count), the camera, the model and the database pose."""
        snapped = all(s is not None and s.applied for s in clicks.seg_snaps)
        return dict(
            segs=np.array(clicks.segs),
            sigma=SNAPPED_SIGMA_PX if snapped else sigma_px,
            hand={j: e for j, e in enumerate(clicks.edge_ids) if e is not None},
            camera=camera,
            model=obj.model,
            T_db=obj.T_world_obj,
        )

    def run(self, job: dict[str, Any], image) -> tuple[list[Match], str]:
        """``app.vision.matching.match_edges`` on the clicks and the frame (outside the lock): the plausible
        assignments, each as the twin nearest the database pose (``core.pose.nearest_twin``), those whose
        drawing misses the frame's edges dropped unless nothing else is left; and what to tell the operator.
        WorkflowError when none fits."""
        from app.vision.matching import match_edges

        camera, model, segs = job["camera"], job["model"], job["segs"]
        try:
            res = match_edges(camera, model, segs, image=image, sigma_px=job["sigma"])
        except ValueError as exc:
            raise WorkflowError(f"automatic matching failed: {exc}") from None
        kept: list[Match] = []
        for c in res.candidates:
            twin = nearest_twin(model, c.T_world_obj, np.asarray(c.edges), job["T_db"], job["hand"])
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
        n = len(kept)
        return kept, (
            f"{n} way{'s' if n > 1 else ''} of pairing your edges with the model's "
            f"edges fit{'' if n > 1 else 's'}; the best is drawn, each clicked "
            "edge labelled with its model edge: Confirm match, or choose another candidate." + warning
        )

    def confirm(self, chosen: int) -> tuple[list[int], str]:
        """Adopt assignment ``chosen``: (its model edge per clicked segment, what to tell the operator);
        WorkflowError when none is shown."""
        if not self.matches:
            raise WorkflowError("no automatic assignment to confirm: click 3 or more edges and Auto match first")
        m = self.matches[chosen]
        edges = [int(e) for e in m.edges]
        self.info = {
            "candidate": chosen + 1,
            "of": len(self.matches),
            "rms_px": m.rms_px,
            "image_px": None if not np.isfinite(m.image_px) else m.image_px,
            "edges": edges,
        }
        self.matches = None
        pairs = ", ".join(f"{j + 1}→e{e}" for j, e in enumerate(edges))
        return edges, f"Assignment {chosen + 1} confirmed: segments {pairs}. Refine, then Accept."
