"""A video that cannot be opened (app/video.py): a missing file, a file that is not a video, an empty
one, a camera index with no camera, a stream nobody answers. Each is a VideoError that says which
and what to do; through ``mcit serve`` it is one line on stderr (OpenCV's and FFmpeg's own lines
silenced) and a non-zero exit."""

from __future__ import annotations

import socket
from pathlib import Path

import pytest

from app.video import VideoError, open_video

ROOT = Path(__file__).resolve().parents[2]
NO_CAMERA = 63  # /dev/video63: checked absent below


def _refused_port() -> int:
    """A local port nothing listens on (bound, then released)."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _bad_sources(tmp_path: Path) -> dict[str, tuple[str, str]]:
    """name -> (spec, what the message must say)."""
    (tmp_path / "notes.mp4").write_text("this is not a video\n" * 20)
    (tmp_path / "empty.avi").write_bytes(b"")
    return {
        "missing": (str(tmp_path / "gone.mp4"), "not found"),
        "not a video": (str(tmp_path / "notes.mp4"), "is not a video OpenCV can decode"),
        "empty": (str(tmp_path / "empty.avi"), "is empty"),
        "no camera": (str(NO_CAMERA), f"there is no camera {NO_CAMERA}"),
        "refused stream": (f"rtsp://op:s3cret@127.0.0.1:{_refused_port()}/live", "Connection refused"),
    }


@pytest.fixture
def no_camera():
    if Path(f"/dev/video{NO_CAMERA}").exists():
        pytest.skip(f"this machine has a /dev/video{NO_CAMERA}")


def test_each_unopenable_source_says_why_and_what_to_do(tmp_path, no_camera):
    for name, (spec, says) in _bad_sources(tmp_path).items():
        with pytest.raises(VideoError) as info:
            open_video(spec)
        message = str(info.value)
        assert says in message and "\n" not in message, (name, message)
        assert "PosixPath" not in message and any(w in message for w in ("check", "give", "plug")), (name, message)
        assert "s3cret" not in message, message  # a stream's password is not repeated


@pytest.mark.parametrize("name", ["missing", "not a video", "empty", "no camera", "refused stream"])
def test_serve_on_an_unopenable_video_is_one_line(tmp_path, no_camera, forked, name):
    spec, says = _bad_sources(tmp_path)[name]
    db = tmp_path / "site.sqlite"
    run = forked.run(["serve", "--video", spec, "--no-devices", "--db", str(db), "--port", "0"], timeout_s=120)
    assert run.returncode != 0
    assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr, run.stderr  # FFmpeg's lines silenced too
    assert run.stderr.startswith("mcit serve: ") and says in run.stderr, run.stderr
    assert run.stdout == ""
