"""The 1D edge search along normals shared by edge snapping and tracking ("moving edges").

Around each sample point p with unit normal n, the smoothed image is read along the normal,
``I(p + t·n)`` for offsets t in pixels, and differentiated in t (central differences). An edge
is a local maximum of the directional derivative ``polarity · dI/dt`` (or of its magnitude when
the polarity is not known); the chosen maximum is refined to sub-pixel by a parabola through it
and its two neighbours. Reading the image by bilinear interpolation along the exact normal
(numpy, no fixed-point table) keeps the sub-pixel position unbiased for lines at any angle.

Pixels: u right, v down, origin at the centre of the top-left pixel (DESIGN.md).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

__all__ = ["EdgeHits", "to_gray_f32", "smooth", "bilinear", "search_along_normals"]


@dataclass(frozen=True)
class EdgeHits:
    """Result of ``search_along_normals`` for N samples.

    offset_px : array, shape (N,), signed offset of the edge along each normal (pixels); NaN where
    none was found. strength : array, shape (N,), the signed directional derivative at the edge
    (grey levels per pixel; its sign is the edge's polarity along n); 0 where none was found.
    found : array, shape (N,), bool.
    """

    offset_px: np.ndarray
    strength: np.ndarray
    found: np.ndarray

    def points(self, points_uv: np.ndarray, normals_uv: np.ndarray) -> np.ndarray:
        """Edge points (N, 2), pixels: ``p + offset·n`` (NaN rows where nothing was found)."""
        return np.asarray(points_uv, float) + self.offset_px[:, None] * np.asarray(normals_uv, float)


def to_gray_f32(image: np.ndarray) -> np.ndarray:
    """Grey float32 image (H, W) from a grey (H, W) or RGB (H, W, 3) image of any numeric dtype."""
    im = np.asarray(image)
    if im.ndim == 3 and im.shape[2] in (3, 4):
        im = (
            cv2.cvtColor(np.ascontiguousarray(im[:, :, :3]), cv2.COLOR_RGB2GRAY)
            if im.dtype == np.uint8
            else im[:, :, :3].mean(axis=2)
        )
    if im.ndim != 2 or im.shape[0] < 3 or im.shape[1] < 3:
        raise ValueError(
            f"image must be grey (H, W) or RGB (H, W, 3) of at least 3 × 3 pixels, got shape {np.shape(image)}"
        )
    return np.ascontiguousarray(im, dtype=np.float32)


def smooth(gray: np.ndarray, sigma_px: float) -> np.ndarray:
    """Gaussian smoothing (OpenCV) of a grey float32 image; sigma_px ≤ 0 returns it unchanged."""
    if sigma_px <= 0:
        return gray
    return cv2.GaussianBlur(
        gray, (0, 0), sigmaX=float(sigma_px), sigmaY=float(sigma_px), borderType=cv2.BORDER_REPLICATE
    )


def bilinear(img: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Bilinear interpolation of a (H, W) image at pixels (u, v) of any equal shapes.

    Coordinates are clamped to the image (callers mask samples outside it themselves).
    """
    H, W = img.shape
    u = np.clip(u, 0.0, W - 1.000001)
    v = np.clip(v, 0.0, H - 1.000001)
    x0 = u.astype(np.intp)
    y0 = v.astype(np.intp)
    fx = u - x0
    fy = v - y0
    flat = img.ravel()
    i00 = y0 * W + x0
    a = flat[i00]
    b = flat[i00 + 1]
    c = flat[i00 + W]
    d = flat[i00 + W + 1]
    top = a + fx * (b - a)
    bot = c + fx * (d - c)
    return top + fy * (bot - top)


def search_along_normals(
    img: np.ndarray,
    points_uv: np.ndarray,
    normals_uv: np.ndarray,
    half_range_px: float,
    *,
    polarity: np.ndarray | float | None = None,
    min_strength: float = 4.0,
    prior_sigma_px: float = np.inf,
    step_px: float = 1.0,
) -> EdgeHits:
    """Find, for each sample, the edge along its normal within ±half_range_px.

    Parameters
    ----------
    img : array, shape (H, W), float32
        The grey image, already smoothed (``smooth``): the derivative is taken on it as is.
    points_uv : array, shape (N, 2), pixels
        Sample points (the predicted edge positions).
    normals_uv : array, shape (N, 2)
        Unit normals (image directions) along which to search.
    half_range_px : float
        Search ±this many pixels along each normal.
    polarity : array (N,) or scalar in {−1, 0, +1}, optional
        Expected sign of dI/dt at the edge (+1: brighter in the direction of n); 0 or None
        accepts either sign (the magnitude is maximised).
    min_strength : float
        Smallest |dI/dt| (grey levels per pixel) accepted as an edge.
    prior_sigma_px : float
        Candidates are scored by strength × exp(−t²/2σ²): a finite σ prefers edges near the
        prediction over stronger ones farther away (tracking); ∞ takes the strongest (snapping).
    step_px : float
        Spacing of the samples along the normal.

    Returns
    -------
    EdgeHits
        Sub-pixel offsets, signed strengths and found flags, one per sample. A sample whose
        search window leaves the image is not found.
    """
    P = np.asarray(points_uv, dtype=float).reshape(-1, 2)
    Nrm = np.asarray(normals_uv, dtype=float).reshape(-1, 2)
    if P.shape != Nrm.shape:
        raise ValueError(f"points_uv {P.shape} and normals_uv {Nrm.shape} must have the same shape (N, 2)")
    if not (half_range_px > 0 and step_px > 0):
        raise ValueError(f"half_range_px and step_px must be positive, got {half_range_px}, {step_px}")
    if img.ndim != 2:
        raise ValueError(f"img must be a grey (H, W) image, got shape {img.shape}")
    n = len(P)
    if n == 0:
        return EdgeHits(np.zeros(0), np.zeros(0), np.zeros(0, bool))
    k_half = int(np.ceil(half_range_px / step_px))
    # Offsets of the intensity samples: the derivative at ±k_half needs one more on each side,
    # a local maximum there needs one more again.
    t = step_px * np.arange(-k_half - 2, k_half + 3)
    U = P[:, :1] + t[None, :] * Nrm[:, :1]
    V = P[:, 1:] + t[None, :] * Nrm[:, 1:]
    H, W = img.shape
    inside = (U[:, 0] >= 0) & (U[:, -1] >= 0) & (U[:, 0] <= W - 1) & (U[:, -1] <= W - 1)
    inside &= (V[:, 0] >= 0) & (V[:, -1] >= 0) & (V[:, 0] <= H - 1) & (V[:, -1] <= H - 1)
    prof = bilinear(img, U, V)
    D = (prof[:, 2:] - prof[:, :-2]) / (2.0 * step_px)  # derivative at t[1:-1]
    td = t[1:-1]
    if polarity is None:
        pol = np.zeros(n)
    else:
        pol = np.broadcast_to(np.asarray(polarity, dtype=float), (n,))
    S = np.where(pol[:, None] == 0, np.abs(D), D * np.sign(pol)[:, None])
    mid = S[:, 1:-1]
    is_max = (mid >= S[:, :-2]) & (mid > S[:, 2:]) & (mid >= min_strength)
    tm = td[1:-1]
    in_range = np.abs(tm) <= half_range_px + 1e-9
    score = np.where(is_max & in_range[None, :], mid, -np.inf)
    if np.isfinite(prior_sigma_px):
        score = score * np.exp(-0.5 * (tm / prior_sigma_px) ** 2)[None, :]
    best = np.argmax(score, axis=1)
    rows = np.arange(n)
    found = np.isfinite(score[rows, best]) & inside
    s0 = S[rows, best]
    s1 = S[rows, best + 1]
    s2 = S[rows, best + 2]
    denom = s0 - 2.0 * s1 + s2
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(denom < 0, 0.5 * (s0 - s2) / denom, 0.0)
    frac = np.clip(frac, -0.5, 0.5)
    offset = np.where(found, tm[best] + frac * step_px, np.nan)
    strength = np.where(found, D[rows, best + 1], 0.0)
    return EdgeHits(offset, strength, found)
