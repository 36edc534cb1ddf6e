"""core.calibration.calibrate_turret_planes: the turret pose from ranges that land on known planes."""

from __future__ import annotations

import numpy as np
import pytest

from core.calibration import calibrate_turret_planes
from core.rangefinder import RangeFinderSpec, aim
from core.transforms import exp_so3, make_T, pose_error, random_rotation


def _planes_and_points(rng, T_true):
    """Points on three perpendicular walls (x = 1.5, y = 1.2, z = -0.4), as the true turret measures them."""
    normals = np.array([[-1.0, 0, 0], [0, -1.0, 0], [0, 0, 1.0]])
    offsets = np.array([1.5, 1.2, 0.4])
    P, N, D = [], [], []
    for n, d in zip(normals, offsets):
        for _ in range(5):
            X = rng.uniform(-0.5, 0.5, 3) + [0.8, 0.6, 0.2]
            X -= (n @ X + d) * n  # onto the plane
            P.append(X)
            N.append(n)
            D.append(d)
    pan, tilt, rho = aim(T_true, np.array(P))
    return pan, tilt, rho, np.array(N), np.array(D)


def test_exact_ranges_recover_the_pose_from_a_wrong_start():
    rng = np.random.default_rng(0)
    for _ in range(5):
        T_true = make_T(random_rotation(rng) if False else exp_so3(rng.normal(0, 0.3, 3)), rng.normal(0, 0.1, 3))
        pan, tilt, rho, N, D = _planes_and_points(rng, T_true)
        T0 = T_true @ make_T(exp_so3(np.radians([1.0, -0.5, 0.8])), [0.02, -0.01, 0.015])
        cal = calibrate_turret_planes(pan, tilt, rho, N, D, T0)
        deg, m = pose_error(cal.T_world_turret, T_true)
        assert deg < 1e-6 and m < 1e-8
        assert cal.rms_m < 1e-9 and cal.linear_rms_m > 1e-3
        assert cal.residuals_m.shape == (15, 3) and cal.cov.shape == (6, 6)


def test_noisy_ranges_scatter_as_the_covariance_says():
    rng = np.random.default_rng(1)
    T_true = make_T(exp_so3([0.1, -0.2, 0.3]), [0.1, 0.0, 0.05])
    spec = RangeFinderSpec(sigma_range_m=0.005)
    errs, covs = [], []
    for _ in range(200):
        pan, tilt, rho, N, D = _planes_and_points(np.random.default_rng(7), T_true)
        noisy = rho + rng.normal(0, spec.sigma_range_m, len(rho))
        cal = calibrate_turret_planes(pan, tilt, noisy, N, D, T_true, spec)
        errs.append(np.linalg.inv(T_true)[:3, :3] @ (cal.T_world_turret[:3, 3] - T_true[:3, 3]))
        covs.append(cal.cov)
    # the translation's scatter (turret frame) matches the predicted σ within 25 %
    predicted = np.sqrt(np.mean([np.diag(c)[3:] for c in covs], axis=0))
    observed = np.std(np.array(errs), axis=0)
    assert np.all(np.abs(observed / predicted - 1) < 0.25), (observed, predicted)


def test_planes_of_two_orientations_are_refused():
    rng = np.random.default_rng(2)
    T = np.eye(4)
    pan, tilt, rho, N, D = _planes_and_points(rng, T)
    keep = np.abs(N[:, 2]) < 0.5  # only the two walls
    with pytest.raises(ValueError, match="fewer than 3 independent normals"):
        calibrate_turret_planes(pan[keep], tilt[keep], rho[keep], N[keep], D[keep], T)
    with pytest.raises(ValueError, match="at least 6"):
        calibrate_turret_planes(pan[:4], tilt[:4], rho[:4], N[:4], D[:4], T)


def test_the_rows_give_the_solve_s_covariance_before_measuring():
    """turret_plane_rows: RᵀR inverted is the covariance calibrate_turret_planes states at the same pose
    (so σ can be predicted for beams not yet measured)."""
    from core.calibration import turret_plane_rows

    rng = np.random.default_rng(3)
    T_true = make_T(exp_so3(rng.normal(0, 0.3, 3)), rng.normal(0, 0.1, 3))
    pan, tilt, rho, N, D = _planes_and_points(rng, T_true)
    cal = calibrate_turret_planes(pan, tilt, rho, N, D, T_true)
    rows = turret_plane_rows(T_true, pan, tilt, rho, N)
    assert rows.shape == (15, 6)
    assert np.allclose(np.linalg.inv(rows.T @ rows), cal.cov, rtol=1e-4, atol=1e-14)


def test_the_next_point_is_the_one_that_shrinks_the_worst_sigma():
    """next_turret_point: with the x wall alone unmeasured, a point on it is chosen over more of the same;
    the σ it returns is that of the pose with the point added."""
    from core.calibration import next_turret_point, turret_plane_rows

    rng = np.random.default_rng(4)
    T = make_T(exp_so3(rng.normal(0, 0.2, 3)), rng.normal(0, 0.1, 3))
    pan, tilt, rho, N, D = _planes_and_points(rng, T)
    rows = turret_plane_rows(T, pan, tilt, rho, N)
    on_x = N[:, 0] < -0.5
    done, cand = rows[~on_x], rows  # 10 on the y and z walls measured; all 15 candidates
    scale = np.array([np.radians(0.2)] * 3 + [0.005] * 3)
    prior = np.array([np.radians(10.0)] * 3 + [0.5] * 3)
    k, sd = next_turret_point(done, cand, scale, prior)
    assert on_x[k]
    info = done.T @ done + np.diag(1 / prior**2) + np.outer(cand[k], cand[k])
    assert np.allclose(sd, np.sqrt(np.diag(np.linalg.inv(info))))
    with pytest.raises(ValueError, match="no candidate"):
        next_turret_point(done, np.zeros((0, 6)), scale, prior)


def test_a_prior_fixes_the_pose_from_fewer_planes_and_counts_in_the_covariance():
    """With a prior (T_prior, cov), one wall's points give the MAP pose: along what the wall does not
    see, the pose stays at the prior and its σ is the prior's; what it sees is fitted."""
    rng = np.random.default_rng(5)
    T_true = make_T(exp_so3(rng.normal(0, 0.2, 3)), rng.normal(0, 0.1, 3))
    pan, tilt, rho, N, D = _planes_and_points(rng, T_true)
    z = N[:, 2] > 0.5  # the floor alone: 5 points, one orientation
    with pytest.raises(ValueError):
        calibrate_turret_planes(pan[z], tilt[z], rho[z], N[z], D[z], T_true)
    prior_cov = np.diag([np.radians(1.0) ** 2] * 3 + [0.03**2] * 3)
    cal = calibrate_turret_planes(pan[z], tilt[z], rho[z], N[z], D[z], T_true, prior=(T_true, prior_cov))
    assert pose_error(cal.T_world_turret, T_true)[1] < 1e-6  # exact ranges, prior at the truth: stays
    sd = np.sqrt(np.diag(cal.cov))
    prior_sd = np.sqrt(np.diag(prior_cov))
    assert np.all(sd <= prior_sd * (1 + 1e-6)) and np.any(sd < 0.5 * prior_sd)
