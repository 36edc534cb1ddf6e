"""Model-based edge tracking: follow a known object from frame to frame once its pose is known.

Each frame (the "moving edges" tracker of Comport, Marchand et al., 2006, as in ViSP):

1. the model's *visible* edges at the current pose (``BRep.wireframe``: hidden-line removal for
   convex objects, cylinder silhouettes and rims) are projected through C and sampled every
   ``sample_step_px`` pixels, keeping ``vertex_margin_px`` away from the vertices;
2. at each sample the image is searched along the projected edge's normal, ±``search_px``, for
   the edge nearest the prediction (``profiles.search_along_normals``), with the polarity each
   model edge had in the previous frame (which side is brighter) when it is known;
3. the pose is refined by the robust (Tukey) iterated small-motion step on the distances of the
   found points to their projected edges (``core.point_line_pose.refine_point_to_line``);
4. steps 1–3 are repeated once at the refined pose with a narrower search (``refine_search_px``);
5. if the answer fails the support check below while its confidence is good (motion beyond the
   band), after at least one frame followed, the frame is tried once more from the same start,
   coarse to fine (``capture_px``, then the two bands above), before the object is declared lost;
6. the motion model (``motion_model``, issue 27): from the third frame after a pose is given, each
   frame starts from the last pose moved once more by the last step (constant velocity, the step
   T_k · T_{k−1}⁻¹ in the world frame), and the first pass's band is twice the last frame's
   surprise (how far, median over the samples, its pose lay from its prediction), between
   ``search_px`` and ``max_band_px``; the coarse passes keep the robust scale at least an eighth of
   their band (a start off as a whole shares one offset in every residual, whose small spread would
   cut them all); and the retry of step 5 runs on any failure (a start, a stop, a jerk the
   prediction missed), from the prediction;
7. the first frame after a pose is given (which may be degrees or a centimetre off) that fails,
   whatever its confidence, is tried again from the same start coarse to fine from each of
   ``start_capture_px`` (±24 and ±16 px): two hypotheses, each kept only if it passes every lost
   test and turns the given pose by at most ``start_capture_deg`` (10°); when neither is kept, the
   pose is searched near the given one (``start_search``, issue 27: ±5° and ±1 cm, scored on the
   frame's oriented Canny edges by the one-click search's machinery, ``edge_field``) and the
   same capture runs from the 4 best poses found. Of the answers kept, the one nearest the image's
   edges (the support check's distance) is reported, and the frame is lost when another kept answer
   lies apart and fits within ``start_ambiguity_px`` as well (the image fits two poses). A first
   frame that passes from the given pose is judged so too (``start_check``): its answer, given one
   more round of passes, joins the search's answers, the best is reported, and the frame is lost
   when two of them lie apart within ``start_ambiguity_px``.

Which edges are seen is computed once per pass, at the pose the pass starts from
(``visible_segments``), and the support check reuses the last pass's; the frame is smoothed only
in tiles around the samples it searches (``BandSmoothed``). Keeping the first pass's visibility for
the whole frame was tried: from starts 5° off on visp-cube, 6 more wrong frames were then reported
tracked (``bench/tracking.py``, "Lost or tracked" (b)), so it is recomputed after the first pass.

Per frame, ``confidence`` is the fraction of the samples whose edge was found and kept by the
robust fit (weight ≥ 0.5). When it falls below ``lost_confidence``, too few samples remain, or the
solution is unusable, the tracker is *lost*: it keeps the last good pose, stops tracking, and
waits for the operator to give a pose again (``reset``).

Is the pose supported by the image? The confidence alone does not say: a pose that converged
wrongly (a model edge locked on its neighbour, the box shifted by its height) keeps the samples
that happen to lie on an edge and still scores 0.5–0.8. So at the final pose each sample is
searched once more, ±``check_search_px`` along its normal, for the nearest edge of either
polarity (``check_min_strength``), and ``edge_distance_px`` is the mean distance to it (capped at
the band: none found counts as the band). The frame is lost when the confidence is below
``lost_confidence`` (0.5) *or* that distance is above ``max_edge_distance_px`` (1.5 px). Both are
calibrated on a rendered box tracked from starts 5–20° / 1–4 cm off, against its true poses
(``bench/tracking.py``, "lost or tracked"): right poses score ≤ 1.2 px, wrong ones (more than 5°
or 1 cm off) ≥ 1.45 px; checked on the workcell video (the scene's truth) and the real visp-cube
(against the tracker's own run from ViSP's pose), where right poses score ≤ 1.5 px.

Not modelled: occlusion of one part of the model by another (the hidden-line removal is per face,
exact for one convex solid) and by other objects; the robust loss absorbs what they spoil.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from core.brep import BRep
from core.camera import Camera
from core.point_line_pose import PointLineFit, point_line_residuals, refine_point_to_line
from core.pose.uncertainty import (
    CURVED_EDGE_BIAS_PX,
    EDGE_BIAS_PX,
    Priors,
    edge_covariance,
    first_order_share,
    grouped_share,
    model_scale_share,
)
from core.transforms import check_T, exp_so3, invert_T, make_T, orthonormalize, pose_error

from .edge_field import EdgeField, _descend, _distinct, _ModelSamples, _score
from .profiles import search_along_normals, to_gray_f32

__all__ = [
    "TrackResult",
    "TrackDiagnostics",
    "EdgeSamples",
    "EdgeTracker",
    "sample_visible_edges",
    "VisibleSegments",
    "visible_segments",
    "sample_view",
    "BandSmoothed",
    "feature_groups",
    "pose_covariance",
    "pose_covariance_parts",
]


class TrackResult(NamedTuple):
    """One frame's answer: the pose, how much of the model the image supports, and whether lost."""

    T_world_obj: np.ndarray
    confidence: float
    lost: bool


@dataclass(frozen=True)
class EdgeSamples:
    """Sample points along the projected visible edges of a model at one pose.

    uv : array, shape (N, 2), pixels. normals : array, shape (N, 2), unit image normals (the
    projected edge direction turned +90° on the screen). X_obj : array, shape (N, 3), metres, the
    samples on the model (object frame). D_obj : array, shape (N, 3), the edge directions there
    (object frame). feature : array, shape (N,), int, which wireframe feature each sample is on
    (stable across frames, ``Wireframe.feature``: model edge k → k; the other outlines numbered after
    them). chord : array, shape (N,), int, the feature's ``Wireframe.chord`` (−1 on a straight one);
    None: all straight.
    """

    uv: np.ndarray
    normals: np.ndarray
    X_obj: np.ndarray
    D_obj: np.ndarray
    feature: np.ndarray
    chord: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.uv)

    def subset(self, mask: np.ndarray) -> EdgeSamples:
        chord = None if self.chord is None else self.chord[mask]
        return EdgeSamples(
            self.uv[mask], self.normals[mask], self.X_obj[mask], self.D_obj[mask], self.feature[mask], chord
        )


@dataclass(frozen=True)
class TrackDiagnostics:
    """What the last ``track`` call saw, for overlays and reports.

    samples : EdgeSamples of the last pass. matched_uv : array, shape (N, 2), the image edge
    found for each sample (NaN where none). weights : array, shape (N,), robust weights (0 where
    none was found). rms_px : weighted RMS of the kept samples' distances to their edges at the
    final pose. n_samples, n_found, n_inliers : counts. reason : why the tracker is lost ("" if not).
    cov : array, shape (6, 6), covariance of the pose's (δt [m], δr [rad]) at the last pose step: the
    edges' errors, the camera's and the model's priors (``pose_covariance``), or None when there was
    none or the tracker was given no ``priors``. edge_distance_px : the support check's mean distance of the
    samples to the nearest image edge at the final pose (NaN when not reached).
    """

    samples: EdgeSamples
    matched_uv: np.ndarray
    weights: np.ndarray
    rms_px: float
    n_samples: int
    n_found: int
    n_inliers: int
    reason: str = ""
    cov: np.ndarray | None = None
    edge_distance_px: float = float("nan")


def _edges_on_faces_seen(
    model: BRep, T_world_obj: np.ndarray, center_world: np.ndarray, max_angle_deg: float
) -> np.ndarray:
    """(E,) bool: the edge borders a face seen at less than max_angle_deg (edges without faces: True)."""
    c_obj = (np.asarray(center_world) - T_world_obj[:3, 3]) @ T_world_obj[:3, :3]
    v = c_obj - model.face_centroids()
    cos = np.einsum("ij,ij->i", model.face_normals(), v) / np.linalg.norm(v, axis=1)
    seen = cos > np.cos(np.radians(max_angle_deg))
    pairs = model.polyhedron.edge_face_pairs()  # (edge, face it borders), all at once (a per-edge loop: 0.5 s a
    E = len(model.edges)  # one-click search on a model of 384 edges, bench/search.py (e))
    borders = np.bincount(pairs[:, 0], minlength=E) > 0
    return ~borders | (np.bincount(pairs[:, 0], weights=seen[pairs[:, 1]], minlength=E) > 0)


def sample_visible_edges(
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    step_px: float = 6.0,
    vertex_margin_px: float = 4.0,
    image_margin_px: float = 2.0,
    rims: bool = False,
    max_face_angle_deg: float = 75.0,
    n_circle: int = 48,
) -> EdgeSamples:
    """Samples every ``step_px`` along the model's visible edges, as projected through C.

    Straight edges and silhouette lines are sampled between ``vertex_margin_px`` from each end (near a
    vertex the neighbouring edge spoils the search); curves (rims, circles, a sphere's outline:
    polygons of short chords) every ``step_px`` along their chords laid end to end. Only samples in
    front of the camera and inside the image (by ``image_margin_px``) are kept. Positions along a
    segment are mapped to the model by perspective-correct interpolation, so each sample's X_obj
    projects exactly on its pixel.

    rims : also sample the rim circles of solids of revolution. Off by default, as in ViSP, whose
        ``.cao`` cylinders are tracked by their silhouettes only: a modelled cylinder's caps are
        often not edges in the image (in the visp-cube video the real cylinder is taller than its
        model, so the model's top rim lies on the cylinder's side). Free circles (a ``.cao``
        circles block) are edges and are always sampled.
    max_face_angle_deg : a polyhedral edge is sampled only when one of its faces is seen at less
        than this angle from its normal (ViSP's ``angle_disappear``): the far edge of a face seen
        almost edge-on lies a pixel or two from the near one, and the search would confuse them.
    """
    T = np.asarray(T_world_obj, dtype=float)
    view = visible_segments(camera, model, T, rims=rims, max_face_angle_deg=max_face_angle_deg, n_circle=n_circle)
    return sample_view(
        camera, view, T, step_px=step_px, vertex_margin_px=vertex_margin_px, image_margin_px=image_margin_px
    )


@dataclass(frozen=True)
class VisibleSegments:
    """The model's visible segments seen from one pose, in the object frame.

    segments : array, shape (M, 2, 3), metres (object frame). kinds : array, shape (M,), str
    ("edge", "silhouette", "rim", "circle"). feature : array, shape (M,), int, stable ids
    (``EdgeSamples``). chord : array, shape (M,), int, −1 for a straight segment, else its index
    along its closed curve (``BRep.Wireframe.chord``): curves are sampled along their chords laid end
    to end. Default: all straight.
    The tracker computes them once per pass and samples them again at the pass's refined pose for
    the support check (a cylinder's silhouette generators, taken from the pass's starting pose,
    move by r·δ²/2 along the line of sight: 6 µm for r = 4 cm and δ = 1°).
    """

    segments: np.ndarray
    kinds: np.ndarray
    feature: np.ndarray
    chord: np.ndarray | None = None


def visible_segments(
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    rims: bool = False,
    max_face_angle_deg: float = 75.0,
    n_circle: int = 48,
) -> VisibleSegments:
    """The segments ``sample_visible_edges`` samples at pose T_world_obj (object frame; see there)."""
    T = np.asarray(T_world_obj, dtype=float)
    # a mesh's smooth-region contours are sides of its tessellation, not edges of the object: not tracked
    wf = model.wireframe(camera.center, T, n_circle=n_circle, contours=False)
    keep = wf.visible & (rims | (wf.kind != "rim"))
    if len(model.faces) and max_face_angle_deg < 90.0:
        edge = wf.edge_index >= 0
        keep[edge] &= _edges_on_faces_seen(model, T, camera.center, max_face_angle_deg)[wf.edge_index[edge]]
    S = wf.segments[keep]
    S_obj = (S - T[:3, 3]) @ T[:3, :3] if len(S) else np.zeros((0, 2, 3))
    return VisibleSegments(S_obj, wf.kind[keep], wf.feature[keep], wf.chord[keep])


def sample_view(
    camera: Camera,
    view: VisibleSegments,
    T_world_obj: np.ndarray,
    *,
    step_px: float = 6.0,
    vertex_margin_px: float = 4.0,
    image_margin_px: float = 2.0,
) -> EdgeSamples:
    """Samples along the segments of ``view`` placed at pose T_world_obj (see ``sample_visible_edges``)."""
    T = np.asarray(T_world_obj, dtype=float)
    fid = view.feature
    chord = view.chord if view.chord is not None else np.full(len(fid), -1, np.int64)
    empty = EdgeSamples(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
    if len(view.segments) == 0:
        return empty
    A_o, B_o = view.segments[:, 0], view.segments[:, 1]
    A, B = A_o @ T[:3, :3].T + T[:3, 3], B_o @ T[:3, :3].T + T[:3, 3]
    sa, sb = camera.depth(A), camera.depth(B)
    front = (sa > 1e-6) & (sb > 1e-6)
    A, B, A_o, B_o, sa, sb, chord, fid = (
        A[front],
        B[front],
        A_o[front],
        B_o[front],
        sa[front],
        sb[front],
        chord[front],
        fid[front],
    )
    if len(A) == 0:
        return empty
    a, b = camera.project(A), camera.project(B)
    d = b - a
    L = np.linalg.norm(d, axis=1)
    straight = chord < 0
    margin = np.where(straight, vertex_margin_px, 0.0)
    usable = L - 2.0 * margin
    count = np.where(straight, np.floor(np.maximum(usable, 0.0) / step_px).astype(int) + (usable >= 0), 0)
    # Rim chords are short: place their samples every step_px along the chords laid end to end.
    cum_end = np.cumsum(np.where(straight, 0.0, L))
    cum_start = cum_end - np.where(straight, 0.0, L)
    count = np.where(
        straight, count, np.floor(cum_end / step_px).astype(int) - np.floor(cum_start / step_px).astype(int)
    )
    count = np.where(L > 1e-9, count, 0)
    seg_idx = np.repeat(np.arange(len(A)), count)
    if len(seg_idx) == 0:
        return empty
    first = np.cumsum(count) - count
    j = np.arange(len(seg_idx)) - np.repeat(first, count)
    c = count[seg_idx].astype(float)
    Ls = L[seg_idx]
    m = margin[seg_idx]
    # Image parameter λ in [0, 1] along each segment: evenly spread over the usable length.
    lam_straight = (m + (Ls - 2.0 * m) * np.where(c > 1, j / np.maximum(c - 1, 1), 0.5)) / Ls
    first_mark = (np.floor(cum_start / step_px) + 1.0) * step_px  # the first multiple of step_px on the chord
    lam_rim = (first_mark[seg_idx] + j * step_px - cum_start[seg_idx]) / Ls
    lam = np.where(straight[seg_idx], lam_straight, lam_rim)
    sA, sB = sa[seg_idx], sb[seg_idx]
    mu = lam * sA / ((1.0 - lam) * sB + lam * sA)  # perspective-correct parameter on the 3D segment
    X_obj = A_o[seg_idx] + mu[:, None] * (B_o - A_o)[seg_idx]
    uv = a[seg_idx] + lam[:, None] * d[seg_idx]
    dirs = d[seg_idx] / Ls[:, None]
    normals = np.column_stack([-dirs[:, 1], dirs[:, 0]])
    inside = camera.in_image(uv, image_margin_px)
    D_obj = (B_o - A_o)[seg_idx]
    return EdgeSamples(
        uv[inside], normals[inside], X_obj[inside], D_obj[inside], fid[seg_idx][inside], chord[seg_idx][inside]
    )


class BandSmoothed:
    """A frame smoothed (Gaussian, σ = sigma_px) only where the edge search reads it.

    The frame is cut into ``tile_px`` tiles; ``around`` smooths the tiles within ``reach_px`` of
    the given sample points that are not smoothed yet (one OpenCV call per run of tiles along a
    row, each read with a margin of the kernel's radius, and the frame's edges replicated as the
    whole-frame blur does), so the smoothed values are those of the whole frame's blur (to float
    rounding: 1 ulp, 2e-5 grey levels, measured), computed in bands around the projected model
    only. ``img`` is the (H, W) float32 grey image; outside the smoothed tiles its values are
    undefined.
    """

    def __init__(self, frame: np.ndarray, sigma_px: float, tile_px: int = 32):
        im = np.asarray(frame)
        to_gray_f32(im[:3, :3])  # the frame's kind checked (grey or RGB) before anything is read
        self.frame = im
        self.sigma_px = float(sigma_px)
        self.tile = int(tile_px)
        H, W = im.shape[:2]
        self.img = np.empty((H, W), np.float32)
        self.done = np.zeros((-(-H // self.tile), -(-W // self.tile)), bool)
        # OpenCV's float kernel reaches 4σ (ksize = 8σ + 1); two pixels more (and every crop ≥ 3 px).
        self.margin = int(np.ceil(4.0 * self.sigma_px)) + 2

    def around(self, points_uv: np.ndarray, reach_px: float) -> np.ndarray:
        """Smooth every tile within reach_px of the points (N, 2); returns ``img``."""
        P = np.asarray(points_uv, float).reshape(-1, 2)
        if len(P) == 0:
            return self.img
        nty, ntx = self.done.shape
        lo = np.floor((P - reach_px) / self.tile).astype(np.int64)
        hi = np.floor((P + reach_px) / self.tile).astype(np.int64)
        need = np.zeros_like(self.done)
        span = int(np.max(hi - lo)) + 1
        for dy in range(span):
            for dx in range(span):
                ty, tx = np.minimum(lo[:, 1] + dy, hi[:, 1]), np.minimum(lo[:, 0] + dx, hi[:, 0])
                ok = (ty >= 0) & (ty < nty) & (tx >= 0) & (tx < ntx)
                need[ty[ok], tx[ok]] = True
        need &= ~self.done
        for ty in np.flatnonzero(need.any(axis=1)):
            row = np.concatenate([[False], need[ty], [False]])
            starts = np.flatnonzero(row[1:] & ~row[:-1])
            ends = np.flatnonzero(~row[1:] & row[:-1])
            for t0, t1 in zip(starts, ends):
                self._smooth(ty * self.tile, (ty + 1) * self.tile, t0 * self.tile, t1 * self.tile)
            self.done[ty] |= need[ty]
        return self.img

    def _smooth(self, y0: int, y1: int, x0: int, x1: int) -> None:
        H, W = self.img.shape
        y1, x1 = min(y1, H), min(x1, W)
        m = self.margin
        Y0, Y1, X0, X1 = max(0, y0 - m), min(H, y1 + m), max(0, x0 - m), min(W, x1 + m)
        crop = to_gray_f32(self.frame[Y0:Y1, X0:X1])
        if self.sigma_px > 0:
            crop = cv2.GaussianBlur(
                crop, (0, 0), sigmaX=self.sigma_px, sigmaY=self.sigma_px, borderType=cv2.BORDER_REPLICATE
            )
        self.img[y0:y1, x0:x1] = crop[y0 - Y0 : y1 - Y0, x0 - X0 : x1 - X0]


def _reach(half_range_px: float) -> float:
    """How far from a sample ``search_along_normals`` reads (its window, the derivative, bilinear)."""
    return float(np.ceil(half_range_px)) + 4.0


@dataclass(frozen=True)
class _Pass:
    """One sample-search-refine pass: samples, found edge points, their strengths and robust weights."""

    samples: EdgeSamples
    matched: np.ndarray
    found: np.ndarray
    strength: np.ndarray
    weights: np.ndarray
    fit: PointLineFit | None

    @classmethod
    def empty(cls) -> _Pass:
        s = EdgeSamples(np.zeros((0, 2)), np.zeros((0, 2)), np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.int64))
        return cls(s, np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0), np.zeros(0), None)


class EdgeTracker:
    """Follows one known object in a video from an initial pose.

    Parameters
    ----------
    camera : Camera
        The calibrated camera (global model C); the object moves, the camera is fixed in the
        world frame (for a moving camera take the world frame to be the camera's).
    model : BRep
        The object's model (object frame, metres).
    T_world_obj : array, shape (4, 4)
        The object's pose in the first frame to track (from the pose solver or a file).
    sample_step_px : spacing of the samples along the projected edges (pixels).
    search_px : half-width of the first search along the normals (pixels): the largest image
        motion of an edge between two frames that the tracker follows.
    refine_search_px : half-width of the second pass's search (pixels).
    sigma_px : Gaussian smoothing of the frame before differentiation (pixels).
    min_strength : smallest intensity derivative (grey levels per pixel) taken as an edge.
    lost_confidence : below this confidence the tracker declares itself lost (0.5: calibrated so that
        wrongly converged poses are flagged, see above; 0 turns the test off).
    max_edge_distance_px : above this mean distance of the samples to the nearest image edge, at
        the final pose, the tracker is lost (the support check, see above; ``inf`` turns it off).
    check_search_px, check_min_strength : the support check's search band (pixels) and smallest
        edge (grey levels per pixel).
    min_inliers : fewer kept samples than this and the tracker is lost.
    loss : robust loss of the pose step ("tukey", "huber" or "l2").
    rims : also track the rims of cylinders and cones (see ``sample_visible_edges``).
    max_face_angle_deg : edges of faces seen more obliquely than this are not tracked (see
        ``sample_visible_edges``).
    capture_px : when a frame fails the support check although most samples found an edge (the
        signature of motion beyond the band; with ``motion_model``, when it fails any lost test,
        from the prediction), and the tracker has followed at least one frame since
        its pose was given (``reset``: a given pose that fails is the operator's or the matcher's
        to fix, and the matcher's one-step settling must stay quick), it is tracked once more from
        the same start, coarse to fine: passes of ±capture_px, halved while wider than ±search_px, then ±search_px and
        ±refine_search_px (the real cube tracked on every 3rd frame). The answer is kept only if
        it passes every lost test, otherwise the object is lost as before. 0 turns it off.
    start_capture_px : the capture range of a given pose. When the first frame after it (the
        constructor's or ``reset``'s) fails a lost test, whatever its confidence, it is tracked
        again from the same start coarse to fine from each of these bands (passes of ±px, halved
        while wider than ±search_px, then ±search_px and ±refine_search_px). Each answer counts
        only if it passes every lost test and turns the given pose by at most ``start_capture_deg``
        (a rendered box started 20° off settles 58° off with its edges on the image's, 0.8 px);
        when two answers count and their samples lie more than
        ``max_edge_distance_px`` apart (median), the image fits both equally (visp-cube's frames
        140–160 from a start 5° off: the cube 4° and 16 mm off, its edges 0.6 px from the image's)
        and the frame is lost (with ``start_search`` on: only when they fit within
        ``start_ambiguity_px`` alike); else the one nearest the image's edges is kept. From 10 starts 5° / 1 cm off on
        visp-cube, 8 of 10 runs tracked whole instead of 4 (``bench/tracking.py``, "Capture
        range"). Off (no capture) when ``lost_confidence`` is 0 or ``max_edge_distance_px`` is
        infinite: a tracker that does not judge its answer with both tests (auto match's settling
        step, the one-click search's) cannot tell a captured pose from a wrong one.
        Bands not wider than ``search_px`` are left out; ``()`` turns it off.
    motion_model : predict each frame's pose from the last two tracked (constant velocity), widen the
        first band to twice the last prediction's miss (at most ``max_band_px``), and retry coarse to
        fine from ``capture_px`` on any failure (step 6 above). A rendered box moving 30 px a frame
        from rest is followed on every frame within 0.25° / 1 mm; False: the tracker of issue 16,
        lost at the first moving frame (``bench/tracking.py``, "Fast motion"; tests/app/vision/test_track.py).
    max_band_px : the widest first band the motion model asks for (pixels).
    start_search : (degrees, metres, n): when no answer of ``start_capture_px`` counts, poses within
        ±degrees (turned about the model's centre) and ±metres (along and across the line of sight) of
        the given pose are scored on the frame's oriented edges (a 3⁶ grid and its coordinate descent,
        ``edge_field``, as the one-click search scores its poses), and the capture runs again from the
        ``n`` best; the answers count as above. The reach is the issue's start error (5°, 1 cm), not
        tuned. From 10 starts 5° / 1 cm off on sequences it was not developed on, the first frame is
        captured on visp-teabox 9 times instead of 3 and on Castle-simu 10 instead of 7; visp-cube's
        runs are unchanged (``bench/tracking.py``, "Capture range"). It costs the first frame 20–90 ms
        more where it runs. n = 0 turns it off.
    start_ambiguity_px : the first frame's answers that count are ranked by the support check's
        distance; another lying apart (median over the samples, more than ``max_edge_distance_px``)
        within this many pixels of the best makes the frame lost. 0.3 px: the two poses visp-cube's
        frame 140 fits (4° apart) score 0.59 and 0.61 px, and must stay lost; on the rendered box of
        the lost rule's calibration right poses score ≤ 1.2 px and wrong ones ≥ 1.45 px. (Seen later
        on the held-out Castle-simu: a right pose 0.38 px beside one 4° off at 1.36 px, the right one
        kept.) Without the search (``start_search`` off), any other answer apart, as before.
    start_check : also search near the given pose when its first frame passes from it, and judge its
        answer (after one more round of passes from where it stopped) with the search's answers as above:
        the one nearest the image's edges is reported, and the frame is lost when another lies apart
        within ``start_ambiguity_px``. The ±8 px band can settle degrees and centimetres off and pass
        the lost tests: on visp-cube from 10 starts 5° / 1 cm off (seed 1) a first frame 1.6° / 10 mm
        off was reported, and on frame 118 one 5° / 14 mm off; both are replaced by the reference, which
        fits better by more than ``start_ambiguity_px``. Where the image fits two poses alike (visp-cube's
        frames 125–160, two poses 4° / 16 mm apart) the band may settle on a third between or beside them
        (frame 144: 6° / 28 mm off, 0.91 px from the image's edges against the reference's 0.66): lost, as
        a first frame that failed from the given pose would be (tests/app/vision/test_track.py). From 10
        starts 5° / 1 cm off on visp-cube, seeds 0–5 (``bench/tracking.py --only capture``): 0 first frames
        reported wrong (before: 1, seed 3), and 8–10 captured (before 9–10): the 3 runs now lost start in
        frames 129–147, where the image fits both poses; visp-teabox and Castle-simu unchanged. It costs
        every first frame after a given pose the search (30–50 ms CPU on one core, ``bench/tracking.py``).
    """

    # The camera's and the model's priors that join each frame's σ (``pose_covariance``, issue 27): a
    # ``core.pose.uncertainty.Priors`` (a calibration's covariance or a camera file's prior, the model's σ), as
    # mcit track and the Track workflow set it; None (the default: auto match and the one-click search settle
    # poses with the tracker and use no σ of it) computes none, ``diagnostics.cov`` is then None.
    priors: Priors | None = None

    def __init__(
        self,
        camera: Camera,
        model: BRep,
        T_world_obj: np.ndarray,
        *,
        sample_step_px: float = 5.0,
        search_px: float = 8.0,
        refine_search_px: float = 3.0,
        sigma_px: float = 1.0,
        min_strength: float = 3.0,
        vertex_margin_px: float = 4.0,
        lost_confidence: float = 0.5,
        min_inliers: int = 20,
        loss: str = "tukey",
        max_iter: int = 8,
        rims: bool = False,
        max_face_angle_deg: float = 75.0,
        max_edge_distance_px: float = 1.5,
        check_search_px: float = 10.0,
        check_min_strength: float = 2.0,
        capture_px: float = 32.0,
        start_capture_px: tuple[float, ...] = (24.0, 16.0),
        start_capture_deg: float = 10.0,
        motion_model: bool = True,
        max_band_px: float = 24.0,
        start_search: tuple[float, float, int] = (5.0, 0.01, 4),
        start_ambiguity_px: float = 0.3,
        start_check: bool = True,
    ):
        if not isinstance(camera, Camera):
            raise ValueError(f"camera must be a core.camera.Camera, got {type(camera).__name__}")
        if not isinstance(model, BRep):
            raise ValueError(f"model must be a core.brep.BRep, got {type(model).__name__}")
        if not (sample_step_px > 0 and search_px > 0 and refine_search_px > 0):
            raise ValueError("sample_step_px, search_px and refine_search_px must be positive")
        if not 0.0 <= lost_confidence < 1.0:
            raise ValueError(f"lost_confidence must be in [0, 1), got {lost_confidence}")
        if not (max_edge_distance_px > 0 and check_search_px > 0 and check_min_strength > 0):
            raise ValueError(
                "max_edge_distance_px, check_search_px and check_min_strength must be positive, got "
                f"{max_edge_distance_px}, {check_search_px}, {check_min_strength}"
            )
        self.camera = camera
        self.model = model
        self.bounds_m = model.bounds()  # (2, 3) object frame, metres: for the model's scale's share of σ
        self.sample_step_px = float(sample_step_px)
        self.search_px = float(search_px)
        self.refine_search_px = float(refine_search_px)
        self.sigma_px = float(sigma_px)
        self.min_strength = float(min_strength)
        self.vertex_margin_px = float(vertex_margin_px)
        self.lost_confidence = float(lost_confidence)
        self.min_inliers = int(min_inliers)
        self.loss = loss
        self.max_iter = int(max_iter)
        self.rims = bool(rims)
        self.max_face_angle_deg = float(max_face_angle_deg)
        self.max_edge_distance_px = float(max_edge_distance_px)
        self.check_search_px = float(check_search_px)
        self.check_min_strength = float(check_min_strength)
        self.capture_px = float(capture_px)
        self.start_capture_deg = float(start_capture_deg)
        self.motion_model = bool(motion_model)
        # the motion model's coarse-pass scale floor, for a tracker that judges its answers with both tests
        self._judged = self.motion_model and self.lost_confidence > 0 and np.isfinite(self.max_edge_distance_px)
        self.max_band_px = float(max_band_px)
        deg, m, n = start_search
        self.start_search = (float(deg), float(m), int(n) if deg > 0 and m > 0 else 0)
        self.start_ambiguity_px = float(start_ambiguity_px)
        self.start_check = bool(start_check)
        self._scored: tuple[_ModelSamples, _ModelSamples] | None = None  # the pose search's samples, once needed
        self.start_capture_px = tuple(
            float(px) for px in np.atleast_1d(np.asarray(start_capture_px, float)) if px > self.search_px
        )
        self.reset(T_world_obj)

    # ------------------------------------------------------------------ state
    def reset(self, T_world_obj: np.ndarray) -> None:
        """Start (again) from a pose the operator or a solver gave; forgets the edges' polarities."""
        self._T = check_T(T_world_obj, "T_world_obj").copy()
        self._lost = False
        self._polarity: dict[int, float] = {}
        self._followed = False  # a frame tracked since this pose was given (the retry is for motion, not for a start)
        self._velocity: np.ndarray | None = None  # T_k · T_{k−1}⁻¹ of the last two frames tracked (world frame)
        self._motion_px = 0.0  # the image motion (median over the samples, px) of that step
        self._surprise_px = 0.0  # how far (px) the last frame's pose lay from its prediction
        self.diagnostics: TrackDiagnostics | None = None

    @property
    def T_world_obj(self) -> np.ndarray:
        """The current (last good) pose, shape (4, 4)."""
        return self._T.copy()

    @property
    def lost(self) -> bool:
        """True once the tracker has lost the object (until ``reset``)."""
        return self._lost

    # ------------------------------------------------------------------ tracking
    def _view(self, T: np.ndarray) -> VisibleSegments:
        """The visible segments at the frame's starting pose T (computed once per frame)."""
        return visible_segments(self.camera, self.model, T, rims=self.rims, max_face_angle_deg=self.max_face_angle_deg)

    def _samples(self, view: VisibleSegments, T: np.ndarray) -> EdgeSamples:
        return sample_view(self.camera, view, T, step_px=self.sample_step_px, vertex_margin_px=self.vertex_margin_px)

    def _schedule(self) -> tuple[float, ...]:
        """The half-widths of the frame's search passes, coarse to fine.

        With the motion model on (``motion_model``), the first band is widened to twice the last frame's surprise (how
        far its pose lay from its prediction, px), at most ``max_band_px``: the prediction is as
        good as the motion is steady."""
        first = self.search_px
        if self.motion_model and self._velocity is not None:
            first = float(np.clip(2.0 * self._surprise_px, self.search_px, max(self.max_band_px, self.search_px)))
        return (first, self.refine_search_px)

    def _prediction(self) -> np.ndarray:
        """Where the object should be in the next frame: the last pose moved once more by the last step
        (constant velocity, ``motion_model``), or the last pose."""
        if not self.motion_model or self._velocity is None:
            return self._T
        T = self._velocity @ self._T
        return make_T(orthonormalize(T[:3, :3]), T[:3, 3])  # a rotation to rounding, as check_T asks

    def _capture_schedule(self, capture_px: float | None = None) -> tuple[float, ...]:
        """The passes tried when the usual ones lose the object: from ``capture_px`` down (none if off)."""
        out, h = [], self.capture_px if capture_px is None else capture_px
        while h > self.search_px:
            out.append(h)
            h /= 2.0
        return tuple(out) + (self.search_px, self.refine_search_px) if out else ()

    def _pass(
        self, band: BandSmoothed, view: VisibleSegments, T: np.ndarray, half_range: float, min_scale_px: float = 0.3
    ) -> _Pass:
        """Sample the visible edges at pose T, search the image along their normals, refine T."""
        samples = self._samples(view, T)
        n = len(samples)
        if n == 0:
            return _Pass(samples, np.zeros((0, 2)), np.zeros(0, bool), np.zeros(0), np.zeros(0), None)
        pol = np.array([self._polarity.get(int(f), 0.0) for f in samples.feature]) if self._polarity else None
        img = band.around(samples.uv, _reach(half_range))
        hits = search_along_normals(
            img,
            samples.uv,
            samples.normals,
            half_range,
            polarity=pol,
            min_strength=self.min_strength,
            prior_sigma_px=half_range / 2.0,
        )
        matched = hits.points(samples.uv, samples.normals)
        found = hits.found
        w = np.zeros(n)
        if found.sum() < max(self.min_inliers, 6):
            return _Pass(samples, matched, found, hits.strength, w, None)
        fit = refine_point_to_line(
            self.camera,
            T,
            samples.X_obj[found],
            samples.D_obj[found],
            matched[found],
            loss=self.loss,
            max_iter=self.max_iter,
            min_scale_px=min_scale_px,
        )
        w[found] = fit.weights
        return _Pass(samples, matched, found, hits.strength, w, fit)

    def _edge_distance(self, band: BandSmoothed, view: VisibleSegments, T: np.ndarray) -> float:
        """Mean distance (px) of the samples at pose T to the nearest image edge along their normals."""
        s = self._samples(view, T)
        if len(s) == 0:
            return float("inf")
        R = self.check_search_px
        img = band.around(s.uv, _reach(R))
        hits = search_along_normals(
            img, s.uv, s.normals, R, min_strength=self.check_min_strength, prior_sigma_px=R / 4.0
        )
        return float(np.mean(np.where(hits.found, np.minimum(np.abs(hits.offset_px), R), R)))

    def _attempt(self, band: BandSmoothed, view: VisibleSegments, schedule: tuple[float, ...], T_start: np.ndarray):
        """The passes of ``schedule`` from T_start (the prediction or the last good pose; ``view`` is
        seen from there), and the lost tests on their answer.

        Returns (T, the last pass, reason ("" if tracked), confidence, inliers (bool per sample),
        edge_distance_px).
        """
        T = T_start
        reason = ""
        p = None
        try:
            for k, half_range in enumerate(schedule):
                if k:  # which edges are seen, again at the pose the last pass reached
                    view = self._view(T)
                # A coarse pass's robust scale is kept at least an eighth of its band: its start may be
                # off as a whole by pixels (a motion the prediction missed), so that every residual
                # shares one offset and their spread, the scale estimated, is small enough to cut them all.
                # Only for a tracker that judges its answers (a wider pull may settle wrongly; the
                # lost tests catch it): auto match's and the one-click search's settling steps keep theirs.
                floor = max(0.3, half_range / 8.0) if self._judged and k < len(schedule) - 1 else 0.3
                p = self._pass(band, view, T, half_range, floor)
                if p.fit is None:
                    reason = (
                        f"the image shows an edge near only {int(p.found.sum())} of the {len(p.samples)} points "
                        "checked along the model's edges"
                    )
                    break
                T = p.fit.T_world_obj
        except ValueError as exc:  # the pose went behind the camera, or an edge is seen end-on
            reason = f"the pose step failed: {exc}"
        if p is None or reason.startswith("the pose step"):
            p = _Pass.empty()
        n = len(p.samples)
        inl = p.weights >= 0.5
        n_inl = int(inl.sum())
        confidence = n_inl / n if n else 0.0
        if not reason:
            if n_inl < self.min_inliers:
                reason = f"only {n_inl} points along the model's edges support the pose (fewer than {self.min_inliers})"
            elif confidence < self.lost_confidence:
                reason = (
                    f"only {100 * confidence:.0f} % of the model's edges lie on image edges "
                    f"(fewer than {100 * self.lost_confidence:.0f} %): the pose is not supported by the image"
                )
            else:
                # A jump larger than the search band cannot come from edges found within it.
                jump = np.linalg.norm(
                    self.camera.project_obj(T, p.samples.X_obj) - self.camera.project_obj(T_start, p.samples.X_obj),
                    axis=1,
                )
                if np.median(jump) > 2.0 * max(schedule):
                    reason = f"the pose jumped {np.median(jump):.1f} px, more than the search band allows"
        edge_px = float("nan")
        if not reason:
            edge_px = self._edge_distance(band, view, T)
            if edge_px > self.max_edge_distance_px:
                reason = (
                    f"the model's edges lie {edge_px:.1f} px from the image's edges on average (more than "
                    f"{self.max_edge_distance_px:.1f} px): the pose is not supported by the image"
                )
        return T, p, reason, confidence, inl, edge_px

    def _start_hypotheses(self, frame: np.ndarray, T: np.ndarray) -> list[np.ndarray]:
        """Starts near a given pose T for its capture (``start_search``): poses within ±deg and ±m of T
        (turned about the model's centre, moved along and across the line of sight), scored on the frame's
        oriented Canny edges by the one-click search's machinery (``edge_field``: a 3⁶ grid, then
        its coordinate descent), the ``n`` best distinct ones."""
        deg, m, n = self.start_search
        if self._scored is None:  # the model's edge samples scored, coarse and fine, as the one-click search's
            pts = self.model.support_points(16)
            self._centre_obj = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
            self._scored = (
                _ModelSamples(self.model, per_edge=3, n_rim=16, max_edges=96),
                _ModelSamples(self.model, per_edge=10, max_edges=96),
            )
        coarse, fine = self._scored
        c = T[:3, :3] @ self._centre_obj + T[:3, 3]
        z = c - self.camera.center
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 1.0, 0.0] if abs(z[1]) < 0.9 else [1.0, 0.0, 0.0])
        x /= np.linalg.norm(x)
        A = np.stack([x, np.cross(z, x), z])  # across, across, along the line of sight

        def to_pose(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            R = np.stack([exp_so3(r @ A) for r in q[:, 3:]]) @ T[:3, :3]
            return R, c + q[:, :3] @ A - R @ self._centre_obj

        ef = EdgeField(frame)
        step = np.array([m, m, m, np.radians(deg), np.radians(deg), np.radians(deg)])
        grid = np.array(np.meshgrid(*([[-1.0, 0.0, 1.0]] * 6), indexing="ij")).reshape(6, -1).T * step

        def evaluate(q: np.ndarray, tau: float, ms: _ModelSamples = fine) -> np.ndarray:
            return _score(ef, self.camera, ms, *to_pose(q), tau)

        seeds = _distinct(grid, evaluate(grid, 12.0, coarse), step, n)
        if not len(seeds):
            return []
        q, best = _descend(evaluate, grid[seeds], step / 2.0, (6.0, 3.0, 3.0))
        R, t = to_pose(q[np.argsort(best, kind="stable")])
        return [make_T(Ri, ti) for Ri, ti in zip(R, t)]

    def _capture_start(
        self, frame: np.ndarray, band: BandSmoothed, view: VisibleSegments, T_start: np.ndarray, passed=None
    ):
        """The first frame after a given pose: when it failed from it (``passed`` None), tried again coarse
        to fine from the given pose (each of ``start_capture_px``), and when none of these answers counts,
        from the starts the pose search finds near it (``start_search``); when it passed (``passed``, the
        answer from the given pose: ``start_check``), that answer and the searched starts' answers. An
        answer counts when it passes every lost test and turns the given pose by at most
        ``start_capture_deg``. Returns the answer, None when none counts, or why none is reported. Of the
        answers that count the one nearest the image's edges (the support check's distance) is kept,
        unless another lies apart and within ``start_ambiguity_px`` of it (with the search off: any other
        apart): the image fits both, and does not show which is right. The answer from the given pose is
        judged so too: the band may have settled it on the second of two poses the image fits alike."""
        schedule = self._capture_schedule(min(self.start_capture_px))

        def counting(tried):  # the answers that pass every lost test and turn the given pose by at most the limit
            return [r for r in tried if not r[2] and pose_error(r[0], self._T)[0] <= self.start_capture_deg]

        def searched():
            return counting(
                [self._attempt(band, self._view(T), schedule, T) for T in self._start_hypotheses(frame, T_start)]
            )

        if passed is not None:
            # its passes (±search_px, ±refine_search_px) may stop short of the pose they head for (from 5° off:
            # 1.3° short on visp-cube's frame 118) while the searched starts' answers had a pass more: one
            # more round from where it stopped, so that two answers apart are two poses, not one reached twice
            again = self._attempt(band, self._view(passed[0]), self._schedule(), passed[0])
            good = counting([again if not again[2] else passed]) + searched()
        else:
            good = counting(
                [self._attempt(band, view, self._capture_schedule(px), T_start) for px in self.start_capture_px]
            )
            if not good and self.start_search[2] > 0:
                good = searched()
        if not good:
            return None
        good.sort(key=lambda r: r[5])  # nearest the image's edges first
        margin = self.start_ambiguity_px if self.start_search[2] > 0 else np.inf  # of before: any two apart, lost
        X = good[0][1].samples.X_obj
        uv0 = self.camera.project_obj(good[0][0], X)
        for g in good[1:]:
            apart = float(np.median(np.linalg.norm(self.camera.project_obj(g[0], X) - uv0, axis=1)))
            if apart > self.max_edge_distance_px and g[5] <= good[0][5] + margin:
                return (
                    f"near the given pose the image fits two poses whose edges lie {apart:.1f} px apart, "
                    "and does not show which is right"
                )
        return good[0]

    def track(self, frame: np.ndarray) -> TrackResult:
        """Follow the object into the next frame.

        Parameters
        ----------
        frame : array, shape (H, W) or (H, W, 3), the video frame (grey or RGB), of the camera's size.

        Returns
        -------
        TrackResult
            (T_world_obj (4, 4), confidence in [0, 1], lost). When lost, T_world_obj is the last
            good pose and tracking stops until ``reset``; ``diagnostics`` says why.
        """
        if self._lost:
            return TrackResult(self._T.copy(), 0.0, True)
        im = np.asarray(frame)
        to_gray_f32(im[:3, :3] if im.ndim >= 2 else im)  # grey or RGB, or a clear error
        if im.shape[:2] != (self.camera.height, self.camera.width):
            raise ValueError(
                f"frame is {im.shape[1]}×{im.shape[0]} px but the camera is {self.camera.width}×{self.camera.height}; "
                "track frames of the calibrated camera"
            )
        band = BandSmoothed(im, self.sigma_px)  # blurred only around the samples, as they are searched
        T_start = self._prediction()
        view = self._view(T_start)  # which edges are seen from the start (shared by a retry's first pass)
        T, p, reason, confidence, inl, edge_px = self._attempt(band, view, self._schedule(), T_start)
        wide = self._capture_schedule()
        if (
            (reason or (self.start_check and self.start_search[2] > 0))
            and not self._followed
            and self.start_capture_px
            and self.lost_confidence > 0
            and np.isfinite(self.max_edge_distance_px)
        ):
            # The first frame after a given pose: the pose may be degrees or a centimetre off (a
            # stale database pose, clicked edges), beyond the ±search_px band. See start_capture_px.
            passed = None if reason else (T, p, reason, confidence, inl, edge_px)
            first = self._capture_start(im, band, view, T_start, passed)
            if isinstance(first, str):
                reason = first
            elif first is not None:  # else the first attempt's reason stands
                T, p, reason, confidence, inl, edge_px = first
        elif (
            reason
            and wide
            and self._followed
            and (self.motion_model or (np.isfinite(edge_px) and confidence >= self.lost_confidence))
        ):
            # Motion beyond the band: the prediction missed (a start, a stop, a jerk). Once more from
            # the same start, coarse to fine from ±capture_px; kept only if it passes every test, else
            # the first answer stands. Without the motion model only when most samples found their edge
            # but the model does not sit on the image's edges (the retry of issue 16).
            retry = self._attempt(band, view, wide, T_start)
            if not retry[2]:
                T, p, reason, confidence, inl, edge_px = retry
        n = len(p.samples)
        n_inl = int(inl.sum())
        rms = p.fit.rms_px if p.fit is not None else float("nan")
        matched = np.where(p.found[:, None], p.matched, np.nan)
        cov = None
        if p.fit is not None and self.priors is not None:
            cov = pose_covariance(self.camera, T, p.samples, matched, p.weights, self.priors, self.bounds_m)
        self.diagnostics = TrackDiagnostics(
            p.samples, matched, p.weights, rms, n, int(p.found.sum()), n_inl, reason, cov, edge_px
        )
        if reason:
            self._lost = True
            return TrackResult(self._T.copy(), float(confidence), True)
        if self._followed:  # the step from a given pose is its correction, not the object's motion
            X = p.samples.X_obj
            uv = self.camera.project_obj(T, X)
            self._surprise_px = float(np.median(np.linalg.norm(uv - self.camera.project_obj(T_start, X), axis=1)))
            self._motion_px = float(np.median(np.linalg.norm(uv - self.camera.project_obj(self._T, X), axis=1)))
            self._velocity = T @ invert_T(self._T)
        self._T = T
        self._followed = True
        # Remember each feature's polarity (the sign of the derivative along its normal).
        pol: dict[int, float] = {}
        for f in np.unique(p.samples.feature[inl]):
            sel = inl & (p.samples.feature == f)
            pol[int(f)] = float(np.sign(np.median(p.strength[sel])))
        self._polarity = pol
        return TrackResult(T.copy(), float(confidence), False)


def feature_groups(s: EdgeSamples, arc: int = 8) -> np.ndarray:
    """Which edge each sample lies on, as group ids: a straight edge or a silhouette line is one group
    (its feature), a curve (a rim, a circle, a sphere's outline) arcs of ``arc`` chords (60° of 48):
    the curve's chords have consecutive features from ``feature − chord`` (``Wireframe.chord``)."""
    f = np.asarray(s.feature, np.int64)
    if s.chord is None:
        return f
    chord = np.asarray(s.chord, np.int64)
    return np.where(chord < 0, f, f - chord + chord // arc)


def pose_covariance(
    camera: Camera,
    T: np.ndarray,
    samples: EdgeSamples,
    matched: np.ndarray,
    weights: np.ndarray,
    priors: Priors,
    bounds_m: np.ndarray | None = None,
) -> np.ndarray | None:
    """(6, 6) covariance of (δt [m], δr [rad]) of a pose fitted to edges found along the samples' normals
    (``matched``, NaN where none; ``weights``, the fit's): the sum of ``pose_covariance_parts``. None with fewer
    than 6 samples kept."""
    parts = pose_covariance_parts(camera, T, samples, matched, weights, priors, bounds_m)
    if parts is None:
        return None
    cov = sum(parts.values())
    return 0.5 * (cov + cov.T)


def pose_covariance_parts(
    camera: Camera,
    T: np.ndarray,
    samples: EdgeSamples,
    matched: np.ndarray,
    weights: np.ndarray,
    priors: Priors,
    bounds_m: np.ndarray | None = None,
) -> dict[str, np.ndarray] | None:
    """``pose_covariance``'s shares by name: "edges" (a noise of each sample plus an offset and a tilt shared by
    each edge's samples, ``core.pose.uncertainty.edge_covariance``), "model" and "camera" (by first order, the
    priors of issue 27; "camera" only with ``priors.camera_cov``), each (6, 6). "model" holds each edge's own
    offset and the model's per-dimension scale (its bounds ``bounds_m`` (2, 3), object frame, the tracker's model's;
    None: the samples' own). None with fewer than 6 samples kept."""
    keep = np.isfinite(matched[:, 0]) & (weights > 0)
    if keep.sum() < 6:
        return None
    s, m, w = samples.subset(keep), matched[keep], weights[keep]
    try:
        r, J, n = point_line_residuals(camera, T, s.X_obj, s.D_obj, m)
        groups = feature_groups(s)
        curved = np.zeros(len(s), bool) if s.chord is None else s.chord >= 0
        floor = np.where(curved, CURVED_EDGE_BIAS_PX, EDGE_BIAS_PX)
        uv = camera.project_obj(T, s.X_obj)
        parts = {"edges": edge_covariance(J, r, w, groups, floor, 6, uv, n)}
        # The residuals' first-order moves, written out (the tracker runs this every frame): a model point moved
        # by d (world axes) moves r by J[:, :3] d (r = n·(m − π(X)), ∂r/∂δt = −n·∂π/∂X); C moved by δC moves it
        # by −n·∂π/∂C δC, with ∂u/∂C₀ = X̃/h₂, ∂u/∂C₂ = −u X̃/h₂ (v likewise).
        parts["model"] = grouped_share(J, w, lambda d: J[:, :3] @ d, groups, priors.model_sigma_m)
        # the model's points moved to scale(X) in its frame move by R (scale(X) − X) in the world
        b = np.array([s.X_obj.min(axis=0), s.X_obj.max(axis=0)]) if bounds_m is None else bounds_m
        scaled = lambda scale: np.einsum("nk,nk->n", J[:, :3], (scale(s.X_obj) - s.X_obj) @ T[:3, :3].T)  # noqa: E731
        parts["model"] = parts["model"] + model_scale_share(J, w, scaled, b, priors.model_sigma_m)
        if priors.camera_cov is not None:
            Xh = np.column_stack([s.X_obj @ T[:3, :3].T + T[:3, 3], np.ones(len(s))])
            h2 = Xh @ camera.C[2]
            dC = -np.hstack([n[:, :1] * Xh, n[:, 1:] * Xh, -(n * uv).sum(axis=1, keepdims=True) * Xh]) / h2[:, None]
            parts["camera"] = first_order_share(J, w, lambda d: dC @ d, priors.camera_cov)
    except ValueError:  # a sample behind the camera or an edge seen end-on at a moved camera
        return None
    return parts
