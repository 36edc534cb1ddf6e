"""Calibrate the turret (``T_world_turret``) from range measurements on the database's known surfaces.

The operator clicks known points in the overlay — a face centre, a model vertex, anywhere on a known
face, or the point circled 'next' (**Measure next** picks and measures it) — and the turret aims at
each and measures. It aims through the beams' estimate so far (``_estimate``: the beams fitted with the
calibration in use as a prior), so that a beam lands where it was aimed even on a thin face such as the
table's 4 cm edge. The point circled 'next' (``_suggest``, ``turret_aims``) is, of a grid on the known
faces both the camera and the turret see, the one that lowers the pose's worst σ most among those a beam
lands on: on the shipped database (the table and one box) the face centres alone leave yaw and
sideways shift confounded (σ of several cm); the suggestions bring σ within 5 mm (bench/turret.py).

Where a beam really lands is not known exactly (the calibration is what is being corrected), but it
lands on a known surface: ``solve()`` finds the turret pose that puts every measured point on the
database's surfaces (point-to-plane, ``core.calibration.calibrate_turret_planes``: each beam first on
the face it was aimed at, those beside it left out, then each on the face it is nearest to, repeated
until the pose stops moving). At least 6 points on faces of three orientations are needed. Every beam
is checked against the database (``beams.check_beams``, the check every workflow that uses beams
makes): one that disagrees by more than 3σ at a known object — when measured, through the calibration
in use, while most agree; or after the fit, through the solved pose — is left out and its object named
as moved. An object the frozen frame shows away from where the database draws it (little of its outline on
the image's edges) is not suggested either, before any beam is spent on it. For an object found moved,
**Update its pose** runs Update pose on it (a ``Detour``) while this workflow waits with its measurements;
once the pose is accepted the beams are checked again against it and its faces are offered again. A solve
far from the beams' guided estimate is said and weak. ``accept()`` stores the calibration (one transaction)
and every later aim uses it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.calibration import calibrate_turret_planes, next_turret_point, turret_plane_rows
from core.rangefinder import aim, beam_point, beam_ray
from core.transforms import log_so3, pose_error

from .base import (
    CANCEL,
    Cancelled,
    Control,
    Detour,
    Marks,
    Step,
    Workflow,
    WorkflowError,
    as_pixel,
    pick_radius_px,
    sigma_over,
)
from .beams import BeamCheck, check_beams, disagreement_text
from .turret_aims import (
    ROOM_SIGMAS,
    ROOM_SPARE_M,
    Candidates,
    face_candidates,
    landing_rows,
    landing_sd,
    room_ratio,
    unlocking,
)

__all__ = ["CalibrateTurret"]

OFF_SURFACE_M = 0.05
POORLY_DEG, POORLY_M = 0.5, 0.01  # σ beyond which the operator is told to measure more
TARGET_DEG, TARGET_M = 0.2, 0.0045  # the σ the suggested points work towards (each axis): the solve's within 5 mm
PRIOR_SD = np.array([np.radians(10.0)] * 3 + [0.5] * 3)  # keeps the information invertible before 6 beams
# The calibration in use, stored without a covariance (or a looser one), is taken to be within this (1σ)
# when aiming: the beams' estimate starts from it (a prior) until they fix the pose themselves.
AIM_PRIOR_SD = np.array([np.radians(1.0)] * 3 + [0.03] * 3)
WANDER_CHI2 = 22.46  # χ²(6) at 99.9 %: a solve farther than this from the beams' guided estimate is doubtful
MAX_REPEATS = 8  # a suggested point is offered until it has been measured this many times
# Below this share of its outline on the frozen frame's edges (``outline_seen``) an object is taken to be away from
# where the database draws it: on the live site's two cameras the moved parallelepiped scores 0.03–0.10, objects in
# place 0.65–1.00.
AWAY_SEEN = 0.25
# At or above this share an object is where the database draws it: a beam at it that disagrees met something not in
# the database in front of it (a new operator's beam at the table by the robot's foot was read as "the table has
# moved", and the same point offered again after each Remove last, some 60 times)
IN_PLACE_SEEN = 0.5
BLOCKED_M = 0.05  # no point is offered this near one whose beam met something not in the database
UNLOCK_GAIN = 0.8  # a point out of reach worth this fraction of the best one's worst σ or less is unlocked first
UNLOCK_STEP = 0.9  # ... by a beam within reach that narrows the aim there by this factor at least, else aimed at


def _at_prior(sd: tuple[float, float]) -> bool:
    """σ (degrees, metres) still at its prior along some direction: the beams leave the pose free there (a new
    operator read 10.00°, 500.0 mm, the prior, through ten table points as the pose's σ)."""
    return sd[0] >= 0.9 * np.degrees(PRIOR_SD[0]) or sd[1] >= 0.9 * PRIOR_SD[3]


class CalibrateTurret(Workflow):
    name = "calibrate_turret"
    title = "Calibrate turret"
    shows_beam = True
    # video pixels per screen pixel where the click being handled was made (the page's zoom, set by the session;
    # 1: not known, a script's)
    actions = (
        "click",
        "choose_point",
        "measure",
        "measure_next",
        "remove_last",
        "remove_measurement",
        "solve",
        "update_moved",
        "accept",
        "cancel",
    )
    controls = (
        Control(
            "measure", "Measure", "M", kind="long", color="blue", hint="Aim at the picked point and measure its range"
        ),
        Control(
            "measure_next",
            "Measure next",
            "G",
            kind="long",
            color="blue",
            hint="Measure the point circled 'next': of the points the beam will land on, the one that reduces σ most",
        ),
        Control(
            "solve",
            "Solve",
            "R",
            color="blue",
            hint="The turret pose that puts every measured point on the known surfaces",
        ),
        Control(
            "update_moved",
            "Update its pose",
            "U",
            hint="Update the pose of the object found moved (Update pose); the measurements here are kept",
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
        self.checks: list[BeamCheck] = []  # each measurement against the database, through the calibration in use
        self.result = None
        self.solve_text = ""  # what the last Solve said (the review step repeats it)
        self.progress: float | None = None
        self.progress_text = ""  # "point k · aiming" / "point k · measuring n shots" while measuring
        self.state = "pick"
        self.moved_text = ""  # what the last Solve left out as disagreeing with the database
        self.elsewhere_text = ""  # what the last Solve said when it wandered from the beams' guided estimate
        self.suggestion: tuple[np.ndarray, str] | None = None  # the point to measure next, and its name
        self.sigma_now: tuple[float, float] | None = None  # σ (°, m) the beams so far give (predicted)
        self.sigma_next: tuple[float, float] | None = None  # ... and with the suggestion measured too
        self._cand_cache: tuple | None = None
        # why the suggestion: "" the best point within reach; a face's name: its beam narrows the aim at that
        # face, out of reach yet; "?": a point out of reach, aimed at anyway (nothing within reach helps)
        self.unlocks = ""
        # why no point is suggested though σ is short of the target: no face left to aim at fixes what the beams
        # leave free (an object that would has moved, or none is known), said in the step
        self.stuck = ""
        # the objects not offered because they look moved, each with why (the beams disagree; the frozen frame shows
        # them away from their drawing): Update its pose (``update_moved``) updates the first
        self.moved_why: dict[str, str] = {}
        self._seen: dict = {}  # (object, version) → its outline's share on the edges of the frame ``_seen_on``
        self._seen_on = None
        # objects the frozen frame shows in place while a beam finds no surface where it shows them: moved since
        self.moved_since: set[str] = set()
        self.blocked: list[np.ndarray] = []  # targets whose beam met something not in the database (kept: BLOCKED_M)
        self._unlock_tries = 0  # suggestions in a row that were to bring the same face into reach
        self.T_aim: np.ndarray | None = None  # the pose the turret aims with (``_estimate``)
        self._suggest()

    # ------------------------------------------------------------------ suggesting where to aim
    def _aim_candidates(self) -> Candidates:
        """``turret_aims.face_candidates`` for the workflow's camera, cached until the objects or the
        calibration in use change."""
        objects = self.site.objects()
        T = self.site.T_world_turret
        robot = self.site.robot  # where it stands hides faces (a beam at the table behind the arm lands on the arm)
        state = None if robot is None else (robot.last_state() or robot.state())
        q = () if state is None else tuple(np.round(state.q, 3))
        key = (tuple((o.name, o.version) for o in objects), T.tobytes(), self.view, q)
        if self._cand_cache is None or self._cand_cache[0] != key:
            self._cand_cache = (key, face_candidates(self.site, self.camera, T))
        return self._cand_cache[1]

    def _suggest(self) -> None:
        """Choose the point to measure next: of the candidates where a beam aimed through the current
        estimate lands on the face aimed at (``turret_aims.landing_sd``), the one that leaves the turret
        pose's worst σ smallest (rotations counted in TARGET_DEG, translations in TARGET_M) with the
        beams measured so far (``core.calibration.next_turret_point``). Sets ``T_aim``, ``suggestion``,
        ``sigma_now`` and ``sigma_next``."""
        self.suggestion = self.sigma_now = self.sigma_next = None
        self.stuck, self.moved_why, self.moved_since = "", {}, set()
        if not self.site.has_turret or not self.site.objects():
            return
        landed, _ = self._landed()
        moved = self._moved(landed)
        landed &= ~moved  # beams at an object that moved would pull the aim
        self.T_aim, cov_aim = self._estimate(landed)
        T, spec = self.T_aim, self.site.scene.rangefinder
        pan, tilt, rho = np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
        normals = np.zeros((len(pan), 3))
        if len(pan):  # each beam on the face it is nearest to at the estimate
            mesh, _ = self.site.surfaces()
            normals = mesh.face_normals[mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))[2]]
        done = turret_plane_rows(T, pan[landed], tilt[landed], rho[landed], normals[landed], spec)
        info = done.T @ done + np.diag(1.0 / PRIOR_SD**2)
        sd = np.sqrt(np.diag(np.linalg.inv(info)))
        self.sigma_now = (float(np.degrees(sd[:3].max())), float(sd[3:].max()))
        c = self._aim_candidates()
        keep = np.ones(len(c.X), bool)
        if len(self.targets) and len(c.X):
            # a point measured MAX_REPEATS times is not offered again; nor the face of a beam that missed it while the
            # turret aimed the same way (once more beams move the estimate, it is offered again)
            tg = np.array(self.targets)[landed].reshape(-1, 3)
            keep &= (np.linalg.norm(c.X[:, None, :] - tg[None], axis=2) < 0.01).sum(axis=1) < MAX_REPEATS
            # (a face whose beam missed it — off every surface, or on another face — waits until two more
            # beams have landed on the faces they were aimed at: the estimate has moved since)
            on_aim = landed & (np.einsum("ij,ij->i", normals, self._aimed_normals()) > np.cos(np.radians(10.0)))
            missed = {self.labels[i] for i in np.flatnonzero(~on_aim) if on_aim[i + 1 :].sum() < 2}
            keep &= np.array([f"a suggested point on {nm}" not in missed for nm in c.names], bool)
        # an object a beam found moved is not offered again (it was, after saying it moved); nor one the frozen frame
        # shows away from its drawing (no beam spent on it)
        if moved.any():
            idx = np.flatnonzero(moved)
            aimed = self._aimed(idx)
            gone = set(aimed) | {self.checks[i].object for i in idx}
            shares = self._outline_shares(gone - {""})
            in_place = {o for o, seen in shares.items() if seen is not None and seen >= IN_PLACE_SEEN}
            self.moved_why = {
                o: "the range finder disagrees with its database pose" for o in sorted(gone - in_place) if o
            }
            for i, o in zip(idx, aimed):
                o = o if o in in_place else self.checks[i].object
                if o not in in_place:
                    continue
                if self.checks[i].farther:  # no surface where the frame shows it: it moved since the frame
                    self.moved_why[o] = "the range finder finds no surface where the frame shows it"
                    self.moved_since.add(o)
                elif not self._near_blocked(self.targets[i]):  # nearer: something stood in front of it there
                    self.blocked.append(np.asarray(self.targets[i], float))
        for o, seen in self._outline_shares(set(c.objects) - set(self.moved_why)).items():
            if seen is not None and seen < AWAY_SEEN:
                self.moved_why[o] = (
                    f"the frozen frame shows only {100 * seen:.0f} % of its outline where the database draws it"
                )
        keep &= np.array([o not in self.moved_why for o in c.objects], bool)
        if self.blocked and len(c.X):
            B = np.array(self.blocked)
            keep &= np.linalg.norm(c.X[:, None, :] - B[None], axis=2).min(axis=1) > BLOCKED_M
        c = c.take(keep)
        rows = np.zeros((0, 6))
        if len(c.X):
            pan_c, tilt_c, rho_c = aim(T, c.X)
            rows = turret_plane_rows(T, pan_c, tilt_c, rho_c, c.normals, spec)
        sd_all = np.sqrt(np.diag(np.linalg.inv(info + rows.T @ rows)))  # every point left measured (none left: now)
        if _at_prior((float(np.degrees(sd_all[:3].max())), float(sd_all[3:].max()))):
            # what the beams leave free no face left to aim at fixes (a new operator measured the table's same
            # four spots 18 times over, σ staying at 500 mm, after the parallelepiped was found moved)
            self.stuck = (
                self._moved_sentence()
                if self.moved_why
                else "model another object (Model object) for a face turned another way, then measure on it here"
            )
            return
        if not len(c.X):
            return
        ratio = room_ratio(c, landing_sd(T, cov_aim, c))  # ≤ 1: a beam aimed there lands on that face
        k = self._choose(c, ratio, rows, done, cov_aim, T)
        sd_k = np.sqrt(np.diag(np.linalg.inv(info + np.outer(rows[k], rows[k]))))
        self.suggestion = (c.X[k].copy(), f"a suggested point on {c.names[k]}")
        self.sigma_next = (float(np.degrees(sd_k[:3].max())), float(sd_k[3:].max()))

    def _choose(self, c: Candidates, ratio: np.ndarray, rows: np.ndarray, done: np.ndarray, cov_aim, T) -> int:
        """Which candidate to suggest (``_suggest``): the best within reach (``ratio`` ≤ 1), unless a point
        out of reach would do much more (UNLOCK_GAIN); then first the beam within reach that brings it into
        reach soonest (e.g. the table top, then the table's edge), or, when none helps or none is within
        reach, that point itself (of each face out of reach only its most central point competes: the
        likeliest to be hit). Sets ``unlocks``."""
        scale = np.array([np.radians(TARGET_DEG)] * 3 + [TARGET_M] * 3)
        reach = ratio <= 1.0
        names = sorted({c.names[i] for i in np.flatnonzero(~reach)})
        far = np.array(
            [min((i for i in np.flatnonzero(~reach) if c.names[i] == nm), key=lambda i: ratio[i]) for nm in names], int
        )
        last, self.unlocks = self.unlocks, ""
        if not reach.any():
            self.unlocks = "?"
            return int(far[next_turret_point(done, rows[far], scale, PRIOR_SD)[0]])
        idx = np.flatnonzero(reach)
        k, sd_k = next_turret_point(done, rows[reach], scale, PRIOR_SD)
        if not len(far):
            return int(idx[k])
        f, sd_f = next_turret_point(done, rows[far], scale, PRIOR_SD)
        if (sd_f / scale).max() >= UNLOCK_GAIN * (sd_k / scale).max():
            return int(idx[k])
        f = int(far[f])
        G = landing_rows(T, c.take(np.arange(len(c.X)) == f))[0]
        room = np.array([c.room[f, :2].min(), c.room[f, 2:].min()])
        ratio_f = np.max((ROOM_SIGMAS * unlocking(G, cov_aim, rows[reach]) + ROOM_SPARE_M) / room, axis=1)
        self._unlock_tries = self._unlock_tries + 1 if last == c.names[f] else 0
        if ratio_f.min() < UNLOCK_STEP * ratio[f] and self._unlock_tries < 2:  # a beam within reach narrows it
            self.unlocks = c.names[f]
            return int(idx[int(np.argmin(ratio_f))])
        self.unlocks = "?"  # nothing within reach helps: aim there anyway (a beam that lands elsewhere waits)
        return f

    def _near_blocked(self, X) -> bool:
        return any(np.linalg.norm(np.asarray(X, float) - b) <= 0.01 for b in self.blocked)

    def _outline_shares(self, names: set) -> dict[str, float | None]:
        """Of the objects ``names``, the share of each one's outline the frozen frame (none frozen: the camera's frame
        now) shows where the database draws it (``app.vision.evaluate.outline_seen``; None: not in view); {} without
        a frame."""
        frame = self.frame_in(self.view)
        image = frame.image if frame is not None else self.site.frame_at(None, self.view)
        if image is None:
            return {}
        from app.vision.evaluate import outline_seen

        if image is not self._seen_on:  # another frame: the shares are its own (the image is held: its id not reused)
            self._seen, self._seen_on = {}, image
        out = {}
        for name in sorted(names):
            try:
                obj = self.site.object(name)
            except KeyError:  # gone from the database meanwhile
                continue
            key = (name, obj.version)
            if key not in self._seen:
                self._seen[key] = outline_seen(image, self.camera, obj.model, obj.T_world_obj)
            out[name] = self._seen[key]
        return out

    def _to_update(self) -> list[str]:
        """The objects found moved that Update its pose can help: not one the frozen frame shows in place (Update
        pose there finds the same: it has moved since the frame)."""
        return [o for o in sorted(self.moved_why) if o not in self.moved_since]

    def _moved_sentence(self) -> str:
        """Which objects look moved and why, and what to do: "the parallelepiped has moved (…): {update_moved} …"."""
        update = self._to_update()
        parts = []
        for o in sorted(self.moved_why):
            if o not in update:  # (a new operator was offered Update its pose again on the frame it came from)
                parts.append(
                    f"the {o} has moved since this frame, which shows it where the database has it "
                    f"({self.moved_why[o]}): measure on it once the video there looks as frozen, or Cancel and start "
                    "again on a newer frame"
                )
            elif o == update[0]:
                parts.append(
                    f"the {o} has moved ({self.moved_why[o]}): "
                    + "{update_moved} (your measurements here are kept), then measure on it here"
                )
            else:
                parts.append(f"the {o} too ({self.moved_why[o]})")
        return "; ".join(parts)

    def update_moved(self) -> Detour:
        """Update pose of the first object found moved, while this workflow waits with its measurements
        (``returned``)."""
        with self.lock:
            self._check_open()
            update = self._to_update()
            if not update:
                raise WorkflowError("no known object is found moved that Update pose on this frame can help")
            return Detour("update_pose", {"object_name": update[0]}, returned=self.returned)

    def returned(self, detour: Workflow) -> None:
        """Back from Update pose: each beam is checked again against the database (the object's pose may be new),
        the suggestions made again, a solve of the old surfaces dropped."""
        name = getattr(detour, "object_name", None) or "object"
        gone: list[str] = []
        with self.lock:
            if not self.finished:
                if detour.accepted:
                    self.result = None
                    self.state = "measure" if self.pending_X is not None else "pick"
                    if self.pan:
                        self.checks = check_beams(
                            self.site,
                            self.site.T_world_turret,
                            np.array(self.pan),
                            np.array(self.tilt),
                            np.array(self.range_m),
                            self.site.calibration_covs[1],
                        )
                    gone = self._measured_while_moving(name)
                self._suggest()
            n = len(self.pan)
            kept = f"your {n} measurement{'s' if n != 1 else ''} here {'are' if n != 1 else 'is'} kept"
            if not detour.accepted:
                self.message = f"Back in {self.title}: Update pose was cancelled; {kept}."
                return
            self.message = f"Back in {self.title}: the {name}'s pose is updated; {kept}" + (
                f", checked again against it ({sum(c.disagrees for c in self.checks)} disagree now)." if n else "."
            )
            if gone:
                self.message += (
                    f" Deleted: {', '.join(gone)} — on the {name}, they disagree with its new pose too (measured while "
                    "it was still moving); measure on it again."
                )

    def _measured_while_moving(self, name: str) -> list[str]:
        """Delete the measurements at object ``name`` that disagree with the database after its pose was updated
        (a beam measured while it slid, which the frozen frame's check against the live video missed: they kept it
        counted as moved, and a new operator had to find and delete them by hand); their labels."""
        aimed = self._aimed(range(len(self.checks)))
        bad = [i for i, c in enumerate(self.checks) if c.disagrees and name in (c.object, aimed[i])]
        out = [f"{i + 1} {self.labels[i]}" for i in bad]
        for i in reversed(bad):
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels, self.checks):
                lst.pop(i)
        return out

    def use_frame(self, frame) -> None:
        """Work on ``frame``: what it shows away from its drawing is not suggested (``_suggest`` again)."""
        super().use_frame(frame)
        with self.lock:
            if not self.finished:
                self._suggest()

    def _landed(self) -> tuple[np.ndarray, np.ndarray]:
        """Which beams landed within OFF_SURFACE_M of a known surface at the calibration in use (N,), and
        the normals (N, 3) of the faces they are nearest to."""
        n = len(self.pan)
        mesh, _ = self.site.surfaces()
        if not n or mesh is None:
            return np.zeros(n, bool), np.zeros((n, 3))
        X = beam_point(self.site.T_world_turret, np.array(self.pan), np.array(self.tilt), np.array(self.range_m))
        _, dist, tri = mesh.nearest.on_surface(X)
        return dist <= OFF_SURFACE_M, mesh.face_normals[tri]

    def _estimate(self, landed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The turret pose to aim with and its covariance (6, 6): the beams that landed, fitted with the
        calibration in use as a prior (its covariance, or AIM_PRIOR_SD where it has none or a looser
        one); the calibration in use and the prior before any beam. Where a beam lands does not matter
        to the solve (it uses the angles the turret reached), but a beam that lands where it was aimed
        measures what was chosen, and a thin face such as the table's edge is hit at all."""
        T0 = self.site.T_world_turret
        cov0 = self.site.calibration_covs[1]
        if cov0 is None or np.any(np.sqrt(np.diag(cov0)) > AIM_PRIOR_SD):
            cov0 = np.diag(AIM_PRIOR_SD**2)
        mesh, _ = self.site.surfaces()
        if not landed.any() or mesh is None:
            return T0, cov0
        pan, tilt, rho = np.array(self.pan), np.array(self.tilt), np.array(self.range_m)
        try:
            cal, T = self._fit(mesh, pan, tilt, rho, landed, T0, "", 5, prior=(T0, cov0))
        except WorkflowError:
            return T0, cov0
        return T, cal.cov

    def _aim_pose(self) -> np.ndarray:
        """The turret pose to aim with (``_estimate``)."""
        return self.T_aim if self.T_aim is not None else self.site.T_world_turret

    def _suggestion_text(self) -> str:
        """The step's sentence on σ and the suggested point ("" without one)."""
        if self.sigma_now is None:
            return ""
        deg, m = self.sigma_now
        reached = deg <= TARGET_DEG and m <= TARGET_M
        now = (
            (
                " The beams so far leave the turret's pose free in some direction: faces of three orientations fix it."
                if _at_prior(self.sigma_now)
                else f" The beams so far give σ {deg:.2f}°, {1000 * m:.1f} mm"
                + (
                    f" (within the {TARGET_DEG}° and {1000 * TARGET_M:.1f} mm aimed for: " + "{solve})."
                    if reached
                    else "."
                )
            )
            if len(self.pan) >= 6
            else ""
        )
        if self.stuck and not reached:
            return (
                f"{now} No known face left to aim at fixes what the beams leave free: {self.stuck[0].upper()}"
                f"{self.stuck[1:]}."
            )
        if self.moved_why and not reached:
            sentence = self._moved_sentence()
            now += f" Not offered: {sentence[0].upper()}{sentence[1:]}."
        if self.blocked and not reached:
            n = len(self.blocked)
            now += (
                f" Not offered near {'the point' if n == 1 else f'{n} points'} where the range finder met something "
                "not in the database in front of a known face."
            )
        if self.suggestion is None or reached:
            return now
        where = self.suggestion[1].split(" on ", 1)[1]
        if self.unlocks and self.unlocks != "?":
            return (
                f"{now} Next, the point circled 'next' (on {where}): it narrows the aim at {self.unlocks}, "
                "which reduces σ the most; {measure_next} measures it."
            )
        return (
            f"{now} Next, the point circled 'next' (on {where}) reduces σ the most"
            + (
                f", to {self.sigma_next[0]:.2f}°, {1000 * self.sigma_next[1]:.1f} mm"
                if len(self.pan) >= 5 and not _at_prior(self.sigma_next)
                else ""
            )
            + "; {measure_next} measures it."
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
            radius = pick_radius_px(self)  # farther: a point on the surface under the click
            if self.suggestion is not None:  # the circled suggestion wins over a corner or centre as near
                d_s = float(np.linalg.norm(cam.project(self.suggestion[0].reshape(1, 3))[0] - p))
                if d_s <= radius and (not len(d) or d_s <= d.min() + 3.0):
                    self.pending_X, self.pending_label = self.suggestion[0].copy(), self.suggestion[1]
                    self.state = "measure"
                    self.message = f"Target: {self.suggestion[1]}."
                    return
            if not len(X) or d.min() > radius:
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
    def measure_next(self):
        """Pick the point circled 'next' (``suggestion``) and measure it (``measure``)."""
        with self.lock:
            self._check_open()
            if self.suggestion is None:
                raise WorkflowError("there is no point to suggest now: click a known point and Measure")
            self.pending_X, self.pending_label = self.suggestion[0].copy(), self.suggestion[1]
            self.state = "measure"
        return self.measure()

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
            pan, tilt, _ = aim(self._aim_pose(), X)
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
            check = check_beams(
                self.site, self.site.T_world_turret, pan_r, tilt_r, m.range_m, self.site.calibration_covs[1]
            )[0]
            self.checks.append(check)
            if check.disagrees:  # said now; Solve leaves it out if it still disagrees through the solved pose
                self.message += (
                    " ⚠ "
                    + disagreement_text(
                        [check], [self.labels[-1]], done="Solve leaves it out", aimed=self._aimed([len(self.pan) - 1])
                    )
                    + "."
                )
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
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels, self.checks):
                lst.pop(i)
            solved, self.result = self.result is not None, None
            self.state = "measure" if self.pending_X is not None else "pick"
            self.message = f"Measurement {i + 1} deleted: {len(self.pan)} left." + (" Solve again." if solved else "")
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
            for lst in (self.pan, self.tilt, self.range_m, self.targets, self.labels, self.checks):
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
            bad = self._moved(used)
            pre_text = ""
            if bad.any():
                used &= ~bad
                idx = np.flatnonzero(bad)
                pre_text = disagreement_text(
                    [self.checks[i] for i in idx], [f"{i + 1} {self.labels[i]}" for i in idx], aimed=self._aimed(idx)
                )
                off_text += f" ⚠ {pre_text}."
            if used.sum() < 6:
                raise WorkflowError(
                    f"only {int(used.sum())} of {n} measurements landed within {100 * OFF_SURFACE_M:.0f} cm "
                    f"of a known surface and agree with the database; measure points well inside faces of "
                    f"known objects.{off_text}"
                )
            # from the beams' estimate (``_estimate``): a start centimetres off associates a beam beside an
            # edge with the wrong face, and the fit settles there
            landed, _ = self._landed()
            landed &= used
            T_est, cov_est = self._estimate(landed)
            cal, T = self._fit(mesh, pan, tilt, rho, used, T_est, off_text, max_rounds)
            cal, T, used, moved_text = self._leave_out_disagreeing(mesh, pan, tilt, rho, used, cal, T, max_rounds)
            moved_text = ". ".join(t for t in (pre_text, moved_text) if t)
            self.used = used
            _, dist, _ = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            dist = dist[used]
            self.result = cal
            self.T_solved = T
            self.T_before = self.site.T_world_turret  # the calibration in use when solved (Result's change from it)
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
            of_all = f" of {len(used)}" if int(used.sum()) < len(used) else ""  # the panel counts every measurement
            self.message = (
                f"RMS {1000 * np.sqrt(np.mean(dist**2)):.1f} mm to the surfaces over {int(used.sum())}{of_all} "
                f"points{exact}{dropped}; {deg:.2f}° and {1000 * m:.1f} mm from the current calibration"
            )
            if moved_text:
                self.message += f". ⚠ {moved_text}"
            far = self._far_points()
            if far:
                self.message += f". ⚠ {far}"
            self.elsewhere_text = self._wandered(T, T_est, cov_est)
            if self.elsewhere_text:
                self.message += f". ⚠ {self.elsewhere_text}"
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

    def _fit(self, mesh, pan, tilt, rho, used, T, off_text: str, max_rounds: int, prior=None):
        """``calibrate_turret_planes`` on the beams ``used``: first each on the face it was aimed at (the
        face nearest its target), the beams that lie off it by more than 3σ_ρ left out (they landed beside
        it) and fitted again; then each on the face it is nearest to, re-associated and fitted again
        until the pose stops moving. Associating by nearness alone from a pose centimetres off puts a beam
        beside an edge on the wrong face, and the fit settles on the wrong side. ``prior``: see
        ``calibrate_turret_planes``. Returns (TurretCalibration, T (4, 4))."""
        least = 1 if prior is not None else 6
        spec = self.site.scene.rangefinder

        def fit(use, normals, closest, T):
            try:
                return calibrate_turret_planes(
                    pan[use],
                    tilt[use],
                    rho[use],
                    normals[use],
                    -np.einsum("ij,ij->i", normals, closest)[use],
                    T,
                    spec,
                    prior=prior,
                )
            except ValueError as exc:
                if "independent normals" in str(exc):
                    raise WorkflowError(self._too_few_orientations(normals[use], use, off_text)) from None
                raise WorkflowError(f"turret calibration failed: {exc}") from None

        closest, _, tri = mesh.nearest.on_surface(np.array(self.targets).reshape(-1, 3))  # the faces aimed at
        normals = mesh.face_normals[tri]
        use = used.copy()
        for _ in range(3):
            cal = fit(use, normals, closest, T)
            off = np.abs(np.einsum("ij,ij->i", normals, beam_point(cal.T_world_turret, pan, tilt, rho) - closest))
            beside = used & (off > 3 * spec.sigma_range_m)
            if not (use & beside).any() or (used & ~beside).sum() < least:
                break
            use = used & ~beside
        T = cal.T_world_turret
        for _ in range(max_rounds):
            closest, dist, tri = mesh.nearest.on_surface(beam_point(T, pan, tilt, rho))
            normals = mesh.face_normals[tri]
            # a beam cannot land on a face turned away from it: one nearest such a face (beside an edge,
            # at a pose still off) is left out of this round rather than pull the pose to the wrong side;
            # so is one more than 3σ_ρ from every face (an object that moved: ``solve`` then says which)
            use = used & (np.einsum("ij,ij->i", normals, beam_ray(T, pan, tilt)[1]) < 0)
            use &= dist <= 3 * spec.sigma_range_m
            if use.sum() < least:
                use = used
            cal = fit(use, normals, closest, T)
            deg, m = pose_error(cal.T_world_turret, T)
            T = cal.T_world_turret
            if deg < 1e-5 and m < 1e-7:
                break
        return cal, T

    def _moved(self, used: np.ndarray) -> np.ndarray:
        """(N,) bool: the beams among ``used`` that disagreed with the database when measured (``checks``,
        through the calibration in use), while most agreed: their object has moved (had the calibration
        been off, most would disagree). They are left out of the estimate and of the solve."""
        bad = used & np.array([c.disagrees for c in self.checks], bool).reshape(-1)
        return bad if bad.sum() <= 0.5 * used.sum() else np.zeros_like(bad)

    def _aimed_normals(self) -> np.ndarray:
        """(N, 3): the normal of the face each measurement was aimed at (the surface nearest its target)."""
        mesh, _ = self.site.surfaces()
        if mesh is None or not self.targets:
            return np.zeros((len(self.targets), 3))
        return mesh.face_normals[mesh.nearest.on_surface(np.array(self.targets).reshape(-1, 3))[2]]

    def _aimed(self, idx) -> list[str]:
        """The object each measurement ``idx`` was aimed at (the owner of the surface nearest its target)."""
        mesh, owner = self.site.surfaces()
        if mesh is None or not len(idx):
            return [""] * len(idx)
        tri = mesh.nearest.on_surface(np.array(self.targets)[list(idx)].reshape(-1, 3))[2]
        return [str(owner[t]) for t in tri]

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
        text = disagreement_text(
            [left[i] for i in order], [f"{i + 1} {self.labels[i]}" for i in order], aimed=self._aimed(order)
        )
        return cal, T, used, text

    def _wandered(self, T: np.ndarray, T_est: np.ndarray, cov_est: np.ndarray) -> str:
        """ "" or what the operator is told when the solved pose ``T`` lies beyond the 99.9 % region of the
        beams' own estimate (``_estimate``: the same beams with the calibration in use as a prior; its
        covariance ``cov_est``): the beams fix the pose too loosely, and the solve wandered along what they
        leave free (measured: from 8 points on the table and the box, a pose 16° and 56 cm off with a
        stated σ of 5.5 mm)."""
        rel = np.linalg.solve(T_est, T)
        d = np.concatenate([log_so3(rel[:3, :3]), rel[:3, 3]])
        if float(d @ np.linalg.solve(cov_est, d)) <= WANDER_CHI2:
            return ""
        deg, m = pose_error(T, T_est)
        return (
            f"the solve lies {deg:.1f}° and {1000 * m:.0f} mm from where the same beams put the turret with the "
            "calibration in use as a guide: they fix the pose too loosely (too few, or on too few faces) and the "
            "solve may be wrong whatever its σ; measure the suggested points and Solve again"
        )

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
        if self._to_update():
            base.add("update_moved")
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
                f"Solved: {self.solve_text}. "
                + "{accept} to use it; or {measure} the point picked "
                + f"({self.pending_label}) and "
                + "{solve} again ({remove_last} drops the pick).",
                frozenset(base | {"accept", "measure"}),
            )
        nxt = {"measure_next"} if self.suggestion is not None else set()
        if self.pending_X is not None:  # (Measure next, G, still measures the circled point: a refused one kept)
            return Step(
                "measure",
                "{measure} " + f"{self.pending_label} (the turret aims through the beams' estimate so far, the "
                "current calibration as its guide), or click another known point.",
                frozenset(base | {"measure"} | nxt),
            )
        if self.result is not None:
            return Step(
                "review",
                f"Solved: {self.solve_text}. "
                + "{accept} to use it, or measure more points and {solve} again"
                + (" ({measure_next} measures the one circled 'next')." if nxt else "."),
                frozenset(base | {"accept"} | nxt),
            )
        more = f" ({6 - n} more at least)" if n < 6 else "; {solve} when done"
        return Step(
            "pick",
            f"Click a known point — a face centre (cyan), a corner, or anywhere on a known face — "
            f"then measure it{more}.{self._suggestion_text()}",
            frozenset(base | nxt),
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
            if getattr(self, "elsewhere_text", ""):
                out.append(self.elsewhere_text)
            if int(np.sum(self.used)) <= 6:
                out.append("only 6 points: little redundancy to catch a wrong one (8 or more is safer)")
            return out

    def marks(self) -> Marks:
        with self.lock:
            cam = self.camera
            m = Marks()
            X, names = self._candidates()
            centres = np.array(  # (not on an object found moved: where the database draws it, nothing stands)
                [x for x, nm in zip(X, names) if nm.endswith("centre") and nm.split(" face ")[0] not in self.moved_why]
            ).reshape(-1, 3)
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
            if self.sigma_now is not None and not _at_prior(self.sigma_now):  # (at the prior: not fixed yet, said)
                out["sigma_predicted"] = {"deg": self.sigma_now[0], "mm": 1000 * self.sigma_now[1]}
            if self.result is not None:
                out["rms_mm"] = float(1000 * np.sqrt(np.mean(self.surface_residuals_m**2)))
                sd_rot_deg, sd_t_m = self._sigmas()
                out["sd_rot_deg"] = [float(v) for v in sd_rot_deg]
                out["sd_t_mm"] = [float(1000 * v) for v in sd_t_m]
                deg, m = pose_error(self.T_solved, self.T_before)
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
