"""Calibrate the camera: pair ≥ 6 known 3D points with their clicked pixels → C by DLT.

The operator alternates two clicks: first a model vertex drawn in the overlay (a known object's
corner, a table corner — the nearest projected vertex is taken), then where that point really is
in the video. ``solve()`` runs ``core.calibration.calibrate_dlt`` and shows the RMS and each
point's residual; ``accept()`` stores the calibration and every overlay is redrawn through the
new C; ``redo()`` starts over. A script may give the 3D point directly with ``choose_point``.

Each clicked image point is snapped to the image's corner on the frame the operator clicked on
(``snapping``: for a model vertex, the intersection of its edges snapped to the image, their
directions from the object's database pose through the current C; for a bare 3D point, OpenCV's
``cornerSubPix``). ``refuse_snap()`` keeps the last click as clicked; the calibration stores the
raw and snapped pixels. The DLT weighs each point by its precision (``core.calibration.calibrate_dlt``'s
``sigma_px``): a snapped corner σ = 0.15 px (measured), a raw click the operator's ``sigma_px``.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.calibration import calibrate_dlt

from .base import Marks, Workflow, WorkflowError, as_pixel
from .snapping import SNAPPED_CORNER_SIGMA_PX, SnapMixin, snap_marks

__all__ = ["CalibrateCamera"]

PICK_RADIUS_PX = 25.0


class CalibrateCamera(SnapMixin, Workflow):
    name = "calibrate_camera"
    title = "Calibrate camera"
    actions = ("click", "choose_point", "choose_vertex", "remove_last", "solve", "accept", "redo", "cancel",
               "refuse_snap", "set_snap")

    def __init__(self, site, client: str = "operator", snap: bool = True, sigma_px: float = 1.0):
        super().__init__(site, client)
        self._init_snap(snap)
        if not sigma_px > 0:
            raise WorkflowError(f"sigma_px (the clicks' noise, pixels) must be positive, got {sigma_px}")
        self.sigma_px = float(sigma_px)
        self.X_world: list[np.ndarray] = []
        self.uv: list[np.ndarray] = []
        self.snaps: list = []  # beside uv: each click's snap (None: snapping off)
        self.labels: list[str] = []
        self.pending_X: np.ndarray | None = None
        self.pending_vertex: tuple[str, int] | None = None  # (object, vertex) of the pending point, if a vertex
        self.pending_label = ""
        self.result = None
        self.state = "pick_model"

    # ------------------------------------------------------------------ actions
    def click(self, uv) -> None:
        """A click on the video: the model vertex (first of a pair) or its image (second)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.pending_X is None:
                name, k, X, dist = self._nearest_vertex(p)
                if dist > PICK_RADIUS_PX:
                    raise WorkflowError(
                        f"no model vertex within {PICK_RADIUS_PX:.0f} px of ({p[0]:.0f}, {p[1]:.0f}) (nearest: "
                        f"{name} vertex {k}, {dist:.0f} px away); click on a corner drawn in the overlay"
                    )
                self._set_pending(X, f"{name}:{k}", (name, k))
            else:
                self._add_pair(p)

    def choose_vertex(self, name: str, index: int) -> None:
        """Pick vertex ``index`` of object ``name`` as the next known point (then click its image)."""
        with self.lock:
            self._check_open()
            try:
                V = self.site.object(name).vertices_world()
            except KeyError as exc:
                raise WorkflowError(str(exc.args[0])) from None
            if not 0 <= int(index) < len(V):
                raise WorkflowError(f"{name} has vertices 0..{len(V) - 1}, not {index}")
            self._set_pending(V[int(index)], f"{name}:{int(index)}", (name, int(index)))

    def choose_point(self, X_world, label: str = "") -> None:
        """Use a known world point X_world (3,) metres as the next known point (then click its image)."""
        X = np.asarray(X_world, dtype=float).reshape(-1)
        if X.shape != (3,) or not np.all(np.isfinite(X)):
            raise WorkflowError(f"a known point is (x, y, z) in metres, got {X_world!r}")
        with self.lock:
            self._check_open()
            self._set_pending(X, label or "point")

    def remove_last(self) -> None:
        """Drop the pending model point, or else the last pair."""
        with self.lock:
            self._check_open()
            if self.pending_X is not None:
                self.pending_X = None
            elif self.X_world:
                self.X_world.pop()
                self.uv.pop()
                self.snaps.pop()
                self.labels.pop()
            self.result = None
            self.state = "pick_model"

    def solve(self):
        """C from the pairs (≥ 6, not coplanar); shows RMS and per-point residuals."""
        with self.lock:
            self._check_open()
            if len(self.X_world) < 6:
                raise WorkflowError(f"{len(self.X_world)} points paired; the DLT needs at least 6 (11 unknowns in C): pair more")
            w, h = self.site.camera.width, self.site.camera.height
            try:
                sigma = [SNAPPED_CORNER_SIGMA_PX if sn is not None and sn.applied else self.sigma_px for sn in self.snaps]
                self.result = calibrate_dlt(np.array(self.X_world), np.array(self.uv), w, h, sigma_px=np.array(sigma))
            except ValueError as exc:
                raise WorkflowError(f"calibration failed: {exc}") from None
            self.state = "review"
            self.message = f"RMS {self.result.rms_px:.2f} px over {len(self.uv)} points"
            return self.result

    def accept(self) -> None:
        """Store the new C (one transaction) and redraw every overlay through it."""
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: solve first")
            self.site.set_camera(
                self.result.camera,
                rms_px=self.result.rms_px,
                residuals_px=self.result.residuals_px,
                cov=self.result.cov,
                points={"X_world": np.array(self.X_world).tolist(), "uv": np.array(self.uv).tolist(), "labels": list(self.labels),
                        # raw and snapped pixels of each point above (None: snapping was off)
                        "snaps": [None if sn is None else sn.record() for sn in self.snaps]},
                client=self.client,
            )
            self.accepted = True
            self.state = "accepted"
            self.message = f"Camera calibrated: RMS {self.result.rms_px:.2f} px."

    def redo(self) -> None:
        """Forget every pair and the result; start again."""
        with self.lock:
            self._check_open()
            self.X_world, self.uv, self.labels, self.snaps = [], [], [], []
            self.pending_X, self.pending_vertex, self.result = None, None, None
            self.state = "pick_model"
            self.message = ""

    # ------------------------------------------------------------------ helpers
    def _set_pending(self, X: np.ndarray, label: str, vertex: tuple[str, int] | None = None) -> None:
        self.pending_X = np.asarray(X, float).copy()
        self.pending_label = label
        self.pending_vertex = vertex
        self.state = "click_image"

    def _add_pair(self, p: np.ndarray) -> None:
        model = T = k = None
        if self.pending_vertex is not None:
            name, k = self.pending_vertex
            try:
                obj = self.site.object(name)
                model, T = obj.model, obj.T_world_obj
            except KeyError:
                k = None
        snap = self._snap_corner(p, model, T, k)
        self.X_world.append(self.pending_X)
        self.uv.append(p if snap is None else snap.used)
        self.snaps.append(snap)
        self.labels.append(self.pending_label)
        self.message = self._snap_message(f"Point {len(self.uv)} ({self.pending_label})", snap)
        self.pending_X = None
        self.pending_vertex = None
        self.result = None
        self.state = "pick_model"

    def _last_snap(self):
        if not self.uv:
            return None, None
        i = len(self.uv) - 1
        return self.snaps[i], lambda raw: self.uv.__setitem__(i, raw)

    def _after_refuse(self) -> None:
        self.result = None
        if self.state == "review":
            self.state = "pick_model"

    def _nearest_vertex(self, p: np.ndarray) -> tuple[str, int, np.ndarray, float]:
        cam = self.site.camera
        best = ("", -1, np.zeros(3), float("inf"))
        for obj in self.site.objects():
            V = obj.vertices_world()
            if not len(V):
                continue
            front = cam.depth(V) > 0
            if not np.any(front):
                continue
            uv = cam.project(V)
            d = np.linalg.norm(uv - p, axis=1)
            d[~front] = np.inf
            k = int(np.argmin(d))
            if d[k] < best[3]:
                best = (obj.name, k, V[k], float(d[k]))
        return best

    # ------------------------------------------------------------------ display
    @property
    def next_step(self) -> str:
        n = len(self.X_world)
        if self.accepted:
            return "Done: the camera is calibrated."
        if self.cancelled:
            return "Cancelled."
        if self.state == "click_image":
            return f"Now click where {self.pending_label} really is in the video."
        if self.state == "review":
            return f"RMS {self.result.rms_px:.2f} px: Accept, or Redo (or click more points)."
        more = max(0, 6 - n)
        tail = f" ({more} more needed)" if more else "; or Solve"
        return f"Click a model corner in the overlay (pair {n + 1}){tail}."

    def marks(self) -> Marks:
        with self.lock:
            cam = self.site.camera
            m = Marks(points=np.array(self.uv).reshape(-1, 2))
            m.labels = [(uv, str(i + 1)) for i, uv in enumerate(self.uv)]
            m.raw_segments, m.raw_points, m.snap_lines, snap_labels = snap_marks(self.snaps)
            m.labels += snap_labels
            if self.pending_X is not None:
                m.pending = cam.project(self.pending_X.reshape(1, 3))
            if self.result is not None and self.uv:
                proj = self.result.camera.project(np.array(self.X_world))
                m.residuals = np.stack([np.array(self.uv), proj], axis=1)
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {"pairs": len(self.uv)}
            snaps = [sn for sn in self.snaps if sn is not None]
            if snaps:
                out["snapped"] = f"{sum(sn.applied for sn in snaps)} of {len(snaps)} points"
            if self.result is not None:
                out["rms_px"] = self.result.rms_px
                out["errors_px"] = self.result.errors_px.tolist()
                out["labels"] = list(self.labels)
            return out
