"""Outlier handling for range-finder data: RANSAC planes and scan segmentation.

Range points aimed at a face can miss it (a beam grazing an edge lands on the next face, or on
the background); a horizontal scan across a solid also returns the background beside it.
"""

from __future__ import annotations

import numpy as np

from ..geometry import as_points

__all__ = ["ransac_plane", "object_runs"]


def ransac_plane(
    X: np.ndarray,
    threshold_m: float,
    *,
    iterations: int = 200,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Inlier mask of the best-supported plane (RANSAC with the MSAC score).

    X : array, shape (N ≥ 3, 3), metres. threshold_m : largest point-to-plane distance of an
    inlier, metres (about 3 σ of the range noise). rng : random generator for the minimal
    samples; a fixed seed by default so the result is reproducible.
    Returns a boolean mask (N,). Each candidate plane is scored by Σ min(dᵢ², threshold²) (MSAC),
    not by its inlier count: on a face small against the threshold, a plane across the face can
    hold as many points as the face itself, but not as closely.
    ValueError for fewer than 3 points or a non-positive threshold; when every triple is
    collinear the mask is all False (the caller's plane fit then raises its own error).
    """
    X = as_points(X, "points", min_count=3)
    if not threshold_m > 0:
        raise ValueError(f"threshold_m must be positive, got {threshold_m}")
    rng = np.random.default_rng(0) if rng is None else rng
    n = len(X)
    if n <= 12:  # small sets: every triple
        idx = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    else:
        idx = np.argsort(rng.random((iterations, n)), axis=1)[:, :3]
    A, B, C = X[idx[:, 0]], X[idx[:, 1]], X[idx[:, 2]]
    nrm = np.cross(B - A, C - A)
    size = np.linalg.norm(nrm, axis=1)
    scale = np.maximum(np.linalg.norm(B - A, axis=1), np.linalg.norm(C - A, axis=1)) ** 2
    ok = size > 1e-9 * np.maximum(scale, 1e-300)
    if not np.any(ok):
        return np.zeros(n, bool)
    nrm = nrm[ok] / size[ok, None]
    d = -np.einsum("ij,ij->i", nrm, A[ok])
    dist = np.abs(X @ nrm.T + d)  # (N, M)
    score = np.minimum(dist, threshold_m) ** 2
    best = int(np.argmin(score.sum(axis=0)))
    return dist[:, best] <= threshold_m


def object_runs(range_m: np.ndarray, jump_m: float) -> list[tuple[int, int]]:
    """Runs of consecutive returns whose ranges change by less than ``jump_m`` between beams.

    range_m : array, shape (N,), metres, NaN for a miss, in scan order. Returns the runs as
    half-open index intervals [start, stop), in scan order. A miss or a jump ends a run.
    """
    rho = np.asarray(range_m, dtype=float).reshape(-1)
    if not jump_m > 0:
        raise ValueError(f"jump_m must be positive, got {jump_m}")
    runs: list[tuple[int, int]] = []
    start = None
    for i in range(len(rho)):
        if not np.isfinite(rho[i]):
            if start is not None:
                runs.append((start, i))
                start = None
            continue
        if start is None:
            start = i
        elif abs(rho[i] - rho[i - 1]) >= jump_m:
            runs.append((start, i))
            start = i
    if start is not None:
        runs.append((start, len(rho)))
    return runs
