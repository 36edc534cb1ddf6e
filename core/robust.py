"""Robust weights: the one place the project's fits down-weight outliers (iteratively reweighted
least squares).

``huber_weights(r, c)``: 1 for |r| ≤ c, c/|r| beyond (a wrong residual pulls with a bounded force);
``tukey_weights(r, c)``: (1 − (r/c)²)² for |r| < c, 0 beyond (a gross outlier does not pull at all);
``robust_weights(r, loss, scale)``: either at the scale of the residuals, with the thresholds that keep
95 % efficiency under Gaussian noise (Huber 1.345, Tukey 4.685); ``huber_loss(r, c)``: the cost the Huber
weights minimise. ``huber_weight`` / ``huber_rho`` are the same Huber weight and cost of one residual, in
plain float arithmetic: the compiled pose refinement (``core.pose._kernels``) compiles these functions
themselves, so that the project's fits — the pose refinement, the modelling fits (``core.modeling.lm``),
the tracker and the one-click search (Tukey) — down-weight through this one module.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "HUBER_K",
    "TUKEY_C",
    "LOSSES",
    "huber_weight",
    "huber_rho",
    "huber_weights",
    "huber_loss",
    "tukey_weights",
    "robust_weights",
]

HUBER_K = 1.345  # 95 % efficiency under Gaussian noise
TUKEY_C = 4.685  # 95 % efficiency under Gaussian noise
LOSSES = ("l2", "huber", "tukey")


def huber_weight(e: float, c: float) -> float:
    """The Huber IRLS weight of one residual of magnitude e ≥ 0 at threshold c: 1 inside, c/e outside
    (``huber_weights`` of one value; compiled as it is by ``core.pose._kernels``)."""
    return min(1.0, c / max(e, 1e-300))


def huber_rho(e: float, c: float) -> float:
    """The Huber cost of one residual of magnitude e ≥ 0 at threshold c: e²/2 inside, c e − c²/2 outside."""
    return 0.5 * e * e if e <= c else c * e - 0.5 * c * c


def huber_weights(r: np.ndarray, c: float) -> np.ndarray:
    """IRLS weights (same shape as r) of the Huber loss with threshold c: 1 inside, c/|r| outside."""
    return np.minimum(1.0, c / np.maximum(np.abs(r), 1e-300))


def huber_loss(r: np.ndarray, c: float) -> float:
    """Σ of ``huber_rho`` over the residuals r: the cost IRLS with ``huber_weights`` minimises."""
    a = np.abs(r)
    return float(np.sum(np.where(a <= c, 0.5 * a * a, c * a - 0.5 * c * c)))


def tukey_weights(r: np.ndarray, c: float) -> np.ndarray:
    """IRLS weights of Tukey's biweight with threshold c: (1 − (r/c)²)² inside, 0 outside."""
    z = np.abs(r) / c
    return np.where(z < 1.0, (1.0 - z * z) ** 2, 0.0)


def robust_weights(r: np.ndarray, loss: str, scale: float) -> np.ndarray:
    """IRLS weights (N,) in [0, 1] of residuals r for a loss ("l2", "huber", "tukey") at a scale (the
    residuals' units): Huber at ``HUBER_K`` scales, Tukey at ``TUKEY_C``."""
    if loss == "l2":
        return np.ones_like(r)
    if loss == "huber":
        return huber_weights(r, HUBER_K * scale)
    if loss == "tukey":
        return tukey_weights(r, TUKEY_C * scale)
    raise ValueError(f"loss must be one of {LOSSES}, got {loss!r}")
