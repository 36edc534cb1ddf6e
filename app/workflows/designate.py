"""Designate a target: click the video → the 3D point on the database's surfaces, for the robot,
checked by the range finder.

The pixel's ray (through C) is cast against every database object at its database pose; the
first surface met is the target, given in world coordinates (metres) with the object's name and
the surface normal. When the site has devices, the range finder is then put on the same pixel
(``app.devices.acquisition.measure_at_pixel``: the parallax iteration aims the turret until the
measured point's image is the clicked pixel) and its point is compared with the database's along
the ray:

    Δ = (X_rf − c)·r − λ_db      (r the ray's unit direction from the camera centre c, λ_db the
                                  database surface's distance along it)

σ_Δ, the model (stated in ``Target.sigma_m``):

* the range finder's point: its covariance from ``measure_at_pixel`` — σ_ρ of the scene's
  range finder spec along the beam (or the shots' spread when larger; the median of ``shots``
  shots is used but σ_ρ is kept, a conservative choice), a turret step's quantisation across it —
  projected on the ray: rᵀ Σ_rf r;
* the turret calibration, when it was calibrated in this database (``site.calibration_covs``):
  the measured beam (pan, tilt, ρ) mapped through ``T_world_turret`` moved ±1σ along its
  covariance's principal axes (``core.calibration.principal_steps``/``perturbed_turret``),
  each shift of the point projected on the ray and added in quadrature;
* the camera calibration is left out: its error tilts the ray by a fraction of a pixel, which
  moves the database's depth along it by well under a millimetre at the workcell's 1–3 m; the
  database objects' pose σ are left out too (the check is of the database as it stands).

|Δ| > 3σ_Δ is a disagreement: the range finder nearer ("something not in the database is in the
way") or farther ("the database's surface is not there"); the target keeps the database's point
and carries the range finder's point and the warning. Where the database has no surface under the
click but the range finder hits something, the target is the range finder's point, with the same
warning. Without devices the target is the database's and the summary says "not checked by the
range finder". The measurement (≈0.1–1 s) runs outside the workflow's lock: the overlay keeps
drawing, and the beam spot follows the aiming. A device fault raises WorkflowError and keeps
nothing. Nothing is written to the database: the targets are shown and copied, and each one goes
out on the site's live feed when one is attached (``mcit serve --feed-socket``; app.feed, docs/exchange.md).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .base import CANCEL, STALE_FRAME_S, Cancelled, Control, Marks, Step, Workflow, WorkflowError, as_pixel
from .beams import LIMIT_SIGMA  # the beam check's limit (app/workflows/beams.py), here along the camera's ray

__all__ = ["Target", "DesignateTarget", "NOT_CHECKED", "LIMIT_SIGMA"]

NOT_CHECKED = "not checked by the range finder"
NOT_IN_DATABASE = "not in the database"
AIM_OFF_PX = 1.0  # a beam that lands farther than this from the click is said so
OLD_FRAME_S = 1.0  # a disagreement found from a frame older than this says when the frame was


@dataclass(frozen=True)
class Target:
    """A designated point: uv (2,) clicked; X_world (3,) metres; object name; range from the
    camera's centre (metres); outward surface normal (3,) (NaN when the point is the range
    finder's only).

    The range finder's check: rangefinder_X (3,) its measured point (None: not measured, or no
    return); disagreement_m its depth along the ray minus the database's (+: the range finder's
    surface is farther; NaN when there is nothing to compare); sigma_m σ of that difference (see
    the module's model); check one sentence saying what the check found; warning "" or the
    sentence the operator must read; frame_age_s how long before the newest frame the clicked frame was
    taken, when that is more than ``STALE_FRAME_S`` (NaN otherwise).
    """

    uv: np.ndarray
    X_world: np.ndarray
    object: str
    range_m: float
    normal: np.ndarray
    rangefinder_X: np.ndarray | None = None
    disagreement_m: float = float("nan")
    sigma_m: float = float("nan")
    check: str = NOT_CHECKED
    warning: str = ""
    frame_age_s: float = float("nan")  # set when the frame clicked on was old (``STALE_FRAME_S``): its age
    details: dict = field(default_factory=dict, compare=False)

    def text(self) -> str:
        """Copyable text: ``x y z`` in metres (world frame)."""
        x, y, z = self.X_world
        return f"{x:.4f} {y:.4f} {z:.4f}"


def _xyz(X: np.ndarray) -> str:
    return " ".join(f"{v:.4f}" for v in X)


def along_ray_sigma(
    cov_rf: np.ndarray, X_rf: np.ndarray, ray: np.ndarray, T_world_turret: np.ndarray, turret_cov: np.ndarray | None
) -> tuple[float, float, float]:
    """σ (metres) of the range finder's point along the ray (unit (3,)): total, the range finder's
    share and the turret calibration's share (0 without a covariance)."""
    from core.calibration import perturbed_turret, principal_steps

    r = np.asarray(ray, float)
    var_rf = float(r @ np.asarray(cov_rf, float) @ r)
    var_T = 0.0
    if turret_cov is not None:
        T = np.asarray(T_world_turret, float)
        x_t = np.linalg.solve(T, np.append(X_rf, 1.0))  # the beam's point in the turret frame (fixed by pan, tilt, ρ)
        for step in principal_steps(turret_cov):
            var_T += float(r @ ((perturbed_turret(T, step) @ x_t)[:3] - X_rf)) ** 2
    return float(np.sqrt(var_rf + var_T)), float(np.sqrt(var_rf)), float(np.sqrt(var_T))


class DesignateTarget(Workflow):
    name = "designate"
    title = "Designate target"
    shows_beam = True
    actions = ("click", "clear", "accept", "cancel")
    controls = (
        Control("clear", "Clear", "X", hint="Forget the targets designated so far"),
        Control("accept", "Done", "enter", color="green", hint="Close (nothing is written)"),
        CANCEL,
    )

    def __init__(self, site, client: str = "operator", view: str | None = None, shots: int = 3):
        super().__init__(site, client, view)
        if not (isinstance(shots, (int, np.integer)) and shots >= 1):
            raise WorkflowError(f"shots must be a positive whole number, got {shots!r}")
        self.shots = int(shots)
        self.targets: list[Target] = []
        self.progress: float | None = None
        self.progress_text = ""
        self.state = "click"

    # ------------------------------------------------------------------ the click
    def click(self, uv) -> Target:
        """Cast the clicked pixel's ray; the first database surface it meets is the target, checked
        by the range finder when the site has one (see the module's docstring)."""
        p = as_pixel(uv)
        with self.lock:  # a snapshot: the measurement below runs without the lock
            self._check_open()
            cam = self.camera
            T = self.site.T_world_turret
            _, turret_cov = self.site.calibration_covs
            devices = self.site.devices
            origin, d = cam.rays(p.reshape(1, 2))
            ray = d[0]
            hit = self.site.raycast(origin, ray)
            if hit is None and devices is None:
                raise WorkflowError(
                    f"the pixel ({p[0]:.0f}, {p[1]:.0f}) sees no object "
                    "of the database; click on an object or the table"
                )
            if devices is not None:
                self.cancel_event.clear()
                self.progress, self.progress_text = 0.0, "aiming"
        if devices is None:
            t = Target(p, hit.X_world, hit.name, hit.distance_m, hit.normal)
            return self._keep(t, _sentence(NOT_CHECKED))
        pm, reach = self._measure(cam, T, p, devices, hit)
        with self.lock:
            self.progress = None
            self._check_open()
            t = self._target(p, origin, ray, hit, pm, reach, T, turret_cov)
            if pm is not None and pm.hit:
                self.site.set_beam(pm.X_world)
            # the target's coordinates are in the instruction: the message is what the range finder found
            return self._keep(t, _sentence(t.warning or t.check))

    def _keep(self, t: Target, message: str) -> Target:
        why = self.scene_changed(t.uv)
        age = _frame_age_s(self)
        if age is not None and age > STALE_FRAME_S:
            # what the database and the range finder say is of the site now: that the frame still shows it here
            # is not known (the live video may look the same while the database moved)
            old = f"this frame is {age:.0f} s old; the scene may have changed since"
            now = f"{t.check} (with the database as it is now)" if t.check.startswith("the range finder agrees") else ""
            t = dataclasses.replace(
                t,
                check=now or t.check,
                frame_age_s=age,
                warning=f"Warning: {old}{': ' + why if why else ''}: the target is where the "
                f"database{' and the range finder' if t.rangefinder_X is not None else ''} put it now, "
                f"{_on(t.object)}, which may not be what this frame shows; look at the live video (L) or freeze a new "
                f"frame (F){'. ' + _sentence(t.warning) if t.warning else ''}",
            )
            message = _sentence(t.warning)
        elif why:
            warning = (
                f"Warning: {why}: the target is where the "
                f"database{' and the range finder' if t.rangefinder_X is not None else ''} put it now, "
                "not what the frozen frame shows; look at the live video (L) or freeze a new frame (F)"
            )
            t = dataclasses.replace(t, warning=warning)
            message = _sentence(warning)
        elif t.warning and t.rangefinder_X is not None and self.frame is not None:
            now = self.site.time_s()
            if (
                abs(now - float(self.frame.t_s)) > OLD_FRAME_S
            ):  # a frozen frame's box was where the database had it: the disagreement read
                # as false to a new operator, though the site had changed since
                t = dataclasses.replace(
                    t,
                    warning=f"{t.warning} (the range finder measures the site as it is now, at "
                    f"t = {now:.1f} s; your click was on the frame of t = {self.frame.t_s:.1f} s)",
                )
                message = _sentence(t.warning)
        with self.lock:
            self.targets.append(t)
            self.message = message
            self._publish(t, len(self.targets))
            return t

    def _publish(self, t: Target, index: int) -> None:
        """Send the target out on the site's live feed (app.feed), when one is attached."""
        if getattr(self.site, "feed", None) is None:
            return
        import time

        from app.feed import target_event

        try:
            version = next((o.version for o in self.site.objects() if o.name == t.object), None)
            self.site.publish(
                target_event(
                    t,
                    index=index,
                    who=self.client,
                    when=time.time(),
                    version=version,
                    camera_centre=self.camera.center,
                    image_time=self.seen_at(),
                )
            )
        except Exception:  # noqa: BLE001 - the target stands (shown, copied) even if the feed fails
            import logging

            logging.getLogger("mcit.feed").exception("target %d could not be sent on the live feed", index)

    def _measure(self, cam, T, p, devices, hit):
        """The range finder put on pixel p (outside the lock): (PixelMeasurement, "") or (None, why
        not) when the turret cannot reach it. A device fault → WorkflowError; a cancel → Cancelled."""
        from app.devices import DeviceError, TurretLimitError
        from app.devices.acquisition import AcquisitionCancelled, measure_at_pixel
        from core.rangefinder import beam_point

        def report(prog) -> None:
            self.progress = prog.done / max(prog.total, 1)
            self.progress_text = "aiming" if "aiming" in prog.message else "measuring"
            if prog.beam is not None and np.isfinite(prog.beam[2]):
                self.site.set_beam(beam_point(T, *prog.beam))

        guess = float(cam.depth(hit.X_world)) if hit is not None else 2.0
        try:
            pm = measure_at_pixel(
                cam,
                T,
                p,
                devices.turret,
                devices.rangefinder,
                shots=self.shots,
                spec=self.site.scene.rangefinder,
                depth_guess_m=guess,
                progress=report,
                cancel=self.cancel_event,
            )
        except AcquisitionCancelled:
            self.progress = None
            self.site.set_beam(None)  # the spot of an aim stopped half-way marks no target
            raise Cancelled() from None
        except TurretLimitError as exc:
            self.progress = None
            self.site.set_beam(None)
            if hit is None:
                raise WorkflowError(
                    f"the pixel ({p[0]:.0f}, {p[1]:.0f}) sees no object of the database and the range "
                    f"finder cannot aim there ({exc}); click on an object or the table"
                ) from None
            return None, f"{NOT_CHECKED}: the turret cannot aim there"
        except DeviceError as exc:
            self.progress = None
            self.site.set_beam(None)
            raise WorkflowError(
                f"device fault while checking the target with the range finder: {exc}. Check the "
                "devices and click again"
            ) from None
        return pm, ""

    def _target(self, p, origin, ray, hit, pm, reach: str, T, turret_cov) -> Target:
        """The target from the database's hit (or None) and the range finder's measurement (or None)."""
        if pm is None or not pm.hit:
            if hit is None:
                raise WorkflowError(
                    f"the pixel ({p[0]:.0f}, {p[1]:.0f}) sees no object of the database and the range "
                    "finder got no return there; click on an object or the table"
                )
            why = reach or f"{NOT_CHECKED}: it got no return there"
            return Target(p, hit.X_world, hit.name, hit.distance_m, hit.normal, check=why)
        X_rf = np.asarray(pm.X_world, float)
        sigma, s_rf, s_T = along_ray_sigma(pm.cov_world, X_rf, ray, T, turret_cov)
        depth_rf = float((X_rf - origin) @ ray)
        details = {"sigma_rangefinder_m": s_rf, "sigma_turret_m": s_T, "aim_error_px": float(pm.aim.error_px)}
        off = (
            f" (the beam landed {pm.aim.error_px:.1f} px from the click)"
            if np.isfinite(pm.aim.error_px) and pm.aim.error_px > AIM_OFF_PX
            else ""
        )
        limit = LIMIT_SIGMA * sigma
        if hit is None:
            warning = (
                f"Warning: the database has no surface here, but the range finder met one {depth_rf:.2f} m "
                f"away, at {_xyz(X_rf)} m: something the database does not have (an object, or the room "
                f"behind){off}"
            )
            return Target(
                p,
                X_rf,
                NOT_IN_DATABASE,
                float(np.linalg.norm(X_rf - origin)),
                np.full(3, np.nan),
                rangefinder_X=X_rf,
                sigma_m=sigma,
                check="the range finder's point: the database has no surface here",
                warning=warning,
                details=details,
            )
        delta = depth_rf - hit.distance_m
        if abs(delta) <= limit:
            check = (
                f"the range finder agrees: {1000 * abs(delta):.1f} mm along the line of sight, within "
                f"{LIMIT_SIGMA:.0f}σ = {1000 * limit:.1f} mm{off}"
            )
            warning = ""
        else:
            check = (
                f"the range finder disagrees by {100 * delta:+.1f} cm along the "
                f"line of sight ({LIMIT_SIGMA:.0f}σ = {1000 * limit:.1f} mm){off}"
            )
            if delta < 0:
                warning = (
                    f"Warning: the range finder met a surface {100 * -delta:.1f} cm in front of the database's "
                    f"{hit.name}, at "
                    f"{_xyz(X_rf)} m: something not in the database is in the way{off}"
                )
            else:
                warning = (
                    f"Warning: the range finder met no surface at {hit.name} but one {100 * delta:.1f} cm behind "
                    f"it, at {_xyz(X_rf)} m: {hit.name} is not where the database has it: the {hit.name} has moved: "
                    f"update its pose first{off}"
                )
        return Target(
            p,
            hit.X_world,
            hit.name,
            hit.distance_m,
            hit.normal,
            rangefinder_X=X_rf,
            disagreement_m=float(delta),
            sigma_m=sigma,
            check=check,
            warning=warning,
            details=details,
        )

    # ------------------------------------------------------------------ other actions
    def on_double_click(self, view: str, uv) -> None:
        """Dropped: its first click designated the point (a habitual double click designated it twice)."""
        return None

    def has_work(self) -> bool:
        return bool(self.targets) or super().has_work()  # nothing written, but the list of targets goes

    def clear(self) -> None:
        """Forget the targets designated so far."""
        with self.lock:
            self.targets = []
            self.message = ""

    def accept(self) -> None:
        """Close the workflow (the targets stay in ``targets``; nothing is written)."""
        with self.lock:
            self._check_open()
            self.accepted = True
            self.state = "accepted"
            n = len(self.targets)
            self.message = f"Closed: {n} target{'s' if n != 1 else ''} designated (nothing is written to the database)."

    @staticmethod
    def _copy_point(t: Target) -> str:
        """What the robot should be sent for target t: where the range finder found the surface when
        it disagrees with the database (the database's point lies behind what is really there), else
        the database's point."""
        if t.warning and t.rangefinder_X is not None and np.all(np.isfinite(t.rangefinder_X)):
            x, y, z = t.rangefinder_X
            return f"{x:.4f} {y:.4f} {z:.4f}"
        return t.text()

    def copy_text(self) -> str:
        """The last target's world coordinates (metres), for the robot: the range finder's point when
        it disagrees with the database."""
        with self.lock:
            return self._copy_point(self.targets[-1]) if self.targets else ""

    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if self.progress is not None:
            return Step(
                "checking",
                f"Checking the target with the range finder: {self.progress_text}… " + "{cancel} stops it.",
                frozenset({"cancel"}),
                clicks=False,
            )
        if self.targets:
            t = self.targets[-1]
            where = _on(t.object)
            if t.warning and np.isfinite(t.frame_age_s):
                head = (
                    f"Target {len(self.targets)}: {self._copy_point(t)} m {where} (in the Target (m) box to "
                    f"copy). {_sentence(t.warning)}"
                )
            elif t.warning:
                head = (
                    f"Target {len(self.targets)}: {self._copy_point(t)} m, where the range finder met a surface (in "
                    f"the Target (m) box to copy). {_sentence(t.warning)}"
                )
            else:
                head = f"Target {len(self.targets)}: {t.text()} m {where} (in the Target (m) box to copy)."
            return Step(
                "targets", f"{head} Click another point, or " + "{accept}.", frozenset({"clear", "accept", "cancel"})
            )
        return Step(
            "click",
            "Click a point on an object or the table in the video; " + "{accept} closes.",
            frozenset({"accept", "cancel"}),
        )

    def marks(self) -> Marks:
        with self.lock:
            cam = self.camera
            m = Marks()
            if self.targets:
                X = np.array([t.X_world for t in self.targets])
                m.targets = cam.project(X)
                m.labels = [
                    (uv, f"T{i + 1}" + (f" ⚠ {_check_word(t)}" if t.warning else ""))
                    for i, (uv, t) in enumerate(zip(m.targets, self.targets))
                ]
                # the range finder's points where they differ from the target (a disagreement or its only point)
                rf = [
                    (i, t.rangefinder_X)
                    for i, t in enumerate(self.targets)
                    if t.warning and t.rangefinder_X is not None
                ]
                rf = [(i, X) for i, X in rf if cam.depth(X) > 0]
                if rf:
                    m.points = cam.project(np.array([X for _, X in rf]))
                    m.labels += [(uv + [0.0, 14.0], f"R{i + 1}") for (i, _), uv in zip(rf, m.points)]
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            rows = []
            for i, t in enumerate(self.targets):
                row = {"target": f"T{i + 1}", "on": t.object, "x y z (m)": self._copy_point(t), "check": _check_word(t)}
                if np.isfinite(t.disagreement_m):
                    row["disagreement_mm"] = _mm(t.disagreement_m)
                rows.append(row)
            return {"targets": rows}


def _on(name: str) -> str:
    """Where a target lies, as a sentence reads it ("on table"; not "on not in the database")."""
    return "on something not in the database" if name == NOT_IN_DATABASE else f"on {name}"


def _frame_age_s(wf: Workflow) -> float | None:
    """How long before its camera's newest frame ``wf``'s frozen frame was taken (seconds, from their capture
    stamps); None without a frozen frame or where a stamp is unknown (a recording read by time)."""
    if wf.frame is None or wf.frame.stamp is None:
        return None
    stamp = getattr(wf.site.latest_frame(wf.frame.view or wf.view), "stamp", None)
    return None if stamp is None else max(0.0, float(stamp) - float(wf.frame.stamp))


def _check_word(t: Target) -> str:
    """The target's check in a few words (the table, the label on the video): what its warning says."""
    if not t.warning:
        return t.check
    if np.isfinite(t.frame_age_s):
        return f"frame {t.frame_age_s:.0f} s old: the site now"
    return "not in the database: the range finder's point" if t.object == NOT_IN_DATABASE else "range finder disagrees"


def _mm(v: float) -> float | None:
    return None if not np.isfinite(v) else 1000 * float(v)


def _sentence(text: str) -> str:
    text = text.strip()
    return (text[0].upper() + text[1:] + ("" if text.endswith(".") else ".")) if text else text
