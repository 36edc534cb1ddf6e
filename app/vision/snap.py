"""Edge snapping: a clicked image segment refined to the image's edge, sub-pixel.

The operator clicks two points along an object's edge; each click is off by a pixel or two.
``snap_segment`` looks for the edge in a band around the clicked segment:

1. the image is smoothed (Gaussian, σ = ``sigma_px``) in a region around the segment;
2. samples every pixel along the segment; at each, the strongest edge along the segment's
   normal within ±``band_px`` (``profiles.search_along_normals``), and its polarity;
3. the dominant polarity (the side that is brighter) is kept and the search repeated with it;
4. a line is fitted robustly to the edge points: every pair of points proposes a line, the one
   that most edge strength supports within ``inlier_px`` wins, then weighted total least squares
   on its inliers;
5. the search is repeated along the fitted line's own normal within ±``refine_px`` (the click's
   direction may be off by a few degrees) and the line refitted, twice;
6. the snapped endpoints are the clicked endpoints projected orthogonally on the fitted line.

The result says how far the segment moved, how much of it found an edge, and whether the snap
is trustworthy (``ok``): the interface shows both segments and the operator may refuse the snap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.camera import as_segment

from .profiles import search_along_normals, smooth, to_gray_f32

__all__ = ["SnapResult", "snap_segment", "fit_line_robust"]


@dataclass(frozen=True)
class SnapResult:
    """A snapped segment and how much to trust it.

    seg_uv : array, shape (2, 2), pixels: the snapped segment (the clicked segment when not ok).
    raw_seg_uv : array, shape (2, 2): the clicked segment.
    moved_px : largest distance an endpoint moved (pixels).
    ok : True when the snap is trustworthy (enough of the segment lies on one straight edge).
    confidence : fraction of the samples along the segment that lie on the fitted edge, in [0, 1].
    rms_px : RMS distance of those edge points to the fitted line (pixels).
    sigma_px : standard deviation of the fitted line's position at its middle (rms/√inliers).
    edge_uv : array, shape (K, 2): the inlier edge points (for display).
    polarity : +1 when the image is brighter to the right of raw p1 → p2 (u right, v down), −1 else.
    reason : why ok is False ("" when ok).
    """

    seg_uv: np.ndarray
    raw_seg_uv: np.ndarray
    moved_px: float
    ok: bool
    confidence: float
    rms_px: float
    sigma_px: float
    edge_uv: np.ndarray
    polarity: int
    reason: str = ""


def _weighted_tls(P: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Line through points P (K, 2) with weights w (K,) ≥ 0: (point on it (2,), unit direction (2,))."""
    c = (w[:, None] * P).sum(axis=0) / w.sum()
    Q = (P - c) * np.sqrt(w)[:, None]
    _, _, Vt = np.linalg.svd(Q, full_matrices=False)
    return c, Vt[0]


def fit_line_robust(
    P: np.ndarray, w: np.ndarray, inlier_px: float, max_pairs: int = 4000, rng_seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Robust 2D line fit: the pair of points whose line most weight supports, then weighted TLS.

    Parameters
    ----------
    P : array, shape (K, 2), pixels; w : array, shape (K,), positive weights (edge strengths).
    inlier_px : distance (pixels) within which a point supports a line.

    Returns
    -------
    centre (2,), unit direction (2,), inlier mask (K,). ValueError with fewer than 2 points.
    """
    P = np.asarray(P, dtype=float)
    w = np.asarray(w, dtype=float)
    K = len(P)
    if K < 2:
        raise ValueError(f"a line needs at least 2 points, got {K}")
    i, j = np.triu_indices(K, k=1)
    if len(i) > max_pairs:  # deterministic subset of the pairs, wide ones first
        keep = np.random.default_rng(rng_seed).choice(len(i), max_pairs, replace=False)
        i, j = i[keep], j[keep]
    d = P[j] - P[i]
    length = np.linalg.norm(d, axis=1)
    ok = length > 1e-9
    i, j, d, length = i[ok], j[ok], d[ok], length[ok]
    if len(i) == 0:
        raise ValueError("all edge points coincide; no line can be fitted")
    nrm = np.column_stack([-d[:, 1], d[:, 0]]) / length[:, None]
    dist = np.abs(np.einsum("pk,pnk->pn", nrm, P[None, :, :] - P[i][:, None, :]))
    support = ((dist <= inlier_px) * w[None, :]).sum(axis=1)
    b = int(np.argmax(support))
    inl = dist[b] <= inlier_px
    for _ in range(3):
        if inl.sum() < 2:
            break
        c, u = _weighted_tls(P[inl], w[inl])
        n = np.array([-u[1], u[0]])
        new = np.abs((P - c) @ n) <= inlier_px
        if np.array_equal(new, inl):
            break
        inl = new
    c, u = _weighted_tls(P[inl], w[inl])
    return c, u, inl


def snap_segment(
    image: np.ndarray,
    seg_uv: np.ndarray,
    band_px: float = 6.0,
    *,
    sigma_px: float = 1.0,
    refine_px: float = 2.0,
    inlier_px: float = 1.0,
    min_strength: float = 4.0,
    min_confidence: float = 0.5,
    max_rms_px: float = 1.0,
) -> SnapResult:
    """Refine a clicked segment to the image's straight edge near it.

    Parameters
    ----------
    image : array, shape (H, W) or (H, W, 3)
        The video frame (grey or RGB, any numeric dtype).
    seg_uv : array, shape (2, 2), pixels
        The clicked segment (two points along the edge).
    band_px : float
        Search for the edge within ±band_px of the clicked segment.
    sigma_px : float
        Gaussian smoothing before differentiation (pixels).
    refine_px : float
        Half-width of the second search, along the fitted line's normal.
    inlier_px : float
        An edge point within this distance of the line supports it.
    min_strength : float
        Smallest intensity derivative (grey levels per pixel) that counts as an edge.
    min_confidence, max_rms_px : float
        The snap is ``ok`` when at least this fraction of the samples lie on the fitted line and
        their RMS distance to it is at most max_rms_px.

    Returns
    -------
    SnapResult
        ``seg_uv`` is the snapped segment when ``ok``; otherwise the clicked one, with ``reason``.
    """
    seg = as_segment(seg_uv)
    if not band_px > 0 or not refine_px > 0 or not inlier_px > 0:
        raise ValueError(f"band_px, refine_px and inlier_px must be positive, got {band_px}, {refine_px}, {inlier_px}")
    gray = to_gray_f32(image)
    H, W = gray.shape
    margin = band_px + 3.0 * max(sigma_px, 0.5) + 4.0
    lo = np.floor(np.maximum(seg.min(axis=0) - margin, 0)).astype(int)
    hi = np.ceil(np.minimum(seg.max(axis=0) + margin, [W - 1, H - 1])).astype(int)
    if np.any(hi - lo < 3):
        return _refused(seg, "the segment lies outside the image")
    roi = smooth(np.ascontiguousarray(gray[lo[1] : hi[1] + 1, lo[0] : hi[0] + 1]), sigma_px)
    S = seg - lo  # ROI pixel coordinates

    d = S[1] - S[0]
    length = float(np.linalg.norm(d))
    u = d / length
    n = np.array([-u[1], u[0]])  # right of p1 → p2 on the screen (u right, v down)
    n_samples = max(int(np.floor(length)) + 1, 2)
    s = np.linspace(0.0, length, n_samples)
    P = S[0] + s[:, None] * u

    prior = band_px / 2.0  # the operator clicked near the edge: prefer near edges to strong far ones
    hits = search_along_normals(
        roi, P, np.tile(n, (len(P), 1)), band_px, min_strength=min_strength, prior_sigma_px=prior
    )
    if hits.found.sum() < 2:
        return _refused(seg, "no edge found near the segment")
    pos = hits.strength[hits.found] > 0
    w_pos = hits.strength[hits.found][pos].sum()
    w_neg = -hits.strength[hits.found][~pos].sum()
    polarity = 1 if w_pos >= w_neg else -1
    hits = search_along_normals(
        roi, P, np.tile(n, (len(P), 1)), band_px, polarity=polarity, min_strength=min_strength, prior_sigma_px=prior
    )
    if hits.found.sum() < 2:
        return _refused(seg, "no edge of one polarity found near the segment")
    E = hits.points(P, np.tile(n, (len(P), 1)))[hits.found]
    c, v, inl = fit_line_robust(E, np.abs(hits.strength[hits.found]), inlier_px)

    # Refine along the fitted line's own normal, over the clicked extent.
    for _ in range(2):
        if v @ u < 0:
            v = -v
        nv = np.array([-v[1], v[0]])
        a0 = (S[0] - c) @ v
        a1 = (S[1] - c) @ v
        m = max(int(np.floor(abs(a1 - a0))) + 1, 2)
        Q = c + np.linspace(a0, a1, m)[:, None] * v
        N2 = np.tile(nv, (m, 1))
        hits = search_along_normals(
            roi, Q, N2, refine_px, polarity=polarity, min_strength=min_strength, prior_sigma_px=refine_px
        )
        if hits.found.sum() < 2:
            return _refused(seg, "the edge fades out along the segment")
        E = hits.points(Q, N2)[hits.found]
        # Weights: the edge strength, capped at its median; near a vertex two edges' gradients add
        # up and would give the points there (pulled off the line) several times the weight.
        wts = np.abs(hits.strength[hits.found])
        wts = np.minimum(wts, np.median(wts))
        c, v, inl = fit_line_robust(E, wts, inlier_px)
        n_total = m
    nv = np.array([-v[1], v[0]])
    res = (E[inl] - c) @ nv
    rms = float(np.sqrt(np.mean(res**2)))
    n_inl = int(inl.sum())
    # Near a vertex the neighbouring edge pulls the edge points off the line by up to a pixel, within
    # inlier_px, and they tilt a least-squares line: reweight (Tukey, scale from the MAD) so that
    # only the points that agree with the bulk count.
    wi = wts * inl
    for _ in range(5):
        r_all = (E - c) @ nv
        scale = max(0.05, 1.4826 * float(np.median(np.abs(r_all[inl]))))
        z = r_all / (4.685 * scale)
        w_t = wi * np.where(np.abs(z) < 1.0, (1.0 - z * z) ** 2, 0.0)
        if np.count_nonzero(w_t) < 5:
            break
        c, v = _weighted_tls(E, w_t)
        nv = np.array([-v[1], v[0]])
    if v @ u < 0:
        v = -v
    confidence = n_inl / n_total
    snapped = c + ((S - c) @ v)[:, None] * v + lo
    moved = float(np.max(np.linalg.norm(snapped - seg, axis=1)))
    edge_uv = E[inl] + lo
    reason = ""
    if confidence < min_confidence:
        reason = f"only {100 * confidence:.0f} % of the segment lies on a straight edge"
    elif rms > max_rms_px:
        reason = f"the edge points scatter {rms:.2f} px about the line (more than {max_rms_px} px)"
    elif moved > band_px + 2.0 * refine_px:
        reason = f"the segment would move {moved:.1f} px, farther than a snap may ({band_px + 2.0 * refine_px:.0f} px)"
    ok = not reason
    return SnapResult(
        seg_uv=snapped if ok else seg.copy(),
        raw_seg_uv=seg.copy(),
        moved_px=moved,
        ok=ok,
        confidence=float(confidence),
        rms_px=rms,
        sigma_px=rms / np.sqrt(max(n_inl, 1)),
        edge_uv=edge_uv,
        polarity=polarity,
        reason=reason,
    )


def _refused(seg: np.ndarray, reason: str) -> SnapResult:
    return SnapResult(seg.copy(), seg.copy(), 0.0, False, 0.0, float("nan"), float("nan"), np.zeros((0, 2)), 0, reason)
