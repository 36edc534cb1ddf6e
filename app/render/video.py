"""The scene's prerecorded video: render every frame with ``Renderer`` and encode it with OpenCV.

Frame k shows the scene at t = k / fps (``VideoSpec``), grey replicated to BGR. The codec follows
the file's extension (``CODECS``): ``.avi`` is Motion-JPEG, the default for scenes — every frame
stands alone (exact seeking in a looping video) and edges survive it: measured by bench/render.py
on the workcell (684 edge × frame pairs), decoded edges lie within 0.12 px of the true ones at the
95th percentile (largest 0.37 px) against 0.09 px (0.22 px) in the frames before encoding, where
MPEG-4 part 2 (``.mp4``, ``mp4v``, the only other lossy codec the pip OpenCV wheels write and read
here) gives 0.18 px (0.72 px) at the bitrate OpenCV sets, which OpenCV offers no way to raise.
Rendering is deterministic and so is the encoder: re-rendering writes the same bytes (tested).

``mcit render --scene DIR`` (app/scene_cli.py) (re)writes the scene's ``video.file``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.scene import Scene, SceneError, VideoSpec

from .renderer import Renderer

__all__ = ["VideoInfo", "render_video", "read_video_info", "read_frame", "CODECS"]

CODECS = {".avi": "MJPG", ".mp4": "mp4v", ".mkv": "FFV1"}  # extension → OpenCV FourCC (FFV1: lossless, large)


@dataclass(frozen=True)
class VideoInfo:
    """What OpenCV reads back from a video file: frame count, rate and size (pixels)."""

    path: Path
    frame_count: int
    fps: float
    width: int
    height: int


def read_video_info(path: str | Path) -> VideoInfo:
    """Open ``path`` with OpenCV and report its frame count, fps and size; ValueError if unreadable."""
    import cv2

    path = Path(path)
    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ValueError(f"{path}: OpenCV cannot open this video")
        info = VideoInfo(
            path,
            int(cap.get(cv2.CAP_PROP_FRAME_COUNT)),
            float(cap.get(cv2.CAP_PROP_FPS)),
            int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)),
            int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT)),
        )
    finally:
        cap.release()
    return info


def read_frame(path: str | Path, k: int) -> np.ndarray:
    """Frame k (H, W) uint8 grey of a video file, decoded by OpenCV (read sequentially from the
    start, which is exact for any codec; fine for the short videos of scenes)."""
    import cv2

    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            raise ValueError(f"{path}: OpenCV cannot open this video")
        frame = None
        for _ in range(k + 1):
            ok, frame = cap.read()
            if not ok:
                raise ValueError(f"{path}: no frame {k} (the video has fewer frames)")
    finally:
        cap.release()
    return cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY)


def render_video(
    scene: Scene,
    path: str | Path | None = None,
    *,
    video: VideoSpec | None = None,
    frames: int | None = None,
    progress: Callable[[int, int], None] | None = None,
    view: str | None = None,
) -> VideoInfo:
    """Render one camera's video (``view``: its name, default the first camera) to ``path`` (default:
    that camera's ``video.file``).

    video : timing (fps, duration) to use instead of the scene's. frames : render only the first
    ``frames`` frames (quick previews and tests). progress : called as ``progress(done, total)``.
    Returns what OpenCV reads back from the written file.
    """
    import cv2

    v = scene.view(view)
    spec = video or v.video
    if spec is None:
        raise SceneError(
            f"scene {scene.name!r}'s camera {v.name!r} has no 'video' block: add "
            '{"file": "video.mp4", "fps": 12, "duration_s": 20}'
        )
    out = Path(path) if path is not None else spec.path
    fourcc = CODECS.get(out.suffix.lower())
    if fourcc is None:
        raise ValueError(f"{out}: write the video as one of {sorted(CODECS)} (the codec follows the extension)")
    total = spec.frame_count if frames is None else min(int(frames), spec.frame_count)
    if total < 1:
        raise ValueError(f"nothing to render: {total} frames")
    renderer = Renderer(scene, camera=v.camera, lens=v.lens)
    w, h = v.camera.width, v.camera.height
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.stem + ".part" + out.suffix)
    writer = cv2.VideoWriter(str(tmp), cv2.CAP_FFMPEG, cv2.VideoWriter_fourcc(*fourcc), float(spec.fps), (w, h))
    if not writer.isOpened():
        raise RuntimeError(f"OpenCV cannot write {fourcc} video to {tmp}")
    try:
        for k in range(total):
            writer.write(renderer.render_bgr(spec.frame_time(k), k))
            if progress:
                progress(k + 1, total)
    finally:
        writer.release()
    tmp.replace(out)  # a finished file or none: an interrupted render leaves the old video intact
    info = read_video_info(out)
    if info.frame_count != total or (info.width, info.height) != (w, h):
        raise RuntimeError(
            f"{out}: read back {info.frame_count} frames of {info.width}×{info.height}, wrote {total} of {w}×{h}"
        )
    return info
