"""Vertices as least-squares points of the planes that meet there, with their joint covariance.

Paper §III.1: an edge is a face plane ∩ the interpretation plane of its clicked image edge; a
vertex is where several such planes meet. Each vertex here is the weighted least-squares point
of every plane through it (face planes, interpretation planes, the support plane), with weights
the inverse variance of each plane's offset at the vertex. Planes are shared between vertices,
so the vertices are correlated: the covariance returned is the joint one, to first order.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from .observations import PlaneObs, plane_var_at

__all__ = ["solve_vertices"]

_MIN_VAR = 1e-16  # (10 nm)²: keeps exact planes (σ = 0) finite in the weights


def solve_vertices(
    planes: Sequence[PlaneObs],
    incidence: Sequence[Sequence[int]],
    names: Sequence[str] | None = None,
    *,
    return_jacobian: bool = False,
):
    """Least-squares points of the planes meeting at each vertex.

    planes : sequence of P PlaneObs (independent measurements). incidence : for each of V
    vertices, the indices of the planes through it (≥ 3 whose normals span 3D). names :
    optional vertex names for the error messages.
    Returns X (V, 3) metres, cov (3V, 3V) m², and per vertex the signed residuals (m) of its planes;
    with ``return_jacobian`` also J (3V, 4P), the derivative of X with respect to the planes' (n, d).
    ValueError naming the vertex when its planes are fewer than 3 or do not span 3D.
    """
    P = len(planes)
    V = len(incidence)
    names = [str(v) for v in range(V)] if names is None else list(names)
    X = np.zeros((V, 3))
    J = np.zeros((3 * V, 4 * P))
    residuals = []
    for v, idx in enumerate(incidence):
        idx = list(idx)
        if len(idx) < 3:
            raise ValueError(
                f"vertex {names[v]} lies on only {len(idx)} measured plane(s); it needs 3 whose "
                "normals span 3D (click more of its edges, or measure one more of its faces)"
            )
        N = np.array([planes[i].plane.n for i in idx])
        d = np.array([planes[i].plane.d for i in idx])
        sv = np.linalg.svd(N, compute_uv=False)
        if sv[-1] < 0.05 * sv[0]:
            raise ValueError(
                f"vertex {names[v]}: its {len(idx)} planes ({', '.join(planes[i].label for i in idx)}) "
                "are nearly parallel to one line, so they do not fix a point; click an edge or "
                "measure a face that crosses them at a larger angle"
            )
        w = np.ones(len(idx))
        for _ in range(3):
            A = N.T @ (w[:, None] * N)
            x = np.linalg.solve(A, -(N.T @ (w * d)))
            var = np.array([max(plane_var_at(planes[i], x), _MIN_VAR) for i in idx])
            w = 1.0 / var
        A = N.T @ (w[:, None] * N)
        x = np.linalg.solve(A, -(N.T @ (w * d)))
        X[v] = x
        r = N @ x + d
        residuals.append(r)
        Ainv = np.linalg.inv(A)
        for k, i in enumerate(idx):
            # ∂x/∂(n_i, d_i) = −A⁻¹ w_i [r_i I + n_i xᵀ, n_i]
            G = np.hstack([r[k] * np.eye(3) + np.outer(N[k], x), N[k][:, None]])
            J[3 * v : 3 * v + 3, 4 * i : 4 * i + 4] = -w[k] * (Ainv @ G)
    S = np.zeros((4 * P, 4 * P))
    for i, p in enumerate(planes):
        S[4 * i : 4 * i + 4, 4 * i : 4 * i + 4] = p.cov
    cov = J @ S @ J.T
    if return_jacobian:
        return X, 0.5 * (cov + cov.T), residuals, J
    return X, 0.5 * (cov + cov.T), residuals
