"""The demo's overlay video: the scene's recorded frames with what the interface drew over them.

Frame k of the scene's video (decoded, never re-rendered) shows video time t = k / fps; over it go
the database's wireframes through the camera calibration of that moment (``app.ui.drawing
.draw_database``: colour by status, hidden edges dashed), the workflow's marks (clicks, assigned
edges, candidate ghosts, range points: ``draw_marks``), the range finder's last spot, and two
text lines (the time and the workflow; its next step or last message) — the ``OverlayState`` the
replay recorded last at or before t. The frame is enlarged ``scale`` times first so that thin
lines and text stay legible; a pixel centre (u, v) goes to ((u + ½)·scale − ½, (v + ½)·scale − ½).
"""

from __future__ import annotations

import bisect
import queue
import threading
from collections.abc import Callable, Sequence
from functools import lru_cache
from pathlib import Path

import numpy as np

from app.overlay import COLORS, LineBatch, circle_marker
from app.ui.drawing import draw_database, draw_marks

from .replay import OverlayState

__all__ = ["ascii_text", "draw_overlay", "state_at", "still_frame", "write_overlay_video"]

FONT_SCALE = 0.42


def _read_frames(cap, total: int):
    """The video's first ``total`` frames (BGR), until one cannot be read."""
    for _ in range(total):
        ok, raw = cap.read()
        if not ok:
            return
        yield raw


class _Pipeline:
    """Iterate a generator on a thread of its own, a few items ahead (``depth``); ``close`` stops it."""

    _END = object()

    def __init__(self, make, depth: int = 4):
        self._q: queue.Queue = queue.Queue(maxsize=depth)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(make,), name="overlay-reader", daemon=True)
        self._thread.start()

    def _run(self, make) -> None:
        try:
            for item in make():
                while not self._stop.is_set():
                    try:
                        self._q.put(item, timeout=0.1)
                        break
                    except queue.Full:
                        continue
                if self._stop.is_set():
                    return
            item = self._END
        except BaseException as exc:  # noqa: BLE001 - raised again by the consumer
            item = exc
        while not self._stop.is_set():
            try:
                self._q.put(item, timeout=0.1)
                return
            except queue.Full:
                continue

    def __iter__(self):
        while True:
            item = self._q.get()
            if item is self._END:
                return
            if isinstance(item, BaseException):
                raise item
            yield item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def still_frame(t_s: float, fps: float) -> int:
    """The first frame showing the state of an action at video time t_s (the frame at or after it)."""
    return int(np.ceil(t_s * fps - 1e-9))


def state_at(timeline: Sequence[OverlayState], t_s: float) -> OverlayState:
    """The last state recorded at or before video time t_s (the first one before any)."""
    times = [s.t_s for s in timeline]
    i = bisect.bisect_right(times, t_s + 1e-9) - 1
    return timeline[max(i, 0)]


_ASCII = {
    "±": "+/-",
    "°": " deg",
    "…": "...",
    "—": "-",
    "–": "-",
    "σ": "s",
    "→": "->",
    "×": "x",
    "²": "2",
    "³": "3",
    "µ": "u",
}


def ascii_text(text: str) -> str:
    """The text in the ASCII that OpenCV's Hershey font draws (±, °, σ, → ... spelt out)."""
    for a, b in _ASCII.items():
        text = text.replace(a, b)
    return text.encode("ascii", "replace").decode("ascii")


def _text(
    img: np.ndarray,
    text: str,
    org: tuple[int, int],
    color=(255, 255, 255),
    scale: float = FONT_SCALE,
    centred: bool = False,
) -> None:
    """Text at org (its baseline's left end, or its middle when centred) on a darkened box, so it
    reads over any background. (An outline drawn thicker would not do: OpenCV advances thicker
    glyphs further.)"""
    import cv2

    text = ascii_text(text)
    (w, h), base = _text_size(text, scale)
    if centred:
        org = (org[0] - w // 2, org[1])
    x0, y0 = max(org[0] - 2, 0), max(org[1] - h - 2, 0)
    x1, y1 = min(org[0] + w + 2, img.shape[1]), min(org[1] + base + 1, img.shape[0])
    if x1 > x0 and y1 > y0:
        img[y0:y1, x0:x1] = (img[y0:y1, x0:x1] * 0.35).astype(img.dtype)
    cv2.putText(img, text, org, cv2.FONT_HERSHEY_SIMPLEX, scale, color, 1, cv2.LINE_AA)


@lru_cache(maxsize=4096)
def _text_size(text: str, scale: float) -> tuple[tuple[int, int], int]:
    import cv2

    return cv2.getTextSize(text, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)


@lru_cache(maxsize=4096)
def _fit(text: str, width_px: int, scale: float = FONT_SCALE) -> str:
    """The text, cut and ended with "..." if it is wider than width_px (OpenCV's font has no "…")."""
    import cv2

    def wide(s: str) -> bool:
        return cv2.getTextSize(s, cv2.FONT_HERSHEY_SIMPLEX, scale, 1)[0][0] > width_px

    text = ascii_text(text)
    if not wide(text):
        return text
    while text and wide(text + "..."):
        text = text[:-1]
    return text + "..."


class _Plan:
    """What one state draws over any frame, in frame pixels × scale, computed once per state:
    the line segments (fixed-point ends with 4 fractional bits, BGR colour), in drawing order, and
    the labels (text, integer position)."""

    __slots__ = ("lines", "labels")

    def __init__(self, lines: list, labels: list):
        self.lines, self.labels = lines, labels


def _db_key(state: OverlayState, w: int, h: int) -> tuple:
    """What the database wireframes depend on: the camera, the frame size and each object's
    snapshot (a state keeps the objects' snapshots until the database changes)."""
    return (
        state.camera.C.tobytes(),
        w,
        h,
        tuple(
            (o.id, o.name, o.status, o.version, id(o.model), np.asarray(o.T_world_obj).tobytes()) for o in state.objects
        ),
    )


def _plan(state: OverlayState, w: int, h: int, scale: int, db_cache: dict | None = None) -> _Plan:
    """The state's _Plan; db_cache : {key: draw_database's result} shared over the states of a video."""
    cam = state.camera
    key = _db_key(state, w, h) if db_cache is not None else None
    if key is not None and key in db_cache:
        batch, db_labels = db_cache[key]
    else:
        batch, db_labels = draw_database(cam, state.objects, w, h)
        if key is not None:
            db_cache[key] = (batch, db_labels)
    labels = [(uv, text) for _, uv, text in db_labels]
    if state.marks is not None:
        marks_batch, mark_labels = draw_marks(cam, state.marks, {o.name: o for o in state.objects}, w, h)
        labels += mark_labels
    else:
        marks_batch = LineBatch()
    beam = LineBatch()
    X = state.beam_X_world
    if X is not None and np.all(np.isfinite(X)) and cam.depth(X) > 0:
        uv = cam.project(np.asarray(X, float))
        beam.add(circle_marker(uv, 5.0), COLORS["beam"])
    to_img = lambda uv: (np.asarray(uv, float) + 0.5) * scale - 0.5  # noqa: E731
    lines = []
    for b in (batch, marks_batch, beam):
        segs, cols = b.arrays()
        P = np.round(to_img(segs) * 16).astype(np.int64)
        for (a, c), col in zip(P.tolist(), np.asarray(cols).tolist()):
            lines.append(((int(a[0]), int(a[1])), (int(c[0]), int(c[1])), (int(col[2]), int(col[1]), int(col[0]))))
    text_at = []
    for uv, text in labels:
        p = to_img(uv)
        if np.all(np.isfinite(p)):
            text_at.append((str(text), (int(p[0]), int(p[1]))))
    return _Plan(lines, text_at)


def _paint(frame_gray: np.ndarray, plan: _Plan, state: OverlayState, t_s: float, scale: int) -> np.ndarray:
    import cv2

    h, w = frame_gray.shape
    img = cv2.cvtColor(
        cv2.resize(frame_gray, (w * scale, h * scale), interpolation=cv2.INTER_LINEAR), cv2.COLOR_GRAY2BGR
    )
    line, aa = cv2.line, cv2.LINE_AA
    for a, c, col in plan.lines:
        line(img, a, c, col, 1, aa, 4)
    for text, org in plan.labels:
        _text(img, text, org, scale=0.35, centred=True)
    head = f"t = {t_s:5.2f} s" + (f"   {state.title}" if state.title else "")
    _text(img, _fit(head, w * scale - 12), (6, 16))
    if state.text:
        _text(img, _fit(state.text, w * scale - 12), (6, h * scale - 8), color=(200, 255, 255))
    return img


def _check_frame(frame_gray: np.ndarray, scale) -> int:
    if frame_gray.ndim != 2:
        raise ValueError(f"frame_gray must be a grey image (H, W), got shape {frame_gray.shape}")
    if int(scale) < 1:
        raise ValueError(f"scale must be a whole number ≥ 1, got {scale}")
    return int(scale)


def draw_overlay(frame_gray: np.ndarray, state: OverlayState, t_s: float, scale: int = 2) -> np.ndarray:
    """One overlay frame: BGR uint8 (H·scale, W·scale, 3) from a grey frame (H, W) and a state."""
    scale = _check_frame(frame_gray, scale)
    h, w = frame_gray.shape
    return _paint(frame_gray, _plan(state, w, h, scale), state, t_s, scale)


def write_overlay_video(
    video_path: str | Path,
    timeline: Sequence[OverlayState],
    out_path: str | Path,
    *,
    fps: float,
    frames: int | None = None,
    scale: int = 2,
    stills: dict[str, float] | None = None,
    progress: Callable[[int, int], None] | None = None,
    lens=None,
) -> int:
    """Write the overlay video (mp4, MPEG-4 part 2) of a replay; returns the frames written.

    video_path : the scene's recorded video (read frame by frame). timeline : the replay's
    states, in time order. fps : the video's rate (frame k shows t = k / fps). frames : only the
    first N frames. stills : {file name: t_s} — also save as a PNG beside the video the first
    frame that shows what was done at t_s (``still_frame``). progress : ``progress(done, total)``.
    lens : the scene camera's lens distortion (app.undistort), or None: frames are undistorted first.
    """
    import cv2

    if not timeline:
        raise ValueError("the timeline is empty: replay a script first")
    out_path = Path(out_path)
    cap = cv2.VideoCapture(str(video_path))
    if not cap.isOpened():
        raise ValueError(f"{video_path}: OpenCV cannot open this video")
    total = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
    if frames is not None:
        total = min(total, int(frames))
    want = {still_frame(t, fps): name for name, t in (stills or {}).items()}
    writer = None
    written = 0
    plans: dict[int, _Plan] = {}  # per state (by its place in the timeline)
    db_cache: dict = {}  # the database's wireframes, per camera and objects' snapshots
    times = [st.t_s for st in timeline]
    # Frames are read and encoded on two more threads (OpenCV lets go of the interpreter while it
    # decodes and encodes), beside the drawing here; the bounded queues keep a few frames each.
    frames_in = _Pipeline(lambda: _read_frames(cap, total))
    encode: queue.Queue = queue.Queue(maxsize=8)
    encoder = None
    failure: list[BaseException] = []

    def encode_all() -> None:
        while (img := encode.get()) is not None:
            if not failure:
                try:
                    writer.write(img)
                except BaseException as exc:  # noqa: BLE001 - raised again in the caller
                    failure.append(exc)

    try:
        for k, raw in enumerate(frames_in):
            t = k / fps
            grey = cv2.cvtColor(raw, cv2.COLOR_BGR2GRAY)
            if lens is not None:  # the scene camera's lens: the overlay is drawn on the undistorted frame
                grey = lens.undistort_image(grey)
            i = max(bisect.bisect_right(times, t + 1e-9) - 1, 0)  # state_at's choice
            if k == 0:
                scale = _check_frame(grey, scale)
            h, w = grey.shape
            if i not in plans:
                plans[i] = _plan(timeline[i], w, h, scale, db_cache)
            img = _paint(grey, plans[i], timeline[i], t, scale)
            if writer is None:
                out_path.parent.mkdir(parents=True, exist_ok=True)
                writer = cv2.VideoWriter(
                    str(out_path), cv2.VideoWriter_fourcc(*"mp4v"), float(fps), (img.shape[1], img.shape[0])
                )
                if not writer.isOpened():
                    raise RuntimeError(f"OpenCV cannot write an mp4v video to {out_path}")
                encoder = threading.Thread(target=encode_all, name="overlay-encoder", daemon=True)
                encoder.start()
            if failure:
                raise failure[0]
            encode.put(img)
            written += 1
            if k in want:
                cv2.imwrite(str(out_path.parent / want[k]), img)
            if progress:
                progress(written, total)
    finally:
        frames_in.close()
        if encoder is not None:
            encode.put(None)
            encoder.join()
        cap.release()
        if writer is not None:
            writer.release()
    if failure:
        raise failure[0]
    if written == 0:
        raise ValueError(f"{video_path}: no frame could be read")
    return written
