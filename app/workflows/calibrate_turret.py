"""Calibrate the turret (``T_world_turret``) from range measurements on the database's known surfaces.

The operator clicks known points in the overlay — a model vertex or the centre of a face (faces
are better: the beam lands on a surface, not on an edge) — and the turret aims at each with the
current calibration and measures. Where the beam really lands is not known exactly (the current
calibration is what is being corrected), but it lands on a known surface: ``solve()`` finds the
turret pose that puts every measured point on the database's surfaces (point-to-plane: each
measured point is associated with the face it is nearest to and ``core.calibration
.calibrate_turret_planes`` re-estimates the pose; repeated until it stops moving). At least 6
points on faces of three different orientations are needed (e.g. the table top and two sides of
a box). ``accept()`` stores
the calibration (one transaction) and every later aim uses it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.calibration import calibrate_turret_planes, next_turret_point, turret_plane_rows
from core.rangefinder import aim, beam_point, beam_ray
from core.transforms import pose_error

from .base import CANCEL, Cancelled, Control, Marks, Step, Workflow, WorkflowError, as_pixel, sigma_over
from .beams import BeamCheck, check_beams, disagreement_text

__all__ = ["CalibrateTurret"]

PICK_RADIUS_PX = 25.0
OFF_SURFACE_M = 0.05
POORLY_DEG, POORLY_M = 0.5, 0.01  # σ beyond which the operator is told to measure more
TARGET_DEG, TARGET_M = 0.2, 0.005  # the σ the suggested points work towards (each axis)
EDGE_MARGIN_M = 0.05  # suggested points keep this far inside a face's edges (a thinner face: its middle line,
# offered once the beams' own solve aims the turret: the calibration in use may be centimetres off)
GRID = 5  # suggested points: a GRID × GRID grid over each face seen by the camera and the turret
PRIOR_SD = np.array([np.radians(10.0)] * 3 + [0.5] * 3)  # keeps the information invertible before 6 beams


class CalibrateTurret(Workflow):
    name = "calibrate_turret"
    title = "Calibrate turret"
    shows_beam = True
    actions = ("click", "choose_point", "measure", "remove_last", "remove_measurement", "solve", "accept", "cancel")
    controls = (
        Control(
            "measure", "Measure", "M", kind="long", color="blue", hint="Aim at the picked point and measure its range"
        ),
        Control(
            "solve",
            "Solve",
            "R",
            color="blue",
            hint="The turret pose that puts every measured point on the known surfaces",
        ),
        Control("accept", "Accept", "enter", color="green", hint="Store the turret calibration"),
        Control("remove_last", "Remove last", "backspace", hint="Drop the picked point, or else the last measurement"),
        Control(
            "measurement",
            "Measurement",
            kind="choice",
            hint="A measured point (its distance to the surfaces after Solve)",
        ),
        Control(
            "remove_measurement", "Delete measurement", arg="measurement", hint="Delete the measurement chosen above"
        ),
        CANCEL,
    )

    @classmethod
    def available(cls, site) -> str:
        if not site.has_turret:
            return "this site is camera-only: it has no turret to calibrate (docs/own-site.md)"
        return ""

    def __init__(self, site, client: str = "operator", view: str | None = None, shots: int = 3):
        super().__init__(site, client, view)
        self.shots = int(shots)
        self.pending_X: np.ndarray | None = None
        self.pending_label = ""
        self.pan: list[float] = []
        self.tilt: list[float] = []
        self.range_m: list[float] = []
        self.targets: list[np.ndarray] = []
        self.labels: list[str] = []
        self.aimed: list[bytes] = []  # the pose each measurement was aimed with (T.tobytes())
        self.result = None
        self.solve_text = ""  # what the last Solve said (the review step repeats it)
        self.progress: float | None = None
        self.progress_text = ""  # "point k · aiming" / "point k · measuring n shots" while measuring
        self.state = "pick"
        self.moved_text = ""  # what the last Solve left out as disagreeing with the database
        self.suggestion: tuple[np.ndarray, str] | None = None  # the point to measure next, and its name
        self.sigma_now: tuple[float, float] | None = None  # σ (°, m) the beams so far give (predicted)
        self.sigma_next: tuple[float, float] | None = None  # ... and with the suggestion measured too
        self._cand_cache: tuple | None = None
        self.T_aim: np.ndarray | None = None  # the pose the turret aims with: the beams' own solve once they fix it
        self._suggest()

    # ------------------------------------------------------------------ suggesting where to aim
    def _aim_candidates(self) -> tuple[np.ndarray, np.ndarray, list[str]]:
        """Points to suggest: a grid over each face of a known object that both the camera and the turret
        face, kept EDGE_MARGIN_M inside its edges, inside the image, and seen by both (the first surface
        on the camera's ray and on the turret's beam at the current calibration). X (M, 3), the faces'
        normals (M, 3), names. Cached until the objects or the calibration change."""
        objects = self.site.objects()
        T = self._aim_pose()
        key = (tuple((o.name, o.version) for o in objects), T.tobytes(), self.view)
        if self._cand_cache is not None and self._cand_cache[0] == key:
            return self._cand_cache[1]
        cam = self.camera
        X, N, names = [], [], []
        for obj in objects:
            for x, n, k in _face_grid(obj, cam.center, T[:3, 3], thin=self.T_aim is not None):
                uv = cam.project(x.reshape(1, 3))[0]
                if (
                    not (4 <= uv[0] <= cam.width - 5 and 4 <= uv[1] <= cam.height - 5)
                    or cam.depth(x.reshape(1, 3))[0] <= 0
                ):
                    continue
                if all(_first_is(self.site, o, x, obj.name) for o in (cam.center, T[:3, 3])):
                    X.append(x)
                    N.append(n)
                    names.append(f"{obj.name} face {k}")
        out = (np.array(X).reshape(-1, 3), np.array(N).reshape(-1, 3), names)
        self._cand_cache = (key, out)
        return out

    def _suggest(self) -> None:
        """Choose the point to measure next: of the candidates not measured yet, the one that leaves the
        turret pose's worst σ smallest (rotations counted in TARGET_DEG, translations in TARGET_M), from
        the beams measured so far (``core.calibration.next_turret_point``). Sets ``suggestion``,
        ``sigma_now`` and ``sigma_next``."""
        self.suggestion = self.sigma_now = self.sigma_next = None
        if not self.site.has_turret or not self.site.objects():
            return
        self.T_aim = self._provisional_pose()
        X, N, names = self._aim_candidates()
        spec, T = self.site.scene.rangefinder, self._aim_pose()
        done = np.zeros((0, 6))
        landed = np.zeros(len(self.pan), bool)
        if self.pan:
            pan, tilt, rho = np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
            mesh, _ = self.site.surfaces()
            if mesh is not None:
                _, dist, tri = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
                landed = dist <= OFF_SURFACE_M  # a beam that missed every known surface tells nothing
                done = turret_plane_rows(
                    T, pan[landed], tilt[landed], rho[landed], mesh.face_normals[tri[landed]], spec
                )
        if len(self.targets) and len(X):
            # a point measured twice is not offered again; nor the face of a beam that missed it while the
            # turret aims the same way (once more beams move the aiming pose, it is offered again)
            tg = np.array(self.targets)
            times = (np.linalg.norm(X[:, None, :] - tg[None, landed, :], axis=2) < 0.01).sum(axis=1)
            missed = {self.labels[i] for i in np.flatnonzero(~landed) if self.aimed[i] == T.tobytes()}
            keep = (times < 2) & np.array([f"a suggested point on {nm}" not in missed for nm in names], bool)
            X, N, names = X[keep], N[keep], [nm for nm, f in zip(names, keep) if f]
        info = done.T @ done + np.diag(1.0 / PRIOR_SD**2)
        sd = np.sqrt(np.diag(np.linalg.inv(info)))
        self.sigma_now = (float(np.degrees(sd[:3].max())), float(sd[3:].max()))
        if not len(X):
            return
        pan_c, tilt_c, rho_c = aim(T, X)
        k, sd_k = next_turret_point(
            done,
            turret_plane_rows(T, pan_c, tilt_c, rho_c, N, spec),
            np.array([np.radians(TARGET_DEG)] * 3 + [TARGET_M] * 3),
            PRIOR_SD,
        )
        self.suggestion = (X[k].copy(), f"a suggested point on {names[k]}")
        self.sigma_next = (float(np.degrees(sd_k[:3].max())), float(sd_k[3:].max()))

    def _aim_pose(self) -> np.ndarray:
        """The turret pose to aim with: the measured beams' own solve once they fix the pose, else the
        calibration in use (a calibration centimetres off misses a thin face such as the table's edge;
        where a beam lands does not matter to the solve, which uses the angles the turret reached)."""
        return self.T_aim if self.T_aim is not None else self.site.T_world_turret

    def _provisional_pose(self) -> np.ndarray | None:
        """The pose the beams measured so far give (``_fit`` of those within OFF_SURFACE_M of a known
        surface at the calibration in use), None while they do not fix it."""
        if len(self.pan) < 6:
            return None
        mesh, _ = self.site.surfaces()
        if mesh is None:
            return None
        pan, tilt, rho = np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
        T = self.site.T_world_turret
        _, dist, _ = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
        used = dist <= OFF_SURFACE_M
        if used.sum() < 6:
            return None
        try:
            cal, T = self._fit(mesh, pan, tilt, rho, used, T, "", 5)
        except WorkflowError:
            return None
        sd = np.sqrt(np.diag(cal.cov))
        # a solve looser than the calibration's own offset would aim worse than it: only a fixed pose is used
        return T if np.degrees(sd[:3].max()) < POORLY_DEG and sd[3:].max() < POORLY_M else None

    def _suggestion_text(self) -> str:
        """The step's sentence on σ and the suggested point ("" without one)."""
        if self.sigma_now is None:
            return ""
        deg, m = self.sigma_now
        reached = deg <= TARGET_DEG and m <= TARGET_M
        now = (
            f" The beams so far give σ {deg:.2f}°, {1000 * m:.1f} mm"
            + (f" (within the {TARGET_DEG}° and {1000 * TARGET_M:.0f} mm aimed for)." if reached else ".")
            if len(self.pan) >= 6
            else ""
        )
        if self.suggestion is None or reached:
            return now
        return (
            f"{now} Next, the point circled 'next' (on {self.suggestion[1].split(' on ', 1)[1]}) reduces σ the most"
            + (f", to {self.sigma_next[0]:.2f}°, {1000 * self.sigma_next[1]:.1f} mm." if len(self.pan) >= 5 else ".")
        )

    # ------------------------------------------------------------------ picking
    def _candidates(self) -> tuple[np.ndarray, list[str]]:
        """Known points: every object's vertices and the centres of its faces that face the camera."""
        cam = self.camera
        X, names = [], []
        for obj in self.site.objects():
            T = obj.T_world_obj
            V = obj.vertices_world()
            X += list(V)
            names += [f"{obj.name} vertex {k}" for k in range(len(V))]
            if obj.model.faces:
                cents = obj.model.face_centroids() @ T[:3, :3].T + T[:3, 3]
                normals = obj.model.face_normals() @ T[:3, :3].T
                for k, (c, n) in enumerate(zip(cents, normals)):
                    if n @ (cam.center - c) > 0:
                        X.append(c)
                        names.append(f"{obj.name} face {k} centre")
        return (np.array(X) if X else np.zeros((0, 3))), names

    def click(self, uv) -> None:
        """Pick the known point nearest the click (a vertex or a face centre drawn in the overlay)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            X, names = self._candidates()
            cam = self.camera
            d = np.linalg.norm(cam.project(X) - p, axis=1) if len(X) else np.zeros(0)
            if len(X):
                d[cam.depth(X) <= 0] = np.inf
            if self.suggestion is not None:  # the circled suggestion wins over a corner or centre as near
                d_s = float(np.linalg.norm(cam.project(self.suggestion[0].reshape(1, 3))[0] - p))
                if d_s <= PICK_RADIUS_PX and (not len(d) or d_s <= d.min() + 3.0):
                    self.pending_X, self.pending_label = self.suggestion[0].copy(), self.suggestion[1]
                    self.state = "measure"
                    self.message = f"Target: {self.suggestion[1]}."
                    return
            if not len(X) or d.min() > PICK_RADIUS_PX:
                # anywhere else on a known surface: the beam lands on it (the fit is point-to-plane)
                origin, ray = cam.rays(p.reshape(1, 2))
                hit = self.site.raycast(origin, ray[0])
                if hit is None:
                    raise WorkflowError(
                        "that click is on no known object: click a face of a known object (a cyan "
                        "centre, a corner, or anywhere on it)"
                    )
                self.pending_X, self.pending_label = hit.X_world.copy(), f"a point on {hit.name}"
                self.state = "measure"
                self.message = f"Target: a point on {hit.name}."
                return
            k = int(np.argmin(d))
            self.pending_X, self.pending_label = X[k].copy(), names[k]
            self.state = "measure"
            self.message = f"target: {names[k]}"

    def choose_point(self, X_world, label: str = "") -> None:
        """Use the known world point X_world (3,) metres as the next target (for scripts)."""
        X = np.asarray(X_world, float).reshape(-1)
        if X.shape != (3,) or not np.all(np.isfinite(X)):
            raise WorkflowError(f"a known point is (x, y, z) in metres, got {X_world!r}")
        with self.lock:
            self._check_open()
            self.pending_X, self.pending_label = X, label or "point"
            self.state = "measure"

    # ------------------------------------------------------------------ measuring
    def measure(self):
        """Aim at the picked point with the current calibration and measure (median of ``shots``).

        The devices run outside the workflow's lock (the overlay keeps drawing); ``progress`` and
        ``progress_text`` say which point and which stage; the beam spot shows the measured point.
        A device fault or a cancel keeps nothing."""
        from app.devices import DeviceError, NoTargetError

        with self.lock:
            self._check_open()
            if self.pending_X is None:
                raise WorkflowError("pick a known point first (click a corner or a face centre)")
            devices = self.site.devices
            if devices is None:
                raise WorkflowError(self.site.no_devices("measure"))
            X, label = self.pending_X, self.pending_label
            T = self.site.T_world_turret
            T_aim = self._aim_pose()
            pan, tilt, _ = aim(T_aim, X)
            k = len(self.pan) + 1
            uv = self.camera.project(X.reshape(1, 3))
        why = self.scene_changed(uv)
        if why:
            raise WorkflowError(
                f"{why}: {label} may not be where the frozen frame shows it. Nothing was measured: "
                "measure again when the video there looks as frozen, or pick another point"
            )
        with self.lock:
            self._check_open()
            self.cancel_event.clear()
            self.progress, self.progress_text = 0.0, f"point {k} · aiming"
        try:
            pan_r, tilt_r = devices.turret.move_to(float(pan), float(tilt), wait=True)  # whole steps, as reached
            if self.cancel_event.is_set():
                raise Cancelled()
            self.progress, self.progress_text = (
                0.5,
                f"point {k} · measuring {self.shots} shot{'s' if self.shots > 1 else ''}",
            )
            m = devices.rangefinder.measure_n(self.shots)
            self.site.set_beam(beam_point(T, pan_r, tilt_r, m.range_m))
            self.progress = 1.0
        except NoTargetError:
            self.progress = None
            raise WorkflowError(
                f"no range return from {label}: pick a point on a surface facing the turret, nearer than 10 m"
            ) from None
        except DeviceError as exc:
            self.progress = None
            raise WorkflowError(f"device fault while measuring: {exc}. Check the devices and Measure again") from None
        except Cancelled:
            self.progress = None
            raise
        with self.lock:
            self.progress = None
            if self.cancelled:  # cancelled while the shots were under way: keep nothing
                raise Cancelled()
            self.pan.append(float(pan_r))
            self.tilt.append(float(tilt_r))
            self.range_m.append(float(m.range_m))
            self.targets.append(X)
            self.labels.append(self.pending_label)
            self.aimed.append(T_aim.tobytes())
            self.pending_X = None
            self.result = None
            self.state = "pick"
            Xm = beam_point(self.site.T_world_turret, pan_r, tilt_r, m.range_m)
            self.site.set_beam(Xm)
            self.message = (
                f"{self.labels[-1]}: {1000 * m.range_m:.1f} mm "
                f"({len(self.pan)} measurement{'s' if len(self.pan) != 1 else ''})."
            )
            check = check_beams(
                self.site, self.site.T_world_turret, pan_r, tilt_r, m.range_m, self.site.calibration_covs[1]
            )[0]
            if check.disagrees:  # said now; Solve leaves it out if it still disagrees through the solved pose
                self.message += " ⚠ " + disagreement_text([check], [self.labels[-1]], done="Solve leaves it out")
            self._suggest()
            off = self._off_surface_m(Xm)
            if off > OFF_SURFACE_M:  # said now, not only when Solve leaves it out
                self.message += (
                    f" It landed {100 * off:.0f} cm from every known surface: the beam missed the object "
                    "(aimed by a turret calibration that far off, or something not in the database is in "
                    "the way); Solve will leave it out — Delete measurement and pick a point nearer a "
                    "face's middle."
                )
            return m

    def _off_surface_m(self, X: np.ndarray) -> float:
        """How far a measured point lies from the database's surfaces (metres; 0 without a mesh)."""
        mesh, _ = self.site.surfaces()
        if mesh is None:
            return 0.0
        _, dist, _ = mesh.nearest.on_surface(np.asarray(X, float).reshape(1, 3))
        return float(dist[0])

    def remove_measurement(self, index: int) -> None:
        """Delete measurement ``index`` (0-based, the residual table's row)."""
        with self.lock:
            self._check_open()
            i = int(index)
            if not 0 <= i < len(self.pan):
                raise WorkflowError(f"there is no measurement {i + 1}: {len(self.pan)} were made")
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels, self.aimed):
                lst.pop(i)
            self.result = None
            self.state = "measure" if self.pending_X is not None else "pick"
            self.message = f"Measurement {i + 1} deleted: {len(self.pan)} left. Solve again."
            self._suggest()

    def remove_last(self) -> None:
        """Drop the picked point, or else the last measurement."""
        with self.lock:
            self._check_open()
            if self.pending_X is None and not self.pan:
                raise WorkflowError("there is no picked point or measurement to remove")
            if self.pending_X is not None:  # the pick only: the measurements, and a solve of them, stand
                self.pending_X = None
                self.state = "review" if self.result is not None else "pick"
                self.message = "The picked point is dropped" + (
                    "; the solve stands." if self.result is not None else "."
                )
                return
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels, self.aimed):
                lst.pop()
            self.result = None
            self.state = "pick"
            self.message = f"The last measurement is removed: {len(self.pan)} left."
            self._suggest()

    # ------------------------------------------------------------------ solving
    def solve(self, max_rounds: int = 10):
        """The turret pose that puts every measured point on the database's surfaces.

        Beams more than 5 cm off every known surface at the current calibration are left out first;
        then, fitted, each beam is checked against the database through the solved pose
        (``beams.check_beams``): the beams at the object that disagrees most (its range more than 3σ
        from the database's) are left out and the pose fitted again, until none disagrees — an object
        that has moved since the database last saw it would otherwise pull the calibration."""
        with self.lock:
            self._check_open()
            n = len(self.pan)
            if n < 6:
                raise WorkflowError(f"{n} measurements; measure at least 6 points on faces of 3 orientations")
            mesh, _ = self.site.surfaces()
            if mesh is None:
                raise WorkflowError("the database has no objects to measure on")
            pan, tilt, rho = np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
            T = self.site.T_world_turret
            # Beams that landed off every known surface (e.g. on the floor, not in the database) would
            # drag the fit: only points within OFF_SURFACE_M of a surface at the current estimate count.
            _, dist0, _ = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            used = dist0 <= OFF_SURFACE_M
            off = [f"{i + 1} {self.labels[i]}" for i in np.flatnonzero(~used)]
            off_text = (
                f" Left out, more than {100 * OFF_SURFACE_M:.0f} cm from every known surface (did their object "
                f"move, or is it not in the database?): {', '.join(off)}."
                if off
                else ""
            )
            if used.sum() < 6:
                raise WorkflowError(
                    f"only {int(used.sum())} of {n} measurements landed within {100 * OFF_SURFACE_M:.0f} cm "
                    f"of a known surface; measure points well inside faces of known objects.{off_text}"
                )
            # from the beams' own provisional solve when there is one: a start centimetres off can associate a beam
            # near an edge with the wrong face and settle there
            cal, T = self._fit(mesh, pan, tilt, rho, used, T, off_text, max_rounds)
            cal, T, used, moved_text = self._leave_out_disagreeing(mesh, pan, tilt, rho, used, cal, T, max_rounds)
            self.used = used
            _, dist, _ = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            dist = dist[used]
            self.result = cal
            self.T_solved = T
            self.surface_residuals_m = dist
            self.moved_text = moved_text
            deg, m = pose_error(T, self.site.T_world_turret)
            self.state = "review"
            dropped = f" ({len(off)} off the known surfaces, left out: {', '.join(off)})" if off else ""
            # the pose has 6 unknowns: with 6 points the fit is exact, its RMS says nothing (a new operator read
            # "RMS 0.0 mm" as a perfect calibration)
            exact = (
                " (6 points for 6 unknowns: an exact fit, its RMS checks nothing; measure more)"
                if int(used.sum()) <= 6
                else ""
            )
            self.message = (
                f"RMS {1000 * np.sqrt(np.mean(dist**2)):.1f} mm to the surfaces over {int(used.sum())} "
                f"points{exact}{dropped}; {deg:.2f}° and {1000 * m:.1f} mm from the current calibration"
            )
            if moved_text:
                self.message += f". ⚠ {moved_text}"
            far = self._far_points()
            if far:
                self.message += f". ⚠ {far}"
            sd_rot_deg, sd_t_m = self._sigmas()
            self.message += f". σ {sd_rot_deg.max():.2f}°, {1000 * sd_t_m.max():.1f} mm"
            if sd_rot_deg.max() > POORLY_DEG or sd_t_m.max() > POORLY_M:
                self.message += (
                    " — poorly determined: measure more points, the suggested ones first (marked next: they "
                    "reduce σ the most)"
                )
            self.solve_text = self.message
            self._suggest()
            return cal

    def _fit(self, mesh, pan, tilt, rho, used, T, off_text: str, max_rounds: int):
        """``calibrate_turret_planes`` on the beams ``used``, each associated with the face it is nearest
        to, re-associated and fitted again until the pose stops moving: (TurretCalibration, T (4, 4))."""
        cal = None
        for _ in range(max_rounds):
            closest, _, tri = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            normals = mesh.face_normals[tri]
            # a beam cannot land on a face turned away from it: one nearest such a face (beside an edge,
            # at a pose still off) is left out of this round rather than pull the pose to the wrong side
            use = used & (np.einsum("ij,ij->i", normals, beam_ray(T, pan, tilt)[1]) < 0)
            if use.sum() < 6:
                use = used
            normals, closest = normals[use], closest[use]
            try:
                cal = calibrate_turret_planes(
                    pan[use],
                    tilt[use],
                    rho[use],
                    normals,
                    -np.einsum("ij,ij->i", normals, closest),
                    T,
                    self.site.scene.rangefinder,
                )
            except ValueError as exc:
                if "independent normals" in str(exc):
                    raise WorkflowError(self._too_few_orientations(normals, used, off_text)) from None
                raise WorkflowError(f"turret calibration failed: {exc}") from None
            deg, m = pose_error(cal.T_world_turret, T)
            T = cal.T_world_turret
            if deg < 1e-5 and m < 1e-7:
                break
        return cal, T

    def _too_few_orientations(self, normals, used, off_text: str) -> str:
        groups = _orientation_groups(normals)
        labels = [self.labels[i] for i in np.flatnonzero(used)]
        spread = "; ".join(
            f"{len(g)} facing {_facing(normals[g[0]])} ({labels[g[0]]}"
            + (f" and {len(g) - 1} more" if len(g) > 1 else "")
            + ")"
            for g in groups
        )
        return (
            f"the {int(used.sum())} measurements on known surfaces do not fix the turret's "
            f"pose: by the way their faces face, {spread}. It needs points spread over three "
            "directions, two or more on each (the table top and two sides of a box at an "
            f"angle): measure more on the fewest.{off_text}"
        )

    def _leave_out_disagreeing(self, mesh, pan, tilt, rho, used, cal, T, max_rounds: int):
        """Check every used beam against the database through the solved pose; while some disagree,
        leave out the beams at the object that disagrees most and fit again. Returns the calibration,
        the pose, the beams used and what the operator is told of those left out ("" for none)."""
        used = used.copy()
        left: dict[int, BeamCheck] = {}
        for _ in range(max_rounds):
            idx = np.flatnonzero(used)
            checks = check_beams(self.site, T, pan[idx], tilt[idx], rho[idx], cal.cov)
            bad = [(abs(c.delta_m) / c.sigma_m, c.object) for c in checks if c.disagrees]
            if not bad:
                break
            worst = max(bad)[1]
            drop = [i for i, c in zip(idx, checks) if c.disagrees and c.object == worst]
            if used.sum() - len(drop) < 6:
                break  # too few would be left: the beams stay, and the far points are named below
            trial = used.copy()
            trial[drop] = False
            try:
                cal_t, T_t = self._fit(mesh, pan, tilt, rho, trial, T, "", max_rounds)
            except WorkflowError:
                break  # without them the pose is not fixed: they stay (and are named as far points)
            left.update({int(i): c for i, c in zip(idx, checks) if int(i) in drop})
            used, cal, T = trial, cal_t, T_t
        order = sorted(left)
        text = disagreement_text([left[i] for i in order], [f"{i + 1} {self.labels[i]}" for i in order])
        return cal, T, used, text

    def _far_points(self) -> str:
        """The measured points that lie more than 3σ of the range finder from their surface after Solve,
        named with their distances, worst first, and what to do; "" when none does. Such a point (a beam
        on an edge, a wrong pick, an object moving when it was measured) pulls the whole solve."""
        sigma = float(self.site.scene.rangefinder.sigma_range_m)
        if self.result is None or sigma <= 0:
            return ""
        idx = np.flatnonzero(self.used)
        far = sorted(((float(d), int(i)) for d, i in zip(self.surface_residuals_m, idx) if d > 3 * sigma), reverse=True)
        if not far:
            return ""
        names = ", ".join(f"{i + 1} {self.labels[i]} ({1000 * d:.1f} mm)" for d, i in far)
        one = len(far) == 1
        return (
            f"{'this point lies' if one else f'{len(far)} points lie'} more than 3σ ({3000 * sigma:.0f} mm) from "
            f"{'its' if one else 'their'} surface — a wrong pick, or the object moving when it was measured? {names}: "
            f"choose {'it' if one else 'each'} under Measurement and Delete measurement, then Solve again"
        )

    def _sigmas(self) -> tuple[np.ndarray, np.ndarray]:
        """Standard deviations of the solved pose: rotation (3,) degrees, translation (3,) metres (turret axes)."""
        var = np.diag(self.result.cov)
        return np.degrees(np.sqrt(var[:3])), np.sqrt(var[3:])

    def accept(self) -> None:
        """Store the new turret pose (one transaction)."""
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: Solve first")
            rms = float(np.sqrt(np.mean(self.surface_residuals_m**2)))
            self.site.set_turret(
                self.T_solved,
                rms_m=rms,
                residuals_m=self.surface_residuals_m,
                cov=self.result.cov,
                measurements={
                    "pan_rad": self.pan,
                    "tilt_rad": self.tilt,
                    "range_m": self.range_m,
                    "targets": np.array(self.targets),
                    "labels": list(self.labels),
                },
                client=self.client,
                method="turret: ranges on known surfaces",
            )
            self.accepted = True
            self.state = "accepted"
            self.message = f"Turret calibrated: RMS {1000 * rms:.1f} mm."

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if self.progress is not None:
            text = getattr(self, "progress_text", "") or "aiming and measuring"
            return Step("measuring", f"Measuring… {text}. " + "{cancel} stops it.", frozenset({"cancel"}), clicks=False)
        n = len(self.pan)
        base = {"cancel"} | ({"remove_last"} if (n or self.pending_X is not None) else set())
        if n:
            base |= {"measurement", "remove_measurement"}
        if n >= 6:
            base.add("solve")
        if self.site.devices is None:
            return Step(
                "no_devices",
                self.site.no_devices("calibrate the turret", sentence=True),
                frozenset(base),
                clicks=False,
            )
        if self.pending_X is not None and self.result is not None:  # solved, and a point picked since: both apply
            return Step(
                "review",
                f"Solved: {self.solve_text}. " + "{accept} to use it; or {measure} " + f"{self.pending_label}, "
                "the point picked, and {solve} again ({remove_last} drops the pick).",
                frozenset(base | {"accept", "measure"}),
            )
        if self.pending_X is not None:
            return Step(
                "measure",
                "{measure} " + f"{self.pending_label} (the turret aims with the current calibration, or once six "
                "points fix the pose, with their solve), or "
                "click another known point.",
                frozenset(base | {"measure"}),
            )
        if self.result is not None:
            return Step(
                "review",
                f"Solved: {self.solve_text}. " + "{accept} to use it, or measure more points and {solve} again.",
                frozenset(base | {"accept"}),
            )
        more = f" ({6 - n} more at least)" if n < 6 else "; {solve} when done"
        return Step(
            "pick",
            f"Click a known point — a face centre (cyan), a corner, or anywhere on a known face — "
            f"then measure it{more}.{self._suggestion_text()}",
            frozenset(base),
        )

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action != "measurement":
            return []
        with self.lock:
            res = None
            if self.result is not None and getattr(self, "used", None) is not None and len(self.used) == len(self.pan):
                res = iter(1000 * self.surface_residuals_m)
            out = []
            for i, lab in enumerate(self.labels):
                text = f"{i + 1} {lab}"
                if res is not None:
                    text += f" · {next(res):.1f} mm" if self.used[i] else " · left out"
                out.append((text, i))
            return out

    def weaknesses(self) -> list[str]:
        with self.lock:
            if self.result is None:
                return []
            out = []
            sd_rot_deg, sd_t_m = self._sigmas()
            if sd_rot_deg.max() > POORLY_DEG or sd_t_m.max() > POORLY_M:
                out.append(
                    "the turret's pose is poorly determined ("
                    + sigma_over(float(sd_rot_deg.max()), 1000 * float(sd_t_m.max()), POORLY_DEG, 1000 * POORLY_M)
                    + ")"
                )
            far = self._far_points()
            if far:
                out.append(far)
            if int(np.sum(self.used)) <= 6:
                out.append("only 6 points: little redundancy to catch a wrong one (8 or more is safer)")
            return out

    def marks(self) -> Marks:
        with self.lock:
            cam = self.camera
            m = Marks()
            X, names = self._candidates()
            centres = np.array([x for x, nm in zip(X, names) if nm.endswith("centre")]).reshape(-1, 3)
            centres = centres[cam.depth(centres) > 0] if len(centres) else centres
            m.targets = cam.project(centres) if len(centres) else np.zeros((0, 2))
            if self.pending_X is not None:
                m.pending = cam.project(self.pending_X.reshape(1, 3))
            elif self.suggestion is not None:
                uv = cam.project(self.suggestion[0].reshape(1, 3))
                m.circles = uv
                m.labels.append((uv[0], "next"))
            if self.pan:
                Xm = beam_point(
                    self.site.T_world_turret, np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
                )
                m.points = cam.project(Xm)
                m.labels = [(uv, str(i + 1)) for i, uv in enumerate(m.points)]
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {"measurements": len(self.pan)}
            if self.sigma_now is not None:
                out["sigma_predicted"] = {"deg": self.sigma_now[0], "mm": 1000 * self.sigma_now[1]}
            if self.result is not None:
                out["rms_mm"] = float(1000 * np.sqrt(np.mean(self.surface_residuals_m**2)))
                sd_rot_deg, sd_t_m = self._sigmas()
                out["sd_rot_deg"] = [float(v) for v in sd_rot_deg]
                out["sd_t_mm"] = [float(1000 * v) for v in sd_t_m]
                deg, m = pose_error(self.T_solved, self.site.T_world_turret)
                out["change"] = {"deg": float(deg), "mm": float(1000 * m)}
                labels = [lab for lab, u in zip(self.labels, self.used) if u]
                ranges = [r for r, u in zip(self.range_m, self.used) if u]
                out["left_out"] = int((~self.used).sum())
                if self.moved_text:
                    out["disagreeing"] = self.moved_text
                out["points"] = [
                    {"point": lab, "range_m": r, "to_surface_mm": 1000 * float(d)}
                    for lab, r, d in zip(labels, ranges, self.surface_residuals_m)
                ]
            return out


def _orientation_groups(normals: np.ndarray, tol_deg: float = 10.0) -> list[list[int]]:
    """The unit normals (N, 3) grouped by the direction they point in (within ``tol_deg``), largest first."""
    groups: list[list[int]] = []
    N = np.asarray(normals, float).reshape(-1, 3)
    for i, n in enumerate(N):
        g = next((g for g in groups if float(n @ N[g[0]]) > np.cos(np.radians(tol_deg))), None)
        if g is None:
            groups.append([i])
        else:
            g.append(i)
    return sorted(groups, key=len, reverse=True)


def _facing(n: np.ndarray) -> str:
    """A world normal in words: "up", "down", or the compass-free "sideways (x +0.71, y -0.71)"."""
    if n[2] > 0.9:
        return "up"
    if n[2] < -0.9:
        return "down"
    return f"sideways (x {n[0]:+.2f}, y {n[1]:+.2f})"


def _face_grid(obj, camera_center: np.ndarray, turret_origin: np.ndarray, thin: bool = True):
    """(X (3,), unit normal (3,), face index) on a GRID × GRID grid over each planar face of ``obj`` that
    faces both the camera and the turret, EDGE_MARGIN_M inside its edges (half its width where it is
    thinner), inside the face's polygon."""
    T = obj.T_world_obj
    model = obj.model
    if not model.faces:
        return
    normals = model.face_normals() @ T[:3, :3].T
    for k, face in enumerate(model.faces):
        V = model.vertices[list(face)] @ T[:3, :3].T + T[:3, 3]
        n, c = normals[k], V.mean(axis=0)
        if n @ (camera_center - c) <= 0 or n @ (turret_origin - c) <= 0:
            continue
        edges = np.roll(V, -1, axis=0) - V
        e1 = edges[int(np.argmax(np.linalg.norm(edges, axis=1)))]
        e1 = e1 / np.linalg.norm(e1)
        e2 = np.cross(n, e1)
        uv = (V - c) @ np.stack([e1, e2], axis=1)  # the polygon in the face's plane
        axes = []
        if not thin and np.ptp(uv, axis=0).min() <= 2 * EDGE_MARGIN_M:
            continue
        for lo, hi in zip(uv.min(axis=0), uv.max(axis=0)):
            m = min(EDGE_MARGIN_M, 0.5 * (hi - lo))
            axes.append(np.linspace(lo + m, hi - m, GRID) if hi - lo > 2 * m else np.array([0.5 * (lo + hi)]))
        for a in axes[0]:
            for b in axes[1]:
                if _inside(uv, np.array([a, b])):
                    yield c + a * e1 + b * e2, n, k


def _inside(poly: np.ndarray, p: np.ndarray) -> bool:
    """Whether the 2D point p lies inside the polygon poly (K, 2) (even–odd rule)."""
    x, y = p
    inside = False
    for (x1, y1), (x2, y2) in zip(poly, np.roll(poly, -1, axis=0)):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _first_is(site, origin: np.ndarray, X: np.ndarray, name: str) -> bool:
    """Whether the first database surface on the ray from ``origin`` towards X is object ``name``, at X."""
    d = X - origin
    dist = float(np.linalg.norm(d))
    hit = site.raycast(origin, d / dist)
    return hit is not None and hit.name == name and abs(hit.distance_m - dist) < 0.005
