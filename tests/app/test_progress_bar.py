"""app/progress.py: a tqdm bar on a terminal only, nothing in a log, a pipe or with --quiet; and the
long commands' progress reaches it without touching what they print on stdout."""

import io
import subprocess
import sys
from pathlib import Path

from app.progress import progress_bar
from tests.app.box_frames import box_frames  # noqa: F401 - a fixture

ROOT = Path(__file__).resolve().parents[2]


class _Tty(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_a_terminal_gets_a_bar_that_ends_its_line():
    out = _Tty()
    show = progress_bar("frames", stream=out)
    for i in range(1, 51):
        show(i, 50)
    text = out.getvalue()
    assert text.startswith("\r") and "frames" in text and "50/50" in text and text.endswith("\n")
    show(51, 50)  # after the end: nothing more
    assert out.getvalue() == text


def test_an_unknown_total_counts_and_closes_with_its_block():
    out = _Tty()
    with progress_bar("frames", stream=out) as show:
        for i in range(1, 8):
            show(i, None)
    assert "7" in out.getvalue().splitlines()[-1] and out.getvalue().endswith("\n")


def test_nothing_in_a_log_or_when_quiet():
    log = io.StringIO()  # a file, a pipe, CI: not a terminal
    show = progress_bar("trials", stream=log)
    for i in range(1, 1301):
        show(i, 1300)
    assert log.getvalue() == "" and not show.enabled
    tty = _Tty()
    with progress_bar("frames", stream=tty, quiet=True) as show:
        show(1, 2)
    assert tty.getvalue() == ""


def test_the_default_stream_is_stderr_as_it_is_when_made(monkeypatch):
    tty = _Tty()
    monkeypatch.setattr(sys, "stderr", tty)
    with progress_bar("frames") as show:
        show(1, 1)
    assert "1/1" in tty.getvalue()


def test_render_with_stderr_a_terminal_draws_the_bar_on_stderr_only(tmp_path):
    """``mcit render`` under a pseudo-terminal for stderr: the bar there, stdout its one result line; with
    --quiet, no bar."""
    import os
    import pty

    code = "import sys; from app.cli import main; sys.exit(main(sys.argv[1:]))"  # stderr: the pty; stdout: a pipe
    for quiet in (False, True):
        leader, follower = pty.openpty()
        argv = ["render", "--camera", "front", "--frames", "1", "--out", str(tmp_path / "v.avi")]  # 3 s a frame
        argv += ["--quiet"] if quiet else []
        proc = subprocess.Popen(
            [sys.executable, "-c", code, *argv], cwd=ROOT, stdout=subprocess.PIPE, stderr=follower, text=True
        )
        os.close(follower)
        err = b""
        while True:
            try:
                chunk = os.read(leader, 4096)
            except OSError:  # the pty closed: the process ended
                break
            if not chunk:
                break
            err += chunk
        out = proc.communicate(timeout=300)[0]
        os.close(leader)
        assert proc.returncode == 0, (out, err)
        assert out.startswith("wrote ") and out.count("\n") == 1, out
        text = err.decode()
        assert ("1/1" in text and "frames" in text) != quiet, text


def test_track_and_calibrate_intrinsics_report_frames_done_of_frames_to_do(box_frames):  # noqa: F811 - fixture
    import numpy as np

    from app.models_io import load_model
    from app.vision.intrinsics_cli import _frames
    from app.vision.sequence import read_visp_pose, track_sequence
    from core.camera import Camera

    d = box_frames
    K = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])
    seen = []
    frames = track_sequence(
        d / "frames",
        Camera.from_intrinsics(K, np.eye(4), 320, 240),
        load_model(d / "box.cao"),
        read_visp_pose(d / "box.pos"),
        start=1,
        progress=lambda done, total: seen.append((done, total)),
    )
    assert len(frames) == 2 and seen == [(1, 2), (2, 2)]
    seen.clear()
    assert [i for i, _ in _frames(str(d / "frames"), 2, lambda done, total: seen.append((done, total)))] == [0, 2]
    assert seen == [(1, 3), (2, 3), (3, 3)]  # every frame read counts, the ones skipped by --every too
