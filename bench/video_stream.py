"""Benchmark: a video stream that is lost — how soon mcit says so, and how soon it is live again.

Setup: Debian's ffmpeg serves a generated 160 × 120 clip at 20 frames/s on this machine, as
Motion-JPEG over HTTP (``-f mpjpeg -listen 1``) and over RTSP (ffmpeg's RTP through the test's RTSP
relay, tests/app/rtsp_relay.py); ``app.video.FrameGrabber`` reads it with mcit's own settings (what
``mcit serve --video URL`` uses: stream read timeout ``STREAM_READ_TIMEOUT_S``, reconnection delays
``RECONNECT_DELAYS_S``, the last repeating, stall after 2 s).

Each trial: frames for 1 s; the server killed (ffmpeg, and the relay for RTSP); kept down for the
outage; started again on the same port. Measured on the grabber's ``status()`` (polled every 10 ms):
kill → "video lost at …" (detect), restart → "live" with new frames (resume), and the tries made.
Then a hang: ffmpeg stopped (SIGSTOP: the connection stays open, no byte comes): → lost (stall) and
→ "reconnecting" (the read timed out).

Run: ``.venv/bin/python bench/video_stream.py [--trials 3] [--outages 1,5]`` (needs ffmpeg).
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402

from app.video import RECONNECT_DELAYS_S, STREAM_READ_TIMEOUT_S, FrameGrabber, open_video  # noqa: E402
from tests.app.test_video_streams import HttpStream, N, RtspStream, clip_frame, open_when_served  # noqa: E402


def wait(predicate, timeout_s: float = 30.0) -> float:
    t0 = time.monotonic()
    while not predicate():
        if time.monotonic() - t0 > timeout_s:
            raise RuntimeError("timed out")
        time.sleep(0.01)
    return time.monotonic()


def trial(kind: str, clip: Path, outage_s: float, stream=None):
    make = HttpStream if kind == "HTTP" else RtspStream
    stream = make(clip).start()
    grabber = FrameGrabber(open_when_served(stream.url) if kind == "RTSP" else open_video(stream.url)).start()
    try:
        wait(lambda: grabber.latest() is not None and grabber.latest().index >= 20)
        stream.kill()
        t_kill = time.monotonic()
        t_lost = wait(lambda: not grabber.status().live)
        time.sleep(max(0.0, outage_s - (time.monotonic() - t_kill)))
        last = grabber.latest().index
        again = (
            make(clip, port=stream.port) if kind == "HTTP" else make(clip, port=stream.port, rtp_port=stream.rtp_port)
        )
        stream = again.start()
        t_up = time.monotonic()
        tries = grabber.status().tries
        t_live = wait(lambda: grabber.status().live and grabber.latest().index > last)
        return t_lost - t_kill, t_live - t_up, tries
    finally:
        grabber.stop()
        stream.kill()


def hang(clip: Path):
    stream = HttpStream(clip).start()
    grabber = FrameGrabber(open_video(stream.url)).start()
    try:
        wait(lambda: grabber.latest() is not None and grabber.latest().index >= 20)
        stream.proc.send_signal(signal.SIGSTOP)
        t0 = time.monotonic()
        t_lost = wait(lambda: not grabber.status().live)
        t_reconnecting = wait(lambda: "reconnecting" in grabber.status().text)
        return t_lost - t0, t_reconnecting - t0
    finally:
        grabber.stop()
        stream.kill()


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=3)
    parser.add_argument("--outages", default="1,5", help="seconds the server stays down, comma-separated")
    args = parser.parse_args()
    if shutil.which("ffmpeg") is None:
        print("ffmpeg is not installed (apt-get install ffmpeg)")
        return 1
    outages = [float(x) for x in args.outages.split(",")]
    print(
        f"load average {os.getloadavg()[0]:.1f}; read timeout {STREAM_READ_TIMEOUT_S} s; reconnection delays "
        f"{'/'.join(f'{d:g}' for d in RECONNECT_DELAYS_S)} s (the last repeats)"
    )
    with tempfile.TemporaryDirectory() as tmp:
        clip = Path(tmp)
        for i in range(N):
            cv2.imwrite(str(clip / f"{i:03d}.png"), clip_frame(i)[:, :, ::-1])
        print(f"{'stream':<6} {'down s':>6} {'detect s (median, max)':>24} {'resume s (median, max)':>24} {'tries':>6}")
        for kind in ("HTTP", "RTSP"):
            for outage in outages:
                rows = [trial(kind, clip, outage) for _ in range(args.trials)]
                detect, resume, tries = zip(*rows)
                print(
                    f"{kind:<6} {outage:>6.1f} {statistics.median(detect):>15.2f} {max(detect):>8.2f} "
                    f"{statistics.median(resume):>15.2f} {max(resume):>8.2f} {statistics.median(tries):>6.0f}"
                )
        stall, reconnecting = hang(clip)
        print(
            f"hang (SIGSTOP, HTTP): said lost after {stall:.2f} s (no frame for 2 s), reconnecting after "
            f"{reconnecting:.2f} s (the read timed out)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
