"""Pick and place: the robot takes the selected object and puts it where the operator clicks; the database
follows it from the robot's kinematics, then looks at it in the video.

Select an object, start Pick and place, click where it goes (a point on the table or on another object's
top): ``app.robot.cell.RobotCell.plan_pick_place`` plans the whole motion (fingers open, down around the
object, close, up, across, down, open, up, back where it started) and checks it; the ghosts show the
object where it will stand and the robot at the place. Pick and place (M) sends it; Stop (Space) or Esc halts it.

When the motion ends with the fingers open at the place and no fault, the object's new pose is written
(method "robot"): the pose it had in the gripper (``T_tool_obj`` from the database's pose at the grasp)
carried by the joints the controller reports through the calibrated base. Its covariance: the database's
covariance before, turned with the object, plus the grasp's (``GRASP_SIGMA_M`` across and along the
fingers and up, ``GRASP_SIGMA_DEG`` about each axis: the fingers centre the object, it may slip) and the
base calibration's when it has one. Then the one-click search (``app.vision.search.search_pose``) looks
for it on the newest frame from that pose, off the robot's way: agreeing within 3σ (and 5 mm / 1°) it is
"confirmed by the video"; else the operator is told how far the two differ, and the database keeps the
robot's pose (a double click updates it from the video). A fault or a stop writes nothing: the robot did
not put the object where the plan said.
"""

from __future__ import annotations

import threading
from typing import Any

import numpy as np

from app.robot.controller import ControllerError
from core.transforms import log_so3

from .base import Control, Ghost, Marks, Step, WorkflowError
from .robot_work import RobotWork, planned
from .writing import write_pose

__all__ = ["PickPlace", "GRASP_SIGMA_M", "GRASP_SIGMA_DEG"]

GRASP_SIGMA_M = 0.002
GRASP_SIGMA_DEG = 0.5
AGREE_SIGMAS = 3.0
AGREE_FLOOR_MM, AGREE_FLOOR_DEG = 5.0, 1.0  # the video and the robot agree within these whatever the σ
PUT_ON_UP_COS = np.cos(np.radians(10.0))  # a place on a surface facing up within 10°
LOOK_WAIT_S = 3.0  # the look waits this long at most for a frame taken after the robot stopped


def _stands_on(obj, objects) -> str | None:
    """The object ``obj`` stands on: the one whose bounds hold its bottom's centre, within 1 cm."""
    lo, hi = obj.model.bounds()
    bottom = obj.T_world_obj @ np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2], 1.0])
    for o in objects:
        if o.name == obj.name:
            continue
        a, b = o.model.bounds()
        p = np.linalg.solve(o.T_world_obj, bottom)[:3]
        if np.all(p >= a - 0.01) and np.all(p <= b + 0.01):
            return o.name
    return None


class PickPlace(RobotWork):
    name = "pick_place"
    title = "Pick and place"
    options = ("object_name",)
    actions = ("click", "move", "stop", "accept", "cancel")
    controls = (
        Control("move", "Pick and place", "M", color="green", hint="Send the robot along the previewed motion"),
        Control("stop", "Stop", "space", color="red", hint="Halt the robot at once, where it is"),
        Control("accept", "Done", "enter", hint="Close"),
        Control("cancel", "Cancel", "escape", color="red", hint="Stop the robot if it moves, and close"),
    )

    needs_gripper = True

    def __init__(self, site, client: str = "operator", view: str | None = None, object_name: str | None = None):
        super().__init__(site, client, view)
        try:
            self.obj = site.object(object_name)
        except KeyError:
            raise WorkflowError(f"{self.title}: no object {object_name!r}; select one first") from None
        if self.obj.kind == "table":
            raise WorkflowError("the robot cannot pick the table: select the object to move")
        self.object_name = self.obj.name
        self.place_X: np.ndarray | None = None  # where the operator clicked to put it
        self.written: dict[str, Any] = {}
        self.look: dict[str, Any] = {}
        self._looking: threading.Thread | None = None
        self._looked = False  # the look ended and the panel was not told yet (tick)
        self.state = "click"

    # ------------------------------------------------------------------ where to put it
    def click(self, uv) -> None:
        with self.lock:
            if self.state == "looking":
                raise WorkflowError("mcit is looking for the object in the video: wait for it")
            _, hit = self._surface_at(uv, "the robot is at work: wait for it, or Stop it (Space)")
            if hit.name == self.obj.name:
                raise WorkflowError(f"that is {self.obj.name} itself: click where it should go")
            if not np.all(np.isfinite(hit.normal)) or hit.normal[2] < PUT_ON_UP_COS:
                raise WorkflowError(f"{hit.name} does not face up there: click a flat top (the table)")
            obj, X, support = self.obj, np.asarray(hit.X_world, float), hit.name
            self.place_X = X
            objects = self.site.objects()
            stands_on = _stands_on(obj, objects)
        from app.robot.cell import obstacles_of

        plan = planned(
            self.cell.plan_pick_place,
            obj.name,
            obj.model,
            obj.T_world_obj,
            X,
            support,
            obstacles_of(objects),
            stands_on=stands_on,
        )
        with self.lock:
            self.plan = plan
            where = f"on {support} at {self._xyz(X)} m"
            if plan.ok:
                self.message = (
                    f"{obj.name} {where}: the motion passes every check ({1000 * plan.preview_s:.0f} ms). "
                    f"The gripper closes on its {100 * plan.width_m:.1f} cm."
                )
            else:
                self.message = f"{obj.name} {where}: refused: {plan.reason}. The robot did not move."

    # ------------------------------------------------------------------ motion
    def move(self) -> None:
        with self.lock:
            self._send("click where the object goes first (a motion that passes the checks)")

    def stop(self) -> None:
        self.cell.stop()
        with self.lock:
            if self.state == "moving":
                self.state = "click"
                self.message = self._outcome = (
                    f"Stopped: nothing was written. {self.obj.name} may be in the gripper or anywhere on the way: "
                    "look at the video."
                )
            else:
                self._idle_stop()

    def accept(self) -> None:
        with self.lock:
            self._check_open()
            if self.state in ("moving", "looking"):
                raise WorkflowError("the robot is at work: wait for it, or Stop it (Space)")
            self.accepted = True
            self.state = "accepted"
            self.message = self.message or "Closed."

    def tick(self) -> bool:
        with self.lock:
            if self._looked:  # the look's verdict came (on its own thread): the panel shows it now, not at a key
                self._looked = False
                return True
            if self.state == "looking":
                return False
            if self.state != "moving":
                return super().tick()
            try:
                s = self.cell.state()
            except ControllerError as exc:
                self.cell.stop()  # the stop circuit: obeyed even when the controller's state cannot be read
                self.state = "click"
                self.message = (
                    f"{exc}. The robot was sent Stop and nothing was written: look at the video before moving it again."
                )
                return True
            if s.moving:
                return True
            if s.fault or np.max(np.abs(s.q - self.sent.path[-1])) > 1e-3:
                self.state = "click"
                why = s.fault or "the robot did not finish the motion"
                self.message = f"Fault: {why}. Nothing was written: look at the video."
                return True
            self._write(s.q)
            return True

    def _write(self, q_end: np.ndarray) -> None:
        """The object's new pose from the kinematics (at the release joints), written; then the look."""
        plan = self.sent
        T_tool = self.cell.tool_pose(plan.q_release)
        T = T_tool @ plan.T_tool_obj
        cov = self._cov(T)
        rec, self.obj = write_pose(
            self,
            self.obj,
            T,
            cov,
            todo="Update its pose from the video (double click on it).",
            method="robot",
            seen_at=None,  # from the joints, not an image
            measurements={"joints": plan.q_release.tolist(), "T_tool_obj": plan.T_tool_obj.tolist()},
        )
        self.obj = self.site.object(self.obj.name)
        err = T[:3, 3] - plan.T_world_obj_place[:3, 3]
        self.written = {"version": int(rec.version), "placed_off_plan_mm": 1000 * float(np.linalg.norm(err))}
        self.state = "looking"
        self.message = (
            f"Put down; its pose from the robot's joints is written. Looking for {self.obj.name} in the video…"
        )
        t_end = self.site.time_s()
        self._looking = threading.Thread(target=self._look, args=(T, cov, t_end), name="pick-place-look", daemon=True)
        self._looking.start()

    def _cov(self, T: np.ndarray) -> np.ndarray:
        """The written pose's covariance (module docstring)."""
        C = np.zeros((6, 6))
        if self.obj.cov is not None:
            R = T[:3, :3] @ self.obj.T_world_obj[:3, :3].T
            B = np.zeros((6, 6))
            B[:3, :3] = B[3:, 3:] = R
            C += B @ np.asarray(self.obj.cov, float) @ B.T
        C += np.diag([GRASP_SIGMA_M**2] * 3 + [np.radians(GRASP_SIGMA_DEG) ** 2] * 3)
        base = getattr(self.cell, "base_cov", None)
        if base is not None:
            C += np.asarray(base, float)
        return C

    def _look(self, T: np.ndarray, cov: np.ndarray, t_end: float) -> None:
        """The one-click search from the written pose on a frame taken after the motion ended (the newest when
        the video is slower than ``LOOK_WAIT_S``); the verdict in ``look``."""
        import time

        from app.vision.search import NoPoseFits, search_pose

        from .model_object import table_support

        deadline = time.monotonic() + LOOK_WAIT_S
        while self.site.time_s() < t_end + 0.2 and time.monotonic() < deadline:
            time.sleep(0.05)
        try:
            image = self.site.frame_at(None, self.view)
            if image is None:
                raise ValueError("there is no video frame to look at")
            cam = self.camera
            centre = T[:3, 3] + T[:3, :3] @ np.mean(self.obj.model.bounds(), axis=0)
            res = search_pose(
                cam,
                self.obj.model,
                T,
                cam.project(centre[None])[0],
                image,
                table=table_support(self.site),
                name=self.obj.name,
                camera_cov=self.site.pose_camera_cov(self.view),
            )
            found = res.candidates[0].T_world_obj
            dp = float(np.linalg.norm(found[:3, 3] - T[:3, 3]))
            dr = float(np.degrees(np.linalg.norm(log_so3(T[:3, :3].T @ found[:3, :3]))))
            s_p = float(np.sqrt(np.trace(cov[:3, :3])))
            s_r = float(np.degrees(np.sqrt(np.trace(cov[3:, 3:]))))
            ok = dp <= max(AGREE_SIGMAS * s_p, AGREE_FLOOR_MM / 1000) and dr <= max(AGREE_SIGMAS * s_r, AGREE_FLOOR_DEG)
            look = {"video_from_robot_mm": 1000 * dp, "video_from_robot_deg": dr, "confirmed": ok}
            if ok:
                text = (
                    f"{self.obj.name} is put down, confirmed by the video: found {1000 * dp:.1f} mm and {dr:.2f}° from "
                    "the robot's pose."
                )
            else:
                text = (
                    f"Warning: the video disagrees: {self.obj.name} was found {1000 * dp:.1f} mm and {dr:.1f}° from "
                    "where the robot put it (beyond 3σ). The database keeps the robot's pose: look at the video, and "
                    "double click the object to update it from there."
                )
        except Exception as exc:  # noqa: BLE001 - no frame, no pose that fits, a failed search: each said alike
            why = str(exc) if isinstance(exc, (NoPoseFits, ValueError)) else f"the search failed: {exc}"
            look, text = (
                {"confirmed": False},
                (
                    f"Warning: the video does not show {self.obj.name} where the robot put it ({why}). The database "
                    "keeps the robot's pose: look at the video."
                ),
            )
        with self.lock:
            self.look = look
            self.state = "done"
            self.message = self._outcome = text
            self._looked = True

    # ------------------------------------------------------------------ the panel
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if self.state == "moving":
            return Step("moving", "The robot is moving: {stop} halts it.", frozenset({"stop", "cancel"}), clicks=False)
        if self.state == "looking":
            return Step("looking", "Looking for it in the video…", frozenset({"cancel"}), clicks=False)
        if self.state == "done":
            return Step("done", "{accept} closes; or click another place to move it again.", frozenset({"accept"}))
        if self.plan is not None and self.plan.ok:
            return Step(
                "preview",
                f"The ghosts show {self.obj.name} where it will stand and the robot there. "
                + "{move} sends it; click another place, or {cancel}.",
                frozenset({"move", "cancel", "stop"}),
            )
        return Step(
            "click",
            f"Click where {self.obj.name} should go, on the table.",
            frozenset({"cancel", "stop"}),
        )

    def marks(self) -> Marks:
        with self.lock:
            m = Marks(selected=self.obj.name)
            if self.place_X is not None and self.state not in ("done", "looking"):
                m.targets = self.camera.project(self.place_X[None])
            plan = self.plan
            if plan is not None and plan.ok:
                m.ghosts = [Ghost(self.obj.model, plan.T_world_obj_place, f"{self.obj.name} here", chosen=True)]
                m.robot_ghost = self.cell.link_breps(plan.q_release)
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {}
            plan = self.plan or self.sent
            if plan is not None:
                out["object"] = plan.name
                out["checked"] = "passed" if plan.ok else "refused"
                out["preview_s"] = plan.preview_s
            out.update(self.written)
            out.update(self.look)
            return out
