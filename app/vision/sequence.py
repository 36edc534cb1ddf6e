"""Tracking a recorded video end to end: read frames, track, draw the overlay, write video and poses.

This is what ``mcit track`` runs. The camera is fixed in the world frame (for a hand-held camera,
as in the ViSP sequences, the world frame *is* the camera frame: C = K [I | 0] and the pose the
tracker follows is the object's pose in the camera, ViSP's ``cMo``).

* ``read_visp_pose(path)``: a ViSP ``.pos`` file (tx ty tz θux θuy θuz: translation in metres,
  then the axis-angle vector in radians) → T (4, 4);
* the pose from clicked model points: ``app.pose_files`` (an ``.init`` and its pixels), through
  ``app.vision.pnp.solve_pnp``;
* ``iter_frames(source)``: the frames of a video file or an image folder, once, in order;
* ``draw_tracking(...)``: the frame with the tracked model and the matched edge samples;
* ``track_sequence(...)``: the loop, returning one ``TrackedFrame`` per frame and optionally
  writing the overlay video and a CSV of the poses.
"""

from __future__ import annotations

import csv
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from app.overlay import project_wireframe
from app.video import FOLDER_FPS
from core.brep import BRep
from core.camera import Camera
from core.pose.uncertainty import Priors
from core.transforms import log_so3

from .track import EdgeTracker, TrackDiagnostics

__all__ = [
    "read_visp_pose",
    "read_init_points",
    "iter_frames",
    "frame_count",
    "draw_tracking",
    "TrackedFrame",
    "track_sequence",
    "world_sigmas",
]

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")


def read_visp_pose(path: str | Path) -> np.ndarray:
    """T (4, 4) from a ViSP ``.pos`` file: six numbers tx ty tz (m) θux θuy θuz (rad) (``app.pose_files``,
    the reader of every pose file)."""
    from app.pose_files import read_visp_pos

    return read_visp_pos(path)


def read_init_points(path: str | Path) -> np.ndarray:
    """Model points (N, 3), metres, from a ViSP ``.init`` file: a count, then X Y Z per line (``#``
    comments), and the ViSP ≥ 3.7 ``load()`` lines (``app.models_io.read_init``, under the ``.cao``
    reader's limits). ValueError (CaoError) naming file:line."""
    from app.models_io import read_init

    return read_init(path)


def iter_frames(source: str | Path, start: int = 0, count: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """(index, RGB uint8 (H, W, 3)) for the frames of a video file or an image folder, once, in order."""
    source = Path(source)
    stop = None if count is None else start + count
    if source.is_dir():
        files = sorted(p for p in source.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
        if not files:
            raise ValueError(f"{source}: no images in this folder")
        for i, f in enumerate(files[start:stop], start):
            raw = cv2.imread(str(f), cv2.IMREAD_COLOR)
            if raw is None:
                raise ValueError(f"{f}: not an image OpenCV can read")
            yield i, cv2.cvtColor(raw, cv2.COLOR_BGR2RGB)
        return
    if not source.is_file():
        raise ValueError(f"{source}: no such video file or image folder")
    cap = cv2.VideoCapture(str(source))
    if not cap.isOpened():
        raise ValueError(f"{source}: OpenCV cannot open this video")
    try:
        i = 0
        while stop is None or i < stop:
            ok, raw = cap.read()
            if not ok:
                break
            if i >= start:
                yield i, cv2.cvtColor(raw, cv2.COLOR_BGR2RGB)
            i += 1
    finally:
        cap.release()


def frame_count(source: str | Path, start: int = 0, count: int | None = None) -> int | None:
    """How many frames ``iter_frames(source, start, count)`` gives: exact for an image folder, the
    container's count for a video (an estimate for some codecs), None when the video does not say."""
    source = Path(source)
    if source.is_dir():
        total = sum(1 for p in source.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    else:
        cap = cv2.VideoCapture(str(source))
        try:
            total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) if cap.isOpened() else 0
        finally:
            cap.release()
        if total <= 0:
            return None
    left = max(0, total - start)
    return left if count is None else min(left, count)


def source_fps(source: str | Path) -> float | None:
    """The frame rate a video file states (None for an image folder, or a video that does not say)."""
    source = Path(source)
    if not source.is_file():
        return None
    cap = cv2.VideoCapture(str(source))
    try:
        fps = float(cap.get(cv2.CAP_PROP_FPS)) if cap.isOpened() else 0.0
    finally:
        cap.release()
    return fps if np.isfinite(fps) and 0 < fps <= 1000 else None


def _line(img: np.ndarray, seg: np.ndarray, color: tuple[int, int, int], thickness: int = 1) -> None:
    p = np.round(np.asarray(seg) * 16).astype(np.int64)
    cv2.line(img, (int(p[0, 0]), int(p[0, 1])), (int(p[1, 0]), int(p[1, 1])), color, thickness, cv2.LINE_AA, 4)


def draw_tracking(
    frame_rgb: np.ndarray,
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    diagnostics: TrackDiagnostics | None = None,
    *,
    confidence: float | None = None,
    lost: bool = False,
    label: str = "",
) -> np.ndarray:
    """The frame (RGB (H, W, 3) uint8 copy) with the model's visible edges and the edge samples.

    Model: green when tracking, red when lost. Samples: the found edge point of each sample,
    cyan when the robust fit kept it, orange when it rejected it.
    """
    img = np.ascontiguousarray(frame_rgb.copy() if frame_rgb.ndim == 3 else cv2.cvtColor(frame_rgb, cv2.COLOR_GRAY2RGB))
    pw = project_wireframe(camera, model, T_world_obj)
    color = (255, 40, 40) if lost else (40, 230, 60)
    for seg in pw.seg_uv[pw.visible]:
        _line(img, seg, color, 1)
    if diagnostics is not None and len(diagnostics.matched_uv):
        ok = np.isfinite(diagnostics.matched_uv[:, 0])
        for p, w in zip(diagnostics.matched_uv[ok], diagnostics.weights[ok]):
            c = (0, 220, 255) if w >= 0.5 else (255, 150, 0)
            q = np.round(p * 16).astype(int)
            cv2.circle(img, (int(q[0]), int(q[1])), 16, c, 1, cv2.LINE_AA, 4)
    text = label
    if confidence is not None:
        text += f"  confidence {confidence:.2f}"
    if lost:
        text += "  LOST: give the pose again"
    if text.strip():
        (w, h), base = cv2.getTextSize(text.strip(), cv2.FONT_HERSHEY_SIMPLEX, 0.5, 1)
        cv2.rectangle(img, (4, 4), (12 + w, 12 + h + base), (0, 0, 0), -1)
        cv2.putText(img, text.strip(), (8, 8 + h), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (255, 255, 255), 1, cv2.LINE_AA)
    return img


@dataclass(frozen=True)
class TrackedFrame:
    """One frame of a tracked sequence: its index, the pose, the confidence, lost, and the step's figures."""

    index: int
    T_world_obj: np.ndarray
    confidence: float
    lost: bool
    rms_px: float
    n_samples: int
    n_inliers: int
    track_ms: float
    reason: str = ""
    # (6, 6) of (δt [m], δr [rad]), world frame (``TrackDiagnostics.cov``); None when lost
    cov: np.ndarray | None = None


def world_sigmas(cov: np.ndarray | None) -> np.ndarray:
    """(sx, sy, sz [m], srx, sry, srz [rad]) of a tracked pose: the σ of its translation along the world's axes
    and of its rotation error's rotation vector (R_est · R_trueᵀ) about them; NaN without a covariance."""
    if cov is None:
        return np.full(6, np.nan)
    return np.sqrt(np.maximum(np.diag(np.asarray(cov, float)), 0.0))


def track_sequence(
    source: str | Path,
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    start: int = 0,
    count: int | None = None,
    video_out: str | Path | None = None,
    csv_out: str | Path | None = None,
    fps_out: float | None = None,
    stop_when_lost: bool = True,
    lens=None,
    progress: Callable[[int, int | None], None] | None = None,
    priors: Priors | None = None,
    **tracker_kwargs,
) -> list[TrackedFrame]:
    """Track a model through a recorded video from an initial pose.

    Parameters
    ----------
    source : a video file or a folder of images. camera : Camera of the frames' size.
    model : BRep. T_world_obj : array, shape (4, 4), the pose in frame ``start``.
    start, count : the frames to track. video_out : write the overlay video there (.mp4/.avi), at ``fps_out``
        frames a second (default: the source video's rate; ``app.video.FOLDER_FPS``, 10, for an image folder or a
        video that does not say, as ``mcit serve`` reads them).
    csv_out : write one row per frame (index, confidence, lost, rms_px, samples, inliers, ms,
        tx ty tz θux θuy θuz of T_world_obj, then its σ: sx_m sy_m sz_m srx_rad sry_rad srz_rad, ``world_sigmas``).
    priors : the camera's and the model's priors joining each frame's σ (``EdgeTracker.priors``; default: the
        default model prior alone; ``mcit track`` gives the camera file's prior too).
    stop_when_lost : stop at the first lost frame (the operator must give the pose again).
    lens : app.undistort.LensDistortion or None: undistort each frame first (once, with precomputed
        maps); camera's C holds in the undistorted frames, which the overlay video shows.
    progress : called as ``progress(frames done, frames to do or None)`` after each frame (app.progress).
    tracker_kwargs : passed to ``EdgeTracker``.

    Returns
    -------
    list of TrackedFrame, one per frame tracked.
    """
    tracker = EdgeTracker(camera, model, T_world_obj, **tracker_kwargs)
    tracker.priors = Priors() if priors is None else priors
    writer = None
    out: list[TrackedFrame] = []
    total = frame_count(source, start, count) if progress is not None else None
    try:
        for index, frame in iter_frames(source, start, count):
            if lens is not None:
                frame = lens.undistort_image(frame)
            t0 = time.perf_counter()
            T, conf, lost = tracker.track(frame)
            ms = 1e3 * (time.perf_counter() - t0)
            d = tracker.diagnostics
            out.append(
                TrackedFrame(
                    index,
                    T,
                    conf,
                    lost,
                    d.rms_px if d else float("nan"),
                    d.n_samples if d else 0,
                    d.n_inliers if d else 0,
                    ms,
                    d.reason if d else "",
                    None if (d is None or lost or d.cov is None) else d.cov,
                )
            )
            if video_out is not None:
                img = draw_tracking(frame, camera, model, T, d, confidence=conf, lost=lost, label=f"frame {index}")
                if writer is None:
                    fps = fps_out or source_fps(source) or FOLDER_FPS
                    writer = _open_writer(Path(video_out), fps, img.shape[1], img.shape[0])
                writer.write(cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            if progress is not None:
                progress(len(out), total)
            if lost and stop_when_lost:
                break
    finally:
        if writer is not None:
            writer.release()
    if csv_out is not None:
        _write_csv(Path(csv_out), out)
    return out


def _open_writer(path: Path, fps: float, width: int, height: int) -> cv2.VideoWriter:
    codecs = ("mp4v", "avc1") if path.suffix.lower() in (".mp4", ".m4v", ".mov") else ("MJPG", "XVID")
    path.parent.mkdir(parents=True, exist_ok=True)
    for code in codecs:
        writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*code), fps, (width, height))
        if writer.isOpened():
            return writer
    raise ValueError(f"{path}: OpenCV cannot write this video (tried codecs {codecs}); use .avi or .mp4")


def _write_csv(path: Path, frames: list[TrackedFrame]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(
            [
                "frame",
                "confidence",
                "lost",
                "rms_px",
                "samples",
                "inliers",
                "track_ms",
                "tx_m",
                "ty_m",
                "tz_m",
                "rx_rad",
                "ry_rad",
                "rz_rad",
                "sx_m",
                "sy_m",
                "sz_m",
                "srx_rad",
                "sry_rad",
                "srz_rad",
            ]
        )
        for f in frames:
            r = log_so3(f.T_world_obj[:3, :3])
            w.writerow(
                [
                    f.index,
                    f"{f.confidence:.4f}",
                    int(f.lost),
                    f"{f.rms_px:.4f}",
                    f.n_samples,
                    f.n_inliers,
                    f"{f.track_ms:.2f}",
                ]
                + [f"{x:.6f}" for x in f.T_world_obj[:3, 3]]
                + [f"{x:.6f}" for x in r]
                + ["" if not np.isfinite(x) else f"{x:.3e}" for x in world_sigmas(f.cov)]
            )
