"""Calibrate the camera: pair known 3D points with their clicked pixels → C by DLT (≥ 6), or,
with the lens known, the camera's pose by PnP (≥ 4).

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

With the lens known (``known_K``: the camera's intrinsics come from a calibration file, the scene's
``intrinsics_file`` or ``mcit serve --intrinsics FILE``), C = K [R | t] has 6 unknowns instead of
11: the "Solve by" chooser offers the camera's pose by PnP (``app.vision.pnp.solve_pnp``, ≥ 4
points, the default) or the full C by DLT (≥ 6). A scene's inline ``K`` or ``C`` is its nominal
start-up camera (the workcell's, the demo's): there only the DLT is offered, as before. The
result, the instruction and the history's record (``method`` "pnp" or "dlt") say which was solved;
a PnP covariance is the pose's (K taken as exact).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.calibration import calibrate_dlt
from core.camera import Camera

from .base import CANCEL, Control, Marks, Step, Workflow, WorkflowError, as_pixel, pick_radius_px
from .snapping import SNAPPED_CORNER_SIGMA_PX, SnapMixin, snap_marks, weak_snaps

__all__ = ["CalibrateCamera", "known_K", "METHODS"]

# Weak results (Accept asks once more): fewer pairs than this leave little redundancy in C's 11
# unknowns (and a snap the image fits poorly: ``ClickSnap.weak``).
MIN_REDUNDANT_PAIRS = 8
# The same redundancy (at least 5 coordinates beyond the unknowns) for the pose's 6 unknowns.
MIN_REDUNDANT_PAIRS_PNP = 6

# What Solve solves: method → (chooser text, points needed, what it solved, in words).
METHODS = {
    "pnp": ("Pose, lens known (PnP)", 4, "the camera's pose", "with the lens known (PnP)"),
    "dlt": ("Full camera matrix (DLT)", 6, "the full camera matrix", "(DLT)"),
}


def _chi2_999(dof: int) -> float:
    from scipy.stats import chi2  # here, not at the top (start-up)

    return float(chi2.ppf(0.999, dof))


def known_K(site, view: str | None = None) -> np.ndarray | None:
    """One camera's intrinsics K (3, 3) when a calibration file gives them (its block in the scene
    names an ``intrinsics_file``; ``mcit serve --intrinsics FILE`` puts the file there), else None: a
    scene's inline K or C is its nominal start-up camera, which this workflow corrects as a whole."""
    scene = getattr(site, "scene", None)
    if scene is None or "intrinsics_file" not in scene.camera_block(view):
        return None
    cam: Camera = scene.view(view).camera
    return cam.decompose()[0]


class CalibrateCamera(SnapMixin, Workflow):
    name = "calibrate_camera"
    title = "Calibrate camera"
    actions = (
        "click",
        "choose_point",
        "choose_vertex",
        "remove_last",
        "remove_pair",
        "solve",
        "accept",
        "redo",
        "cancel",
        "refuse_snap",
        "set_snap",
        "set_method",
    )
    controls = (
        Control(
            "set_method",
            "Solve by",
            kind="choice",
            hint="With the lens known: the camera's pose alone (PnP, 4 points or more) or the full camera matrix "
            "(DLT, 6 or more)",
        ),
        Control("solve", "Solve", "R", color="blue", hint="C from the paired points (PnP or DLT, as chosen)"),
        Control(
            "accept",
            "Accept",
            "enter",
            color="green",
            hint="Store the new calibration: every overlay is redrawn through it",
        ),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last click as clicked, not moved onto the image's corner"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click"),
        Control("pair", "Point", kind="choice", hint="A paired point (its residual after Solve)"),
        Control("remove_pair", "Delete point", arg="pair", hint="Delete the point chosen above"),
        Control("redo", "Redo", confirm="Forget every paired point and start again?"),
        CANCEL,
    )

    def __init__(
        self,
        site,
        client: str = "operator",
        view: str | None = None,
        snap: bool = True,
        sigma_px: float = 1.0,
        method: str | None = None,
    ):
        super().__init__(site, client, view)
        self._init_snap(snap)
        if not sigma_px > 0:
            raise WorkflowError(f"sigma_px (the clicks' noise, pixels) must be positive, got {sigma_px}")
        self.sigma_px = float(sigma_px)
        self.K = known_K(site, self.view)  # the lens, when a calibration file gives it (PnP offered), else None
        self.method = "pnp" if self.K is not None else "dlt"
        self.solved_by: str | None = None  # the method of ``result``
        if method is not None:
            self._check_method(method)
            self.method = method
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
                radius = pick_radius_px(self)
                if dist > radius:
                    near = f" (the nearest visible one, {name} corner {k}, is {dist:.0f} px away)" if k >= 0 else ""
                    raise WorkflowError(
                        f"No visible model corner within {radius:.0f} px of your click{near}: "
                        "click on a corner drawn in the overlay."
                    )
                self._set_pending(X, f"{name} corner {k}", (name, k))
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
            self._set_pending(V[int(index)], f"{name} corner {int(index)}", (name, int(index)))

    def choose_point(self, X_world, label: str = "") -> None:
        """Use a known world point X_world (3,) metres as the next known point (then click its image)."""
        X = np.asarray(X_world, dtype=float).reshape(-1)
        if X.shape != (3,) or not np.all(np.isfinite(X)):
            raise WorkflowError(f"a known point is (x, y, z) in metres, got {X_world!r}")
        with self.lock:
            self._check_open()
            self._set_pending(X, label or "point")

    def remove_pair(self, index: int) -> None:
        """Delete pair ``index`` (0-based; the residual table's row) whatever its place."""
        with self.lock:
            self._check_open()
            i = int(index)
            if not 0 <= i < len(self.uv):
                raise WorkflowError(f"there is no point {i + 1}: {len(self.uv)} are paired")
            for seq in (self.X_world, self.uv, self.snaps, self.labels):
                seq.pop(i)
            self.result = None
            self.state = "click_image" if self.pending_X is not None else "pick_model"
            self.message = f"Point {i + 1} deleted: {len(self.uv)} left. Solve again."

    def remove_last(self) -> None:
        """Drop the pending model point, or else the last pair."""
        with self.lock:
            self._check_open()
            if self.pending_X is None and not self.X_world:
                raise WorkflowError("there is no click to remove")
            if self.pending_X is not None:
                self.pending_X = None
                self.pending_vertex = None
                self.message = "The chosen model corner is dropped."
            elif self.X_world:
                self.X_world.pop()
                self.uv.pop()
                self.snaps.pop()
                self.labels.pop()
                self.message = f"The last point is removed: {len(self.uv)} left."
            self.result = None
            self.state = "pick_model"

    def _check_method(self, method: str) -> None:
        if method not in METHODS:
            raise WorkflowError(f"Solve by is one of {', '.join(METHODS)}, not {method!r}")
        if method == "pnp" and self.K is None:
            raise WorkflowError(
                "the camera's lens is not known here, so only the full camera matrix (DLT, 6 points or "
                "more) can be solved; start mcit serve with --intrinsics FILE to solve the pose alone"
            )

    def set_method(self, method: str) -> None:
        """What Solve solves: "pnp" (the camera's pose, the lens known: ≥ 4 points) or "dlt" (the full C: ≥ 6)."""
        with self.lock:
            self._check_open()
            self._check_method(method)
            if method != self.method:
                self.method = method
                self.result, self.solved_by = None, None
                if self.state == "review":
                    self.state = "pick_model"
            self.message = f"Solve by: {METHODS[method][0]}."

    def _sigmas(self) -> np.ndarray:
        return np.array(
            [SNAPPED_CORNER_SIGMA_PX if sn is not None and sn.applied else self.sigma_px for sn in self.snaps]
        )

    def solve(self):
        """C from the pairs: by PnP with the lens known (≥ 4 points) or by DLT (≥ 6, not coplanar); shows
        RMS and per-point residuals, and says which was solved."""
        with self.lock:
            self._check_open()
            n = len(self.X_world)
            text, need, what, how = METHODS[self.method]
            if n < need:
                unknowns = "6 unknowns: the pose" if self.method == "pnp" else "11 unknowns in C"
                other = (
                    " (4 are enough for the pose alone: choose it in Solve by)"
                    if self.K is not None and self.method == "dlt"
                    else ""
                )
                raise WorkflowError(f"{n} points paired; {what} needs at least {need} ({unknowns}): pair more{other}")
            w, h = self.camera.width, self.camera.height
            try:
                if self.method == "pnp":
                    from app.vision.pnp import solve_pnp

                    self.result = solve_pnp(
                        self.K, np.array(self.X_world), np.array(self.uv), w, h, sigma_px=self._sigmas()
                    )
                else:
                    self.result = calibrate_dlt(
                        np.array(self.X_world), np.array(self.uv), w, h, sigma_px=self._sigmas()
                    )
            except ValueError as exc:
                raise WorkflowError(f"calibration failed: {exc}") from None
            self.solved_by = self.method
            self.state = "review"
            self.message = self._solved_text() + "."
            return self.result

    def _solved_text(self) -> str:
        """ "Solved the camera's pose from 5 points with the lens known (PnP): RMS 0.4 px" (or the DLT's)."""
        _, _, what, how = METHODS[self.solved_by]
        text = f"Solved {what} from {len(self.uv)} points {how}: RMS {self.result.rms_px:.1f} px"
        if self.solved_by == "pnp":
            text += (
                f", position ±{1000 * self.result.std_position_m:.1f} mm, "
                f"orientation ±{np.degrees(self.result.std_angle_rad):.2f}°"
            )
        return text

    def accept(self) -> None:
        """Store the new C (one transaction) and redraw every overlay through it."""
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: solve first")
            points = {
                "X_world": np.array(self.X_world).tolist(),
                "uv": np.array(self.uv).tolist(),
                "labels": list(self.labels),
                # raw and snapped pixels of each point above (None: snapping was off)
                "snaps": [None if sn is None else sn.record() for sn in self.snaps],
                "frame": self.frame_record(),  # the frozen frame clicked on (None: the site's frame)
                "solved_by": self.solved_by,
            }
            if self.solved_by == "pnp":  # the lens it was solved with, and the pose's σ (K taken as exact)
                points.update(
                    K=np.asarray(self.K).tolist(),
                    std_position_m=self.result.std_position_m,
                    std_angle_rad=self.result.std_angle_rad,
                )
            self.site.set_camera(
                self.result.camera,
                rms_px=self.result.rms_px,
                residuals_px=self.result.residuals_px,
                cov=self.result.cov,
                points=points,
                client=self.client,
                method=self.solved_by,
                view=self.view,
            )
            self.accepted = True
            self.state = "accepted"
            what = "pose with the lens known (PnP" if self.solved_by == "pnp" else "full camera matrix (DLT"
            self.message = (
                f"Camera calibrated from its {what}, RMS {self.result.rms_px:.1f} px): every overlay is now "
                "drawn through it."
            )

    def redo(self) -> None:
        """Forget every pair and the result; start again."""
        with self.lock:
            self._check_open()
            n = len(self.uv)
            self.X_world, self.uv, self.labels, self.snaps = [], [], [], []
            self.pending_X, self.pending_vertex, self.result, self.solved_by = None, None, None, None
            self.state = "pick_model"
            self.message = f"Started again: {n} points forgotten."

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
        """The nearest model vertex to pixel p that the camera sees: in front of it, on an edge its
        object shows (convex hidden-line removal) and not behind another database surface."""
        cam = self.camera
        cands = []
        for obj in self.site.objects():
            V = obj.vertices_world()
            if not len(V):
                continue
            front = cam.depth(V) > 0
            if not np.any(front):
                continue
            shown = np.zeros(len(V), bool)
            if len(obj.model.edges):
                wf = obj.model.wireframe(cam.center, obj.T_world_obj)
                E = np.asarray(obj.model.edges)
                vis = [int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"]
                shown[E[vis].ravel()] = True
            else:
                shown[:] = True
            d = np.linalg.norm(cam.project(V) - p, axis=1)
            for k in np.flatnonzero(front & shown & (d <= 3 * pick_radius_px(self))):
                cands.append((float(d[k]), obj.name, int(k), V[k]))
        for d, name, k, X in sorted(cands, key=lambda c: c[0]):
            if self._unoccluded(X):
                return name, k, X, d
        return "", -1, np.zeros(3), float("inf")

    def _unoccluded(self, X: np.ndarray) -> bool:
        """True when no database surface lies between the optical centre and X (1 mm tolerance)."""
        c = self.camera.center
        ray = X - c
        dist = float(np.linalg.norm(ray))
        try:
            hit = self.site.raycast(c, ray / dist)
        except Exception:  # noqa: BLE001 - no ray casting (no trimesh index): keep the vertex
            return True
        return hit is None or hit.distance_m >= dist - 1e-3

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        n = len(self.X_world)
        has = {"cancel"} | ({"remove_last"} if (n or self.pending_X is not None) else set())
        if n:
            has |= {"pair", "remove_pair"} | ({"redo"} if n >= 2 else set())
        if self._last_snap()[0] is not None and self._last_snap()[0].applied:
            has.add("refuse_snap")
        if self.K is not None:
            has.add("set_method")
        if self.state == "click_image":
            return Step(
                "click_image",
                f"Now click where {self.pending_label} (circled) really is in the video; "
                "{remove_last} if you picked the wrong corner.",
                frozenset(has),
            )
        _, need, what, how = METHODS[self.method]
        if n >= need:
            has.add("solve")
        if self.state == "review" and self.result is not None:
            return Step(
                "review",
                f"{self._solved_text()}. {{accept}} to use it, or delete a point with a "
                "large residual ({remove_pair}) and {solve} again.",
                frozenset(has | {"accept"}),
            )
        more = max(0, need - n)
        tail = f" ({more} more needed for {what} {how})." if more else f", or {{solve}} for {what} {how}."
        choose = (
            " {set_method} chooses the pose alone (the lens is known) or the full camera matrix."
            if self.K is not None
            else ""
        )
        return Step(
            "pick_model", f"Click a model corner drawn in the overlay (point {n + 1}){tail}{choose}", frozenset(has)
        )

    def choice_value(self, action: str) -> Any:
        return self.method if action == "set_method" else None

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action == "set_method":
            return [(METHODS[m][0], m) for m in ("pnp", "dlt")] if self.K is not None else []
        if action != "pair":
            return []
        with self.lock:  # after a Solve the farthest off first, as Delete point's default (it deleted the best)
            err = self.result.errors_px if self.result is not None else None
            out = [
                (f"{i + 1} {lab}" + (f" · {err[i]:.1f} px" if err is not None and i < len(err) else ""), i)
                for i, lab in enumerate(self.labels)
            ]
            if err is not None and len(err) == len(out):
                out.sort(key=lambda item: -float(err[item[1]]))
            return out

    def weaknesses(self) -> list[str]:
        with self.lock:
            out = []
            if self.result is None:
                return out
            n = len(self.uv)
            pnp = self.solved_by == "pnp"
            least = MIN_REDUNDANT_PAIRS_PNP if pnp else MIN_REDUNDANT_PAIRS
            if n < least:
                unknowns = "the pose's 6 unknowns" if pnp else "C's 11 unknowns"
                out.append(
                    f"only {n} points ({2 * n} coordinates) for {unknowns}: enough to solve, but little "
                    f"redundancy to catch a wrong click ({least} or more is safer)"
                )
            sig = self._sigmas()
            bad = [i for i, (e, sg) in enumerate(zip(self.result.errors_px, sig)) if e > 3 * max(sg, 0.5)]
            chi = float(np.sum((self.result.errors_px / np.maximum(sig, 0.5)) ** 2))
            if pnp and n > 4 and chi > _chi2_999(2 * n - 6):  # the residuals, all told, beyond the clicks' precision
                out.append(
                    f"the points fit the known lens poorly (RMS {self.result.rms_px:.1f} px): a wrong click, or a "
                    "lens file that is not this camera's (zoom, focus, image size)? Solve by the full camera "
                    "matrix to compare"
                )
            for i in bad:
                out.append(
                    f"point {i + 1} ({self.labels[i]}) is {self.result.errors_px[i]:.1f} px from where C puts it "
                    "(more than 3σ): a wrong corner?"
                )
            out += weak_snaps((f"point {i + 1}", sn) for i, sn in enumerate(self.snaps))
            return out

    def marks(self) -> Marks:
        with self.lock:
            cam = self.camera
            m = Marks(points=np.array(self.uv).reshape(-1, 2))
            m.labels = [(uv, str(i + 1)) for i, uv in enumerate(self.uv)]
            m.raw_segments, m.raw_points, m.snap_lines, snap_labels = snap_marks(self.snaps)
            m.labels += snap_labels
            if self.pending_X is not None and cam.depth(self.pending_X.reshape(1, 3))[0] > 0:
                m.pending = cam.project(self.pending_X.reshape(1, 3))
                m.circles = m.pending.copy()  # the picked corner, highlighted
                m.labels.append((m.pending[0] + [8.0, -8.0], self.pending_label))
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
                out["solved_by"] = METHODS[self.solved_by][0]
                out["rms_px"] = self.result.rms_px
                if self.solved_by == "pnp":
                    out["std_position_mm"] = 1000 * self.result.std_position_m
                    out["std_angle_deg"] = float(np.degrees(self.result.std_angle_rad))
                # a table, one row a point (its residual beside its name: two lists read poorly)
                out["points"] = [
                    {"point": label, "residual_px": float(e)} for label, e in zip(self.labels, self.result.errors_px)
                ]
            return out
