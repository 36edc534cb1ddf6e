"""Inverse kinematics: round trips on random reachable poses, limits held, the solution nearest q0,
unreachable targets refused with the reason."""

import numpy as np
import pytest

from core.robot import reach_m, solve_ik
from core.transforms import make_T, rotation_angle
from tests.core.robot.arms import PI, planar_2r, random_q, ur_like

HOME = np.array([0, -PI / 2, PI / 2, -PI / 2, -PI / 2, 0, 0.02])


def test_round_trips_on_random_reachable_poses():
    m = ur_like()
    rng = np.random.default_rng(0)
    for _ in range(40):
        T = m.tool_pose(random_q(m, rng))
        r = solve_ik(m, T, HOME)
        assert r.ok, r.reason
        got = m.tool_pose(r.q)
        assert np.linalg.norm(got[:3, 3] - T[:3, 3]) < 1e-4
        assert rotation_angle(got[:3, :3], T[:3, :3]) < 1e-3
        assert r.position_error_m < 1e-4 and r.rotation_error_rad < 1e-3
        assert m.within_limits(r.q) is None
        assert r.q[-1] == HOME[-1]  # the fingers do not move the tool: left as they were


def test_the_solution_nearest_q0_is_preferred():
    m = ur_like()
    rng = np.random.default_rng(1)
    for _ in range(10):
        q_true = random_q(m, rng)
        q0 = q_true + rng.normal(0, 0.05, m.n)
        q0[-1] = q_true[-1]
        r = solve_ik(m, m.tool_pose(q_true), q0)
        assert r.ok
        np.testing.assert_allclose(r.q, q_true, atol=1e-3)  # the same branch, not one of the 7 others


def test_a_whole_turn_nearer_q0_is_taken_when_the_limits_allow():
    m = ur_like()
    q_true = np.array([-0.5, -1.0, 1.0, -1.2, 0.8, 0.3, 0.02])
    q0 = q_true.copy()
    q0[0] += 2 * PI - 0.02  # the pan one turn (less a little) away: ±2π limits hold both
    r = solve_ik(m, m.tool_pose(q_true), q0)
    assert r.ok and abs(r.q[0] - (q_true[0] + 2 * PI)) < 1e-3


def test_limits_are_respected_when_another_branch_exists():
    m = ur_like(elbow_joint=(0.0, PI))  # elbow one side only
    rng = np.random.default_rng(2)
    for _ in range(10):
        q = random_q(m, rng)
        r = solve_ik(m, m.tool_pose(q), HOME)
        assert r.ok, r.reason
        assert m.within_limits(r.q) is None and r.q[2] >= 0


def test_a_target_beyond_a_joint_limit_is_refused_naming_the_joint():
    m = ur_like(shoulder_pan_joint=(-0.5, 0.5))
    q = HOME.copy()
    q[0] = 1.5  # the arm turned to a side its pan cannot reach
    T = m.tool_pose(q)
    r = solve_ik(m, T, HOME)
    assert not r.ok
    assert r.reason.startswith("joint limits") and "shoulder_pan_joint" in r.reason
    assert m.within_limits(r.q) is None  # the pose returned is within the limits


def test_a_target_too_far_is_refused_as_out_of_reach():
    m = ur_like()
    origin, reach = reach_m(m)
    assert 1.0 < reach < 1.5
    T = make_T(np.eye(3), origin + [reach + 0.1, 0, 0])
    r = solve_ik(m, T, HOME)
    assert not r.ok and r.reason.startswith("out of reach") and f"{reach:.3f} m" in r.reason


def test_an_orientation_the_arm_cannot_take_is_out_of_reach():
    m = planar_2r()
    T = make_T(np.eye(3), [0.4, 0.2, 0.05])  # off the arm's plane
    r = solve_ik(m, T, [0.1, 0.1])
    assert not r.ok and r.reason.startswith("out of reach")
    assert r.position_error_m >= 0.05 - 1e-9
    # how near counts as reached is said: "0.7 mm off" alone read as reached to a new operator
    assert r.reason.endswith("off the target (a target is reached within 0.01 mm and 0.006°)"), r.reason


def test_planar_round_trip_from_the_other_elbow():
    """Position and heading fix a 2R arm's joints: found from a start on the other elbow branch."""
    m = planar_2r()
    T = m.tool_pose([0.4, 0.9])
    r = solve_ik(m, T, [1.3, -0.9])
    assert r.ok
    np.testing.assert_allclose(r.q, [0.4, 0.9], atol=1e-4)


def test_bad_targets_are_refused():
    m = ur_like()
    with pytest.raises(ValueError, match="T_base_target"):
        solve_ik(m, np.eye(3), HOME)
    with pytest.raises(ValueError, match="q0"):
        solve_ik(m, np.eye(4), HOME[:3])


def test_the_other_solutions_reach_the_target_and_come_after_by_travel():
    from core.robot import lever_arms

    m = ur_like()
    T = m.tool_pose(np.array([0.4, -1.1, 1.3, -1.5, -1.2, 0.6, 0.02]))
    r = solve_ik(m, T, HOME, seeds=24)
    assert r.ok and len(r.alternatives) >= 2 and r.alternatives.shape[1] == m.n
    C = lever_arms(m)
    travel = [float((C @ np.abs(q - HOME)).max()) for q in [r.q, *r.alternatives]]
    assert travel == sorted(travel)
    for q in r.alternatives:
        got = m.tool_pose(q)
        assert np.linalg.norm(got[:3, 3] - T[:3, 3]) < 1e-4 and rotation_angle(got[:3, :3], T[:3, :3]) < 1e-3
        assert m.within_limits(q) is None
