"""Where a workflow gets the video frame the operator clicked on (for snapping, matching, tracking).

A *frame provider* is a callable ``provider(t_s) -> image | None``: the frame (RGB or grey uint8,
(H, W, 3) or (H, W)) that shows scene time ``t_s`` seconds, or None when there is none. ``Site``
holds one (``Site.frame_at``):

* ``SceneVideoFrames`` — the scene's prerecorded video, decoded at the frame that shows ``t_s``
  (``VideoSpec.frame_index``): what a headless replay (``mcit demo``) clicked on. The default of
  ``Site`` when the scene has a video file.
* ``GrabberFrames`` — the interface's video grabber: its latest frame, i.e. what the operator
  sees when the click arrives (``t_s`` is ignored). ``InterfaceServer`` installs it.
* any callable, e.g. ``lambda t: frames[int(round(t * fps))]`` in tests.
"""

from __future__ import annotations

import collections
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["FrameProvider", "SceneVideoFrames", "GrabberFrames"]

FrameProvider = Callable[[float], "np.ndarray | None"]


class SceneVideoFrames:
    """Frames of a prerecorded video file by scene time (OpenCV, thread-safe, a few cached).

    Parameters
    ----------
    video : app.scene.VideoSpec
        The file, its frame rate and length; frame k shows scene time k / fps.
    cache : how many decoded frames to keep (clicks and tracking revisit the same ones).
    lens : app.undistort.LensDistortion or None: the scene camera's lens; each frame is undistorted
        once when decoded (C holds in the undistorted frames).
    """

    def __init__(self, video: Any, cache: int = 8, lens: Any = None):
        self.video = video
        self.lens = lens
        self.path = Path(video.path)
        if not self.path.is_file():
            raise ValueError(
                f"the scene's video {self.path} does not exist: render it (mcit render) or give another source"
            )
        self._cap = None
        self._lock = threading.Lock()
        self._cache: collections.OrderedDict[int, np.ndarray] = collections.OrderedDict()
        self._size = int(cache)
        self._next = -1  # the frame the capture reads next (sequential reads skip the seek)

    def index(self, t_s: float) -> int:
        """The frame showing scene time t_s (nearest, clamped to the video)."""
        return int(self.video.frame_index(float(t_s)))

    def __call__(self, t_s: float) -> np.ndarray | None:
        import cv2

        k = self.index(t_s)
        with self._lock:
            if k in self._cache:
                self._cache.move_to_end(k)
                return self._cache[k]
            if self._cap is None:
                self._cap = cv2.VideoCapture(str(self.path))
                if not self._cap.isOpened():
                    raise ValueError(f"OpenCV cannot open the video {self.path}")
            if k != self._next:
                self._cap.set(cv2.CAP_PROP_POS_FRAMES, k)
            ok, bgr = self._cap.read()
            if not ok:
                self._next = -1
                return None
            self._next = k + 1
            rgb = np.ascontiguousarray(bgr[:, :, ::-1]) if bgr.ndim == 3 else bgr
            if self.lens is not None:
                rgb = self.lens.undistort_image(rgb)
            rgb.setflags(write=False)
            self._cache[k] = rgb
            while len(self._cache) > self._size:
                self._cache.popitem(last=False)
            return rgb

    def close(self) -> None:
        with self._lock:
            if self._cap is not None:
                self._cap.release()
                self._cap = None
            self._cache.clear()


class GrabberFrames:
    """The interface's live frames: the grabber's latest one, whatever the time asked."""

    def __init__(self, grabber: Any):
        self.grabber = grabber

    def __call__(self, t_s: float) -> np.ndarray | None:
        frame = self.grabber.latest()
        return None if frame is None else frame.image

    def latest(self) -> Any:
        """The newest ``app.video.Frame`` (its index, times and capture stamp), None before the first."""
        return self.grabber.latest()
