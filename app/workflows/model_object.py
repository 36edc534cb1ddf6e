"""Model an unknown object from clicked image edges and range measurements (source paper §III).

The operator gives the semantics when starting — the shape ("box", "cylinder", "cone"), whether it
is vertical, whether it lies on the table — and the sensors give the numbers:

* box: for each visible face (1 to 3) click its sides in the video (two clicks per side), then
  ``measure()``: the turret scans a patch of range points inside the clicked outline; the next click
  (or ``next_face()``) starts the next face. ``solve()`` builds the box (``core.modeling.model_box``:
  face planes ∩ interpretation planes, the table as the bottom face). Optionally ``scan()`` after measuring:
  two horizontal profiles at the turret's finest step across the box given by the faces (at 50 %
  and 75 % of its height, 3 cm past it on each side); ``solve()`` then fuses them ("fused" with
  scans: the profiles' edge transitions pin the far vertical edges the clicks place poorly).
* cylinder / cone: click the two silhouette lines, each from its bottom end to its top end, then
  ``scan()``: two horizontal range profiles across the object (misses kept); ``solve(method=...)``
  fits it (``core.modeling.model_cylinder``; "fused" by default, or the paper's "tangential",
  "bisecting", "rf_tangential").

``measure()``/``scan()`` drive the devices (aiming, progress in ``progress`` 0..1 and ``progress_text``
"profile k of 2 · beam i of m" / "face patch · beam i of m", ``cancel()`` stops them at the next
beam); while they run the beam spot follows each beam (``site.set_beam``) and the points measured so
far (``live_points_world``) are drawn. The preview is drawn as a ghost with its dimensions ± σ; ``accept()`` adds
the object (status "modelled") with its clicks and measurements in one transaction.

Each clicked segment (a face's side, a silhouette) is snapped to the image's edge on the frame the
operator clicked on (``snapping``: the snapped ends are the clicks moved onto the edge, so a
silhouette keeps its clicked height); ``refuse_snap()`` keeps the last one as clicked; the history
records both.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.geometry import Plane
from core.modeling.result import DIMENSION_WORDS
from core.rangefinder import RangeScan, aim, beam_point_cov

from .base import CANCEL, Control, Ghost, Marks, Step, Workflow, WorkflowError, as_pixel
from .range_modelling import RangeModelling
from .snapping import SnapMixin, snap_marks, weak_snaps

__all__ = ["ModelObject", "SHAPES", "table_support"]

SHAPES = ("box", "cylinder", "cone")
MIN_SEGMENT_PX = 3.0
# A box's profiles: heights (fractions of the box's) and how far past its corners they sweep. Above
# mid-height the jump from the box's last return to the table behind stays well over 5 cm
# (docs/modeling.md), so the box's run ends where its edge is.
BOX_SCAN_FRACTIONS = (0.5, 0.75)
BOX_SCAN_MARGIN_M = 0.03
# A model is weak (Accept asks once more) when a dimension's σ exceeds this, or a snap fits the image
# poorly where it put a click (``ClickSnap.weak``).
WEAK_SIGMA_MM = 5.0
CYLINDER_METHODS = {
    "fused": "fused (all measurements)",
    "tangential": "tangential planes (camera + range finder)",
    "bisecting": "bisecting planes (camera + range finder)",
    "rf_tangential": "tangential planes (range finder alone)",
}


# A clicked side this far from the model's edge (px, 3σ of a 1 px click): the model does not fit the clicks (weak).
MAX_CLICK_RESIDUAL_PX = 3.0


def _placed(r) -> str:
    """ "; placed to ± 4.1 mm": the σ of where a modelled object stands (its frame's origin, or its axis),
    "" when the result has none (a new operator saw a box sit 1 cm off with only its sizes' σ shown)."""
    for k, what in (("position", "placed"), ("axis_position", "axis placed")):
        v = r.sigmas.get(k)
        if v is not None and np.isfinite(v):
            return f"; {what} to ± {1000 * v:.1f} mm"
    return ""


def table_support(site) -> Plane | None:
    """The top plane of the database's table (normal up), or None when there is no table."""
    for obj in site.objects():
        if obj.kind == "table":
            lo, hi = obj.model.bounds()
            T = obj.T_world_obj
            n = T[:3, 2]
            X = T[:3, :3] @ np.array([0.0, 0.0, hi[2]]) + T[:3, 3]
            return Plane(n, float(-n @ X))
    return None


class ModelObject(RangeModelling, SnapMixin, Workflow):
    name = "model_object"
    form = ("shape", "vertical", "on_table")
    title = "Model object"
    actions = (
        "click",
        "add_segment",
        "remove_last",
        "measure",
        "scan",
        "next_face",
        "solve",
        "accept",
        "cancel",
        "refuse_snap",
        "set_snap",
        "set_method",
    )
    controls = (
        Control(
            "measure",
            "Measure face",
            "M",
            kind="long",
            color="blue",
            hint="The turret scans range points inside the face's clicked sides",
        ),
        Control(
            "scan",
            "Scan profile",
            "P",
            kind="long",
            color="blue",
            hint="Two horizontal range profiles across the object",
        ),
        Control(
            "set_method", "Method", kind="choice", hint="How a cylinder or cone is fitted (the paper's three, or fused)"
        ),
        Control("solve", "Solve", "R", color="blue", hint="Build the model from the clicks and ranges"),
        Control("accept", "Accept", "enter", color="green", hint="Add the modelled object to the database"),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last side as clicked, not moved onto the image's edge"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click, measurement or face"),
        CANCEL,
    )

    def __init__(
        self,
        site,
        client: str = "operator",
        view: str | None = None,
        shape: str = "box",
        vertical: bool = True,
        on_table: bool = True,
        object_name: str | None = None,
        method: str = "fused",
        spacing_px: float | None = None,
        beams: int = 40,
        snap: bool = True,
    ):
        super().__init__(site, client, view)
        self._init_snap(snap)
        if shape not in SHAPES:
            raise WorkflowError(f"shape must be one of {', '.join(SHAPES)}, got {shape!r}")
        self.shape = shape
        self.vertical = bool(vertical)
        self.on_table = bool(on_table)
        self.method = method
        self.spacing_px = spacing_px
        self.beams = int(beams)
        self.support = table_support(site) if on_table else None
        if on_table and self.support is None:
            raise WorkflowError("'lies on the table' needs a table in the database; untick it or add the table")
        taken = {o.name for o in site.objects()}
        if object_name is None:
            i = 1
            while f"{shape}_{i}" in taken:
                i += 1
            object_name = f"{shape}_{i}"
        elif object_name in taken:
            raise WorkflowError(f"an object named {object_name!r} already exists; choose another name")
        self.object_name = object_name
        # box: one entry per face {"segs": [...], "snaps": [...], "points": (N, 3), "covs": (N, 3, 3),
        # "scan": RangeScan, "good": (len(scan),) the beams that gave "points"}
        self.faces: list[dict[str, Any]] = [self._new_face()]
        self.silhouettes: list[np.ndarray] = []
        self.silhouette_snaps: list = []
        self.scans: list[RangeScan] = []
        self.pending: np.ndarray | None = None
        self.result = None
        self._init_acquisition()
        self.state = "click"

    # ------------------------------------------------------------------ clicks
    @property
    def _segments(self) -> list:
        return self.faces[-1]["segs"] if self.shape == "box" else self.silhouettes

    @property
    def _snaps(self) -> list:
        """Each clicked segment's snap, beside ``_segments``."""
        return self.faces[-1]["snaps"] if self.shape == "box" else self.silhouette_snaps

    def _last_snap(self):
        segs = self._segments
        if self.shape == "box" and self.faces[-1]["points"] is not None:
            return None, None  # the face is measured: its sides are fixed (Remove last first)
        if not segs:
            return None, None
        i = len(segs) - 1
        return self._snaps[i], lambda raw: segs.__setitem__(i, raw)

    def _after_refuse(self) -> None:
        self.result = None

    def click(self, uv) -> None:
        """First or second end of an image edge (a side of the current face, or a silhouette)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.pending is None:
                if self.shape != "box" and len(self.silhouettes) == 2:
                    raise WorkflowError(
                        "Both silhouettes are clicked: Scan profile next, or Remove last to click one again."
                    )
                if self.shape == "box" and self.faces[-1]["points"] is not None:
                    if len(self.faces) == 3:
                        raise WorkflowError("A box shows at most 3 faces and 3 are measured: Solve now.")
                    self.faces.append(self._new_face())  # the measured face is done: this click starts the next one
                    self.result = None
                    self.message = f"Face {len(self.faces)} started: click two points on each of its sides."
                if self.shape == "box" and len(self._segments) == 4:
                    raise WorkflowError("A face has at most 4 sides: Measure face next, or Remove last.")
                self.pending = p
                return
            seg, snap = self._finish_segment(self.pending, p, MIN_SEGMENT_PX)
            self.pending = None
            self._segments.append(seg)
            self._snaps.append(snap)
            self.result = None
            self.message = self._snap_message(
                f"{'Side' if self.shape == 'box' else 'Silhouette'} {len(self._segments)}", snap
            )

    def add_segment(self, seg_uv) -> None:
        """A clicked segment (2, 2) at once (for scripts)."""
        self._click_segment(seg_uv)

    def set_method(self, method: str) -> None:
        """Cylinder or cone: the fitting method (``CYLINDER_METHODS``) Solve uses."""
        with self.lock:
            self._check_open()
            if self.shape == "box":
                raise WorkflowError("a box has one method; the method is for cylinders and cones")
            if method not in CYLINDER_METHODS:
                raise WorkflowError(f"the method is one of {', '.join(CYLINDER_METHODS)}, not {method!r}")
            if method != self.method:
                self.method = method
                self.result = None
                self.message = f"Method: {CYLINDER_METHODS[method]}. Solve again."

    def remove_last(self) -> None:
        """Undo the last click, measurement or face."""
        with self.lock:
            self._check_open()
            if not self._has_something():
                raise WorkflowError("there is no click or measurement to remove")
            self.result = None
            if self.pending is not None:
                self.pending = None
            elif self.shape == "box" and self.scans:
                self.scans = []
            elif self.shape == "box":
                face = self.faces[-1]
                if face["points"] is not None:
                    face.update(points=None, covs=None, scan=None, good=None)
                elif face["segs"]:
                    face["segs"].pop()
                    face["snaps"].pop()
                elif len(self.faces) > 1:
                    self.faces.pop()
            elif self.scans:
                self.scans = []
            elif self.silhouettes:
                self.silhouettes.pop()
                self.silhouette_snaps.pop()

    def _has_something(self) -> bool:
        if self.pending is not None or self.scans:
            return True
        if self.shape == "box":
            return len(self.faces) > 1 or bool(self.faces[0]["segs"]) or self.faces[0]["points"] is not None
        return bool(self.silhouettes)

    def next_face(self) -> None:
        """Box: the current face is done (sides clicked and measured); go on to the next one."""
        with self.lock:
            self._check_open()
            if self.shape != "box":
                raise WorkflowError("next face is for boxes")
            face = self.faces[-1]
            if face["points"] is None:
                raise WorkflowError("measure this face first (Measure face)")
            if len(self.faces) == 3:
                raise WorkflowError("a box shows at most 3 faces: Solve now")
            self.faces.append(self._new_face())

    # ------------------------------------------------------------------ measurements
    def _profile(self, devices, k: int, T: np.ndarray, **sweep) -> RangeScan:
        """Profile k + 1 of 2 (``app.devices.acquisition.profile_scan`` with ``sweep``): the bar over
        both, "profile k + 1 of 2 · beam i of m", each beam's point shown as it comes."""
        from app.devices.acquisition import profile_scan

        return profile_scan(
            devices.turret,
            devices.rangefinder,
            progress=self._progress(T, f"profile {k + 1} of 2", k, 2),
            cancel=self.cancel_event,
            **sweep,
        )

    def measure(self):
        """Box: range points on the current face, inside its clicked outline (face patch scan)."""
        with self.lock:
            self._check_open()
            if self.shape != "box":
                raise WorkflowError("Measure face is for boxes; for a cylinder use Scan profile")
        return self._measure_face()

    def box_faces(self, T_world_turret: np.ndarray | None = None, faces: list | None = None) -> list:
        """The measured faces (of ``faces``, default this run's); with ``T_world_turret``, their range
        points mapped to the world through it from the raw beams (pan, tilt, range) instead of
        through the turret pose of the measurement."""
        from core.modeling import BoxFace

        out = []
        for f in self.faces if faces is None else faces:
            if f["points"] is None:
                continue
            X, covs = f["points"], f["covs"]
            if T_world_turret is not None and f.get("scan") is not None:
                scan, good = f["scan"], f["good"]
                X = scan.points(T_world_turret)[good]
                covs = beam_point_cov(
                    T_world_turret, scan.pan_rad[good], scan.tilt_rad[good], scan.range_m[good], self._spec()
                )
            out.append(BoxFace(X, np.array(f["segs"]).reshape(-1, 2, 2), covs))
        return out

    def _scan_box(self) -> list[RangeScan]:
        """Box: two horizontal profiles across the box that the measured faces give (finest step)."""
        from core.modeling import model_box

        with self.lock:
            self._check_open()
            faces = self.box_faces()
            if not faces:
                raise WorkflowError(
                    "measure the box's faces first (click a face's sides, Measure face): the "
                    "profiles are placed across the box they give"
                )
            devices = self._devices()
            try:
                box = model_box(self.camera, faces, self.support)
            except ValueError as exc:
                raise WorkflowError(f"cannot place the profiles: the measured faces give no box yet ({exc})") from None
            T = self.site.T_world_turret
            Tb, h = box.T_world_obj, box.dimensions["size_z"]
            corners = box.vertices_world
            camera = self.camera
        self._refuse_if_changed(camera.project(corners[camera.depth(corners) > 0]), "the box", inside=True)
        with self.lock:
            self._check_open()
            self.cancel_event.clear()
            self._clear_live()
            self.progress, self.progress_text = 0.0, "profile 1 of 2 · aiming"
        scans = []
        with self._acquiring("scanning", "Scan again", "cannot scan across the box"):
            for k, frac in enumerate(BOX_SCAN_FRACTIONS):
                pan0, tilt0, rho0 = aim(T, Tb[:3, :3] @ [0.0, 0.0, frac * h] + Tb[:3, 3])
                rel = (aim(T, corners)[0] - pan0 + np.pi) % (2 * np.pi) - np.pi
                pad = float(np.arctan(BOX_SCAN_MARGIN_M / rho0))
                scans.append(
                    self._profile(
                        devices,
                        k,
                        T,
                        tilt_rad=float(tilt0),
                        pan_start_rad=float(pan0 + rel.min() - pad),
                        pan_stop_rad=float(pan0 + rel.max() + pad),
                    )
                )
        scans, moved = self._leave_out_moved(scans, T)
        with self.lock:
            self.progress = None
            self._clear_live()  # now in self.scans
            self.scans = scans
            self.result = None
            hits = [int(s.hits.sum()) for s in scans]
            self.message = (
                f"2 profiles across the box: {hits[0]} and {hits[1]} returns "
                f"of {len(scans[0])} and {len(scans[1])} beams"
            ) + (f". ⚠ {moved}" if moved else "")
            return scans

    def scan(self) -> list[RangeScan]:
        """Two horizontal range profiles: cylinder/cone at 30 % and 70 % of its height; box (optional,
        after Measure face) at 50 % and 75 % of the height of the box its faces give, finest step."""
        from app.devices.acquisition import measure_at_pixel

        if self.shape == "box":
            return self._scan_box()
        with self.lock:
            self._check_open()
            if len(self.silhouettes) < 2:
                raise WorkflowError(f"click both silhouettes first ({len(self.silhouettes)} clicked)")
            devices = self._devices()
            camera, T = self.camera, self.site.T_world_turret
            sil = np.array(self.silhouettes)
        self._refuse_if_changed(sil.reshape(-1, 2), f"the {self.shape}", inside=True)
        with self.lock:
            self._check_open()
            self.cancel_event.clear()
            self._clear_live()
            self.progress, self.progress_text = 0.0, "profile 1 of 2 · aiming"
        scans = []
        with self._acquiring("scanning", "Scan again", "cannot scan across the object"):
            for k, frac in enumerate((0.3, 0.7)):
                left, right = sil[0, 0] + frac * (sil[0, 1] - sil[0, 0]), sil[1, 0] + frac * (sil[1, 1] - sil[1, 0])
                mid = (left + right) / 2
                m = measure_at_pixel(
                    camera,
                    T,
                    mid,
                    devices.turret,
                    devices.rangefinder,
                    depth_guess_m=float(camera.depth(self.support_point(mid))),
                    progress=self._progress(T, f"profile {k + 1} of 2", k, 2, aiming=True),
                    cancel=self.cancel_event,
                )
                if not m.hit:
                    raise WorkflowError(
                        f"no range return at the object's centre ({mid[0]:.0f}, {mid[1]:.0f}): check the "
                        "silhouettes and the range finder"
                    )
                depth = float(camera.depth(m.X_world))
                XL, XR = camera.backproject(np.array([left, right]), depth)
                pans = aim(T, np.array([XL, XR]))[0]
                half = abs(pans[1] - pans[0]) / 2
                lo, hi = min(pans) - 0.8 * half, max(pans) + 0.8 * half
                step = max(devices.turret.pan_step_rad, (hi - lo) / self.beams)
                scans.append(
                    self._profile(
                        devices, k, T, tilt_rad=m.tilt_rad, pan_start_rad=lo, pan_stop_rad=hi, pan_step_rad=step
                    )
                )
        scans, moved = self._leave_out_moved(scans, T)
        with self.lock:
            self.progress = None
            self._clear_live()  # now in self.scans
            self.scans = scans
            hits = [int(s.hits.sum()) for s in scans]
            if min(hits) < 3:
                raise WorkflowError(f"the scans hit the object with {hits} beams: too few; click the silhouettes again")
            last = scans[-1]
            self.site.set_beam(last.points(T)[np.nonzero(last.hits)[0][-1]])
            self.result = None
            self.message = f"2 profiles: {hits[0]} and {hits[1]} returns of {len(scans[0])} and {len(scans[1])} beams"
            if moved:
                self.message += f". ⚠ {moved}"
            return scans

    # ------------------------------------------------------------------ solve and accept
    def solve(self, method: str | None = None):
        """Build the model; its preview (ghost) and dimensions ± σ are shown."""
        from core.modeling.uncertainty import with_calibration_uncertainty

        with self.lock:
            self._check_open()
            cam, T = self.camera, self.site.T_world_turret
            camera_cov, turret_cov = self.site.camera_cov(self.view), self.site.calibration_covs[1]
            if self.shape == "box" and not self.box_faces():
                raise WorkflowError("measure at least one face first (click its sides, then Measure face)")
            if self.shape != "box":
                if len(self.scans) < 2 and (method or self.method) != "tangential":
                    raise WorkflowError("scan the object first (Scan profile)")
                if len(self.silhouettes) < 2:
                    raise WorkflowError("click both silhouettes first")
                self.method = method or self.method
            build = self._builder()
        # Outside the lock (the overlay keeps drawing): built from the raw beams, so that the turret's
        # calibration can be moved through its σ as well as the camera's (core.modeling.uncertainty):
        # the stated σ include both calibrations' share when they were calibrated in this database.
        try:
            result = with_calibration_uncertainty(build, cam, T, camera_cov=camera_cov, turret_cov=turret_cov)
        except ValueError as exc:
            raise WorkflowError(f"cannot build the {self.shape}: {exc}") from None
        with self.lock:
            self._check_open()
            self.result = result
            self.state = "review"
            parts = result.details.get("sigma_parts", {})
            self.message = (
                result.dimension_text("cm")
                + _placed(result)
                + (f" (σ include the {' and '.join(k for k in parts if k != 'measurements')})" if parts else "")
            )
            return result

    def _builder(self):
        """build(camera, T_world_turret) -> ModelResult from this run's clicks and raw range data."""
        from core.modeling import model_box, model_cylinder

        spec, support = self._spec(), self.support
        if self.shape == "box":  # a snapshot: clicks made while it runs do not change it
            faces = [dict(f, segs=list(f["segs"])) for f in self.faces]
            scans = list(self.scans)
            if scans:  # the profiles are fused with the faces and clicks
                return lambda cam, T: model_box(
                    cam, self.box_faces(T, faces), support, method="fused", scans=scans, T_world_turret=T, spec=spec
                )
            return lambda cam, T: model_box(cam, self.box_faces(T, faces), support)
        sil, scans, method, cone = np.array(self.silhouettes), list(self.scans), self.method, self.shape == "cone"
        axis_dir = np.array([0.0, 0.0, 1.0]) if (self.vertical and support is None) else None
        return lambda cam, T: model_cylinder(
            cam,
            method,
            silhouettes_uv=sil,
            scans=scans,
            T_world_turret=T,
            spec=spec,
            support=support,
            axis_dir=axis_dir,
            cone=cone,
        )

    def accept(self):
        """Add the modelled object to the database (one transaction, status "modelled")."""
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: Solve first")
            r = self.result
            if self.shape == "box":
                clicks = {
                    "frame": self.frame_record(),
                    "faces": [np.array(f["segs"]).reshape(-1, 2, 2) for f in self.faces],
                    # raw and snapped pixels of each side (None: snapping was off)
                    "snaps": [[None if sn is None else sn.record() for sn in f["snaps"]] for f in self.faces],
                }
                measurements = {"faces": [f["points"] for f in self.faces if f["points"] is not None]}
                if self.scans:
                    measurements["scans"] = [
                        {"pan_rad": s.pan_rad, "tilt_rad": s.tilt_rad, "range_m": s.range_m} for s in self.scans
                    ]
            else:
                clicks = {
                    "frame": self.frame_record(),
                    "silhouettes_uv": np.array(self.silhouettes),
                    "snaps": [None if sn is None else sn.record() for sn in self.silhouette_snaps],
                }
                measurements = {
                    "scans": [{"pan_rad": s.pan_rad, "tilt_rad": s.tilt_rad, "range_m": s.range_m} for s in self.scans]
                }
            return self._write_model(
                r,
                method=f"model {r.kind} ({r.method})",
                clicks=clicks,
                measurements=measurements,
                note=f"hints: {'vertical' if self.vertical else 'oblique'}{', on the table' if self.on_table else ''}",
                text=r.dimension_text("cm"),
            )

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        done, base = self._common_step()
        if done is not None:
            return done
        devices = self.site.devices is not None
        no_dev = "" if devices else f" ({self.site.no_devices('measure', sentence=True)})"
        if self.shape != "box":
            base.add("set_method")
        if self.result is not None:
            again = {"solve"} | ({"scan"} if devices and (self.shape != "box" or self.box_faces()) else set())
            return Step(
                "review",
                f"{self.result.dimension_text('cm')}{_placed(self.result)}. "
                + "{accept} to add it, or add measurements and "
                "{solve} again.",
                frozenset(base | again | {"accept"}),
            )
        if self.pending is not None:
            side = "silhouette" if self.shape != "box" else "side"
            return Step("click_end", f"Click the other end of that {side}.", frozenset(base))
        if self.shape == "box":
            face = self.faces[-1]
            n = len(self.faces)
            # Solve once it can work: two faces measured, or one and the profile scans
            measured = sum(f["points"] is not None for f in self.faces) >= 2 or (
                bool(self.scans) and any(f["points"] is not None for f in self.faces)
            )
            solvable = {"solve"} if measured else set()
            if face["points"] is not None:
                if self.scans:
                    return Step(
                        "scanned",
                        "Profiles scanned: {solve} (fused with the faces and clicks).",
                        frozenset(base | {"solve", "scan"}),
                    )
                if not measured:  # one face does not fix the three sizes: Solve would only refuse (a new operator's)
                    scan = ", or {scan} for the far edges" if devices else ""
                    return Step(
                        "face_measured",
                        f"Face {n} measured. A box needs a second face: click the sides of another visible face{scan}.",
                        frozenset(base | ({"scan"} if devices else set())),
                    )
                nxt = "" if n == 3 else "Click the sides of another face for more accuracy, "
                scan = "{scan} for the far edges, or " if devices else ""
                return Step(
                    "face_measured",
                    f"Face {n} measured. {nxt}{scan}" + "{solve}.",
                    frozenset(base | {"solve"} | ({"scan"} if devices else set())),
                )
            tail = " Or {solve} with the faces measured." if measured else ""
            if len(face["segs"]) < 2:
                return Step(
                    "click_sides",
                    f"Face {n}: click two points on each side of one visible face, all four "
                    f"where you see them (side {len(face['segs']) + 1}).{tail}",
                    frozenset(base | solvable),
                )
            if not devices:
                return Step(
                    "sides_clicked",
                    f"Face {n}: {len(face['segs'])} sides clicked.{no_dev}{tail}",
                    frozenset(base | solvable),
                )
            # all four: two upright sides alone gave a new operator a box half as deep
            more = "click its other sides (all four fix the box's corners), or " if len(face["segs"]) < 4 else ""
            return Step(
                "sides_clicked",
                f"Face {n}: {len(face['segs'])} sides clicked; "
                + more
                + "{measure} (the turret scans inside them)."
                + tail,
                frozenset(base | solvable | {"measure"}),
            )
        if len(self.silhouettes) < 2:
            which = "left" if not self.silhouettes else "right"
            return Step(
                "click_silhouettes",
                f"Click the {which} silhouette of the {self.shape} (its outline's {which} "
                "side): its bottom end, where it meets the table, then its top end, where it meets the top rim — "
                "the clicked ends give the height.",
                frozenset(base),
            )
        tangential = {"solve"} if self.method == "tangential" else set()
        if not self.scans:
            if not devices:
                return Step("no_devices", f"Both silhouettes clicked.{no_dev}", frozenset(base | tangential))
            return Step(
                "scan",
                "{scan}: the turret sweeps the range finder across the object at two heights.",
                frozenset(base | tangential | {"scan"}),
            )
        return Step(
            "solve",
            "{solve} " + f"with the method {CYLINDER_METHODS.get(self.method, self.method)}; another "
            "{set_method} can be chosen.",
            frozenset(base | {"solve", "scan"}),
        )

    def choice_value(self, action: str) -> Any:
        return self.method if action == "set_method" else None

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action == "set_method" and self.shape != "box":
            return [(text, key) for key, text in CYLINDER_METHODS.items()]
        return []

    def weaknesses(self) -> list[str]:
        with self.lock:
            r = self.result
            if r is None:
                return []
            out = [
                f"the {DIMENSION_WORDS.get(k, k.replace('_', ' '))} is uncertain: σ {1000 * v:.1f} mm (more than "
                f"{WEAK_SIGMA_MM:.0f} mm)"
                for k, v in r.sigmas.items()
                if np.isfinite(v) and 1000 * v > WEAK_SIGMA_MM
            ]
            res = np.abs(np.asarray(r.residuals.get("clicks_px", []), float))
            if self.shape == "box" and len(res) and res.max() > MAX_CLICK_RESIDUAL_PX:
                # the box drawn does not run through a side clicked (a new operator's box from two upright sides
                # per face came out half as deep, σ 3 mm, and was offered without a word)
                out.append(
                    f"a clicked side is {res.max():.1f} px from the box's edge (more than "
                    f"{MAX_CLICK_RESIDUAL_PX:.0f} px): the box does not fit your clicks; click all the sides "
                    "of each face (four), or check them"
                )
            snaps = (
                [sn for f in self.faces for sn in f["snaps"]] if self.shape == "box" else list(self.silhouette_snaps)
            )
            out += weak_snaps(("a click", sn) for sn in snaps)
            if self.shape == "box" and len(self.box_faces()) == 1 and not self.scans:
                out.append(
                    "one face measured: the box's depth rests on the clicks alone (measure a second face, or scan)"
                )
        return out + self._overlaps(r)

    def marks(self) -> Marks:
        with self.lock:
            m = Marks()
            segs = [s for f in self.faces for s in f["segs"]] if self.shape == "box" else list(self.silhouettes)
            if segs:
                m.segments = np.array(segs)
            if self.pending is not None:
                m.pending = self.pending.reshape(1, 2)
            snaps = (
                [sn for f in self.faces for sn in f["snaps"]] if self.shape == "box" else list(self.silhouette_snaps)
            )
            m.raw_segments, _, _, m.labels = snap_marks(snaps)
            cam = self.camera
            pts = [f["points"] for f in self.faces if f.get("points") is not None]
            T = self.site.T_world_turret
            pts += [s.points(T)[s.hits] for s in self.scans]
            if pts:
                X = np.concatenate(pts)
                X = X[cam.depth(X) > 0]
                m.points = cam.project(X) if len(X) else np.zeros((0, 2))
            live = self._live_points()  # the acquisition under way: its points so far
            live = live[cam.depth(live) > 0] if len(live) else live
            m.live_points = cam.project(live) if len(live) else np.zeros((0, 2))
            if self.result is not None:
                m.ghosts = [Ghost(self.result.model, self.result.T_world_obj, self.object_name, chosen=True)]
                lo, hi = self.result.model.bounds()
                # above the middle of its top (a prism's origin may be at a corner of its footprint)
                top = (
                    self.result.T_world_obj[:3, :3] @ np.array([0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1]), hi[2]])
                    + self.result.T_world_obj[:3, 3]
                )
                if cam.depth(top) > 0:
                    m.labels = [
                        (cam.project(top) - [0, 14], self.result.dimension_text("cm"))
                    ]  # the result, not the snaps
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {
                "name": self.object_name,
                "shape": self.shape,
                "hints": ("vertical" if self.vertical else "oblique") + (", on the table" if self.on_table else ""),
            }
            if self.shape == "box":
                out["faces"] = [
                    {"face": i + 1, "sides": len(f["segs"]), "points": 0 if f["points"] is None else len(f["points"])}
                    for i, f in enumerate(self.faces)
                ]
                if self.scans:
                    out["scans"] = [int(s.hits.sum()) for s in self.scans]
            else:
                out["silhouettes"] = len(self.silhouettes)
                out["scans"] = [int(s.hits.sum()) for s in self.scans]
            if self.result is not None:
                r = self.result
                out["method"] = r.method
                parts = r.details.get("sigma_parts", {})
                short = {
                    "measurements": "σ clicks+ranges (cm)",
                    "camera calibration": "σ camera (cm)",
                    "turret calibration": "σ turret (cm)",
                }
                out["dimensions"] = [
                    {
                        "dimension": DIMENSION_WORDS.get(k, k),
                        "value_cm": 100 * v,
                        "sigma_cm": 100 * r.sigmas.get(k, float("nan")),
                        **{short.get(src, src): 100 * p.get(k, float("nan")) for src, p in parts.items()},
                    }
                    for k, v in r.dimensions.items()
                ]
                for k in ("position", "axis_position"):  # where it stands, with its σ (only the sizes' were shown)
                    if k in r.sigmas:
                        out[f"sigma_{k}_mm"] = 1000 * r.sigmas[k]
            return out
