"""A refined pose whose clicks disagree more than their σ says is weak, and said so: its σ is understated
(a new user's snapped clicks on real images sat 1-2 px off on a neighbouring edge, each within 3σ, and the
written pose was 7 σ off, with nothing said)."""

from types import SimpleNamespace

import numpy as np

from app.workflows.pose_presentation import clicks_disagree


def _refined(residuals_px: np.ndarray) -> SimpleNamespace:
    n = len(residuals_px) // 2
    return SimpleNamespace(
        residuals_px=residuals_px, weights=np.ones(n), rms_px=float(np.sqrt(np.mean(residuals_px**2)))
    )


def test_residuals_as_their_sigma_says_are_not_said():
    rng = np.random.default_rng(0)
    assert clicks_disagree(_refined(rng.normal(0.0, 0.3, 14)), [0.3] * 7) == ""


def test_residuals_far_above_their_sigma_are_said_with_the_factor():
    rng = np.random.default_rng(0)
    said = clicks_disagree(_refined(rng.normal(0.0, 0.45, 14)), [0.15] * 7)  # the snapped σ, 3× too small
    assert "disagree more than their σ" in said and "understated about" in said


def test_no_redundancy_says_nothing():
    assert clicks_disagree(_refined(np.full(6, 5.0)), [0.15] * 3) == ""
