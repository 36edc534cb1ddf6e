"""How well a posed model sits on an image: the distance of its projected edges to the image's edges.

An independent yardstick for the tracker (it shares nothing with the tracker's own edge search):
the image's edges are OpenCV's Canny edge pixels, each with its gradient orientation (Sobel);
the model's visible edges are sampled every ``step_px`` along their projection; each sample's
distance is the Euclidean distance to the nearest Canny pixel whose gradient is within
``orient_tol_deg`` of the projected edge's normal (either sign): an oriented chamfer distance,
read from one distance transform per orientation bin. Texture edges across the model's edges do
not count; distances are capped at ``max_px`` (an edge not found at all counts as ``max_px``).

Canny pixels sit at pixel centres, so a perfectly posed model still scores about 0.25 px (the
mean distance of a line to the pixel centres along it).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from core.brep import BRep
from core.camera import Camera

from .profiles import bilinear, to_gray_f32
from .track import sample_visible_edges

__all__ = ["OrientedEdges", "EdgeDistance", "oriented_edges", "edge_distance"]


@dataclass(frozen=True)
class OrientedEdges:
    """An image's Canny edges as one distance transform (H, W) float32 per orientation bin.

    dist : array, shape (B, H, W), pixels to the nearest edge pixel whose gradient direction
    (mod 180°) is within the bin's tolerance of the bin's centre. bin_deg : bin spacing (degrees).
    """

    dist: np.ndarray
    bin_deg: float


@dataclass(frozen=True)
class EdgeDistance:
    """Distances of a posed model's projected edges to the image's edges.

    distances_px : array, shape (N,), per sample (capped at max_px). uv : array, shape (N, 2).
    mean_px, median_px : over the samples. matched : fraction of the samples with an edge closer
    than max_px.
    """

    distances_px: np.ndarray
    uv: np.ndarray
    mean_px: float
    median_px: float
    matched: float


def oriented_edges(
    image: np.ndarray, *, canny_low: float = 10.0, canny_high: float = 30.0, sigma_px: float = 1.0, orient_tol_deg: float = 30.0, n_bins: int = 12
) -> OrientedEdges:
    """Canny edges of an image (grey or RGB) split by gradient orientation, as distance transforms."""
    gray = to_gray_f32(image)
    blur = cv2.GaussianBlur(gray, (0, 0), sigma_px) if sigma_px > 0 else gray
    g8 = np.clip(np.round(blur), 0, 255).astype(np.uint8)
    edges = cv2.Canny(g8, canny_low, canny_high, L2gradient=True) > 0
    gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3)
    gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3)
    theta = np.degrees(np.arctan2(gy, gx)) % 180.0
    bin_deg = 180.0 / n_bins
    H, W = gray.shape
    dist = np.empty((n_bins, H, W), np.float32)
    for b in range(n_bins):
        centre = b * bin_deg
        diff = np.abs((theta - centre + 90.0) % 180.0 - 90.0)
        mask = edges & (diff <= orient_tol_deg)
        src = np.where(mask, 0, 255).astype(np.uint8)
        dist[b] = cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) if mask.any() else np.float32(1e6)
    return OrientedEdges(dist, bin_deg)


def edge_distance(
    image_or_edges: np.ndarray | OrientedEdges,
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    step_px: float = 2.0,
    max_px: float = 10.0,
    vertex_margin_px: float = 4.0,
    rims: bool = False,
) -> EdgeDistance:
    """Oriented chamfer distance of the model's visible projected edges to the image's Canny edges.

    image_or_edges : the frame (grey or RGB), or its ``oriented_edges`` (to score several poses).
    rims : also score the rims of solids of revolution (``track.sample_visible_edges``).
    """
    oe = image_or_edges if isinstance(image_or_edges, OrientedEdges) else oriented_edges(image_or_edges)
    s = sample_visible_edges(camera, model, T_world_obj, step_px=step_px, vertex_margin_px=vertex_margin_px, rims=rims)
    if len(s) == 0:
        return EdgeDistance(np.zeros(0), np.zeros((0, 2)), float("nan"), float("nan"), 0.0)
    normal_deg = np.degrees(np.arctan2(s.normals[:, 1], s.normals[:, 0])) % 180.0
    b = np.round(normal_deg / oe.bin_deg).astype(int) % len(oe.dist)
    d = np.empty(len(s))
    for k in np.unique(b):
        sel = b == k
        d[sel] = bilinear(oe.dist[k], s.uv[sel, 0], s.uv[sel, 1])
    d = np.minimum(d, max_px)
    return EdgeDistance(d, s.uv, float(d.mean()), float(np.median(d)), float(np.mean(d < max_px)))
