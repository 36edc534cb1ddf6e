"""The emulated joint controller: paths followed in time, stops, and the faults of a real robot."""

import time

import numpy as np
import pytest

from app.robot.controller import ControllerError, ControllerFaults, ControllerSilent, EmulatedController

NAMES = ("a", "b", "c")
LIM = np.radians([170.0, 170.0, 170.0])


class Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def _controller(clock, **kw):
    return EmulatedController(NAMES, -LIM, LIM, np.radians([90.0, 45.0, 90.0]), np.zeros(3), clock=clock, **kw)


def _settle(ctl):
    """Let the controller's thread run one update at the clock's present."""
    time.sleep(0.1)
    return ctl.state()


def test_path_followed_at_the_slowest_joint_speed_and_ends_at_its_goal():
    clock = Clock()
    ctl = _controller(clock, speed_scale=1.0)
    seen = []
    ctl.add_listener(seen.append)
    try:
        goal = np.radians([45.0, 45.0, 0.0])  # joint b at 45°/s is the slowest: 1 s
        ctl.move(goal[None])
        clock.t += 0.5
        s = _settle(ctl)
        assert s.moving and np.allclose(s.q, goal / 2, atol=1e-9)
        clock.t += 0.6
        assert ctl.wait_idle(2.0)
        s = ctl.state()
        assert not s.moving and np.allclose(s.q, goal) and s.fault is None
        assert any(x.moving for x in seen) and not seen[-1].moving
    finally:
        ctl.close()


def test_stop_halts_where_the_robot_is_and_a_second_move_while_moving_is_refused():
    clock = Clock()
    ctl = _controller(clock, speed_scale=1.0)
    try:
        ctl.move(np.radians([[90.0, 0.0, 0.0]]))
        with pytest.raises(ControllerError, match="moving"):
            ctl.move(np.radians([[0.0, 10.0, 0.0]]))
        clock.t += 0.25
        ctl.stop()
        s = ctl.state()
        assert not s.moving and np.degrees(s.q[0]) == pytest.approx(22.5, abs=1e-6)
        clock.t += 5.0
        assert np.degrees(_settle(ctl).q[0]) == pytest.approx(22.5, abs=1e-6)  # it stays stopped
    finally:
        ctl.close()


def test_waypoints_outside_the_limits_or_not_finite_are_refused_naming_the_joint():
    ctl = _controller(Clock())
    try:
        with pytest.raises(ControllerError, match="joint b .* outside its limits"):
            ctl.move(np.radians([[0.0, 175.0, 0.0]]))
        with pytest.raises(ControllerError, match="finite"):
            ctl.move(np.array([[0.0, np.nan, 0.0]]))
        with pytest.raises(ControllerError, match="3 joints"):
            ctl.move(np.zeros((2, 4)))
        assert not ctl.state().moving and np.allclose(ctl.state().q, 0)
    finally:
        ctl.close()


def test_a_stalled_joint_is_reported_and_the_state_says_where_it_stopped():
    clock = Clock()
    ctl = _controller(clock, speed_scale=1.0, faults=ControllerFaults(stall_joint="c", stall_at=0.5))
    try:
        ctl.move(np.radians([[0.0, 0.0, 60.0]]))
        clock.t += 2.0
        assert ctl.wait_idle(2.0)
        s = ctl.state()
        assert np.degrees(s.q[2]) == pytest.approx(30.0, abs=1e-6)
        assert "joint c did not reach its command" in s.fault and "up to 30.0° short" in s.fault
    finally:
        ctl.close()


def test_a_silent_controller_raises_on_every_call_but_obeys_stop():
    clock = Clock()
    faults = ControllerFaults()
    ctl = _controller(clock, faults=faults)
    try:
        ctl.move(np.radians([[10.0, 0.0, 0.0]]))
        faults.silent = True
        with pytest.raises(ControllerSilent, match="does not answer"):
            ctl.state()
        with pytest.raises(ControllerSilent):
            ctl.move(np.zeros((1, 3)))
        ctl.stop()
        faults.silent = False
        assert not ctl.state().moving
    finally:
        ctl.close()
