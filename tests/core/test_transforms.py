import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from core.transforms import (
    check_T,
    exp_so3,
    invert_T,
    log_so3,
    make_T,
    orthonormalize,
    pose_error,
    random_rotation,
    rot_x,
    rot_y,
    rot_z,
    rotation_angle,
    skew,
    transform_points,
)

vec3 = st.lists(st.floats(-3.0, 3.0, allow_nan=False), min_size=3, max_size=3).map(np.array)


def test_skew_is_cross_product():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 3))
    np.testing.assert_allclose(skew(a) @ b, np.cross(a, b), atol=1e-15)


@given(vec3)
def test_exp_log_round_trip(r):
    theta = np.linalg.norm(r)
    if theta > np.pi - 1e-3:  # log returns the angle in [0, π]
        r = r / theta * (np.pi - 1e-3)
    R = exp_so3(r)
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(log_so3(R), r, atol=1e-9)


@pytest.mark.parametrize("angle", [0.0, 1e-9, 1e-4, 1.0, np.pi - 1e-6, np.pi])
def test_log_near_singularities(angle):
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    R = exp_so3(angle * axis)
    np.testing.assert_allclose(exp_so3(log_so3(R)), R, atol=1e-7)
    assert np.linalg.norm(log_so3(R)) == pytest.approx(angle, abs=1e-7)


def test_elementary_rotations_are_right_handed():
    np.testing.assert_allclose(rot_z(np.pi / 2) @ [1, 0, 0], [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(rot_x(np.pi / 2) @ [0, 1, 0], [0, 0, 1], atol=1e-15)
    np.testing.assert_allclose(rot_y(np.pi / 2) @ [0, 0, 1], [1, 0, 0], atol=1e-15)


def test_invert_and_compose_cancel_inner_frames():
    rng = np.random.default_rng(0)
    T_a_b = make_T(random_rotation(rng), rng.normal(size=3))
    T_b_c = make_T(random_rotation(rng), rng.normal(size=3))
    X_c = rng.normal(size=(5, 3))
    np.testing.assert_allclose(invert_T(T_a_b) @ T_a_b, np.eye(4), atol=1e-12)
    np.testing.assert_allclose(
        transform_points(T_a_b @ T_b_c, X_c), transform_points(T_a_b, transform_points(T_b_c, X_c)), atol=1e-12
    )


def test_rotation_angle_and_pose_error():
    R = rot_z(0.3)
    assert rotation_angle(np.eye(3), R) == pytest.approx(0.3)
    # Accurate for tiny angles and up to π (arccos of the trace alone saturates near 1e-8 rad).
    for angle in (1e-12, 1e-9, 1e-6, np.pi - 1e-9, np.pi):
        assert rotation_angle(np.eye(3), exp_so3(angle * np.array([0.6, 0.0, 0.8]))) == pytest.approx(
            angle, rel=1e-6, abs=1e-15
        )
    deg, m = pose_error(make_T(R, [1, 2, 3]), make_T(np.eye(3), [1, 2, 3.5]))
    assert deg == pytest.approx(np.degrees(0.3))
    assert m == pytest.approx(0.5)


def test_random_rotation_is_uniformish():
    rng = np.random.default_rng(1)
    Rs = np.array([random_rotation(rng) for _ in range(4000)])
    # For a uniform rotation the mean of each matrix entry is 0.
    assert np.abs(Rs.mean(axis=0)).max() < 0.05
    np.testing.assert_allclose(np.linalg.det(Rs), 1.0, atol=1e-12)


def test_orthonormalize_projects_to_SO3():
    rng = np.random.default_rng(2)
    R = random_rotation(rng) + 1e-3 * rng.normal(size=(3, 3))
    Q = orthonormalize(R)
    np.testing.assert_allclose(Q.T @ Q, np.eye(3), atol=1e-12)
    assert np.linalg.det(Q) == pytest.approx(1.0)


def test_check_T_rejects_bad_transforms():
    with pytest.raises(ValueError, match="shape"):
        check_T(np.eye(3))
    with pytest.raises(ValueError, match="NaN"):
        check_T(np.full((4, 4), np.nan))
    bad = np.eye(4)
    bad[0, 0] = -1.0
    with pytest.raises(ValueError, match="proper rotation"):
        check_T(bad)
    bad = np.eye(4)
    bad[3, 0] = 1.0
    with pytest.raises(ValueError, match="last row"):
        check_T(bad)
