"""core.robust: the one module of robust weights; its one-residual Huber weight and cost are the ones
the compiled pose refinement runs."""

import numpy as np

from core.robust import huber_loss, huber_rho, huber_weight, huber_weights, robust_weights, tukey_weights


def test_one_residuals_huber_weight_and_cost_are_the_arrays_ones():
    r = np.array([-5.0, -3.0, -0.5, 0.0, 0.5, 3.0, 7.0])
    assert np.allclose([huber_weight(abs(x), 3.0) for x in r], huber_weights(r, 3.0))
    assert np.isclose(sum(huber_rho(abs(x), 3.0) for x in r), huber_loss(r, 3.0))
    assert huber_weights(r, 3.0).tolist() == [0.6, 1.0, 1.0, 1.0, 1.0, 1.0, 3.0 / 7.0]
    assert huber_rho(1.0, 3.0) == 0.5 and huber_rho(5.0, 3.0) == 15.0 - 4.5


def test_the_huber_cost_is_what_its_weights_minimise():
    """IRLS with huber_weights finds the minimum of huber_loss: a location among an outlier."""
    x = np.array([0.0, 0.1, -0.1, 0.05, 10.0])
    mu = 0.0
    for _ in range(100):
        w = huber_weights(x - mu, 0.5)
        mu = float(np.sum(w * x) / np.sum(w))
    grid = np.linspace(-1, 1, 20001)
    assert abs(grid[np.argmin([huber_loss(x - m, 0.5) for m in grid])] - mu) < 1e-3


def test_robust_weights_by_loss():
    r = np.array([0.0, 1.0, 10.0])
    assert robust_weights(r, "l2", 1.0).tolist() == [1.0, 1.0, 1.0]
    assert np.allclose(robust_weights(r, "huber", 1.0), huber_weights(r, 1.345))
    assert (
        np.allclose(robust_weights(r, "tukey", 1.0), tukey_weights(r, 4.685))
        and robust_weights(r, "tukey", 1.0)[2] == 0
    )
