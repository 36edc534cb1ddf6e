"""The robot sent through a calibration's preset joint configurations, one at a time, each motion checked.

A calibration workflow (Calibrate robot, Calibrate camera from robot) composes a ``RobotTour``: ``go()``
plans the motion to the next pose with the cell's machinery (``RobotCell.plan_joints``: the straight
joint path, else through home, every sample checked against every database object with its margin and
against the robot itself) and sends it; ``tick()`` follows it at the interface's frame rate and notices
its end: arrived (the joints within ``ARRIVED_RAD`` of the pose), stopped short (Stop), or a fault the
controller reports. Once arrived, the video is given two new frames and ``SETTLE_S`` of scene time, so that
the newest frame shows the robot at rest (a frame is drawn from the site's state when its rendering starts,
and under load that can be a good fraction of a second before it arrives: the frame that arrives just after
the robot stopped may show it moving); then the state is "at" and the workflow takes a frozen frame (the
panel freezes the newest when ``follows_live`` says nothing). ``q`` is the pose's joints as the controller
reported them on arrival: what the calibration computes the robot's shapes from.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from app.robot.controller import ControllerError

from .base import Control, Step, Workflow, WorkflowError
from .robot_work import planned

__all__ = ["RobotTour", "TourWorkflow", "ARRIVED_RAD", "SETTLE_S"]

ARRIVED_RAD = 2e-3  # a joint this near its pose has arrived (the emulated controller's are exact)
SETTLE_S = 0.4  # scene time given to the video after arrival before a frame is frozen


class RobotTour:
    """The poses ``qs`` (k, n) visited in order by the site's robot (module docstring).

    index : the pose the robot is at or going to (−1 before the first). state : "idle" (not at a pose),
    "moving", "settling" (arrived, waiting for the video), "at" (settled at pose ``index``), "skipped" (pose
    ``index`` left out). arrived : {pose index: the joints (n,) reported on arrival}. refused : the pose whose
    motion was refused last (None once a motion is sent): the operator may leave it out (``skip``).
    """

    def __init__(self, site, qs: np.ndarray, what: str):
        self.site = site
        self.cell = site.robot
        self.qs = np.asarray(qs, float).reshape(-1, self.cell.model.n)
        self.what = what  # "base" or "camera": which of the scene's calibration poses, in messages
        self.index = -1
        self.state = "idle"
        self.arrived: dict[int, np.ndarray] = {}
        self.refused: int | None = None
        self.skipped: list[int] = []
        self._frame_times: list[float] = []
        self._seen_at = 0.0  # when the arrival was seen (unix seconds): a frozen frame is one taken after it
        spec = getattr(site.scene, "robot", None)
        self.home = spec.home_q(self.cell.model) if spec is not None else None

    @property
    def n(self) -> int:
        return len(self.qs)

    @property
    def next_index(self) -> int | None:
        """The pose Go sends the robot to (None after the last)."""
        k = self.index + 1 if self.state in ("at", "settling", "skipped") or self.index < 0 else self.index
        return k if k < self.n else None

    @property
    def at(self) -> int | None:
        """The pose the robot is settled at, None when it is not at one."""
        return self.index if self.state == "at" else None

    def moving(self) -> bool:
        """The controller says a motion is under way (one that stopped answering: not known to move)."""
        try:
            return bool(self.cell.state().moving)
        except ControllerError:
            return False

    def go(self) -> str:
        """Plan and send the motion to the next pose; what to tell the operator. WorkflowError (nothing moves)
        when there is none left, the robot moves, or the motion is refused."""
        from app.robot.cell import obstacles_of

        k = self.next_index
        if k is None:
            out = f" ({len(self.skipped)} left out)" if self.skipped else ""
            raise WorkflowError(f"no calibration pose is left of {self.n}{out}: Solve, or Cancel")
        if self.moving():
            raise WorkflowError("the robot is moving: Stop it (Space) or wait for it to stop")
        via = [] if self.home is None else [self.home]
        plan = planned(self.cell.plan_joints, self.qs[k], obstacles_of(self.site.objects()), via=via)
        if not plan.ok:
            self.refused = k
            raise WorkflowError(
                f"the motion to pose {k + 1} was refused: {plan.reason}. The robot did not move; Skip pose (K) "
                "leaves this pose out"
            )
        try:
            self.cell.move(plan)
        except ControllerError as exc:
            raise WorkflowError(str(exc)) from None
        self.index, self.state, self.refused = k, "moving", None
        said = f" ({'; '.join(plan.warnings)})" if plan.warnings else ""
        return (
            f"Moving to pose {k + 1} of {self.n} (its path checked: {plan.samples_checked} poses{said}): Stop "
            "(Space) halts it."
        )

    def skip(self) -> str:
        """Leave out the pose whose motion was refused (the robot stays where it is); what to tell the operator.
        WorkflowError when no motion to the next pose was refused."""
        k = self.next_index
        if k is None or self.refused != k:
            raise WorkflowError("only a pose whose motion was refused can be left out: Next pose (G) tries it first")
        self.index, self.state, self.refused = k, "skipped", None
        self.skipped.append(k)
        nxt = self.next_index
        then = f"Next pose (G) sends the robot to pose {nxt + 1}" if nxt is not None else "it was the last: Solve"
        return f"Pose {k + 1} of {self.n} left out: {then}."

    def stop(self) -> None:
        self.cell.stop()

    def tick(self) -> str | None:
        """Follow the motion; what to tell the operator when something changed (its end, or the video caught
        up: the frame can be frozen), else None."""
        if self.state == "moving" and not self.moving():
            return self._ended()
        if self.state == "settling":
            t = self.site.time_s()
            if t != self._frame_times[-1]:
                self._frame_times.append(t)
            # two new frames since the arrival (the second was rendered after the first arrived, itself after the
            # arrival was seen: a frame rendering while the robot moved is not the one frozen), and SETTLE_S; and a
            # frame taken after the arrival by its own stamp (a real camera's transport lags its images)
            frame = self.site.latest_frame()
            stamp = None if frame is None else getattr(frame, "stamp", None)
            taken_after = stamp is None or stamp >= self._seen_at
            settled = len(self._frame_times) >= 3 and (t - self._frame_times[0] >= SETTLE_S or t < self._frame_times[0])
            if settled and taken_after:
                self.state = "at"
                return ""
        return None

    def _ended(self) -> str:
        k = self.index
        try:
            s = self.cell.state()
        except ControllerError as exc:
            self.state = "idle"
            return f"{exc}. Look at the video, then Go again."
        off = float(np.max(np.abs(s.q - self.qs[k])))
        if s.fault or off > ARRIVED_RAD:
            self.state = "idle"
            why = f"fault: {s.fault}" if s.fault else f"stopped {np.degrees(off):.1f}° short of it"
            return f"The robot did not reach pose {k + 1} ({why}): Go sends it there again."
        self.arrived[k] = np.asarray(s.q, float).copy()
        self.state = "settling"
        self._frame_times = [self.site.time_s()]  # the video's time at the arrival, then each new frame's
        self._seen_at = time.time()
        return f"At pose {k + 1} of {self.n}."

    def follows_live(self) -> str:
        """Why the workflow shows the live video now ("" once the robot is settled at a pose)."""
        if self.state == "at":
            return ""
        if self.state == "moving":
            return f"the robot is moving to pose {self.index + 1}: the frame is frozen once it is there"
        if self.state == "settling":
            return "the robot has arrived: the frame is frozen in a moment"
        return "the robot is not at a calibration pose yet: Go sends it to the next one"


def tour_poses(site, which: str) -> np.ndarray:
    """The scene's calibration poses (k, n) of ``which`` ("base" or "camera"); (0, 0) without a robot."""
    spec = getattr(site.scene, "robot", None)
    if spec is None or site.robot is None:
        return np.zeros((0, 0))
    return spec.calibration_qs(site.robot.model, which)


def tour_unavailable(site, which: str, what: str) -> str:
    """Why a calibration tour of ``which`` cannot run on ``site`` ("" when it can); ``what`` names its poses."""
    if site.robot is None:
        return "this site has no robot: give the scene a robot block (docs/robot.md)"
    if not tour_poses(site, which).size:
        return f"the scene gives the robot no {what} (robot.calibration_{which}_deg)"
    return ""


def start_tour(wf, which: str, snap: bool, sigma_px) -> None:
    """What both calibration tours set up: the robot, the poses' tour, the snapper, the clicks' σ (pixels)."""
    from .snapping import Snapper

    why = tour_unavailable(wf.site, which, wf.poses_named)
    if why:
        raise WorkflowError(why)
    if not sigma_px > 0:
        raise WorkflowError(f"sigma_px (the clicks' noise, pixels) must be positive, got {sigma_px}")
    wf.sigma_px = float(sigma_px)
    wf.cell = wf.site.robot
    wf.model = wf.cell.model
    wf.tour = RobotTour(wf.site, tour_poses(wf.site, which), which)
    wf.snapper = Snapper(wf, snap)


class TourWorkflow(Workflow):
    """What both calibration tours do with the robot (``tour``, a RobotTour, made by ``start_tour``): Next pose sends
    it (``go``, refused while ``_busy()`` says why), Stop halts it, ``tick`` follows it (``state`` becomes
    ``at_state`` once it is settled at a pose), the frame frozen there is that pose's (``frames``), and Cancel stops
    a moving robot first; ``_tour_step()`` is the panel's step while it moves or settles (None otherwise)."""

    at_state = "click"
    which = "base"  # the scene's calibration poses it visits: "base" or "camera"
    poses_named = "calibration poses"  # what the scene must give, in the refusal when it does not
    GO = Control(
        "go", "Next pose", "G", color="blue", hint="Send the robot to the next calibration pose (checked first)"
    )
    STOP = Control("stop", "Stop", "space", color="red", hint="Halt the robot at once, where it is")
    SKIP = Control("skip", "Skip pose", "K", hint="Leave out the pose whose motion was refused: Next pose goes on")

    @classmethod
    def available(cls, site) -> str:
        return tour_unavailable(site, cls.which, cls.poses_named)

    def __init__(self, site, client: str = "operator", view: str | None = None, snap: bool = True, sigma_px=1.0):
        super().__init__(site, client, view)
        start_tour(self, self.which, snap, sigma_px)
        self.frames: dict[int, Any] = {}  # pose → the frame its clicks were made on
        self.state = "go"

    def _busy(self) -> str:
        """Why Next pose must wait ("" when it need not): work under way at this pose."""
        return ""

    def go(self) -> None:
        """Send the robot to the next pose."""
        with self.lock:
            self._check_open()
            busy = self._busy()
            if busy:
                raise WorkflowError(busy)
            self.message = self.tour.go()
            self.state = "moving"

    def skip(self) -> None:
        """Leave out the next pose, whose motion was refused."""
        with self.lock:
            self._check_open()
            self.message = self.tour.skip()
            self.state = "go"

    def stop(self) -> None:
        self.tour.stop()

    def _tour_controls(self, has: set[str], ready: bool) -> set[str]:
        """``has`` with Next pose when the tour has a next pose and the workflow is ``ready`` for it, and Skip pose
        when that pose's motion was refused."""
        t = self.tour
        if ready and t.next_index is not None:
            has = has | {"go"} | ({"skip"} if t.refused == t.next_index else set())
        return has

    def tick(self) -> bool:
        with self.lock:
            if self.finished:
                return False
            said = self.tour.tick()
            if said is None:
                return False
            if said:
                self.message = said
            self.state = (
                self.at_state if self.tour.at is not None else ("moving" if self.tour.state == "moving" else "go")
            )
            return True

    def follows_live(self) -> str:
        return self.tour.follows_live()

    def use_frame(self, frame) -> None:
        super().use_frame(frame)
        with self.lock:
            if frame is not None and self.tour.at is not None:
                self.frames[self.tour.at] = frame

    def cancel(self) -> None:
        if self.tour.moving():
            self.tour.stop()
        super().cancel()

    def _tour_step(self) -> Step | None:
        t = self.tour
        if t.state == "moving":
            return Step(
                "moving",
                f"The robot is moving to pose {t.index + 1}: {{stop}} halts it.",
                frozenset({"stop", "cancel"}),
                False,
            )
        if t.state == "settling":
            return Step(
                "settling",
                f"The robot is at pose {t.index + 1}: its frame is frozen in a moment.",
                frozenset({"stop", "cancel"}),
                False,
            )
        return None
