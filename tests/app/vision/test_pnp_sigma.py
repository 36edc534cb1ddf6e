"""PnP's σ holds K's stated prior (issue 27): the camera's pose and C, solved with the file's K while the true lens
is drawn from that prior, scatter as ``solve_pnp``'s covariances say (seeded Monte Carlo, within 20 %)."""

from __future__ import annotations

import numpy as np
import pytest

from app.vision.pnp import solve_pnp
from core.camera import Camera
from core.transforms import exp_so3, log_so3, make_T

K = np.array([[800.0, 0, 319.5], [0, 790.0, 239.5], [0, 0, 1]])
T_CAM_WORLD = make_T(exp_so3([2.0, 0.3, -0.2]), [0.05, -0.02, 2.0])


def _points():
    rng = np.random.default_rng(0)
    X_cam = np.column_stack([rng.uniform(-0.5, 0.5, 8), rng.uniform(-0.4, 0.4, 8), rng.uniform(1.6, 2.4, 8)])
    T_wc = np.linalg.inv(T_CAM_WORLD)
    return X_cam @ T_wc[:3, :3].T + T_wc[:3, 3]


def test_the_lens_prior_joins_the_pose_and_c_as_cameras_drawn_from_it_scatter():
    X = _points()
    true_uv = Camera.from_intrinsics(K, T_CAM_WORLD, 640, 480).project(X)
    sig = np.full(len(X), 1e-3)  # clicks exact: the lens alone
    f_rel, c_px = 0.004, 2.0
    res = solve_pnp(K, X, true_uv, 640, 480, sigma_px=sig, k_prior=(f_rel, c_px), points_sigma_m=0.0)
    bare = solve_pnp(K, X, true_uv, 640, 480, sigma_px=sig, k_prior=(0.0, 0.0), points_sigma_m=0.0)
    assert np.trace(res.cov_pose) > 100 * np.trace(bare.cov_pose)
    rng = np.random.default_rng(1)
    dpose, dC = [], []
    for _ in range(200):
        Kt = K.copy()
        Kt[0, 0] *= 1 + f_rel * rng.standard_normal()
        Kt[1, 1] *= 1 + f_rel * rng.standard_normal()
        Kt[:2, 2] += c_px * rng.standard_normal(2)
        true = Camera.from_intrinsics(Kt, T_CAM_WORLD, 640, 480)
        fit = solve_pnp(K, X, true.project(X), 640, 480, sigma_px=sig, k_prior=(0.0, 0.0), points_sigma_m=0.0)
        T = fit.T_cam_world
        dpose.append(np.r_[log_so3(T[:3, :3] @ T_CAM_WORLD[:3, :3].T), T[:3, 3] - T_CAM_WORLD[:3, 3]])
        dC.append(fit.camera.C.ravel() - true.C.ravel())
    dpose, dC = np.array(dpose), np.array(dC)
    for part in (slice(0, 3), slice(3, 6)):  # rotation, translation (PnP's order)
        observed = np.sqrt(dpose[:, part].var(axis=0).sum())
        assert observed == pytest.approx(np.sqrt(np.trace(res.cov_pose[part, part])), rel=0.2)
    assert np.sqrt(np.mean(np.sum(dC**2, axis=1))) == pytest.approx(np.sqrt(np.trace(res.cov)), rel=0.2)
