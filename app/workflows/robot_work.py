"""What the workflows that send the robot share: the site's robot, the live video (the robot is watched
moving, no frame frozen), the surface under a click, sending a checked plan, and Stop / Cancel that halt it."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from app.robot.controller import ControllerError

from .base import Workflow, WorkflowError, as_pixel

__all__ = ["RobotWork", "planned"]


def planned(plan: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """``plan(*args, **kwargs)``, one of the robot cell's planners; WorkflowError when the robot's controller does not
    answer (a planner starts from where the robot is: a robot not heard from is not planned for)."""
    try:
        return plan(*args, **kwargs)
    except ControllerError as exc:
        raise WorkflowError(f"{exc}: nothing was planned, the robot did not move") from None


class RobotWork(Workflow):
    """Base of Move robot and Pick and place (``cell``: the site's ``app.robot.cell.RobotCell``)."""

    needs_gripper = False

    @classmethod
    def available(cls, site) -> str:
        if site.robot is None:
            return "this site has no robot: give the scene a robot block (docs/robot.md)"
        if cls.needs_gripper and site.robot.finger is None:
            return "this site's robot has no gripper"
        return ""

    def __init__(self, site, client: str = "operator", view: str | None = None):
        super().__init__(site, client, view)
        if self.available(site):
            raise WorkflowError(self.available(site))
        self.cell = site.robot
        self.plan = None  # the plan previewed (app.robot.cell.MovePlan or PickPlan)
        self.sent = None  # the plan the robot was sent on

    def follows_live(self) -> str:
        return f"{self.title} watches the robot on the live video: nothing to freeze"

    def _moving(self) -> bool:
        """The controller says a motion is under way (one that stopped answering: not known to move)."""
        try:
            return bool(self.cell.state().moving)
        except ControllerError:
            return False

    def _surface_at(self, uv, busy: str):
        """(pixel, the database's first surface under it: ``RayHit``), the robot not at work (``busy`` says why it
        must not be); under the workflow's lock."""
        p = as_pixel(uv)
        self._check_open()
        if self._moving():
            raise WorkflowError(busy)
        origin, d = self._click_camera().rays(p.reshape(1, 2))
        hit = self.site.raycast(origin, d[0])
        if hit is None:
            raise WorkflowError(
                f"the pixel ({p[0]:.0f}, {p[1]:.0f}) sees no object of the database: click on an object or the table"
            )
        return p, hit

    def _send(self, what: str) -> None:
        """Send the previewed plan (under the lock); ``what`` names it when there is none."""
        self._check_open()
        if self.plan is None or not self.plan.ok:
            raise WorkflowError(what if self.plan is None else f"this motion was refused: {self.plan.reason}")
        try:
            self.cell.move(self.plan)
        except ControllerError as exc:
            raise WorkflowError(str(exc)) from None
        self.sent, self.plan = self.plan, None
        self.state = "moving"
        self.message = "Moving: Stop (Space) halts the robot at once."

    def cancel(self) -> None:
        """Esc: a moving robot is stopped (the workflow stays: Esc again closes it); else the workflow closes."""
        try:
            moving = self.cell.state().moving
        except ControllerError:
            self.cell.stop()  # not known: sent Stop all the same (a real robot's stop is its own circuit)
            moving = False
        if moving:
            self.stop()
            with self.lock:
                self.message += " Esc again closes."
            return
        super().cancel()
        with self.lock:
            self.message = "Cancelled: the robot is stopped; nothing was written."

    def stop(self) -> None:
        """Space: halt the robot at once (each workflow says what it stopped)."""
        raise NotImplementedError

    def tick(self) -> bool:
        """A previewed plan whose start is no longer where the robot stands (another operator moved it) is
        dropped, and said: Move would be refused, and the ghost and path no longer show what would happen."""
        with self.lock:
            plan = self.plan
            if plan is None or not plan.ok or self.state == "moving":
                return False
            try:
                s = self.cell.state()
            except ControllerError:
                return False
            if s.moving or np.max(np.abs(s.q - plan.path[0])) > 1e-3:
                self.plan = None
                self.message = (
                    "The robot moved since this motion was planned (another operator's motion): click the target "
                    "again to plan from where it stands."
                )
                return True
            return False

    def _idle_stop(self) -> None:
        """Space with the robot standing still: said, the last outcome kept."""
        self.message = f"The robot is not moving: nothing to stop. {self._outcome}".strip()

    _outcome = ""  # the last thing the workflow said of a motion (kept when Space is pressed idle)

    def _xyz(self, X: np.ndarray) -> str:
        return " ".join(f"{v:.3f}" for v in X)
