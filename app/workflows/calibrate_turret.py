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

from core.calibration import calibrate_turret_planes
from core.rangefinder import aim, beam_point
from core.transforms import pose_error

from .base import CANCEL, Cancelled, Control, Marks, Step, Workflow, WorkflowError, as_pixel, sigma_over

__all__ = ["CalibrateTurret"]

# a corner or a face centre is picked within this many screen pixels of the click (in video pixels it
# depends on the zoom); farther, the click is a point on the surface under it (a new operator's click on the
# table 24 video px from a box corner became "parallelepiped vertex 1")
PICK_RADIUS_SCREEN_PX = 12.0
OFF_SURFACE_M = 0.05
POORLY_DEG, POORLY_M = 0.5, 0.01  # σ beyond which the operator is told to measure more


class CalibrateTurret(Workflow):
    name = "calibrate_turret"
    title = "Calibrate turret"
    shows_beam = True
    # video pixels per screen pixel where the click being handled was made (the page's zoom, set by the session;
    # 1: not known, a script's)
    click_px_per_screen_px: float = 1.0
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
        self.result = None
        self.solve_text = ""  # what the last Solve said (the review step repeats it)
        self.progress: float | None = None
        self.progress_text = ""  # "point k · aiming" / "point k · measuring n shots" while measuring
        self.state = "pick"

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
            if not len(X) or d.min() > PICK_RADIUS_SCREEN_PX * self.click_px_per_screen_px:
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
            pan, tilt, _ = aim(T, X)
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
            self.pending_X = None
            self.result = None
            self.state = "pick"
            Xm = beam_point(self.site.T_world_turret, pan_r, tilt_r, m.range_m)
            self.site.set_beam(Xm)
            self.message = (
                f"{self.labels[-1]}: {1000 * m.range_m:.1f} mm "
                f"({len(self.pan)} measurement{'s' if len(self.pan) != 1 else ''})."
            )
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
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels):
                lst.pop(i)
            self.result = None
            self.state = "measure" if self.pending_X is not None else "pick"
            self.message = f"Measurement {i + 1} deleted: {len(self.pan)} left. Solve again."

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
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels):
                lst.pop()
            self.result = None
            self.state = "pick"
            self.message = f"The last measurement is removed: {len(self.pan)} left."

    # ------------------------------------------------------------------ solving
    def solve(self, max_rounds: int = 10):
        """The turret pose that puts every measured point on the database's surfaces."""
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
            cal = None
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
            for _ in range(max_rounds):
                # each measured point belongs to the face it is nearest to (re-associated every round)
                closest, _, tri = mesh.nearest.on_surface(beam_point(T, pan[used], tilt[used], rho[used]))
                normals = mesh.face_normals[tri]
                try:
                    cal = calibrate_turret_planes(
                        pan[used],
                        tilt[used],
                        rho[used],
                        normals,
                        -np.einsum("ij,ij->i", normals, closest),
                        T,
                        self.site.scene.rangefinder,
                    )
                except ValueError as exc:
                    if "independent normals" in str(exc):
                        groups = _orientation_groups(normals)
                        labels = [self.labels[i] for i in np.flatnonzero(used)]
                        spread = "; ".join(
                            f"{len(g)} facing {_facing(normals[g[0]])} ({labels[g[0]]}"
                            + (f" and {len(g) - 1} more" if len(g) > 1 else "")
                            + ")"
                            for g in groups
                        )
                        raise WorkflowError(
                            f"the {int(used.sum())} measurements on known surfaces do not fix the turret's "
                            f"pose: by the way their faces face, {spread}. It needs points spread over three "
                            "directions, two or more on each (the table top and two sides of a box at an "
                            f"angle): measure more on the fewest.{off_text}"
                        ) from None
                    raise WorkflowError(f"turret calibration failed: {exc}") from None
                deg, m = pose_error(cal.T_world_turret, T)
                T = cal.T_world_turret
                if deg < 1e-5 and m < 1e-7:
                    break
            self.used = used
            _, dist, _ = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            dist = dist[used]
            self.result = cal
            self.T_solved = T
            self.surface_residuals_m = dist
            deg, m = pose_error(T, self.site.T_world_turret)
            self.state = "review"
            dropped = f" ({n - int(used.sum())} off the known surfaces, left out: {', '.join(off)})" if off else ""
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
            far = self._far_points()
            if far:
                self.message += f". ⚠ {far}"
            sd_rot_deg, sd_t_m = self._sigmas()
            if sd_rot_deg.max() > POORLY_DEG or sd_t_m.max() > POORLY_M:
                few = len(self.site.objects()) <= 2
                self.message += (
                    f". Poorly determined (σ up to {sd_rot_deg.max():.2f}° and {1000 * sd_t_m.max():.1f} mm): "
                    "measure faces of other objects, at other distances, before accepting"
                    + (
                        " (with only the table and one box known, model another object first: Model object; "
                        "it measures with the current calibration, which stays in use until one is accepted)"
                        if few
                        else ""
                    )
                )
            self.solve_text = self.message
            return cal

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
                "{measure} " + f"{self.pending_label} (the turret aims with the current calibration), or "
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
            f"then measure it{more}.",
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
