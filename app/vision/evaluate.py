"""How well a posed model sits on an image: the distance of its projected edges to the image's edges.

An independent yardstick for the tracker (it shares nothing with the tracker's own edge search):
the image's edges are OpenCV's Canny edge pixels, each with its gradient orientation (Sobel);
the model's visible edges are sampled every ``step_px`` along their projection; each sample's
distance is the Euclidean distance to the nearest Canny pixel whose gradient is within
``orient_tol_deg`` of the projected edge's normal (either sign): an oriented chamfer distance,
read from one distance transform per orientation bin (evaluated only at the pixels around the
samples, see ``OrientedEdges``; computed once per frame). Texture edges across the model's edges do
not count; distances are capped at ``max_px`` (an edge not found at all counts as ``max_px``).

Canny pixels sit at pixel centres, so a perfectly posed model still scores about 0.25 px (the
mean distance of a line to the pixel centres along it).
"""

from __future__ import annotations

import threading
import zlib
from collections import OrderedDict
from dataclasses import dataclass

import cv2
import numpy as np

from core.brep import BRep
from core.camera import Camera

from .profiles import to_gray_f32
from .track import sample_visible_edges

__all__ = [
    "OrientedEdges",
    "EdgeDistance",
    "oriented_edges",
    "edge_distance",
    "outline_seen",
    "sample_distances",
    "prepare_frame",
]

_CACHE: OrderedDict = OrderedDict()  # the last few frames' OrientedEdges, by contents and options
_CACHE_SIZE = 4
_CACHE_LOCK = threading.Lock()


class OrientedEdges:
    """An image's Canny edges split by gradient orientation, read as distances.

    The distance of any pixel to the nearest edge pixel of an orientation bin (the bin's distance
    transform) is computed only where it is asked for (``distance``): each bin's edge pixels are put
    in a k-d tree on first use, and only the pixels around the samples are queried. The values are
    OpenCV's exact Euclidean distance transform (``DIST_MASK_PRECISE``) at those pixels, so the
    scores are those of the whole-frame transforms, at a fraction of the cost.

    bin_deg : bin spacing (degrees). ``dist`` : array, shape (B, H, W), every bin's whole distance
    transform (computed on first access; scoring does not need it).
    """

    def __init__(
        self, edges_uv: np.ndarray, theta_deg: np.ndarray, shape: tuple[int, int], bin_deg: float, orient_tol_deg: float
    ):
        self.edges_uv = edges_uv
        self.theta_deg = theta_deg
        self.shape = shape
        self.bin_deg = float(bin_deg)
        self.orient_tol_deg = float(orient_tol_deg)
        self.n_bins = int(round(180.0 / self.bin_deg))
        self._trees: dict[int, object] = {}
        self._dist: np.ndarray | None = None

    def __len__(self) -> int:
        return self.n_bins

    def _in_bin(self, b: int) -> np.ndarray:
        diff = np.abs((self.theta_deg - b * self.bin_deg + 90.0) % 180.0 - 90.0)
        return diff <= self.orient_tol_deg

    def prepare(self) -> OrientedEdges:
        """Build every bin's k-d tree now (each is otherwise built on its first ``distance``)."""
        from scipy.spatial import cKDTree

        for b in range(self.n_bins):
            if b not in self._trees:
                pts = self.edges_uv[self._in_bin(b)]
                self._trees[b] = cKDTree(pts) if len(pts) else None
        return self

    def distance(self, b: int, u: np.ndarray, v: np.ndarray, max_px: float) -> np.ndarray:
        """Bin b's distance transform read bilinearly at pixels (u, v), capped at max_px."""
        from scipy.spatial import cKDTree

        H, W = self.shape
        u = np.clip(np.asarray(u, float), 0.0, W - 1.000001)
        v = np.clip(np.asarray(v, float), 0.0, H - 1.000001)
        if b not in self._trees:
            pts = self.edges_uv[self._in_bin(b)]
            self._trees[b] = cKDTree(pts) if len(pts) else None
        tree = self._trees[b]
        if tree is None:
            return np.full(u.shape, float(max_px))
        x0, y0 = u.astype(np.intp), v.astype(np.intp)
        fx, fy = u - x0, v - y0
        # The four pixels around each sample, each queried once. Neighbouring pixels' distances
        # differ by at most √2, so beyond max_px + 1.5 every corner is beyond max_px: capped anyway.
        corners = np.stack([y0 * W + x0, y0 * W + x0 + 1, (y0 + 1) * W + x0, (y0 + 1) * W + x0 + 1], axis=-1)
        uniq, inv = np.unique(corners.ravel(), return_inverse=True)
        q = np.column_stack([uniq % W, uniq // W]).astype(float)
        dq, _ = tree.query(q, distance_upper_bound=float(max_px) + 1.5)
        dq = np.where(np.isfinite(dq), dq, 1e6).astype(np.float32)[inv].reshape(corners.shape)
        top = dq[..., 0] + fx * (dq[..., 1] - dq[..., 0])
        bot = dq[..., 2] + fx * (dq[..., 3] - dq[..., 2])
        return np.minimum(top + fy * (bot - top), max_px)

    @property
    def dist(self) -> np.ndarray:
        if self._dist is None:
            H, W = self.shape
            dist = np.empty((self.n_bins, H, W), np.float32)
            for b in range(self.n_bins):
                sel = self._in_bin(b)
                src = np.full((H, W), 255, np.uint8)
                src[self.edges_uv[sel, 1].astype(int), self.edges_uv[sel, 0].astype(int)] = 0
                dist[b] = (
                    cv2.distanceTransform(src, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) if sel.any() else np.float32(1e6)
                )
            self._dist = dist
        return self._dist


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
    image: np.ndarray,
    *,
    canny_low: float = 10.0,
    canny_high: float = 30.0,
    sigma_px: float = 1.0,
    orient_tol_deg: float = 30.0,
    n_bins: int = 12,
) -> OrientedEdges:
    """Canny edges of an image (grey or RGB) split by gradient orientation, to read as distances.

    Computed once per frame: a call on an image of the same contents and options returns the
    same ``OrientedEdges`` (the last few frames are kept), so auto match's candidates and a
    benchmark's scores share them.
    """
    im = np.ascontiguousarray(image)
    key = (
        im.shape,
        im.dtype.str,
        zlib.crc32(im.view(np.uint8).reshape(-1)) if im.size else 0,
        float(canny_low),
        float(canny_high),
        float(sigma_px),
        float(orient_tol_deg),
        int(n_bins),
    )
    with _CACHE_LOCK:
        hit = _CACHE.get(key)
        if hit is not None:
            _CACHE.move_to_end(key)
            return hit
    gray = to_gray_f32(im)
    blur = cv2.GaussianBlur(gray, (0, 0), sigma_px) if sigma_px > 0 else gray
    g8 = np.clip(np.round(blur), 0, 255).astype(np.uint8)
    ys, xs = np.nonzero(cv2.Canny(g8, canny_low, canny_high, L2gradient=True))
    gx = cv2.Sobel(blur, cv2.CV_32F, 1, 0, ksize=3)[ys, xs]
    gy = cv2.Sobel(blur, cv2.CV_32F, 0, 1, ksize=3)[ys, xs]
    theta = np.degrees(np.arctan2(gy, gx)) % 180.0
    out = OrientedEdges(np.column_stack([xs, ys]).astype(float), theta, gray.shape, 180.0 / n_bins, orient_tol_deg)
    with _CACHE_LOCK:
        _CACHE[key] = out
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.popitem(last=False)
    return out


def prepare_frame(image: np.ndarray) -> None:
    """Compute a frame's oriented edges and their k-d trees ahead of use (the interface does it in
    the background when a workflow freezes a frame: auto match and the one-click search then find
    them ready, a few ms less on the operator's wait)."""
    oriented_edges(image).prepare()


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
    d = sample_distances(oe, s, max_px)
    return EdgeDistance(d, s.uv, float(d.mean()), float(np.median(d)), float(np.mean(d < max_px)))


def outline_seen(image: np.ndarray, camera: Camera, model: BRep, T_world_obj: np.ndarray, within_px: float = 1.5):
    """The share of the model's visible outline at pose ``T_world_obj`` that lies within ``within_px`` of an
    image edge of its orientation (``edge_distance``), or None when none of it is in view. A model drawn where
    the image shows it scores most of it; one drawn where the object is not (moved, or a wrong pose that fits
    the clicks) scores little."""
    d = edge_distance(image, camera, model, T_world_obj, max_px=10.0)
    return float(np.mean(d.distances_px <= within_px)) if len(d.distances_px) else None


def sample_distances(oe: OrientedEdges, samples, max_px: float = 10.0) -> np.ndarray:
    """(N,) distance (pixels, capped at max_px) of each edge sample (``track.EdgeSamples``) to the
    nearest image edge of its orientation."""
    normal_deg = np.degrees(np.arctan2(samples.normals[:, 1], samples.normals[:, 0])) % 180.0
    b = np.round(normal_deg / oe.bin_deg).astype(int) % len(oe)
    d = np.empty(len(samples))
    for k in np.unique(b):
        sel = b == k
        d[sel] = oe.distance(int(k), samples.uv[sel, 0], samples.uv[sel, 1], max_px)
    return d
