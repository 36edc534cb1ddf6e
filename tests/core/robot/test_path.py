"""Joint paths: no point of any link moves more than the step between samples."""

import numpy as np
import pytest

from core.robot import joint_path, lever_arms, step_bound_m
from tests.core.robot.arms import link_points, planar_2r, random_q, ur_like


@pytest.mark.parametrize("make", [ur_like, planar_2r], ids=["ur_like", "planar"])
def test_no_link_point_moves_more_than_the_step(make):
    m = make()
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(8):
        q0, q1 = random_q(m, rng), random_q(m, rng)
        step = 0.01
        Q = joint_path(m, q0, q1, step)
        assert Q.shape[1] == m.n and len(Q) >= 2
        np.testing.assert_allclose(Q[0], q0)
        np.testing.assert_allclose(Q[-1], q1)
        # the samples and 4 more between each pair: a point's chord between samples is at most its arc
        fine = joint_path(m, q0, q1, step / 5)
        P = link_points(m, Q)
        moved = np.linalg.norm(np.diff(P, axis=0), axis=2).max()
        assert moved <= step
        F = link_points(m, fine)
        arc = np.linalg.norm(np.diff(F, axis=0), axis=2).sum(axis=0).max()  # longest path of a point
        assert arc <= step_bound_m(m, q0, q1) + 1e-12
        worst = max(worst, moved / step)
    assert worst > 0.2  # the bound is not wildly loose: the sampling is not 5× finer than it needs


def test_lever_arms_bound_a_single_joint_turn():
    m = ur_like()
    C = lever_arms(m)
    assert C.shape == (len(m.links), m.n)
    R = C.max(axis=0)
    assert np.all(R > 0)
    assert R[-1] == pytest.approx(1.0)  # each finger slides with the joint (its mimic twin the other way)
    assert R[0] > R[1] > R[3] > R[5]
    assert not C[m.links.index("base_link")].any()  # nothing moves the base


def test_a_still_path_is_its_two_ends():
    m = planar_2r()
    Q = joint_path(m, [0.1, 0.2], [0.1, 0.2], 0.01)
    assert Q.shape == (2, 2)


def test_bad_steps_are_refused():
    m = planar_2r()
    with pytest.raises(ValueError, match="max_step_m"):
        joint_path(m, [0, 0], [1, 1], 0.0)
    with pytest.raises(ValueError, match="q1"):
        joint_path(m, [0, 0], [1, 1, 1], 0.01)


def test_pair_lever_arms_bound_the_change_of_distance_between_two_links():
    from core.robot import pair_lever_arms

    m = ur_like()
    lever = pair_lever_arms(m, "wrist_1_link", "gripper_link")
    assert np.all(lever[:4] == 0)  # pan, lift, elbow, wrist 1 move both together
    assert lever[4] > 0 and lever[5] > 0
    rng = np.random.default_rng(3)
    names = [name for name, _, _ in m.link_breps(np.zeros(m.n))]
    ia, ib = names.index("wrist_1_link"), names.index("gripper_link")
    for _ in range(20):
        q0, q1 = random_q(m, rng), random_q(m, rng)
        A0, B0 = (b.support_points(16) @ T[:3, :3].T + T[:3, 3] for _, b, T in [m.link_breps(q0)[i] for i in (ia, ib)])
        A1, B1 = (b.support_points(16) @ T[:3, :3].T + T[:3, 3] for _, b, T in [m.link_breps(q1)[i] for i in (ia, ib)])
        d0 = np.linalg.norm(A0[:, None] - B0[None], axis=2)
        d1 = np.linalg.norm(A1[:, None] - B1[None], axis=2)
        assert np.abs(d1 - d0).max() <= lever @ np.abs(q1 - q0) + 1e-12
