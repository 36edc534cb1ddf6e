"""What the range-finder modelling workflows share: faces measured by a patch of beams inside their
clicked sides, the acquisition's progress, beam spot and live points, device faults and cancels said
to the operator, the model's write, and the steps every modelling workflow has.

``RangeModelling`` is a mixin of ``ModelObject`` (boxes, cylinders, cones) and ``ModelPolyhedron``
(wedges, pyramids). It uses their ``site``, ``lock``, ``cancel_event``, ``faces`` (one dict per face:
"segs", "snaps", "points" (N, 3) world metres, "covs" (N, 3, 3) m², "scan", "good"), ``spacing_px``,
``object_name`` and their ``_has_something()`` / ``_last_snap()``; ``_init_acquisition()`` sets its own state.
"""

from __future__ import annotations

import threading
from contextlib import contextmanager
from typing import Any

import numpy as np

from core.geometry import hull_overlap
from core.rangefinder import RangeFinderSpec, beam_point, beam_point_cov

from .base import Cancelled, Step, WorkflowError

# A modelled object that shares this much of the smaller one's volume with an object already in the
# database is probably that object modelled again: Accept asks once more.
OVERLAP_SHARE = 0.25


def _hull_points(model, T_world_obj: np.ndarray) -> np.ndarray:
    """Points whose convex hull stands for the object's volume, in the world, (N, 3)."""
    V = model.triangles(16)[0]
    return V @ T_world_obj[:3, :3].T + T_world_obj[:3, 3] if len(V) else np.zeros((0, 3))


__all__ = ["RangeModelling"]


class RangeModelling:
    """Range-finder measurements and the model's write for a modelling workflow (module docstring)."""

    shows_beam = True
    selects_result = True  # the object just modelled is selected: Update pose, Track … apply to it next

    @classmethod
    def available(cls, site) -> str:
        """A camera-only site cannot model: every shape needs range-finder measurements (paper §III)."""
        if not site.has_turret:
            return "this site is camera-only: modelling an object needs the range finder (docs/own-site.md)"
        return ""

    def _init_acquisition(self) -> None:
        """The acquisition's state: progress (0..1 or None), its text, and the range points measured so
        far (world, metres; one per returned beam, appended from the acquiring thread under their own
        lock, drawn by ``marks()`` while it runs)."""
        self.progress: float | None = None
        self.progress_text = ""
        self.live_points_world: list[np.ndarray] = []
        self._live_lock = threading.Lock()
        self._acquiring_since: float | None = None  # when the acquisition under way started (its time left)

    @staticmethod
    def _new_face() -> dict[str, Any]:
        return {"segs": [], "snaps": [], "points": None, "covs": None, "scan": None, "good": None}

    def _devices(self):
        devices = self.site.devices
        if devices is None:
            raise WorkflowError(self.site.no_devices("measure"))
        return devices

    def _report(self, fraction: float, text: str, X: np.ndarray | None = None, keep: bool = True) -> None:
        """One step of an acquisition (called on the acquiring thread): the bar at ``fraction``, the
        text, the beam spot moved to the point X just measured (None: no return) and, with ``keep``,
        X added to the live points; Cancelled when the operator cancelled."""
        import time

        now = time.monotonic()
        if self._acquiring_since is None:
            self._acquiring_since = now
        elapsed = now - self._acquiring_since
        left = elapsed * (1.0 - fraction) / max(fraction, 1e-9)
        if fraction >= 0.05 and elapsed >= 3.0 and left >= 15.0:  # said once the pace is known (a scan took 70 s,
            text += f" · about {_duration(left)} left"  # unannounced); a short patch's "5 s" went stale
        self.progress = float(fraction)
        self.progress_text = text
        if X is not None and np.all(np.isfinite(X)):
            self.site.set_beam(X)
            if keep:
                with self._live_lock:
                    self.live_points_world.append(np.asarray(X, float).copy())
        if self.cancel_event.is_set():
            raise Cancelled()

    def _progress(self, T: np.ndarray, label: str, k: int = 0, parts: int = 1, aiming: bool = False):
        """The ``progress`` callback of acquisition k (from 0) of ``parts``: "label · beam i of m" (a
        report with done = 0, or any with ``aiming``: "label · aiming", its point not kept)."""

        def report(p) -> None:
            X = None if p.beam is None else beam_point(T, *p.beam)
            if aiming or p.done == 0:
                self._report(k / parts, f"{label} · aiming", X, keep=False)
            else:
                self._report((k + p.done / max(p.total, 1)) / parts, f"{label} · beam {p.done} of {p.total}", X)

        return report

    def _clear_live(self) -> None:
        self._acquiring_since = None
        with self._live_lock:
            self.live_points_world = []

    def _live_points(self) -> np.ndarray:
        """The live points so far, (L, 3)."""
        with self._live_lock:
            return np.array(self.live_points_world).reshape(-1, 3)

    @contextmanager
    def _acquiring(self, doing: str, again: str, refused: str):
        """Around a device acquisition: a cancel → Cancelled, a device fault or a refused request
        (ValueError) → WorkflowError saying what to do; the progress bar is cleared on failure."""
        from app.devices import DeviceError
        from app.devices.acquisition import AcquisitionCancelled

        try:
            yield
        except (AcquisitionCancelled, Cancelled):
            self.progress = None
            self._clear_live()
            raise Cancelled() from None
        except DeviceError as exc:
            self.progress = None
            self._clear_live()
            raise WorkflowError(f"device fault while {doing}: {exc}. Check the devices and {again}") from None
        except WorkflowError:
            self.progress = None
            self._clear_live()
            raise
        except ValueError as exc:
            self.progress = None
            self._clear_live()
            raise WorkflowError(f"{refused}: {exc}") from None

    def _measure_face(self):
        """Range points on the current face (``self.faces[-1]``), inside its clicked outline: the turret
        scans a patch of beams there; the face keeps its points, their covariances, the scan and
        which beams gave points. Shared by the polyhedra's workflow."""
        from app.devices.acquisition import face_patch_scan

        with self.lock:
            self._check_open()
            segs = self.faces[-1]["segs"]
            if self.faces[-1]["points"] is not None:
                raise WorkflowError("this face is measured: click the sides of the next face, or Solve")
            if len(segs) < 2:
                raise WorkflowError(f"click at least 2 sides of this face first ({len(segs)} clicked)")
            devices = self._devices()
            ends = np.concatenate(segs)
            centre = ends.mean(axis=0)
            # The patch: the clicked sides' ends shrunk towards their centre, so that beams stay on the face.
            poly = centre + 0.6 * (_convex_hull(ends) - centre)
            q = np.roll(poly, -1, axis=0)
            area = 0.5 * abs(float(np.sum(poly[:, 0] * q[:, 1] - q[:, 0] * poly[:, 1])))  # shoelace
            spacing = self.spacing_px or max(2.0, float(np.sqrt(area / 25.0)))
            camera, T = self.camera, self.site.T_world_turret
        self._refuse_if_changed(np.vstack([ends, centre]), "this face", inside=True)
        with self.lock:
            self._check_open()
            self.cancel_event.clear()
            self._clear_live()
            self.progress, self.progress_text = 0.0, "face patch · aiming"
        with self._acquiring("measuring", "Measure again", "cannot measure this face"):
            scan = face_patch_scan(
                camera,
                T,
                devices.turret,
                devices.rangefinder,
                polygon_uv=poly,
                spacing_px=spacing,
                depth_guess_m=float(camera.depth(self.support_point(centre))),
                progress=self._progress(T, "face patch"),
                cancel=self.cancel_event,
            )
        (scan,), moved = self._leave_out_moved([scan], T)
        with self.lock:
            self.progress = None
            self._clear_live()  # kept in the face below, or dropped with it
            good = scan.hits & np.asarray(scan.meta.get("inside", scan.hits), bool)
            if good.sum() < 3:
                raise WorkflowError(
                    f"only {int(good.sum())} of {len(scan)} beams came back from the face: no range "
                    "return; click the face's sides again (larger), or check the range finder"
                )
            X = scan.points(T)[good]
            spec = self._spec()
            covs = beam_point_cov(T, scan.pan_rad[good], scan.tilt_rad[good], scan.range_m[good], spec)
            self.faces[-1].update(points=X, covs=covs, scan=scan, good=good)
            self.site.set_beam(X[-1])
            self.result = None
            self.message = f"Face {len(self.faces)}: {len(X)} range points of {len(scan)} beams."
            if moved:
                self.message += f" ⚠ {moved}."
            doubt = _patch_doubts(X, covs, len(scan))
            if doubt:
                # said now, not as a wrong face blamed at Solve (a new operator's patch fell half off its face)
                self.message += (
                    f" ⚠ {doubt}: part of the patch may lie off face {len(self.faces)} (on another "
                    "surface, or beyond it). Remove last drops these points; click all of the face's "
                    "visible sides, then Measure face again."
                )
            return scan

    def _leave_out_moved(self, scans: list, T: np.ndarray) -> tuple[list, str]:
        """The scans with each beam that met a known object farther than the database has it by more than
        3σ (``beams.check_beams``: that object's surface is not there, it has moved) made a miss, and what
        the operator is told ("" for none). A return nearer than the database's surface is what is being
        modelled (the database does not have it yet), so only farther ones are left out."""
        import dataclasses

        from .beams import check_beams, disagreement_text

        out, moved, labels = [], [], []
        for k, scan in enumerate(scans):
            hit = np.flatnonzero(scan.hits)
            checks = check_beams(
                self.site, T, scan.pan_rad[hit], scan.tilt_rad[hit], scan.range_m[hit], self.site.calibration_covs[1]
            )
            far = [(i, c) for i, c in zip(hit, checks) if c.farther]
            rho = scan.range_m.copy()
            rho[[i for i, _ in far]] = np.nan
            out.append(dataclasses.replace(scan, range_m=rho) if far else scan)
            moved += [c for _, c in far]
            labels += [f"beam {i + 1}" + (f" of profile {k + 1}" if len(scans) > 1 else "") for i, _ in far]
        return out, disagreement_text(moved, labels)

    def _refuse_if_changed(self, uv: np.ndarray, what: str, inside: bool = False) -> None:
        """WorkflowError when the live video around the pixels ``uv`` differs from the frozen frame:
        the devices would measure what the clicks do not show (Workflow.scene_changed). ``inside``:
        the pixels outline what is measured; they are taken a third of the way in towards their centre
        (on the outline the background shows, and something moving behind is no change of the object).
        Call it without the lock."""
        from app.vision.change import inside as inward

        uv = np.asarray(uv, float).reshape(-1, 2)
        if inside:
            uv = inward(uv)
        why = self.scene_changed(uv)
        if why:
            raise WorkflowError(
                f"{why}: {what} may not be where the frozen frame shows it. Nothing was measured: "
                "measure again when the video there looks as frozen, or Cancel and start on a new frame"
            )

    def support_point(self, uv: np.ndarray) -> np.ndarray:
        """The table point seen at pixel uv (a depth guess for aiming), else a point 2 m away."""
        cam = self.camera
        o, d = cam.rays(np.asarray(uv, float).reshape(1, 2))
        hit = self.site.raycast(o, d[0])
        return hit.X_world if hit is not None else o + 2.0 * d[0]

    def _spec(self) -> RangeFinderSpec:
        """The range finder's noise model (the scene's: σ_ρ, limits, the turret's step)."""
        return self.site.scene.rangefinder

    def _overlaps(self, r) -> list[str]:
        """The database objects the result ``r`` overlaps by a quarter of the smaller one's volume or
        more (each a weakness: the object may be in the database already). Called outside the lock."""
        if r is None:
            return []
        mine = _hull_points(r.model, r.T_world_obj)
        if len(mine) < 4:
            return []
        lo, hi = mine.min(0), mine.max(0)
        out = []
        for obj in self.site.objects():
            if obj.name == self.object_name:
                continue
            theirs = _hull_points(obj.model, obj.T_world_obj)
            if len(theirs) < 4 or np.any(theirs.min(0) > hi) or np.any(theirs.max(0) < lo):
                continue
            share = max(hull_overlap(mine, theirs), hull_overlap(theirs, mine))
            if share >= OVERLAP_SHARE:
                out.append(
                    f"it overlaps {obj.name} ({100 * share:.0f} % of the smaller one's volume): is it in the "
                    "database already? (Accept anyway adds a second object)"
                )
        return out

    def _write_model(self, r, *, method: str, clicks: Any, measurements: Any, note: str, text: str):
        """Add the modelled object ``r`` (a ModelResult; one transaction, status "modelled") and close
        the workflow (the lock held). Shared by the polyhedra's workflow."""
        try:
            rec = self.site.add_object(
                self.object_name,
                r.kind,
                r.model,
                r.T_world_obj,
                dims=r.dimensions,
                sigmas={k: v for k, v in r.sigmas.items() if np.isfinite(v)},
                status="modelled",
                method=method,
                client=self.client,
                clicks=clicks,
                measurements=measurements,
                residuals={k: np.asarray(v) for k, v in r.residuals.items()},
                note=note,
                seen_at=self.seen_at(),
            )
        except ValueError as exc:
            raise WorkflowError(f"the database refused the object: {exc}") from None
        self.accepted = True
        self.state = "accepted"
        self.message = f"{self.object_name} added: {text}"
        return rec

    def _common_step(self) -> tuple[Step | None, set]:
        """What every modelling workflow's step shares: the step itself when finished or measuring,
        else None and the controls enabled in any state (Cancel, Remove last, Refuse snap)."""
        if self.finished:
            return self._finished_step(), set()
        if self.progress is not None:
            return Step(
                "measuring",
                f"Measuring… {self.progress_text}. " + "{cancel} stops it.",
                frozenset({"cancel"}),
                clicks=False,
            ), set()
        base = {"cancel"} | ({"remove_last"} if self._has_something() else set())
        snap, _ = self._last_snap()
        if snap is not None and snap.applied and self.pending is None:
            base.add("refuse_snap")
        return None, base


def _cross2(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def _convex_hull(P: np.ndarray) -> np.ndarray:
    """Convex hull (K, 2) of pixels (N, 2), counter-clockwise (monotone chain)."""
    pts = sorted(map(tuple, np.asarray(P, float)))
    if len(pts) <= 2:
        return np.array(pts)

    def half(points):
        out: list = []
        for p in points:
            while len(out) >= 2 and _cross2(np.subtract(out[-1], out[-2]), np.subtract(p, out[-2])) <= 0:
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(list(reversed(pts)))
    return np.array(lower[:-1] + upper[:-1])


def _duration(seconds: float) -> str:
    """A time left as said: "40 s", "2 min"."""
    s = max(0.0, float(seconds))
    return f"{5 * max(1, round(s / 5)):.0f} s" if s < 90 else f"{round(s / 60):.0f} min"


PATCH_MIN_RETURNED = 0.6  # _patch_doubts: at least this share of a face patch's beams come back from the face ...
PATCH_MAX_OFF_PLANE = 0.2  # ... and at most this share of its points lie off the plane the others fit


def _patch_doubts(X: np.ndarray, covs: np.ndarray, n_beams: int) -> str:
    """Why a face patch's points may not all be on the face ("" when nothing is wrong): few of its beams
    came back, or many of its points lie off the plane the others fit (the RANSAC of the face's plane
    fit at Solve, ``core.modeling.observations.fit_face_plane``: 3.5 σ along the beam, at least 3 mm)."""
    from core.modeling.observations import fit_face_plane

    out = []
    if len(X) < PATCH_MIN_RETURNED * n_beams:
        out.append(f"only {len(X)} of {n_beams} beams came back from the patch")
    if len(X) >= 4:
        try:
            share = 1.0 - float(np.mean(fit_face_plane(X, covs=covs).inliers))
        except ValueError:
            share = 1.0
        if share > PATCH_MAX_OFF_PLANE:
            out.append(f"{share:.0%} of its points lie off the plane of the others")
    return " and ".join(out)
