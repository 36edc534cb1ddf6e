"""Video sources for the interface: OpenCV captures (camera index, file, stream URL), image-sequence
folders and still images, read by a background grabber that keeps the latest frame.

Every frame handed out is RGB ``uint8`` of shape (H, W, 3) (grey images are expanded), with its
index and its time ``t_s`` in seconds. For a prerecorded source (a file, a folder, a still) the
time is the position in the recording, ``index / fps`` modulo its length: that is the scene time
the emulated devices and the ground truth use, so a looping video replays the same motion. For a
live source (a camera or a stream) the time is the wall-clock time since the source was opened.

``open_video(spec)`` understands:

* an integer, or a string of digits: a camera index (``cv2.VideoCapture(0)``);
* a string with ``://`` (``rtsp://``, ``http://``...): a stream URL (opened and read with time limits:
  ``STREAM_OPEN_TIMEOUT_S``, ``STREAM_READ_TIMEOUT_S``, so that a stream that stops cannot hang a read);
* a folder: the images in it (``.png``, ``.jpg``, ``.jpeg``, ``.bmp``, ``.tif``, ``.tiff``, ``.pgm``,
  ``.ppm``) in name order, played at ``fps`` (default 10) and looped;
* an image file: a still frame; any other file: a video file, looped at its own frame rate.

A live source that fails (a stream whose server stops, a camera unplugged) is not the end:
``FrameGrabber`` says so in ``status()`` ("video lost at HH:MM:SS, reconnecting (try n)") and reopens
it with a growing delay (``RECONNECT_DELAYS_S``) until frames arrive again ("live"). A live source
that stays silent longer than ``stall_s`` is reported lost even while its read is still waiting.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

log = logging.getLogger("mcit.video")

FOLDER_FPS = 10.0  # the rate an image folder or a still is read at when none is given (serve and track alike)

__all__ = [
    "Frame",
    "VideoError",
    "VideoSource",
    "CaptureSource",
    "FolderSource",
    "StillSource",
    "open_video",
    "why_not_opened",
    "FrameGrabber",
    "VideoStatus",
    "stamp_not_live",
    "IMAGE_SUFFIXES",
]

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm")
STREAM_OPEN_TIMEOUT_S = 5.0  # a stream URL that does not answer within this is not opened
STREAM_READ_TIMEOUT_S = 3.0  # a stream read that waits longer fails (the grabber then reconnects)
RECONNECT_DELAYS_S = (0.25, 0.5, 1.0, 2.0)  # waits before each reconnection try; the last repeats


class VideoError(ValueError):
    """A video source cannot be opened or read; the message says which and what to do."""


@dataclass(frozen=True)
class Frame:
    """One frame: ``image`` RGB uint8 (H, W, 3); ``index`` since the source was opened (it keeps
    counting across loops); ``t_s`` the scene time in seconds (see the module docstring); ``stamp`` when the
    image was taken, unix seconds: the sender's stamp where the source carries one (a ROS 2 image's header),
    else when mcit read it (None: not known)."""

    image: np.ndarray
    index: int
    t_s: float
    stamp: float | None = None


def _to_rgb(image: np.ndarray) -> np.ndarray:
    """BGR/BGRA/grey OpenCV image → contiguous RGB uint8 (H, W, 3)."""
    import cv2

    if image.dtype != np.uint8:
        if np.issubdtype(image.dtype, np.integer):
            image = (image >> (8 * (image.dtype.itemsize - 1))).astype(np.uint8)
        else:
            image = np.clip(image * 255.0, 0, 255).astype(np.uint8)
    if image.ndim == 2:
        return cv2.cvtColor(image, cv2.COLOR_GRAY2RGB)
    if image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2RGB)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


class VideoSource:
    """A source of RGB frames. Subclasses set ``width``, ``height``, ``fps``, ``live``,
    ``description`` and implement ``_read() -> image | None``."""

    width: int
    height: int
    fps: float
    live: bool = False
    description: str = ""
    frame_count: int | None = None
    reconnects: bool = False  # True when reopen() can bring a failed live source back

    def __init__(self) -> None:
        self._index = -1
        self._position = -1  # frame position in the recording; subclasses reset it to -1 on a loop
        self._opened_at = time.monotonic()

    def read(self) -> Frame:
        """The next frame (blocking for live sources); VideoError when the source has failed."""
        image = self._read()
        if image is None:
            raise VideoError(
                f"{self.description}: no frame could be read (the source ended or failed); check the source"
            )
        self._index += 1
        self._position += 1
        t_s = time.monotonic() - self._opened_at if self.live else self._position / self.fps
        return Frame(image, self._index, float(t_s), self._stamp())

    def _read(self) -> np.ndarray | None:  # pragma: no cover - abstract
        raise NotImplementedError

    def _stamp(self) -> float | None:
        """When the image ``_read`` just gave was taken (unix seconds): now, unless the source knows better."""
        return time.time()

    def skip(self, n: int) -> None:
        """Pass over the next ``n`` frames unseen (a prerecorded source played behind its clock)."""
        for _ in range(max(0, int(n))):
            if self._read() is None:
                raise VideoError(f"{self.description}: no frame could be read (the source ended or failed)")
            self._index += 1
            self._position += 1

    @property
    def duration_s(self) -> float | None:
        """Length of a prerecorded source in seconds (None for live sources)."""
        if self.live or not self.frame_count:
            return None
        return self.frame_count / self.fps

    def close(self) -> None:
        """Release the device or file."""

    def reopen(self) -> None:
        """Open the source again after a failure (``reconnects`` sources); VideoError if it cannot be."""
        raise VideoError(f"{self.description} cannot be reopened")

    def __enter__(self) -> VideoSource:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _without_password(url: str) -> str:
    """The URL with its password (if any) replaced by *** (never repeated in a message, the panel or a log)."""
    from urllib.parse import urlsplit

    try:
        parts = urlsplit(url)
        if parts.password:
            return parts._replace(netloc=parts.netloc.replace(f":{parts.password}@", ":***@")).geturl()
    except ValueError:
        pass
    return url


def why_not_opened(target: int | str | Path, probe: bool = True) -> str:
    """Why OpenCV could not open ``target`` and what to do, in one line (OpenCV only says "no"; its
    and FFmpeg's own log lines are silenced by ``mcit``, see app/cli.py). ``probe``: for a stream,
    try a connection to its host to say whether it answers (not while reconnecting: a server that
    takes one client, as ``ffmpeg -listen 1``, would take the probe for it)."""
    if isinstance(target, int):
        device = Path(f"/dev/video{target}")
        if not device.exists() and Path("/dev").is_dir():
            return (
                f"there is no camera {target} on this computer (no {device}); plug it in or give another index "
                "(ls /dev/video*)"
            )
        return (
            f"camera {target} could not be opened: another program may be using it, or this user may not (group "
            "video); close the other program or check the permissions"
        )
    text = str(target)
    if "://" in text:
        from urllib.parse import urlsplit

        try:
            url = urlsplit(text)
            host, port = url.hostname, url.port or {"rtsp": 554, "http": 80, "https": 443, "rtmp": 1935}.get(url.scheme)
        except ValueError:
            return f"cannot open the stream {text}: the address is not a valid URL; check it"
        text = _without_password(text)  # never repeat a password in a message or a log
        reason = ""
        if host and port and probe:
            import socket

            try:
                socket.create_connection((host, port), timeout=2.0).close()
            except OSError as exc:
                reason = f" ({host}:{port}: {exc.strerror or exc})"
        return (
            f"cannot open the stream {text}{reason}; check the address and that the camera or server is on and "
            "reachable"
        )
    path = Path(text)
    if not os.access(path, os.R_OK):
        return f"cannot read the video {path} (permission denied); check its permissions"
    if path.stat().st_size == 0:
        return f"the video {path} is empty; give another file"
    return (
        f"{path} is not a video OpenCV can decode (an unsupported format or a damaged file); convert it (e.g. "
        "ffmpeg -i in out.mp4) or give another file"
    )


class CaptureSource(VideoSource):
    """An OpenCV ``VideoCapture``: a camera index, a video file (looped) or a stream URL.

    fps : overrides the frame rate the capture reports (files and streams often lie; a camera
    reporting 0 gets 30).
    """

    def __init__(self, target: int | str | Path, fps: float | None = None):
        super().__init__()
        import cv2

        self._target = target
        self.live = not (isinstance(target, (str, Path)) and Path(str(target)).is_file())
        self.reconnects = self.live
        self._closed = False
        self._cap = self._open()
        if not self._cap.isOpened():
            raise VideoError(why_not_opened(target))
        first = self._grab_first()
        self.height, self.width = first.shape[:2]
        reported = float(self._cap.get(cv2.CAP_PROP_FPS) or 0.0)
        self.fps = float(fps) if fps else (reported if 1.0 <= reported <= 240.0 else 30.0)
        count = int(self._cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0)
        self.frame_count = count if (not self.live and count > 0) else None
        kind = "camera" if isinstance(target, int) else ("file" if not self.live else "stream")
        self.description = f"{kind} {_without_password(str(target)) if kind == 'stream' else target}"
        self._pending: np.ndarray | None = first

    def _open(self):
        import cv2

        target = self._target
        if isinstance(target, int):
            return cv2.VideoCapture(target)
        if "://" in str(target):  # a stream: bounded open and reads (FFmpeg's interrupt callback)
            params = [
                cv2.CAP_PROP_OPEN_TIMEOUT_MSEC,
                int(STREAM_OPEN_TIMEOUT_S * 1000),
                cv2.CAP_PROP_READ_TIMEOUT_MSEC,
                int(STREAM_READ_TIMEOUT_S * 1000),
            ]
            return cv2.VideoCapture(str(target), cv2.CAP_FFMPEG, params)
        return cv2.VideoCapture(str(target))

    def reopen(self) -> None:
        """Release the capture and open the target again (a stream or camera that failed); its first
        frame must have the size the source had. VideoError saying why when it cannot."""
        if not self.live:
            raise VideoError(f"{self.description} cannot be reopened")
        self._cap.release()
        cap = self._open()
        if not cap.isOpened():
            cap.release()
            raise VideoError(why_not_opened(self._target, probe=False))
        ok, image = cap.read()
        if not ok or image is None:
            cap.release()
            raise VideoError(f"{self.description} opened again but gave no frame; check the camera or server")
        image = _to_rgb(image)
        if image.shape[:2] != (self.height, self.width):
            cap.release()
            raise VideoError(
                f"{self.description} came back with {image.shape[1]}×{image.shape[0]} frames, it gave "
                f"{self.width}×{self.height} before; set the camera back to that size or restart mcit"
            )
        if self._closed:  # closed while this reopened: do not keep the new capture
            cap.release()
            raise VideoError(f"{self.description} was closed")
        self._cap = cap
        self._pending = image

    def _grab_first(self) -> np.ndarray:
        ok, image = self._cap.read()
        if not ok or image is None:
            self._cap.release()
            raise VideoError(
                f"video {self._target} opened but gave no frame (an empty or damaged file, or a camera still "
                "starting); check it, or try again"
            )
        return _to_rgb(image)

    def _read(self) -> np.ndarray | None:
        import cv2

        if self._pending is not None:
            image, self._pending = self._pending, None
            return image
        ok, image = self._cap.read()
        if not ok and not self.live and self._position >= 0:
            # End of a prerecorded file: loop (the index keeps counting, the position restarts).
            # The frames actually read are the true length (a container's count may be wrong).
            self.frame_count = self._position + 1
            self._cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            self._position = -1
            ok, image = self._cap.read()
        if not ok or image is None:
            return None
        return _to_rgb(image)

    def close(self) -> None:
        self._closed = True
        self._cap.release()


class FolderSource(VideoSource):
    """The images of a folder in name order, played at ``fps`` and looped (decoded lazily)."""

    def __init__(self, folder: str | Path, fps: float = FOLDER_FPS):
        super().__init__()
        folder = Path(folder)
        files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES) if folder.is_dir() else []
        if not files:
            raise VideoError(
                f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder: give the folder of the video's "
                "frames"
            )
        if fps <= 0:
            raise VideoError(f"fps must be positive, got {fps}")
        self._files = files
        self._images: dict[int, np.ndarray] = {}
        first = self._load(0)
        self.height, self.width = first.shape[:2]
        self.fps = float(fps)
        self.frame_count = len(files)
        self.description = f"folder {folder} ({len(files)} images)"

    def _load(self, i: int) -> np.ndarray:
        import cv2

        image = self._images.get(i)
        if image is None:
            raw = cv2.imread(str(self._files[i]), cv2.IMREAD_UNCHANGED)
            if raw is None:
                raise VideoError(f"{self._files[i]}: not an image OpenCV can read")
            image = _to_rgb(raw)
            if len(self._images) < 512:  # keep short sequences in memory; long ones re-decode
                self._images[i] = image
        return image

    def _read(self) -> np.ndarray | None:
        if self._position + 1 >= len(self._files):
            self._position = -1
        i = self._position + 1
        image = self._load(i)
        if image.shape[:2] != (self.height, self.width):
            raise VideoError(
                f"{self.description}: image {i} is "
                f"{image.shape[1]}×{image.shape[0]}, the first is {self.width}×{self.height}; "
                "a sequence must keep one size"
            )
        return image


class StillSource(VideoSource):
    """One image repeated at ``fps``: an image file, or an array (e.g. a frame rendered from the scene)."""

    def __init__(self, image: np.ndarray | str | Path, fps: float = FOLDER_FPS, description: str | None = None):
        super().__init__()
        if isinstance(image, (str, Path)):
            import cv2

            raw = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
            if raw is None:
                raise VideoError(f"{image}: not an image OpenCV can read")
            description = description or f"image {image}"
            image = _to_rgb(raw)
        else:
            image = np.asarray(image)
            if image.dtype != np.uint8 or image.ndim not in (2, 3):
                raise VideoError(
                    f"a still frame must be a uint8 (H, W) or (H, W, 3) array, got {image.dtype} {image.shape}"
                )
            if image.ndim == 2:
                image = np.repeat(image[:, :, None], 3, axis=2)
        self._image = np.ascontiguousarray(image)
        self.height, self.width = self._image.shape[:2]
        self.fps = float(fps)
        self.frame_count = 1
        self.description = description or f"still {self.width}×{self.height}"

    def _read(self) -> np.ndarray | None:
        self._position = -1
        return self._image


def open_video(spec: int | str | Path, fps: float | None = None) -> VideoSource:
    """A video source from a command-line style spec (see the module docstring)."""
    if isinstance(spec, int) or (isinstance(spec, str) and spec.strip().isdigit()):
        return CaptureSource(int(spec), fps)
    text = str(spec)
    if "://" in text:
        return CaptureSource(text, fps)
    path = Path(text).expanduser()
    if path.is_dir():
        return FolderSource(path, fps or FOLDER_FPS)
    if path.is_file():
        if path.suffix.lower() in IMAGE_SUFFIXES:
            return StillSource(path, fps or FOLDER_FPS)
        return CaptureSource(path, fps)
    raise VideoError(
        f"video source {text!r} not found: give a camera index (0), a video file, an image folder, "
        "an image file or a stream URL (rtsp://...)"
    )


@dataclass(frozen=True)
class VideoStatus:
    """What the operator must know of the video now: ``live`` is True while frames arrive;
    ``text`` is "live", "video lost at HH:MM:SS, reconnecting (try n)" (HH:MM:SS: this computer's
    clock when the last frame arrived), "video stopped: ..." (a source that cannot come back) or
    "waiting for the first frame"; ``reason`` why the last reconnection try failed ("" if none);
    ``lost_at`` the wall-clock time (``time.time()``) of the last frame before the loss, or None;
    ``tries`` the reconnection tries so far."""

    live: bool
    text: str
    reason: str = ""
    lost_at: float | None = None
    tries: int = 0


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t))


def stamp_not_live(image: np.ndarray, text: str) -> np.ndarray:
    """A copy of ``image`` (RGB uint8) marked as not live: grey and darkened, framed in red, with a
    red band across the top saying "NOT LIVE: <text>" — what the operator sees in place of a frozen
    image while the video is lost."""
    import cv2

    h, w = image.shape[:2]
    grey = cv2.cvtColor(np.ascontiguousarray(image), cv2.COLOR_RGB2GRAY)
    out = cv2.cvtColor((grey.astype(np.float32) * 0.55 + 20.0).astype(np.uint8), cv2.COLOR_GRAY2RGB)
    red = (200, 30, 30)
    border = max(2, min(h, w) // 60)
    cv2.rectangle(out, (0, 0), (w - 1, h - 1), red, 2 * border)
    label = ("NOT LIVE: " + text).encode("ascii", "replace").decode("ascii")
    font, thickness = cv2.FONT_HERSHEY_SIMPLEX, max(1, h // 240)
    band = max(16, h // 12)
    (tw, th), _ = cv2.getTextSize(label, font, 1.0, thickness)
    scale = min(0.7 * band / th, 0.94 * w / tw)
    (tw, th), base = cv2.getTextSize(label, font, scale, thickness)
    band = max(band, th + base + 8)
    out[:band] = red
    cv2.putText(out, label, ((w - tw) // 2, (band + th) // 2), font, scale, (255, 255, 255), thickness, cv2.LINE_AA)
    return out


def stamp_replay_time(image: np.ndarray, t_s: float, duration_s: float, label: str = "REPLAY") -> np.ndarray:
    """A copy of ``image`` (RGB or grey uint8) with "REPLAY 12.3 / 28.6 s" in a dark box at its
    bottom-left corner: a recording replayed in a loop (the workcell's), whose objects jump back when it
    restarts, says where it is on the video itself (a new operator took a restart for a wrong update).
    ``label``: another word for what loops ("SCRIPT": a live site's scripted motions)."""
    return stamp_corner(image, f"{label} {t_s % duration_s:4.1f} / {duration_s:.1f} s")


def stamp_corner(image: np.ndarray, label: str) -> np.ndarray:
    """A copy of ``image`` (RGB or grey uint8) with ``label`` (ASCII) in a dark box at its bottom-left corner."""
    import cv2

    out = np.ascontiguousarray(image).copy()
    h, w = out.shape[:2]
    font, thickness = cv2.FONT_HERSHEY_SIMPLEX, 1
    scale = max(0.35, h / 900.0)
    (tw, th), base = cv2.getTextSize(label, font, scale, thickness)
    x0, y1 = 4, h - 4
    colour = (255, 255, 255) if out.ndim == 3 else 255
    cv2.rectangle(out, (x0 - 2, y1 - th - base - 4), (x0 + tw + 4, y1), (0, 0, 0) if out.ndim == 3 else 0, -1)
    cv2.putText(out, label, (x0 + 1, y1 - base - 1), font, scale, colour, thickness, cv2.LINE_AA)
    return out


class FrameGrabber:
    """Reads a source on a background thread and keeps the latest frame.

    Prerecorded sources are paced at their frame rate on a clock (real-time playback): frame k is shown
    at ``start_at + k / fps`` (monotonic; default: when the grabber starts), and frames due while a slow
    decode held the thread go unseen, so that grabbers given one ``start_at`` (a scene's cameras) show
    frames of the same moment however long each decode takes. Live sources are read as fast as they
    deliver. ``latest()`` never blocks. ``measured_fps`` is the delivered rate over
    the last second or so. ``status()`` says whether the video is live (see ``VideoStatus``).

    A read error of a live source that can be reopened (a stream, a camera: ``source.reconnects``)
    starts reconnection: the source is reopened after ``RECONNECT_DELAYS_S`` (the last delay repeats)
    until it gives frames again; meanwhile ``latest()`` keeps the last frame and ``status()`` says the
    video is lost. A live source that gives no frame for ``stall_s`` seconds (default: the larger of
    2 s and 5 frame periods) is reported lost too, while its read still waits (a stream read gives up
    after ``STREAM_READ_TIMEOUT_S``, then reconnection starts). Any other read error stops the thread
    and is kept in ``error`` (shown to the operator). ``on_frame`` callbacks (and those of
    ``add_listener``) run on the grabber thread and must be quick.
    """

    def __init__(
        self,
        source: VideoSource,
        on_frame: Callable[[Frame], None] | None = None,
        stall_s: float | None = None,
        reconnect_delays_s: tuple[float, ...] = RECONNECT_DELAYS_S,
        start_at: float | None = None,
    ):
        self.source = source
        self.start_at = start_at
        self._listeners: list[Callable[[Frame], None]] = [on_frame] if on_frame is not None else []
        self._lock = threading.Lock()
        self._latest: Frame | None = None
        self._stop = threading.Event()
        self._times: list[float] = []
        self.error: Exception | None = None
        self.stall_s = float(stall_s) if stall_s is not None else max(2.0, 5.0 / max(float(source.fps), 1e-3))
        self._delays = tuple(float(d) for d in reconnect_delays_s) or (1.0,)
        self._last_mono: float | None = None  # arrival of the latest frame (monotonic, wall clock)
        self._last_wall: float | None = None
        self._lost_at: float | None = None  # wall-clock time of the last frame before the loss
        self._tries = 0
        self._reason = ""
        self.losses = 0  # how many times the video was lost (a read failed) since the start
        self._thread = threading.Thread(target=self._run, name="mcit-video", daemon=True)

    def start(self) -> FrameGrabber:
        """Start reading (once; later calls do nothing)."""
        if self._thread.ident is None:
            self._thread.start()
        return self

    def _run(self) -> None:
        try:
            self._read_loop()
        finally:
            if self._stop.is_set():  # stopped while a read waited: stop() left the release to this thread
                self.source.close()

    def _read_loop(self) -> None:
        period = 1.0 / self.source.fps
        if self.start_at is None:
            self.start_at = time.monotonic()
        while not self._stop.is_set():
            try:
                frame = self.source.read()
            except Exception as exc:  # noqa: BLE001 - a live source reconnects; otherwise kept, the thread ends
                if self._stop.is_set():
                    return
                if self.source.live and getattr(self.source, "reconnects", False):
                    self._reconnect(exc)
                    continue
                self.error = exc
                return
            now = time.monotonic()
            with self._lock:
                self._latest = frame
                self._last_mono, self._last_wall = now, time.time()
                self._lost_at, self._tries, self._reason = None, 0, ""
                self._times.append(now)
                while self._times and now - self._times[0] > 1.0:
                    self._times.pop(0)
            for listener in list(self._listeners):
                listener(frame)
            if not self.source.live:
                due = self.start_at + (frame.index + 1) * period  # when the next frame is to be shown
                late = int((time.monotonic() - due) / period)
                if late >= 1:  # fell behind (a slow decode): the frames due meanwhile go unseen, no burst
                    self.source.skip(late)
                else:
                    self._stop.wait(max(0.0, due - time.monotonic()))

    def _reconnect(self, exc: Exception) -> None:
        """The live source failed: reopen it with growing delays until it opens (its frames then clear
        the loss) or the grabber stops."""
        with self._lock:
            if self._lost_at is None:
                self._lost_at = self._last_wall if self._last_wall is not None else time.time()
                self.losses += 1
            self._reason = str(exc)
            self._times.clear()
        log.warning("video lost at %s, reconnecting: %s", _clock(self._lost_at), exc)
        while not self._stop.is_set():
            with self._lock:
                self._tries += 1
                delay = self._delays[min(self._tries - 1, len(self._delays) - 1)]
            if self._stop.wait(delay):
                return
            try:
                self.source.reopen()
            except Exception as failure:  # noqa: BLE001 - said in the status; the next try follows
                with self._lock:
                    self._reason = str(failure)
                continue
            log.info("video reopened after %d tries", self._tries)
            return

    def status(self) -> VideoStatus:
        """Whether frames arrive now, and if not since when and what is being done (never blocks)."""
        with self._lock:
            if self.error is not None:
                return VideoStatus(False, f"video stopped: {self.error}", reason=str(self.error))
            if self._lost_at is not None:
                return VideoStatus(
                    False,
                    f"video lost at {_clock(self._lost_at)}, reconnecting (try {max(self._tries, 1)})",
                    self._reason,
                    self._lost_at,
                    self._tries,
                )
            if self._latest is None:
                return VideoStatus(False, "waiting for the first frame")
            if self.source.live and self._last_mono is not None and time.monotonic() - self._last_mono > self.stall_s:
                silent = time.monotonic() - self._last_mono
                return VideoStatus(
                    False,
                    f"video lost at {_clock(self._last_wall)}, no frame for {silent:.0f} s; waiting for it",
                    lost_at=self._last_wall,
                )
            return VideoStatus(True, "live" if self.source.live else "playing")

    def add_listener(self, on_frame: Callable[[Frame], None]) -> None:
        """Call ``on_frame(frame)`` (on the grabber thread; keep it quick) for every new frame."""
        self._listeners.append(on_frame)

    def remove_listener(self, on_frame: Callable[[Frame], None]) -> None:
        """Stop calling ``on_frame`` (no error if it was not registered)."""
        try:
            self._listeners.remove(on_frame)
        except ValueError:
            pass

    def latest(self) -> Frame | None:
        """The most recent frame, or None before the first."""
        with self._lock:
            return self._latest

    @property
    def measured_fps(self) -> float:
        """Frames delivered per second over the last second."""
        with self._lock:
            if len(self._times) < 2:
                return 0.0
            span = self._times[-1] - self._times[0]
            return (len(self._times) - 1) / span if span > 0 else 0.0

    def stop(self) -> None:
        """Stop the thread and release the source (a read that still waits, at most a stream's read
        timeout, is not cut under the thread: the thread releases the source when it returns)."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=2.0)
        if not self._thread.is_alive():
            self.source.close()
