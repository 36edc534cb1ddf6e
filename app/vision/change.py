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

__all__ = ["camera_shift", "changed_share", "inside", "CHANGED_GREY", "CHANGED_SHARE", "HALF_PX"]

CHANGED_GREY = 20.0  # grey levels (0-255) of difference that count as a change
CHANGED_SHARE = 0.08  # share of a patch's pixels that must change
# Half size of the patch around each pixel: the beam lands within a few pixels of the pixel it is aimed
# at. 24 px (a tenth of the workcell's image) saw the parallelepiped moving beside a box that stood still
# and refused to scan the box (a new-operator run: 3 of 5 scans).
HALF_PX = 8
SHIFT_RESPONSE = 0.1  # phase correlation's peak (0-1) above which the whole image is taken to have shifted


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
