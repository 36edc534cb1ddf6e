"""A small Levenberg–Marquardt solver with a Huber loss (iteratively reweighted, the weights and the
cost ``core.robust``'s), for the fits, and the one finite-difference Jacobian the modelling code uses
where no analytic one is at hand.

The problems here are small (3–8 parameters, a few hundred residuals) and their Jacobians are
analytic: a plain loop is several times faster than scipy's general ``least_squares`` on them.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from ..robust import huber_loss, huber_weights

__all__ = ["levenberg_marquardt", "numeric_jacobian"]


def numeric_jacobian(
    fun: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    step: float | np.ndarray,
    *,
    central: bool = False,
    f0: np.ndarray | None = None,
) -> np.ndarray:
    """Finite-difference Jacobian (m, n) of fun: x (n,) → (m,) at x, for maps with no analytic one.

    step : the step of every parameter (a float), or of each (n,); a parameter whose step is 0
    (no spread, or no influence) gets a zero column without calling fun. Forward differences
    (fun(x + h e_j) − fun(x)) / h, reusing f0 = fun(x) when given, or with ``central``
    (fun(x + h e_j) − fun(x − h e_j)) / 2h.
    """
    x = np.asarray(x, dtype=float)
    h = np.broadcast_to(np.asarray(step, dtype=float), x.shape)
    if not central and f0 is None:
        f0 = np.asarray(fun(x), dtype=float)
    J = None
    for j in np.flatnonzero(h):
        e = np.zeros_like(x)
        e[j] = h[j]
        col = (fun(x + e) - fun(x - e)) / (2 * h[j]) if central else (fun(x + e) - f0) / h[j]
        if J is None:
            J = np.zeros((len(col), len(x)))
        J[:, j] = col
    if J is None:  # no column to difference: the shape from one call
        J = np.zeros((len(f0 if f0 is not None else fun(x)), len(x)))
    return J


def levenberg_marquardt(
    fun: Callable[[np.ndarray], np.ndarray],
    jac: Callable[[np.ndarray], np.ndarray],
    x0: np.ndarray,
    *,
    huber: float = 3.0,
    max_iter: int = 100,
    xtol: float = 1e-10,
    ftol: float = 1e-10,
) -> tuple[np.ndarray, int]:
    """Minimise Σ huber(fun(x)) from x0; returns (x, iterations).

    fun : x (n,) → residuals (m,), normalised by their σ. jac : x → (m, n).
    Stops when a step changes x by less than xtol relative (plus xtol absolute), or lowers the
    cost by less than ftol relative.
    """
    x = np.asarray(x0, dtype=float).copy()
    r = fun(x)
    cost = huber_loss(r, huber)
    lam = 1e-3
    it = 0
    for it in range(1, max_iter + 1):  # noqa: B007 - the count of iterations, returned
        J = jac(x)
        w = huber_weights(r, huber)
        H = J.T @ (w[:, None] * J)
        g = J.T @ (w * r)
        D = np.maximum(np.diag(H), 1e-300)
        accepted = converged = False
        for _ in range(30):
            try:
                step = -np.linalg.solve(H + lam * np.diag(D), g)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            if np.all(np.abs(step) <= xtol * (np.abs(x) + xtol)):
                converged = True  # the step left is below the tolerance: done
                break
            x_new = x + step
            r_new = fun(x_new)
            c_new = huber_loss(r_new, huber)
            if c_new <= cost:
                converged = cost - c_new <= ftol * cost
                x, r, cost = x_new, r_new, c_new
                lam = max(lam / 10.0, 1e-12)
                accepted = True
                break
            lam *= 10.0
        if converged or not accepted:
            break
    return x, it
