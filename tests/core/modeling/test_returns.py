import numpy as np
import pytest

from core.modeling.lm import huber_weights, levenberg_marquardt
from core.modeling.returns import (
    beam_gap,
    beam_gap_jacobian,
    incidence_cos,
    make_returns,
    range_residuals,
)
from core.transforms import make_T, rot_z

T_WT = make_T(rot_z(np.pi / 2), [0.0, -1.3, 0.4])  # turret looking along +y
P0, A = np.array([0.004, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def _returns(rho, pan, tilt=-0.2):
    return make_returns(T_WT, pan, np.full(len(pan), tilt), rho, 0.005, 2.6e-4)


def test_range_residuals_zero_on_the_surface_and_jacobian_matches_differences():
    pan = np.linspace(-0.03, 0.03, 25)
    ret0 = _returns(np.ones(25), pan)
    # True ranges to the cylinder r = 5 cm: the model's own beam intersection.
    _, X = beam_gap(ret0.origin, ret0.dirs, P0, A, 0.05, 0.0)
    w = ret0.origin - P0
    wp, Dp = w - (w @ A) * A, ret0.dirs - np.outer(ret0.dirs @ A, A)
    a_, b_, c_ = np.einsum("ij,ij->i", Dp, Dp), Dp @ wp, wp @ wp - 0.05**2
    s = (-b_ - np.sqrt(b_**2 - a_ * c_)) / a_
    ret = _returns(s, pan)
    cos = incidence_cos(ret, P0, A, 0.05, 0.0)
    assert np.all((cos > 0) & (cos <= 1))
    res, J = range_residuals(ret, P0, A, 0.05, 0.0, jac=True)
    assert np.abs(res).max() < 1e-9
    # Away from grazing the analytic Jacobian (σ_eff held) equals finite differences.
    m = cos > 0.5
    th = np.concatenate([P0, A, [0.05, 0.0]])
    for j in (0, 1, 6, 7):
        e = np.zeros(8)
        e[j] = 1e-7
        fd = (range_residuals(ret, *np.split(th + e, [3, 6])[:2], (th + e)[6], (th + e)[7]) - res) / 1e-7
        assert np.allclose(J[m, j], fd[m], rtol=1e-3, atol=1e-3)


def test_beam_gap_is_distance_minus_radius_and_its_jacobian():
    pan = np.array([0.08, 0.1])
    ret = _returns(np.ones(2), pan, tilt=0.0)
    g, X = beam_gap(ret.origin, ret.dirs, P0, A, 0.05, 0.0)
    # Horizontal beams, vertical axis: the gap is the 2D line–point distance minus r.
    d2 = ret.dirs[:, :2]
    o2 = ret.origin[:2] - P0[:2]
    dist = np.abs(o2[0] * d2[:, 1] - o2[1] * d2[:, 0])
    assert np.allclose(g, dist - 0.05, atol=1e-12)
    J = beam_gap_jacobian(ret.origin, ret.dirs, P0, A, 0.05, -0.1)
    th = np.concatenate([P0, A, [0.05, -0.1]])
    for j in range(8):
        e = np.zeros(8)
        e[j] = 1e-7
        fd = (
            beam_gap(ret.origin, ret.dirs, (th + e)[:3], (th + e)[3:6], (th + e)[6], (th + e)[7])[0]
            - beam_gap(ret.origin, ret.dirs, th[:3], th[3:6], th[6], th[7])[0]
        ) / 1e-7
        assert np.allclose(J[:, j], fd, atol=1e-5)


def test_levenberg_marquardt_and_huber():
    assert huber_weights(np.array([0.5, -6.0]), 3.0).tolist() == [1.0, 0.5]
    rng = np.random.default_rng(0)
    x = np.linspace(0, 1, 50)
    y = 2.0 * np.exp(-1.5 * x) + rng.normal(0, 0.01, 50)
    y[10] += 5.0  # an outlier
    fun = lambda p: (p[0] * np.exp(-p[1] * x) - y) / 0.01  # noqa: E731
    jac = lambda p: np.column_stack([np.exp(-p[1] * x), -p[0] * x * np.exp(-p[1] * x)]) / 0.01  # noqa: E731
    p, it = levenberg_marquardt(fun, jac, np.array([1.0, 1.0]))
    assert p == pytest.approx([2.0, 1.5], abs=0.02)
    assert 1 <= it < 100
