"""Move robot: video control of the robot. Click a target on the video; the robot's motion there is
planned, previewed as a ghost and checked against the database before anything moves; Move robot sends
it; Stop halts it at once.

The click's ray (through C) meets the database's first surface: the target point and its outward
normal. ``app.robot.cell.RobotCell.plan_approach`` plans the tool there, ``standoff`` off the surface
along the normal (the Standoff chooser; the operator sees the ghost move as they change it), and checks
every sample of the path against every database object with its margin and against the robot itself.
A refused motion names the object or the joint, and Move robot stays disabled. While the robot moves,
the overlay follows its joint states; Stop (Space) or Esc halts it where it is. When it stops, the
workflow says how far the tool is from the commanded pose (from the joints the controller reports),
or what went wrong (a joint that did not reach its command, a controller that stopped answering).
Nothing is written to the database: the robot moved nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from app.robot.controller import ControllerError
from core.transforms import log_so3

from .base import Control, Marks, Step, WorkflowError
from .robot_tour import ARRIVED_RAD
from .robot_work import RobotWork, planned

__all__ = ["MoveRobot", "STANDOFFS_MM"]

STANDOFFS_MM = (5, 10, 20, 50, 100)
DEFAULT_STANDOFF_MM = 20


class MoveRobot(RobotWork):
    name = "move_robot"
    title = "Move robot"
    actions = ("click", "set_standoff", "move", "stop", "accept", "cancel")
    controls = (
        Control("move", "Move robot", "M", color="green", hint="Send the robot along the previewed motion"),
        Control("stop", "Stop", "space", color="red", hint="Halt the robot at once, where it is"),
        Control("set_standoff", "Standoff", kind="choice", hint="How far the tool stops off the surface (mm)"),
        Control("accept", "Done", "enter", hint="Close (nothing is written)"),
        Control("cancel", "Cancel", "escape", color="red", hint="Stop the robot if it moves, and close"),
    )

    def __init__(self, site, client: str = "operator", view: str | None = None):
        super().__init__(site, client, view)
        self.standoff_mm = DEFAULT_STANDOFF_MM
        self.target: tuple[np.ndarray, np.ndarray, str, np.ndarray] | None = None  # (X, normal, object, uv)
        self.arrival: dict[str, Any] = {}
        self.state = "click"

    # ------------------------------------------------------------------ target and plan
    def click(self, uv) -> None:
        with self.lock:
            p, hit = self._surface_at(uv, "the robot is moving: Stop it (Space) before choosing another target")
            self.target = (np.asarray(hit.X_world, float), np.asarray(hit.normal, float), hit.name, p)
        self._replan()

    def set_standoff(self, value) -> None:
        try:
            mm = float(str(value).split()[0])
        except (ValueError, IndexError):
            raise WorkflowError(f"a standoff is a distance in mm, got {value!r}") from None
        if not (np.isfinite(mm) and 0 < mm <= 500):
            raise WorkflowError(f"a standoff is between 0 and 500 mm, got {mm:g}")
        with self.lock:
            self.standoff_mm = mm
        if self.target is not None and not self._moving():
            self._replan()

    def _replan(self) -> None:
        """Plan and check the motion to the target (outside the lock: the overlay keeps drawing)."""
        with self.lock:
            X, n, name, _ = self.target
            standoff = self.standoff_mm / 1000.0
            objects = self.site.objects()
        from app.robot.cell import obstacles_of

        plan = planned(self.cell.plan_approach, X, n, standoff, obstacles_of(objects))
        with self.lock:
            self.plan = plan
            self.arrival = {}
            where = f"{name} at {' '.join(f'{v:.3f}' for v in X)} m"
            if plan.ok:
                self.message = (
                    f"Target on {where}: the motion passes every check ({plan.samples_checked} poses checked against "
                    f"the database's {len(objects)} objects and itself, in {1000 * plan.preview_s:.0f} ms). What the "
                    "database lacks is not checked: look at the video before Move robot."
                )
            else:
                self.message = f"Target on {where}: refused: {plan.reason}. The robot did not move."
                if plan.q_contact is not None:
                    self.message += " The red robot shows where the path would hit."
            if plan.warnings:
                self.message += " " + "; ".join(plan.warnings) + "."

    # ------------------------------------------------------------------ motion
    def move(self) -> None:
        with self.lock:
            self._send("click a target on the video first")
            self.arrival = {}

    def stop(self) -> None:
        was_moving = self.state == "moving"
        self.cell.stop()
        with self.lock:
            if self.state == "moving":
                self._arrived()
            elif was_moving:  # the frame loop saw this Stop end the motion first, and said so
                self.message = self._outcome
            else:
                self._idle_stop()

    def accept(self) -> None:
        with self.lock:
            self._check_open()
            if self._moving():
                raise WorkflowError("the robot is moving: Stop it (Space) or wait for it to arrive")
            self.accepted = True
            self.state = "accepted"
            self.message = "Closed (nothing is written to the database)."

    def _arrived(self) -> None:
        """The motion ended: how far the tool is from the commanded pose, or what went wrong."""
        try:
            s = self.cell.state()
        except ControllerError as exc:
            self.cell.stop()  # the stop circuit: obeyed even when the controller's state cannot be read
            self.state = "fault"
            self.message = (
                f"{exc}. The robot was sent Stop; it may be anywhere on its way: look at the video before moving it "
                "again."
            )
            return
        T = self.cell.tool_pose(s.q)
        G = self.sent.T_world_goal
        dp = float(np.linalg.norm(T[:3, 3] - G[:3, 3]))
        dr = float(np.degrees(np.linalg.norm(log_so3(G[:3, :3].T @ T[:3, :3]))))
        self.arrival = {"tool_from_goal_mm": 1000 * dp, "tool_turn_from_goal_deg": dr}
        self.state = "click"
        if s.fault:
            self.message = f"Fault: {s.fault}. The tool is {1000 * dp:.1f} mm from the commanded pose."
        elif np.max(np.abs(s.q - self.sent.q_goal)) > ARRIVED_RAD:  # short of its goal: stopped (a Stop the frame
            # loop saw first, or this one); a Stop pressed once the robot stood at its goal stopped nothing
            self.message = f"Stopped: the tool is {1000 * dp:.1f} mm from the commanded pose. Click a new target."
        else:
            self.message = (
                f"Arrived: the tool is {1000 * dp:.1f} mm and {dr:.2f}° from the commanded pose (from the joints "
                "the controller reports). Click another target, or Done."
            )
        if not s.fault and self.site.robot_base_nominal:  # the joints say where the tool is from the base only
            self.message += (
                " The robot's base is not calibrated: in the world, and in the video, the tool can be centimetres "
                "from its target (Calibrate robot)."
            )
        self._outcome = self.message

    def tick(self) -> bool:
        """The robot's motion, followed at the interface's frame rate: its end noticed (and said); a plan another
        operator's motion made stale, dropped (``RobotWork.tick``)."""
        with self.lock:
            if self.state != "moving":
                return super().tick()
            if not self._moving():
                self._arrived()
            return True

    # ------------------------------------------------------------------ the panel
    def question(self, action: str, *args: Any) -> str:
        """Move with the robot's base not calibrated (the drawing's pose) is asked once more, saying why."""
        why = self.site.robot_base_warning() if action == "move" else ""
        return f"{why}, or move it anyway." if why else super().question(action, *args)

    def choices(self, action: str) -> list[tuple[str, Any]]:
        if action == "set_standoff":
            return [(f"{mm} mm", mm) for mm in STANDOFFS_MM]
        return []

    def choice_value(self, action: str) -> Any:
        return self.standoff_mm if action == "set_standoff" else None

    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        if self.state == "moving":
            return Step("moving", "The robot is moving: {stop} halts it.", frozenset({"stop", "cancel"}), clicks=False)
        if self.plan is not None and self.plan.ok:
            return Step(
                "preview",
                "The ghost shows where the robot will go. {move} sends it; change the {set_standoff}, click another "
                "target, or {accept}.",
                frozenset({"move", "set_standoff", "accept", "cancel", "stop"}),
            )
        return Step(
            "click",
            "Click the target on an object or the table in the video; the {set_standoff} is how far the tool stops "
            "off it. {accept} closes.",
            frozenset({"set_standoff", "accept", "cancel", "stop"}),
        )

    def marks(self) -> Marks:
        with self.lock:
            m = Marks()
            cam = self.camera
            if self.target is not None:
                m.targets = cam.project(self.target[0][None])
                m.labels = [(m.targets[0], "target")]
            plan = self.plan
            if plan is not None and not plan.ok and plan.q_contact is not None:
                m.robot_contact = self.cell.link_breps(plan.q_contact)  # red: where the refused path would hit
            if plan is not None and plan.ok:
                m.robot_ghost = self.cell.link_breps(plan.q_goal)
                tips = np.array([self.cell.tool_pose(q)[:3, 3] for q in plan.path[:: max(1, len(plan.path) // 40)]])
                tips = np.vstack([tips, plan.T_world_goal[:3, 3]])
                if np.all(cam.depth(tips) > 0):
                    uv = cam.project(tips)
                    m.robot_path = np.stack([uv[:-1], uv[1:]], axis=1)
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {"standoff_mm": float(self.standoff_mm)}
            plan = self.plan or self.sent
            if plan is not None:
                out["target"] = self.target[2] if self.target else ""
                out["x y z (m)"] = " ".join(f"{v:.4f}" for v in plan.target_X)
                out["checked"] = "passed" if plan.ok else "refused"
                out["preview_s"] = plan.preview_s
            out.update(self.arrival)
            return out
