"""Clicks snapped to the image: what the workflows share.

When the operator finishes a clicked segment (the second click on an image edge) the workflow
snaps it to the image's edge (``app.vision.snap.snap_segment``) on the frame the operator clicked
on (``Site.frame_at``); a clicked image point of a known model vertex is snapped to the image's
corner (``app.vision.corner.snap_corner``: the intersection of the vertex's edges snapped to the
image, directions from the model at its current estimate; OpenCV's ``cornerSubPix`` when the
vertex is not known or its edges are not found). Each click keeps a ``ClickSnap``: the raw click,
the snapped one, how far it moved, or why the snap failed (the raw click is then used). The
overlay shows both (``snap_marks``); ``refuse_snap`` goes back to the raw click; the history
records raw and snapped coordinates (``ClickSnap.record``).

``Snapper`` is a workflow's snapping as a collaborator (Update pose composes one); ``SnapMixin`` gives
the other workflows the ``snap`` option (on by default), ``set_snap(on)`` and the bookkeeping through
one, each workflow saying which of its clicks is the last one (``_last_snap``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from .base import WorkflowError

__all__ = [
    "ClickSnap",
    "Snapper",
    "SnapMixin",
    "segment_of",
    "vertex_edge_directions",
    "snap_marks",
    "SNAPPED_CORNER_SIGMA_PX",
    "SNAPPED_SEGMENT_SIGMA_PX",
    "weak_snaps",
]

# The precision of a corner snapped to the image, pixels: bench/corner_snapping.py measured a mean
# error of 0.13 px (95 % within 0.29 px) on the workcell's frames; a raw click is the operator's σ.
SNAPPED_CORNER_SIGMA_PX = 0.15
# The precision of a clicked segment snapped to the image's edge, pixels: bench/snapping.py measured
# 95 % of accepted snaps within 0.07 px (max 0.25 px) of the true edge on rendered frames; 0.15 px
# leaves room for real images (compression, blur, shading at silhouettes).
SNAPPED_SEGMENT_SIGMA_PX = 0.15
# A snap in use is weak (Accept asks once more) when the image fits it poorly at the snapped place, however far
# it moved (a gate on the distance moved flagged a click snapped 2.6 px onto the true silhouette). Measured by
# bench/snap_gates.py on the workcell's rendered frames (clicks 0-3 px off every visible edge and corner, t = 5 s
# and 16 s): 98 of the 102 edge snaps that moved more than 2 px and all 46 such corner snaps landed within 0.5 px
# of the truth; where they landed right, a snapped edge's points' RMS about its line was at most 0.16 px, a
# corner's lines' at most 0.28 px, cornerSubPix's fit (``app.vision.corner``) at most 3.2 px: the limits sit
# above those. A snap onto a neighbouring straight edge fits as well as the right one (0.05-0.10 px): the
# refined pose's residuals (3σ) are what catch it.
WEAK_EDGE_RMS_PX = 0.3
WEAK_CORNER_FIT_PX = {"edges": 0.5, "subpix": 3.5}


@dataclass
class ClickSnap:
    """One click (a segment (2, 2) or a point (2,), pixels) and its snap.

    raw : the operator's click. snapped : the snapped click, None when the snap failed.
    kind : "segment" or "corner". method : how it was snapped ("edge", "edges", "subpix").
    moved_px : largest distance a clicked pixel moved. reason : why it failed ("" if it did not).
    refused : the operator refused the snap (the raw click is used).
    lines_uv : (K, 2, 2) the image edges a corner was found on (display).
    fit_px : how well the image fits it at the snapped place (pixels; NaN: not known): a segment's edge points'
    RMS about the snapped line, a corner's ``CornerSnap.fit_px``.
    """

    kind: str
    raw: np.ndarray
    snapped: np.ndarray | None
    moved_px: float = 0.0
    method: str = ""
    reason: str = ""
    refused: bool = False
    lines_uv: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    fit_px: float = float("nan")

    @property
    def applied(self) -> bool:
        """True when the snapped click is the one in use."""
        return self.snapped is not None and not self.refused

    @property
    def used(self) -> np.ndarray:
        """The click in use: snapped, unless the snap failed or was refused."""
        return (self.snapped if self.applied else self.raw).copy()

    def weak(self) -> str:
        """ "" unless the snap in use fits the image poorly where it put the click (``WEAK_EDGE_RMS_PX``,
        ``WEAK_CORNER_FIT_PX``): then why, as a sentence's end."""
        if not self.applied or not np.isfinite(self.fit_px):
            return ""
        limit = WEAK_EDGE_RMS_PX if self.kind == "segment" else WEAK_CORNER_FIT_PX.get(self.method, np.inf)
        if self.fit_px <= limit:
            return ""
        what = "edge's points scatter" if self.kind == "segment" else "corner fits the image within"
        return f"the image's {what} {self.fit_px:.2f} px there (more than {limit:g} px)"

    def text(self) -> str:
        """A short label for the overlay."""
        if self.applied:
            return f"snapped {self.moved_px:.1f} px"
        if self.refused:
            return "raw (snap refused)"
        return "raw (no snap)"

    def record(self) -> dict[str, Any]:
        """JSON-ready history entry: raw and snapped coordinates, whether the snap is used."""
        return {
            "kind": self.kind,
            "raw_uv": np.asarray(self.raw).tolist(),
            "snapped_uv": None if self.snapped is None else np.asarray(self.snapped).tolist(),
            "snapped": self.applied,
            "refused": self.refused,
            "moved_px": float(self.moved_px),
            "method": self.method,
            "reason": self.reason,
        }


def vertex_edge_directions(
    camera: Any, model: Any, T_world_obj: np.ndarray, vertex: int
) -> tuple[np.ndarray, np.ndarray]:
    """Image directions (K, 2) and projected lengths (K,) (pixels) of the model edges that leave
    ``vertex`` and are visible at ``T_world_obj`` (convex hidden-line removal), through ``camera``."""
    if not len(model.edges) or not 0 <= int(vertex) < len(model.vertices):
        return np.zeros((0, 2)), np.zeros(0)
    wf = model.wireframe(camera.center, T_world_obj)
    visible = {int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"}
    D, L = [], []
    for k, (i, j) in enumerate(np.asarray(model.edges).tolist()):
        if k not in visible or vertex not in (i, j):
            continue
        other = j if i == vertex else i
        X = model.vertices[[vertex, other]] @ T_world_obj[:3, :3].T + T_world_obj[:3, 3]
        if np.any(camera.depth(X) <= 0):
            continue
        a, b = camera.project(X)
        if np.linalg.norm(b - a) > 1e-6:
            D.append(b - a)
            L.append(float(np.linalg.norm(b - a)))
    return np.array(D).reshape(-1, 2), np.array(L)


def snap_marks(snaps: list[ClickSnap | None]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list]:
    """What to draw for snapped clicks: raw segments (K, 2, 2) and raw points (N, 2) of the snaps
    in use (beside the snapped ones the workflow draws), the corners' edge lines (M, 2, 2), and
    labels (uv, text) saying how far each moved or that a snap failed or was refused."""
    raw_segs, raw_pts, lines, labels = [], [], [], []
    for s in snaps:
        if s is None:
            continue
        at = s.used.reshape(-1, 2)
        anchor = at.mean(axis=0) + ([0.0, 12.0] if s.kind == "segment" else [6.0, 10.0])
        if s.applied:
            (raw_segs if s.kind == "segment" else raw_pts).append(s.raw)
            if len(s.lines_uv):
                lines.extend(s.lines_uv)
        labels.append((anchor, s.text()))
    return (
        np.array(raw_segs).reshape(-1, 2, 2),
        np.array(raw_pts).reshape(-1, 2),
        np.array(lines).reshape(-1, 2, 2),
        labels,
    )


class Snapper:
    """A workflow's snapping, composed rather than inherited: on or off, the frame a view's clicks were
    made on, and the snap of a finished segment or of a clicked corner there. It reads only the
    workflow's frames (``Workflow.frame``, ``frame_in``, ``site``, ``view``)."""

    def __init__(self, workflow: Any, on: bool = True):
        self.wf = workflow
        self.on = bool(on)
        self.error = ""  # why the last frame could not be read

    def frame(self, view: str | None = None) -> np.ndarray | None:
        """The frame clicks in ``view`` (the workflow's own for None) were made on: the frozen one (or,
        in another camera, its frame frozen with it), else the site's newest; None when none can be read."""
        wf = self.wf
        view = view or wf.view
        if view != wf.view:
            ref = wf.frame_in(view)
            if ref is not None:
                return ref.image
        elif wf.frame is not None:
            return wf.frame.image
        try:
            return wf.site.frame_at(None, view)
        except Exception as exc:  # noqa: BLE001 - a broken video must not stop the click: it is kept raw
            self.error = f"the video frame could not be read ({exc})"
            return None

    def no_frame_reason(self) -> str:
        return self.error or "no video frame to snap to"

    def _active(self) -> bool:
        return self.on and (self.wf.site.has_frames_of(self.wf.view) or self.wf.frame is not None)

    def segment(self, seg: np.ndarray, view: str | None = None) -> ClickSnap | None:
        """Snap a finished segment (2, 2) clicked in ``view`` to the image's edge; None when snapping is
        off or the site has no video frames."""
        if not self._active():
            return None
        from app.vision.snap import snap_segment

        image = self.frame(view)
        if image is None:
            return ClickSnap("segment", seg.copy(), None, reason=self.no_frame_reason())
        try:
            res = snap_segment(image, seg)
        except ValueError as exc:
            return ClickSnap("segment", seg.copy(), None, reason=str(exc))
        if not res.ok:
            return ClickSnap(
                "segment", seg.copy(), None, moved_px=float(res.moved_px), method="edge", reason=res.reason
            )
        return ClickSnap("segment", seg.copy(), res.seg_uv.copy(), float(res.moved_px), "edge", fit_px=res.rms_px)

    def corner(
        self,
        uv: np.ndarray,
        view: str | None = None,
        model: Any = None,
        T_world_obj: np.ndarray | None = None,
        vertex: int | None = None,
    ) -> ClickSnap | None:
        """Snap a clicked image point (2,) in ``view`` of a model vertex (if known) to the image's corner;
        None when snapping is off or the site has no video frames."""
        if not self._active():
            return None
        from app.vision.corner import snap_corner

        image = self.frame(view)
        if image is None:
            return ClickSnap("corner", uv.copy(), None, reason=self.no_frame_reason())
        D = L = None
        if model is not None and vertex is not None and T_world_obj is not None:
            camera = self.wf.site.camera_of(view or self.wf.view)
            D, L = vertex_edge_directions(camera, model, np.asarray(T_world_obj, float), int(vertex))
        try:
            res = snap_corner(image, uv, D, L)
        except ValueError as exc:
            return ClickSnap("corner", uv.copy(), None, reason=str(exc))
        if not res.ok:
            return ClickSnap("corner", uv.copy(), None, method=res.method, reason=res.reason)
        return ClickSnap(
            "corner",
            uv.copy(),
            res.uv.copy(),
            float(res.moved_px),
            res.method,
            lines_uv=res.lines_uv,
            fit_px=res.fit_px,
        )

    def take_segment(self, seg: np.ndarray, view: str, sigma_px: float) -> tuple[np.ndarray, float, ClickSnap | None]:
        """A finished segment (2, 2) as it is used: (the pixels, their σ — a snap's measured precision,
        ``SNAPPED_SEGMENT_SIGMA_PX``, or the operator's ``sigma_px`` —, the snap or None)."""
        snap = self.segment(seg, view)
        if snap is None or not snap.applied:
            return (seg if snap is None else snap.used), sigma_px, snap
        return snap.used, SNAPPED_SEGMENT_SIGMA_PX, snap

    def take_corner(
        self, uv: np.ndarray, view: str, sigma_px: float, model: Any, T_world_obj: np.ndarray, vertex: int
    ) -> tuple[np.ndarray, float, ClickSnap | None]:
        """A clicked image point of a model vertex as it is used: (the pixel, its σ —
        ``SNAPPED_CORNER_SIGMA_PX`` when snapped, else ``sigma_px`` —, the snap or None)."""
        snap = self.corner(uv, view, model, T_world_obj, vertex)
        if snap is None or not snap.applied:
            return (uv if snap is None else snap.used), sigma_px, snap
        return snap.used, SNAPPED_CORNER_SIGMA_PX, snap

    def add_segment(self, clicks: Any, seg: np.ndarray, view: str, sigma_px: float) -> str:
        """Add a finished segment (2, 2) clicked in ``view`` to ``clicks`` (a ``core.pose.PoseClicks``) as it
        is used (``take_segment``), its snap kept beside it; what to tell the operator."""
        uv, sigma, snap = self.take_segment(seg, view, sigma_px)
        clicks.add_segment(uv, view, sigma, snap)
        return self.message(f"Edge {len(clicks.segs)}", snap)

    def add_point(
        self, clicks: Any, uv: np.ndarray, vertex: int, view: str, sigma_px: float, model: Any, T_world_obj: np.ndarray
    ) -> str:
        """Add the image point of model ``vertex`` clicked at ``uv`` in ``view`` to ``clicks`` as it is used
        (``take_corner``: directions from ``model`` at ``T_world_obj``); what to tell the operator."""
        clicks.check_vertex(vertex)
        p, sigma, snap = self.take_corner(uv, view, sigma_px, model, T_world_obj, vertex)
        clicks.add_point(p, vertex, view, sigma, snap)
        return self.message(f"Point v{vertex}", snap)

    @staticmethod
    def message(what: str, s: ClickSnap | None) -> str:
        """What the operator is told of a click's snap ("" without one)."""
        if s is None:
            return ""
        if s.applied:
            return (
                f"{what} snapped {s.moved_px:.1f} px to the image's "
                f"{'edge' if s.kind == 'segment' else 'corner'} (Refuse snap keeps your click)."
            )
        return f"{what} kept as clicked: {s.reason}."

    def set(self, on: bool) -> str:
        """Snapping on or off; what to tell the operator."""
        self.on = bool(on)
        if self.on:
            return "Clicks will be snapped to the image's edges and corners."
        return "Clicks will be used as clicked (snapping off)."

    def refuse(self, clicks: Any, sigma_px: float) -> str:
        """Refuse the snap of the last click of ``clicks`` (a ``core.pose.PoseClicks``): its raw pixels come
        back, with the operator's ``sigma_px``; what to tell the operator. WorkflowError when the last
        click's snap is not in use."""
        last = clicks.last_click()
        snap = self.refusable(None if last is None else clicks.note(*last))
        snap.refused = True
        clicks.replace(*last, snap.raw.copy(), sigma_px)
        return "Snap refused: the last click is used as you clicked it."

    @staticmethod
    def refusable(snap: ClickSnap | None) -> ClickSnap:
        """The last click's snap, to be refused; WorkflowError when there is none in use."""
        if snap is None:
            raise WorkflowError(
                "the last click was not snapped (snapping is off, there is no video frame, or there is "
                "no click to change since the last step): nothing to refuse"
            )
        if not snap.applied:
            raise WorkflowError(
                f"the last click is already used as clicked ({'refused' if snap.refused else snap.reason})"
            )
        return snap


def weak_snaps(named: Any) -> list[str]:
    """The weak snaps among ``named`` ((what, ClickSnap or None) pairs, e.g. ("point 2", snap)), each said:
    "point 2's snap: the image's corner fits … (more than … px)"."""
    return [f"{what}'s snap: {sn.weak()}" for what, sn in named if sn is not None and sn.weak()]


def click_segment(wf, seg_uv) -> None:
    """Both clicks of a segment (2, 2) at once (a script's ``add_segment``), through ``wf.click``; refused while
    an edge waits for its second click (``wf.pending``)."""
    seg = np.asarray(seg_uv, dtype=float)
    if seg.shape != (2, 2):
        raise WorkflowError(f"a segment is two pixels [[u1, v1], [u2, v2]], got {seg_uv!r}")
    with wf.lock:
        if wf.pending is not None:
            raise WorkflowError("finish the edge under way first (or Remove last)")
        wf.click(seg[0])
        wf.click(seg[1])


class SnapMixin:
    """Snapping for a workflow: the ``snap`` option, ``set_snap``, ``refuse_snap`` and the snap calls,
    through a ``Snapper`` (``self.snapper``).

    The workflow calls ``_snap_segment(seg)`` / ``_snap_corner(uv, ...)`` for each finished click
    and keeps the returned ``ClickSnap`` beside it; it implements ``_last_snap()`` → (ClickSnap or
    None, a function that puts a click back in place) for ``refuse_snap``.
    """

    snapping: ClassVar[bool] = True  # Session.start passes its "Snap clicks" setting as snap=

    def _init_snap(self, snap: bool) -> None:
        self.snapper = Snapper(self, snap)

    @property
    def snap(self) -> bool:
        return self.snapper.on

    def set_snap(self, on: bool = True) -> None:
        """Snap the next clicks to the image's edges and corners (on), or use them as clicked (off)."""
        with self.lock:
            self.message = self.snapper.set(on)

    def _frame(self) -> np.ndarray | None:
        """The frame the clicks were made on: the workflow's frozen frame, else the site's now."""
        return self.snapper.frame(getattr(self, "click_view", None))

    def _no_frame_reason(self) -> str:
        return self.snapper.no_frame_reason()

    def _click_segment(self, seg_uv) -> None:
        click_segment(self, seg_uv)

    def _finish_segment(
        self, first: np.ndarray, second: np.ndarray, min_px: float
    ) -> tuple[np.ndarray, ClickSnap | None]:
        """The segment of two clicks on an image edge, snapped: (the segment to use (2, 2), its
        snap or None); WorkflowError when the clicks are closer than ``min_px``."""
        seg = segment_of(first, second, min_px)
        snap = self._snap_segment(seg)
        return (seg if snap is None else snap.used), snap

    def _snap_segment(self, seg: np.ndarray) -> ClickSnap | None:
        """Snap a finished segment (2, 2) on the current frame; None when snapping is off or the
        site has no video frames."""
        return self.snapper.segment(seg, getattr(self, "click_view", None))

    def _snap_corner(
        self, uv: np.ndarray, model: Any = None, T_world_obj: np.ndarray | None = None, vertex: int | None = None
    ) -> ClickSnap | None:
        """Snap a clicked image point (2,) of a model vertex (if known) to the image's corner; None
        when snapping is off or the site has no video frames."""
        return self.snapper.corner(uv, getattr(self, "click_view", None), model, T_world_obj, vertex)

    def _snap_message(self, what: str, s: ClickSnap | None) -> str:
        return Snapper.message(what, s)

    def _last_snap(self) -> tuple[ClickSnap | None, Any]:  # pragma: no cover - per workflow
        raise NotImplementedError

    def refuse_snap(self) -> None:
        """Use the last click as clicked, not snapped (its raw pixels come back)."""
        with self.lock:
            self._check_open()
            snap, put_back = self._last_snap()
            Snapper.refusable(snap).refused = True
            put_back(snap.raw.copy())
            self._after_refuse()
            self.message = "Snap refused: the last click is used as you clicked it."

    def _after_refuse(self) -> None:
        """A click changed: drop results that depend on it (the workflow's own invalidation)."""


def segment_of(first: np.ndarray, second: np.ndarray, min_px: float) -> np.ndarray:
    """The segment (2, 2) of two clicks on an image edge; WorkflowError when they are closer than ``min_px``."""
    seg = np.array([first, second], dtype=float)
    gap = float(np.linalg.norm(seg[1] - seg[0]))
    if gap < min_px:
        raise WorkflowError(
            f"the two clicks are {gap:.1f} px apart: click the edge's other end, at least "
            f"{min_px:.0f} px away along it (second click again)"
        )
    return seg
