"""Corner snapping: a clicked image point of a model vertex refined to the image's corner, sub-pixel.

The operator clicks where a known corner (a box's vertex, a table's corner) is in the video; the
click is off by a pixel or two. Two ways to find the corner near the click:

* ``snap_corner_edges`` — the intersection of the image edges that meet at the vertex: the model
  says which edges leave the vertex and roughly in which image directions (its projection through
  the current C); each is snapped to the image (``snap.snap_segment`` on a stretch of it starting
  a few pixels from the click), and the corner is the least-squares point of the snapped lines
  (two or three, at least ``min_angle_deg`` apart). Each line is fitted on tens of edge points, so
  the corner is as precise as the lines.
* ``snap_corner_subpix`` — OpenCV's ``cornerSubPix`` on the frame (the point where the gradients
  of a window around the click are orthogonal to the lines joining them to it): needs no model,
  only a corner in the image.

``snap_corner`` tries the edges when directions are given and falls back on ``cornerSubPix``
otherwise (or when fewer than two edges snap). ``bench/corner_snapping.py`` measures both on the
workcell's frames against the true corners: the edge intersection is the more accurate there
(docs/beyond.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .profiles import to_gray_f32
from .snap import snap_segment

__all__ = ["CornerSnap", "snap_corner", "snap_corner_edges", "snap_corner_subpix"]


@dataclass(frozen=True)
class CornerSnap:
    """A snapped corner and how much to trust it.

    uv : array, shape (2,), pixels: the snapped corner (the clicked point when not ok).
    raw_uv : array, shape (2,): the clicked point. moved_px : distance between them (pixels).
    ok : True when the snap is trustworthy. method : "edges" or "subpix".
    sigma_px : standard deviation of the corner's position (pixels; NaN when unknown).
    lines_uv : array, shape (K, 2, 2): the snapped edge segments that meet there (method "edges"),
        for display. reason : why ok is False ("" when ok).
    fit_px : how well the image fits a corner at ``uv`` (pixels; NaN when not ok): method "edges", the
        largest RMS distance of a line's edge points to its snapped line; "subpix", the RMS distance of
        the window's gradient lines from ``uv`` (weighted by gradient strength; an ideal corner's is 0).
    """

    uv: np.ndarray
    raw_uv: np.ndarray
    moved_px: float
    ok: bool
    method: str
    sigma_px: float
    lines_uv: np.ndarray
    reason: str = ""
    fit_px: float = float("nan")


def _as_point(uv) -> np.ndarray:
    p = np.asarray(uv, dtype=float).reshape(-1)
    if p.shape != (2,) or not np.all(np.isfinite(p)):
        raise ValueError(f"uv must be a finite pixel (u, v), got {uv!r}")
    return p


def _refused(p: np.ndarray, method: str, reason: str, lines: np.ndarray | None = None) -> CornerSnap:
    return CornerSnap(
        p.copy(), p.copy(), 0.0, False, method, float("nan"), np.zeros((0, 2, 2)) if lines is None else lines, reason
    )


def snap_corner_edges(
    image: np.ndarray,
    uv,
    directions_uv,
    lengths_px=None,
    *,
    start_px: float = 3.0,
    max_length_px: float = 60.0,
    min_segment_px: float = 6.0,
    band_px: float = 5.0,
    min_angle_deg: float = 20.0,
    max_move_px: float = 6.0,
    min_strength: float = 3.0,
) -> CornerSnap:
    """The corner as the intersection of the snapped image edges leaving it.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, 3), the frame.
    uv : array, shape (2,), pixels: the clicked corner.
    directions_uv : array, shape (K, 2): image directions of the K ≥ 2 edges leaving the vertex
        (need not be unit; e.g. the projected far end minus the projected vertex).
    lengths_px : array, shape (K,), optional: the edges' projected lengths (pixels); each edge is
        snapped on [start_px, min(max_length_px, length − start_px)] from the click (on a stretch
        0.4 then 0.2 times as long when that fails: another object may hide the edge farther on).
    start_px : the stretch starts this far from the click (the corner itself blurs both edges).
    min_segment_px : edges whose stretch is shorter are left out.
    band_px : the edge search band of ``snap_segment``.
    min_angle_deg : two lines closer in direction than this do not fix a point.
    max_move_px : a corner farther than this from the click is refused.
    min_strength : smallest intensity derivative (grey levels per pixel) taken as an edge
        (``snap_segment``'s).

    Returns
    -------
    CornerSnap
        method "edges"; ok when at least two snapped lines at least ``min_angle_deg`` apart meet
        within ``max_move_px`` of the click.
    """
    p = _as_point(uv)
    D = np.asarray(directions_uv, dtype=float).reshape(-1, 2)
    if len(D) == 0:
        return _refused(p, "edges", "no edge directions given")
    norms = np.linalg.norm(D, axis=1)
    if np.any(~np.isfinite(norms)) or np.any(norms <= 0):
        raise ValueError(f"directions_uv must be finite non-zero vectors, got {D.tolist()}")
    D = D / norms[:, None]
    L = np.full(len(D), np.inf) if lengths_px is None else np.asarray(lengths_px, dtype=float).reshape(-1)
    if L.shape != (len(D),):
        raise ValueError(f"lengths_px must have shape ({len(D)},), got {L.shape}")
    centres, dirs, weights, drawn, fits = [], [], [], [], []
    for d, length in zip(D, L):
        res = None
        # The whole stretch first (more edge points, a better line); if another object hides
        # part of it, the snap is refused and a shorter stretch near the corner is tried.
        for reach in (max_length_px, 0.4 * max_length_px, 0.2 * max_length_px):
            end = min(reach, length - start_px)
            if end - start_px < min_segment_px:
                break
            res = snap_segment(image, np.array([p + start_px * d, p + end * d]), band_px, min_strength=min_strength)
            if res.ok or end < reach:
                break
        if res is None or not res.ok:
            continue
        s = res.seg_uv
        u = (s[1] - s[0]) / np.linalg.norm(s[1] - s[0])
        centres.append(s.mean(axis=0))
        dirs.append(u)
        sig = res.sigma_px if np.isfinite(res.sigma_px) and res.sigma_px > 0 else 0.1
        weights.append(1.0 / max(sig, 0.02) ** 2)
        drawn.append(s)
        fits.append(res.rms_px)
    lines = np.array(drawn).reshape(-1, 2, 2)
    if len(dirs) < 2:
        return _refused(p, "edges", f"{len(dirs)} of the corner's edges found in the image (2 needed)", lines)
    U = np.array(dirs)
    sin = np.abs(U[:, None, 0] * U[None, :, 1] - U[:, None, 1] * U[None, :, 0])
    if sin.max() < np.sin(np.radians(min_angle_deg)):
        return _refused(p, "edges", "the edges found at the corner are nearly parallel in the image", lines)
    Nrm = np.column_stack([-U[:, 1], U[:, 0]])
    w = np.array(weights)
    A = (Nrm * w[:, None]).T @ Nrm
    b = (Nrm * w[:, None]).T @ np.einsum("ij,ij->i", Nrm, np.array(centres))
    X = np.linalg.solve(A, b)
    cov = np.linalg.inv(A)
    moved = float(np.linalg.norm(X - p))
    if moved > max_move_px:
        return _refused(p, "edges", f"the edges meet {moved:.1f} px from the click (more than {max_move_px} px)", lines)
    # The lines were fitted from the click's end: draw them from the corner found.
    lines = np.array([[X + ((s[0] - X) @ u) * u, X + ((s[1] - X) @ u) * u] for s, u in zip(drawn, U)])
    fit = float(max(fits))
    return CornerSnap(X, p.copy(), moved, True, "edges", float(np.sqrt(np.trace(cov) / 2.0)), lines, fit_px=fit)


def snap_corner_subpix(
    image: np.ndarray, uv, *, win_px: int = 5, max_move_px: float = 4.0, min_gradient: float = 8.0
) -> CornerSnap:
    """The corner by OpenCV's ``cornerSubPix`` in a (2 win_px + 1)² window around the click.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, 3). uv : array, shape (2,), pixels: the clicked corner.
    win_px : half-size of the window (pixels). max_move_px : a corner farther than this is refused.
    min_gradient : the window must hold gradients of at least this (grey levels per pixel) in two
        directions (the smaller eigenvalue of the structure tensor, as a gradient): else there is
        no corner there.

    Returns
    -------
    CornerSnap
        method "subpix"; ``sigma_px`` NaN (OpenCV gives no uncertainty).
    """
    import cv2

    p = _as_point(uv)
    gray = to_gray_f32(image)
    H, W = gray.shape
    if not (win_px + 1 <= p[0] <= W - win_px - 2 and win_px + 1 <= p[1] <= H - win_px - 2):
        return _refused(p, "subpix", "the click is too near the image's border for a corner search")
    x0, y0 = int(round(p[0])), int(round(p[1]))
    patch = gray[y0 - win_px : y0 + win_px + 1, x0 - win_px : x0 + win_px + 1]
    gy, gx = np.gradient(patch)
    S = np.array([[np.mean(gx * gx), np.mean(gx * gy)], [np.mean(gx * gy), np.mean(gy * gy)]])
    if np.sqrt(max(np.linalg.eigvalsh(S)[0], 0.0)) < min_gradient / 4.0:
        return _refused(p, "subpix", "no corner near the click (the image has one edge direction there, or none)")
    corners = p.reshape(1, 1, 2).astype(np.float32)
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 40, 0.001)
    cv2.cornerSubPix(gray, corners, (int(win_px), int(win_px)), (-1, -1), criteria)
    X = corners.reshape(2).astype(float)
    moved = float(np.linalg.norm(X - p))
    if not np.all(np.isfinite(X)) or moved > max_move_px:
        return _refused(p, "subpix", f"the corner search moved {moved:.1f} px away (more than {max_move_px} px)")
    # cornerSubPix's own equation at X: each gradient's line (through its pixel, across the gradient) passes
    # through an ideal corner; their RMS distance from X says how well a corner fits there
    ys, xs = np.mgrid[y0 - win_px : y0 + win_px + 1, x0 - win_px : x0 + win_px + 1]
    w = gx * gx + gy * gy
    dist = gx * (X[0] - xs) + gy * (X[1] - ys)  # |g| × the distance of X from the gradient's line
    fit = float(np.sqrt(np.sum(dist * dist) / max(np.sum(w), 1e-12)))
    return CornerSnap(X, p.copy(), moved, True, "subpix", float("nan"), np.zeros((0, 2, 2)), fit_px=fit)


def snap_corner(image: np.ndarray, uv, directions_uv=None, lengths_px=None, **kw) -> CornerSnap:
    """The corner near a click: the snapped edges' intersection when their directions are known
    (``snap_corner_edges``), else — or when that fails — OpenCV's ``cornerSubPix``.

    ``kw`` go to ``snap_corner_edges``. The result's ``method`` says which answered; when both
    fail, the edge method's reason is kept (it is the more informative).
    """
    p = _as_point(uv)
    first = None
    if directions_uv is not None and len(np.asarray(directions_uv).reshape(-1, 2)) >= 2:
        first = snap_corner_edges(image, p, directions_uv, lengths_px, **kw)
        if first.ok:
            return first
    sub = snap_corner_subpix(image, p)
    if sub.ok or first is None:
        return sub
    return first
