"""Has the site changed since the frozen frame? A look at the live video around given pixels.

The range finder and the turret measure the site as it is now, while the operator clicked on a frozen
frame that may be seconds or minutes old. Where the live video around the clicked pixels no longer
looks like the frozen frame (an object moved in or out), a measurement made now would be put on
something the frozen frame does not show: the workflows refuse it, or say so.

Test: both patches are blurred (5 px Gaussian, σ 1.2 px: sensor noise and JPEG blocks), their
difference has its median taken off (a change of exposure or lighting shifts the whole patch), and
the patch (17 × 17 px) has changed when more than ``CHANGED_SHARE`` of its pixels differ by more than
``CHANGED_GREY`` grey levels — an object moved in or out changes most of it; the workcell's rendered
noise (σ 2 grey levels, √2·2 in a difference, less after the blur) changes none. The workflows give
pixels inside what they measure (a face, a box), not on its outline, where the background shows.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "camera_shift",
    "changed_share",
    "inside",
    "object_motion_px",
    "CHANGED_GREY",
    "CHANGED_SHARE",
    "HALF_PX",
    "MOVING_PX",
]

CHANGED_GREY = 20.0  # grey levels (0-255) of difference that count as a change
CHANGED_SHARE = 0.08  # share of a patch's pixels that must change
# Half size of the patch around each pixel: the beam lands within a few pixels of the pixel it is aimed
# at. 24 px (a tenth of the workcell's image) saw the parallelepiped moving beside a box that stood still
# and refused to scan the box (a new-operator run: 3 of 5 scans).
HALF_PX = 8
SHIFT_RESPONSE = 0.1  # phase correlation's peak (0-1) above which the whole image is taken to have shifted
# An object moved between two frames when its image moved more than this against the view's own motion (pixels,
# ``object_motion_px``). Measured by bench/moving.py on the workcell's video, frames 0.3 s apart: the box in
# transit 4.8-7.4 px (at 12.6, 13.4, 14.5 s), standing still 0.1 px; the whole view turned 1.2-3° or zoomed 2 %
# 0.06-0.27 px (where the changed-pixel test saw 19-42 % of the box's pixels change: "moving").
MOVING_PX = 1.5


def _grey(image: np.ndarray) -> np.ndarray:
    import cv2

    a = np.asarray(image)
    if a.ndim == 3:
        a = cv2.cvtColor(a, cv2.COLOR_RGB2GRAY)
    return a.astype(np.float32)


def inside(uv: np.ndarray) -> np.ndarray:
    """Pixels to look at for an outline ``uv`` (N, 2): its centre and its points taken a third of the way in
    towards it (on the outline itself the background shows, and something moving behind is no change of
    the object)."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    if not len(uv):
        return uv
    c = uv.mean(axis=0)
    return np.vstack([c, uv + (c - uv) / 3.0])


def camera_shift(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The whole image's shift (dx, dy) from grey image ``a`` to ``b`` (phase correlation, sub-pixel), zero when
    the correlation is not clear (nothing moved, or only a part of the image): what a moving camera does."""
    import cv2

    window = cv2.createHanningWindow((a.shape[1], a.shape[0]), cv2.CV_32F)
    (dx, dy), response = cv2.phaseCorrelate(a, b, window)
    return np.array([dx, dy]) if response > SHIFT_RESPONSE and np.hypot(dx, dy) >= 0.5 else np.zeros(2)


def changed_share(
    frozen: np.ndarray, live: np.ndarray, uv: np.ndarray, half_px: int = HALF_PX, follow_camera: bool = False
) -> float:
    """The largest share of changed pixels over the patches around the pixels ``uv`` (N, 2) between
    the frozen frame and the live one (same size); 0.0 for pixels outside the image. See the module.

    follow_camera : the first image shifted by the whole image's shift first (``camera_shift``): what moved with
    the view (a camera turned or carried) is no change, what moved in the scene still is."""
    import cv2

    a, b = _grey(frozen), _grey(live)
    if a.shape != b.shape:
        raise ValueError(f"the frozen frame is {a.shape[1]}×{a.shape[0]} px and the live one {b.shape[1]}×{b.shape[0]}")
    if follow_camera:
        dx, dy = camera_shift(a, b)
        if dx or dy:
            M = np.array([[1.0, 0.0, dx], [0.0, 1.0, dy]], np.float32)
            a = cv2.warpAffine(a, M, (a.shape[1], a.shape[0]), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    h, w = a.shape
    worst = 0.0
    for u, v in np.asarray(uv, float).reshape(-1, 2):
        if not (np.isfinite(u) and np.isfinite(v)):
            continue
        x0, x1 = max(int(u) - half_px, 0), min(int(u) + half_px + 1, w)
        y0, y1 = max(int(v) - half_px, 0), min(int(v) + half_px + 1, h)
        if x1 - x0 < 5 or y1 - y0 < 5:
            continue
        d = cv2.GaussianBlur(a[y0:y1, x0:x1], (5, 5), 1.2) - cv2.GaussianBlur(b[y0:y1, x0:x1], (5, 5), 1.2)
        d -= np.median(d)
        worst = max(worst, float(np.mean(np.abs(d) > CHANGED_GREY)))
    return worst


def _tracked(a: np.ndarray, b: np.ndarray, mask: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The corners OpenCV finds in frame ``b`` (grey uint8) under ``mask`` (uint8, 255 where to look), (K, 2), and
    where pyramidal Lucas-Kanade puts them in frame ``a`` (K, 2): only those that track back to within 0.5 px."""
    import cv2

    none = np.zeros((0, 2)), np.zeros((0, 2))
    pts = cv2.goodFeaturesToTrack(b, maxCorners=n, qualityLevel=0.01, minDistance=4, mask=mask, blockSize=5)
    if pts is None:
        return none
    lk = dict(winSize=(15, 15), maxLevel=3, criteria=(cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 0.01))
    back, st, _ = cv2.calcOpticalFlowPyrLK(b, a, pts, None, **lk)
    again, st2, _ = cv2.calcOpticalFlowPyrLK(a, b, back, None, **lk)
    ok = (st.ravel() == 1) & (st2.ravel() == 1) & (np.linalg.norm((again - pts).reshape(-1, 2), axis=1) < 0.5)
    return pts.reshape(-1, 2)[ok].astype(float), back.reshape(-1, 2)[ok].astype(float)


def object_motion_px(before: np.ndarray, frame: np.ndarray, outline_uv: np.ndarray) -> float | None:
    """How far (pixels) the object inside the outline ``outline_uv`` (N, 2; its convex hull is taken) moved from
    ``before`` to ``frame`` against the view: the median, over the corners found on it (its hull dilated by
    2 px) and followed by Lucas-Kanade, of the distance between where they were and where the view's own
    motion puts them. The view's motion is a similarity (shift, turn, zoom) fitted by RANSAC to the corners
    followed outside the object (beyond 6 px of it): what moved with the view (a hand-held, turning or
    zooming camera) did not move, and what moves elsewhere in the image (outliers to that fit) does not count.
    With fewer than 6 such corners (a plain background) the whole image's shift (``camera_shift``) stands for
    the view's motion. None when fewer than 3 corners on the object could be followed."""
    import cv2

    a = np.clip(_grey(before), 0, 255).astype(np.uint8)
    b = np.clip(_grey(frame), 0, 255).astype(np.uint8)
    if a.shape != b.shape:
        raise ValueError(f"the frames are {a.shape[1]}×{a.shape[0]} px and {b.shape[1]}×{b.shape[0]} px")
    uv = np.asarray(outline_uv, float).reshape(-1, 2)
    uv = uv[np.all(np.isfinite(uv), axis=1)]
    if len(uv) < 3:
        return None
    obj = np.zeros(b.shape, np.uint8)
    cv2.fillConvexPoly(obj, cv2.convexHull(np.round(uv).astype(np.int32)), 255)

    def grown(px: int) -> np.ndarray:
        return cv2.dilate(obj, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * px + 1, 2 * px + 1)))

    on_b, on_a = _tracked(a, b, grown(2), 40)
    if len(on_b) < 3:
        return None
    out_b, out_a = _tracked(a, b, cv2.bitwise_not(grown(6)), 300)
    M = None
    if len(out_b) >= 6:
        M, _ = cv2.estimateAffinePartial2D(out_b, out_a, method=cv2.RANSAC, ransacReprojThreshold=1.0)
    if M is not None:
        expected = on_b @ M[:, :2].T + M[:, 2]  # where the view's motion puts the object's corners in ``before``
    else:
        expected = on_b - camera_shift(a.astype(np.float32), b.astype(np.float32))
    return float(np.median(np.linalg.norm(on_a - expected, axis=1)))
