"""core.point_line_pose: the tracker's robust point-to-projected-line pose step."""

import numpy as np
import pytest

from core.brep import BRep
from core.camera import Camera
from core.point_line_pose import point_line_residuals, refine_point_to_line, robust_weights
from core.transforms import exp_so3, make_T, pose_error, random_rotation

K = np.array([[500.0, 0.0, 320.0], [0.0, 500.0, 240.0], [0.0, 0.0, 1.0]])


def _camera():
    return Camera.from_intrinsics(K, np.eye(4), 640, 480)


def _samples(rng, T_true, camera, per_edge=8):
    """Points on every edge of a box, with their exact images slid along the projected edges."""
    box = BRep.box(0.2, 0.12, 0.08)
    S = box.edge_segments()
    lam = rng.uniform(0.05, 0.95, (len(S), per_edge))
    X = (S[:, None, 0] + lam[..., None] * (S[:, None, 1] - S[:, None, 0])).reshape(-1, 3)
    D = np.repeat(S[:, 1] - S[:, 0], per_edge, axis=0)
    # The measured point is another point of the same edge: only the across-edge distance counts.
    lam2 = np.clip(lam + rng.uniform(-0.04, 0.04, lam.shape), 0, 1)
    Y = (S[:, None, 0] + lam2[..., None] * (S[:, None, 1] - S[:, None, 0])).reshape(-1, 3)
    uv = camera.project_obj(T_true, Y)
    return X, D, uv


def _true_pose(rng):
    return make_T(random_rotation(rng), [rng.uniform(-0.1, 0.1), rng.uniform(-0.1, 0.1), rng.uniform(0.8, 1.2)])


def test_converges_to_the_exact_pose_from_a_small_motion():
    rng = np.random.default_rng(0)
    cam = _camera()
    for _ in range(5):
        T_true = _true_pose(rng)
        X, D, uv = _samples(rng, T_true, cam)
        axis = rng.normal(size=3)
        T0 = make_T(
            exp_so3(np.radians(5.0) * axis / np.linalg.norm(axis)) @ T_true[:3, :3],
            T_true[:3, 3] + [0.01, -0.015, 0.02],
        )
        fit = refine_point_to_line(cam, T0, X, D, uv, loss="l2", max_iter=20, tol_px=1e-10)
        rot_deg, trans_m = pose_error(fit.T_world_obj, T_true)
        assert rot_deg < 1e-7 and trans_m < 1e-9
        assert np.max(np.abs(fit.residuals_px)) < 1e-6
        assert fit.converged
        assert (
            fit.T_world_obj.shape == (4, 4) and fit.residuals_px.shape == (len(X),) and fit.weights.shape == (len(X),)
        )
        assert fit.cov.shape == (6, 6) and np.allclose(fit.cov, fit.cov.T)


def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(1)
    cam = _camera()
    T = _true_pose(rng)
    X, D, uv = _samples(rng, T, cam)
    uv = uv + rng.normal(0, 2.0, uv.shape)
    r, J, n = point_line_residuals(cam, T, X, D, uv)
    assert r.shape == (len(X),) and J.shape == (len(X), 6) and n.shape == (len(X), 2)
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    eps = 1e-7
    for k in range(6):
        d = np.zeros(6)
        d[k] = eps
        Tk = make_T(exp_so3(d[3:]) @ T[:3, :3], T[:3, 3] + d[:3])
        # hold the normals fixed, as the Gauss–Newton step does
        proj = cam.project_obj(Tk, X)
        rk = np.einsum("ij,ij->i", n, uv - proj)
        assert np.allclose((rk - r) / eps, J[:, k], rtol=1e-4, atol=1e-3)


def test_residual_is_the_distance_to_the_projected_edge_line():
    cam = _camera()
    T = make_T(np.eye(3), [0.0, 0.0, 1.0])
    X = np.array([[0.0, 0.0, 0.0]] * 6)
    D = np.array([[1.0, 0.0, 0.0]] * 6)  # projects to a horizontal line through (320, 240)
    uv = np.array([[300.0, 243.0], [350.0, 240.0], [0.0, 230.0], [320.0, 241.5], [10.0, 240.0], [400.0, 238.0]])
    r, _, n = point_line_residuals(cam, T, X, D, uv)
    # n is the direction (1, 0) turned +90° on the screen (u right, v down): (0, 1), downwards.
    assert np.allclose(n, [[0.0, 1.0]] * 6)
    assert np.allclose(r, [3.0, 0.0, -10.0, 1.5, 0.0, -2.0])


def test_tukey_rejects_gross_outliers_that_spoil_least_squares():
    rng = np.random.default_rng(2)
    cam = _camera()
    T_true = _true_pose(rng)
    X, D, uv = _samples(rng, T_true, cam, per_edge=10)
    uv = uv + rng.normal(0, 0.3, uv.shape)
    bad = rng.random(len(uv)) < 0.3
    uv[bad] += rng.uniform(-8, 8, (bad.sum(), 2))
    T0 = make_T(exp_so3([0.03, -0.02, 0.02]) @ T_true[:3, :3], T_true[:3, 3] + [0.005, 0.005, -0.01])
    robust = refine_point_to_line(cam, T0, X, D, uv, loss="tukey", max_iter=30)
    plain = refine_point_to_line(cam, T0, X, D, uv, loss="l2", max_iter=30)
    rot_r, tr_r = pose_error(robust.T_world_obj, T_true)
    rot_p, tr_p = pose_error(plain.T_world_obj, T_true)
    assert rot_r < 0.15 and tr_r < 1.5e-3
    assert rot_p > 2 * rot_r or tr_p > 2 * tr_r
    # most rejected samples are the corrupted ones
    rejected = robust.weights < 0.1
    assert np.mean(bad[rejected]) > 0.8


def test_robust_weights():
    r = np.array([0.0, 1.0, 2.0, 10.0])
    assert np.allclose(robust_weights(r, "l2", 1.0), 1.0)
    assert np.allclose(robust_weights(r, "huber", 1.0), [1.0, 1.0, 1.345 / 2.0, 0.1345])
    w = robust_weights(r, "tukey", 1.0)
    assert w[0] == 1.0 and 0 < w[2] < w[1] < 1 and w[3] == 0.0
    with pytest.raises(ValueError, match="loss"):
        robust_weights(r, "cauchy", 1.0)


def test_bad_input_raises():
    cam = _camera()
    T = make_T(np.eye(3), [0, 0, 1.0])
    X = np.zeros((8, 3))
    D = np.tile([1.0, 0, 0], (8, 1))
    uv = np.zeros((8, 2))
    with pytest.raises(ValueError, match="X_obj must have shape"):
        refine_point_to_line(cam, T, X[:, :2], D, uv)
    with pytest.raises(ValueError, match="D_obj"):
        refine_point_to_line(cam, T, X, D[:5], uv)
    with pytest.raises(ValueError, match="uv must have shape"):
        refine_point_to_line(cam, T, X, D, uv[:3])
    with pytest.raises(ValueError, match="at least 6"):
        refine_point_to_line(cam, T, X[:4], D[:4], uv[:4])
    with pytest.raises(ValueError, match="loss"):
        refine_point_to_line(cam, T, X, D, uv, loss="cauchy")
    with pytest.raises(ValueError, match="finite"):
        refine_point_to_line(cam, T, X, D, np.full((8, 2), np.nan))
    with pytest.raises(ValueError, match="behind the camera"):
        refine_point_to_line(cam, make_T(np.eye(3), [0, 0, -1.0]), X, D, uv)
    with pytest.raises(ValueError, match="end-on"):
        refine_point_to_line(cam, T, X, np.tile([0, 0, 1.0], (8, 1)), uv)
