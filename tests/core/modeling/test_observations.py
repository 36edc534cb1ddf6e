import numpy as np
import pytest

from core.geometry import Plane
from core.modeling.observations import fit_face_plane, interpretation_plane_obs, plane_var_at, support_obs
from core.modeling.simulate import look_at_setup


def test_interpretation_plane_covariance_matches_monte_carlo():
    cam, _ = look_at_setup(np.zeros(3), 1.5)
    seg = np.array([[100.0, 80.0], [300.0, 150.0]])
    obs = interpretation_plane_obs(cam, seg, 1.0)
    X = np.array([0.05, 0.02, 0.0])
    rng = np.random.default_rng(1)
    d = []
    for _ in range(2000):
        p = cam.interpretation_plane(seg + rng.normal(0, 1.0, (2, 2)))
        if p.n @ obs.plane.n < 0:
            p = p.flipped()
        d.append(p.n @ X + p.d)
    assert np.std(d) == pytest.approx(np.sqrt(plane_var_at(obs, X)), rel=0.1)


def test_face_plane_exact_and_both_fits_reported():
    rng = np.random.default_rng(2)
    n = np.array([0.2, -0.3, 1.0])
    n /= np.linalg.norm(n)
    P = rng.uniform(-0.1, 0.1, (20, 3))
    P -= np.outer(P @ n + 0.3, n)
    for method in ("tls", "ols"):
        fit = fit_face_plane(P, sigma_m=0.005, method=method)
        assert abs(abs(fit.obs.plane.n @ n) - 1) < 1e-12
        assert np.allclose(P @ fit.obs.plane.n + fit.obs.plane.d, 0, atol=1e-12)
        assert fit.fits["ols"] is not None and fit.fits["tls"] is not None
        assert fit.obs.cov.shape == (4, 4)


def test_face_plane_robust_to_edge_hits():
    rng = np.random.default_rng(3)
    P = np.column_stack([rng.uniform(0, 0.1, 30), rng.uniform(0, 0.1, 30), rng.normal(0, 0.002, 30)])
    bad = np.column_stack([rng.uniform(0, 0.1, 5), np.full(5, 0.1), rng.uniform(0.03, 0.08, 5)])  # the next face
    fit = fit_face_plane(np.vstack([P, bad]), sigma_m=0.002)
    assert not fit.inliers[30:].any()
    assert abs(fit.obs.plane.n[2]) > 0.999
    loose = fit_face_plane(np.vstack([P, bad]), sigma_m=0.002, robust=False)
    assert abs(loose.obs.plane.n[2]) < abs(fit.obs.plane.n[2])


def test_face_plane_errors():
    with pytest.raises(ValueError, match="at least 3"):
        fit_face_plane(np.zeros((2, 3)))
    line = np.outer(np.linspace(0, 1, 6), [1.0, 2.0, 0.5])
    with pytest.raises(ValueError, match="collinear"):
        fit_face_plane(line, sigma_m=0.001)
    vertical = np.array([[0, 0, 0], [0, 1, 0], [0, 0, 1], [0, 1, 1], [0, 0.5, 0.3]], float)
    with pytest.raises(ValueError, match="parallel to the z axis"):
        fit_face_plane(vertical, sigma_m=0.001, method="ols")
    with pytest.raises(ValueError, match="Plane"):
        support_obs((np.zeros(3), 0.0), 0.001)
    assert support_obs(Plane(np.array([0, 0, 2.0]), 1.0), 0.001).plane.d == pytest.approx(0.5)
