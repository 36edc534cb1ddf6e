"""Calibrate camera from robot: the robot is the calibration object. Its tool's tip, shown at known joint
configurations (the scene's ``calibration_camera_deg``), gives the DLT (or, the lens known, the PnP) its
known points: a site needs no calibration object.

**Next pose** (G) sends the robot to the next pose (its motion checked against the database and itself,
``RobotTour``); once it is there the newest frame is frozen and the corner of the tool's tip that the
camera sees (``core.robot.calibration.tip_corners``: the closed fingertips' end, the corner nearest the
camera that no link hides) is circled where the current calibration puts it. The operator clicks where
that corner really is in the video, snapped to the image's corner (its edges' directions from the finger's
model). Its world position comes from the joints the controller reported and the robot's calibrated base
(the database's "robot_base": calibrate the base first, Calibrate robot). **Solve** (R) runs
``core.calibration.calibrate_dlt`` (≥ 6 poses, not all in one plane) or, with the lens known (as Calibrate
camera: ``known_K``), ``app.vision.pnp.solve_pnp`` (≥ 4), with each point's residual; **Accept** stores the
camera's calibration (methods "robot dlt", "robot pnp", undoable in History) and every overlay is redrawn
through it.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from core.calibration import calibrate_dlt
from core.robot.calibration import tip_corners
from core.transforms import transform_points

from .base import CANCEL, Control, Marks, Step, WorkflowError, as_pixel
from .calibrate_camera import METHODS, MIN_REDUNDANT_PAIRS, MIN_REDUNDANT_PAIRS_PNP, known_K
from .robot_tour import TourWorkflow
from .snapping import Snapper, snap_marks, weak_snaps

__all__ = ["CalibrateCameraFromRobot", "visible_tip"]


def visible_tip(camera, model, q, T_world_base) -> tuple[np.ndarray, int, int] | None:
    """The corner of the tool's tip (``tip_corners``) at q that ``camera`` sees best: on an edge its finger
    shows (convex hidden-line removal), hidden by no other link, the nearest the camera. (X_world (3,), shape
    index into ``link_breps``, vertex index), or None when the camera sees none."""
    from app.render.raycast import SceneCaster

    X_base, shapes, vertices = tip_corners(model, q)
    if not len(X_base):
        return None
    placed = model.link_breps(q, T_world_base)
    X = transform_points(np.asarray(T_world_base, float), X_base)
    c = camera.center
    caster = SceneCaster([_Body(b) for _, b, _ in placed], [T for _, _, T in placed])
    best = None
    for x, k, v in zip(X, shapes, vertices):
        brep, T = placed[k][1], placed[k][2]
        wf = brep.wireframe(c, T)
        shown = {int(e) for e, vis, kind in zip(wf.edge_index, wf.visible, wf.kind) if vis and kind == "edge"}
        if not any(int(v) in brep.edges[e] for e in shown) or camera.depth(x[None])[0] <= 0:
            continue
        if caster.occluded(c, x[None], body=int(k), tol_m=1e-4)[0]:
            continue
        d = float(np.linalg.norm(x - c))
        if best is None or d < best[0]:
            best = (d, x.copy(), int(k), int(v))
    return None if best is None else best[1:]


class _Body:
    def __init__(self, model):
        self.model = model


class CalibrateCameraFromRobot(TourWorkflow):
    name = "calibrate_camera_robot"
    title = "Calibrate camera from robot"
    snapping = True
    actions = (
        "go",
        "skip",
        "stop",
        "click",
        "remove_last",
        "pose",
        "remove_pose",
        "solve",
        "accept",
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
            hint="With the lens known: the camera's pose alone (PnP, 4 poses or more) or the full camera matrix "
            "(DLT, 6 or more)",
        ),
        TourWorkflow.GO,
        TourWorkflow.SKIP,
        TourWorkflow.STOP,
        Control("solve", "Solve", "R", color="blue", hint="The camera from the tool tip's clicked positions"),
        Control(
            "accept", "Accept", "enter", color="green", hint="Store the camera's calibration: every overlay is redrawn"
        ),
        Control("refuse_snap", "Refuse snap", "U", hint="Use the last click as clicked, not moved onto the corner"),
        Control("remove_last", "Remove last", "backspace", hint="Forget the last pose's click"),
        Control("pose", "Pose", kind="choice", hint="A clicked pose: its tip's residual after a Solve"),
        Control("remove_pose", "Remove pose", arg="pose", hint="Forget the chosen pose's click (a wrong corner)"),
        CANCEL,
    )

    which = "camera"
    poses_named = "camera calibration poses"

    def __init__(self, site, client: str = "operator", view: str | None = None, snap: bool = True, sigma_px=1.0):
        super().__init__(site, client, view, snap, sigma_px)
        self.K = known_K(site, self.view)
        self.method = "pnp" if self.K is not None else "dlt"
        self.solved_by: str | None = None
        self.points: dict[int, dict[str, Any]] = {}  # pose → {"X", "uv", "sigma", "snap", "frame"}
        self.order: list[int] = []  # the poses clicked, in click order (Remove last)
        self.result = None
        self.pose_chosen: int | None = None  # the pose the operator chose in Pose since the clicks last changed

    def _tip(self, k: int) -> tuple[np.ndarray, int, int] | None:
        """The tip corner at pose k (its world point through the database's base), as ``visible_tip``."""
        return visible_tip(self.camera, self.model, self.tour.arrived[k], self.cell.T_world_base)

    # ------------------------------------------------------------------ clicks
    def click(self, uv) -> None:
        """Where the circled corner of the tool's tip is in the video (a second click at a pose replaces it)."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            k = self.tour.at
            if k is None:
                raise WorkflowError("the robot is not at a calibration pose: Next pose (G) sends it to one")
            tip = self._tip(k)
            if tip is None:
                raise WorkflowError(f"the camera sees no corner of the tool's tip at pose {k + 1}: Next pose (G)")
            X, shape, vertex = tip
            _, brep, T = self.model.link_breps(self.tour.arrived[k], self.cell.T_world_base)[shape]
            used, sigma, snap = self.snapper.take_corner(p, self.view, self.sigma_px, brep, T, vertex)
            replaced = k in self.points
            self.points[k] = {"X": X, "uv": np.asarray(used, float), "sigma": float(sigma), "snap": snap}
            if k in self.order:
                self.order.remove(k)
            self.order.append(k)
            self.result, self.solved_by, self.pose_chosen = None, None, None
            said = Snapper.message(f"Pose {k + 1}'s tip", snap)
            self.message = (said + " " if said else "") + ("(It replaces this pose's last click.)" if replaced else "")

    def remove_last(self) -> None:
        with self.lock:
            self._check_open()
            if not self.order:
                raise WorkflowError("there is no click to remove")
            self._forget(self.order[-1])

    def remove_pose(self, k: int) -> None:
        """Forget pose ``k``'s click (from 0), whichever pose it was: a wrong corner the Solve's residuals point at."""
        with self.lock:
            self._check_open()
            if int(k) not in self.points:
                raise WorkflowError(f"pose {int(k) + 1} has no click: choose one of the poses in the list")
            self._forget(int(k))

    def _forget(self, k: int) -> None:
        self.order.remove(k)
        self.points.pop(k)
        self.result, self.solved_by, self.pose_chosen = None, None, None
        self.message = f"Pose {k + 1}'s click is removed: {len(self.order)} left."

    def pose(self, k: int) -> None:
        """The operator chose pose ``k`` in the Pose chooser (kept until the clicks or the Solve change)."""
        with self.lock:
            self.pose_chosen = int(k)

    def refuse_snap(self) -> None:
        with self.lock:
            self._check_open()
            if not self.order:
                raise WorkflowError("there is no click whose snap to refuse")
            pt = self.points[self.order[-1]]
            Snapper.refusable(pt["snap"]).refused = True
            pt["uv"], pt["sigma"] = pt["snap"].raw.copy(), self.sigma_px
            self.result, self.solved_by = None, None
            self.message = "Snap refused: the last click is used as you clicked it."

    def set_snap(self, on: bool = True) -> None:
        with self.lock:
            self.message = self.snapper.set(on)

    def set_method(self, method: str) -> None:
        with self.lock:
            self._check_open()
            if method not in METHODS:
                raise WorkflowError(f"Solve by is one of {', '.join(METHODS)}, not {method!r}")
            if method == "pnp" and self.K is None:
                raise WorkflowError("the camera's lens is not known here: only the full camera matrix (DLT) is solved")
            if method != self.method:
                self.method, self.result, self.solved_by = method, None, None
            self.message = f"Solve by: {METHODS[method][0]}."

    # ------------------------------------------------------------------ solving
    def _arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        X = np.array([self.points[k]["X"] for k in self.order]).reshape(-1, 3)
        uv = np.array([self.points[k]["uv"] for k in self.order]).reshape(-1, 2)
        return X, uv, np.array([self.points[k]["sigma"] for k in self.order])

    def solve(self):
        with self.lock:
            self._check_open()
            _, need, what, how = METHODS[self.method]
            n = len(self.order)
            if n < need:
                raise WorkflowError(f"{n} poses clicked; {what} needs at least {need}: Next pose (G), click its tip")
            X, uv, sig = self._arrays()
            w, h = self.camera.width, self.camera.height
            try:
                if self.method == "pnp":
                    from app.vision.pnp import solve_pnp

                    self.result = solve_pnp(self.K, X, uv, w, h, sigma_px=sig)
                else:
                    self.result = calibrate_dlt(X, uv, w, h, sigma_px=sig)
            except ValueError as exc:
                raise WorkflowError(f"calibration failed: {exc}") from None
            self.solved_by, self.state, self.pose_chosen = self.method, "review", None
            self.message = self._solved_text() + "."
            return self.result

    def _solved_text(self) -> str:
        _, _, what, how = METHODS[self.solved_by]
        return f"Solved {what} from the tool's tip at {len(self.order)} poses {how}: RMS {self.result.rms_px:.2f} px"

    def accept(self) -> None:
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: Solve first")
            X, uv, sig = self._arrays()
            points = {
                "X_world": X.tolist(),
                "uv": uv.tolist(),
                "labels": [f"tool tip at pose {k + 1}" for k in self.order],
                "snaps": [
                    None if self.points[k]["snap"] is None else self.points[k]["snap"].record() for k in self.order
                ],
                "poses_q": [self.tour.arrived[k].tolist() for k in self.order],
                "T_world_base": np.asarray(self.cell.T_world_base).tolist(),
                "base_nominal": bool(self.site.robot_base_nominal),
                "frames": {str(k): fr.record() for k, fr in self.frames.items()},
                "solved_by": self.solved_by,
            }
            if self.solved_by == "pnp":
                points.update(K=np.asarray(self.K).tolist())
            self.site.set_camera(
                self.result.camera,
                rms_px=self.result.rms_px,
                residuals_px=self.result.residuals_px,
                cov=self.result.cov,
                points=points,
                client=self.client,
                method=f"robot {self.solved_by}",
                view=self.view,
            )
            self.accepted, self.state = True, "accepted"
            self.message = (
                f"Camera calibrated from the robot's tool tip ({METHODS[self.solved_by][2]}, RMS "
                f"{self.result.rms_px:.2f} px): every overlay is now drawn through it."
            )

    # ------------------------------------------------------------------ the panel
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        moving = self._tour_step()
        if moving is not None:
            return moving
        t = self.tour
        has = {"cancel"} | ({"remove_last", "pose", "remove_pose"} if self.order else set())
        last = self.points[self.order[-1]]["snap"] if self.order else None
        if last is not None and last.applied:
            has.add("refuse_snap")
        if self.K is not None:
            has.add("set_method")
        has = self._tour_controls(has, True)
        _, need, what, how = METHODS[self.method]
        if len(self.order) >= need:
            has.add("solve")
        base = (
            " (the robot's base is not calibrated: its drawing's pose is used)" if self.site.robot_base_nominal else ""
        )
        if self.result is not None and (t.at is None or t.at in self.points):
            return Step(
                "review",
                f"{self._solved_text()}. {{accept}} stores it"
                + ("; more poses ({go}) and {solve} again improve it." if "go" in has else "."),
                frozenset(has | {"accept"}),
            )
        more = max(0, need - len(self.order))
        tally = f"{len(self.order)} of {t.n} poses clicked" + (
            f" ({more} more needed for {what} {how})." if more else f": {{solve}} for {what} {how}."
        )
        if t.at is None:
            nxt = "" if t.next_index is None else f"{{go}} sends the robot to pose {t.next_index + 1} of {t.n}. "
            return Step("go", nxt + tally + base, frozenset(has), False)
        clicked = " again to replace it" if t.at in self.points else ""
        if self.result is not None:
            has.add("accept")
        return Step(
            "click_tip",
            f"Pose {t.at + 1} of {t.n}: click the circled corner of the tool's tip where the video shows it{clicked}. "
            + tally
            + base,
            frozenset(has),
        )

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action == "set_method" and self.K is not None:
            return [(METHODS[m][0], m) for m in ("pnp", "dlt")]
        if action != "pose":
            return []
        with self.lock:
            # after a Solve the farthest off first (a wrong corner), else the newest first
            errors = {} if self.result is None else dict(zip(self.order, self.result.errors_px))
            out = []
            for i, k in enumerate(self.order):
                e = errors.get(k)
                off = "" if e is None else f", {e:.1f} px off"
                out.append((i if e is None else float(e), f"pose {k + 1}{off}", k))
            return [(text, k) for _, text, k in sorted(out, key=lambda t: -t[0])]

    def choice_value(self, action: str) -> Any:
        """Solve by shows the method; Pose the operator's choice, else the first listed (after a Solve the farthest
        off, so that Remove pose at once takes the likeliest wrong corner)."""
        if action == "set_method":
            return self.method
        if action != "pose":
            return None
        values = [k for _, k in self.choices("pose")]
        return self.pose_chosen if self.pose_chosen in values else (values[0] if values else None)

    def marks(self) -> Marks:
        with self.lock:
            cam = self.camera
            m = Marks()
            uv = np.array([self.points[k]["uv"] for k in self.order]).reshape(-1, 2)
            m.points = uv
            m.labels = [(p + [6.0, -6.0], str(k + 1)) for p, k in zip(uv, self.order)]
            m.raw_segments, m.raw_points, m.snap_lines, snap_labels = snap_marks(
                [self.points[k]["snap"] for k in self.order]
            )
            k = self.tour.at
            if k is not None:
                tip = self._tip(k)
                if tip is not None and cam.depth(tip[0][None])[0] > 0:
                    m.circles = cam.project(tip[0][None])
                    m.labels.append((m.circles[0] + [9.0, -9.0], "tool tip"))
            if self.result is not None and len(uv):
                X, _, _ = self._arrays()
                m.residuals = np.stack([uv, self.result.camera.project(X)], axis=1)
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {
                "poses": f"{len(self.tour.arrived)} of {self.tour.n} visited",
                "clicked": len(self.order),
            }
            if self.result is not None:
                out["solved_by"] = METHODS[self.solved_by][0]
                out["rms_px"] = self.result.rms_px
                out["points"] = [
                    {"point": f"tool tip at pose {k + 1}", "residual_px": float(e)}
                    for k, e in zip(self.order, self.result.errors_px)
                ]
            return out

    def weaknesses(self) -> list[str]:
        with self.lock:
            if self.result is None:
                return []
            out = []
            n = len(self.order)
            least = MIN_REDUNDANT_PAIRS_PNP if self.solved_by == "pnp" else MIN_REDUNDANT_PAIRS
            if n < least:
                out.append(
                    f"only {n} poses: enough to solve, but little redundancy to catch a wrong click ({least} or more "
                    "is safer)"
                )
            if self.site.robot_base_nominal:
                out.append(
                    "the robot's base is not calibrated: the tip's world positions rest on the drawing's base pose"
                )
            _, _, sig = self._arrays()
            for k, e, s in zip(self.order, self.result.errors_px, sig):
                if e > 3 * max(s, 0.5):
                    out.append(
                        f"pose {k + 1}'s tip is {e:.1f} px from where C puts it (more than 3σ): a wrong corner? "
                        "(Remove pose forgets it)"
                    )
                out += weak_snaps([(f"pose {k + 1}", self.points[k]["snap"])])
            return out
