"""Video sources: files loop with the recording's time, folders play in name order, stills repeat."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from app.video import CaptureSource, FolderSource, FrameGrabber, StillSource, VideoError, open_video


def _write_video(path, n=7, size=(64, 48), fps=10.0):
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert writer.isOpened()
    for i in range(n):
        frame = np.full((size[1], size[0], 3), 30 * i % 256, np.uint8)
        writer.write(frame)
    writer.release()


def test_file_loops_and_time_wraps_with_the_recording(tmp_path):
    path = tmp_path / "clip.avi"
    _write_video(path, n=7)
    with open_video(str(path)) as src:
        assert isinstance(src, CaptureSource) and not src.live
        assert (src.width, src.height) == (64, 48)
        assert src.fps == pytest.approx(10.0)
        frames = [src.read() for _ in range(16)]
    assert [f.index for f in frames] == list(range(16))
    # 7 frames at 10 fps: frame 7 is the first frame again, at t = 0.
    assert [f.t_s for f in frames[:9]] == pytest.approx([0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.1])
    assert src.frame_count == 7
    # the looped frame has the first frame's content (MJPG is lossy: compare means)
    assert abs(frames[7].image.mean() - frames[0].image.mean()) < 2
    assert frames[0].image.dtype == np.uint8 and frames[0].image.shape == (48, 64, 3)


def test_folder_in_name_order_grey_to_rgb(tmp_path):
    for i, value in enumerate([10, 200, 90]):
        cv2.imwrite(str(tmp_path / f"f{i:03d}.png"), np.full((8, 12), value, np.uint8))
    (tmp_path / "notes.txt").write_text("not an image")
    src = open_video(tmp_path, fps=5)
    assert isinstance(src, FolderSource) and src.frame_count == 3
    values = [int(src.read().image[0, 0, 0]) for _ in range(5)]
    assert values == [10, 200, 90, 10, 200]
    frame = src.read()
    assert frame.image.shape == (8, 12, 3) and frame.t_s == pytest.approx(2 / 5)


def test_real_visp_frames_folder(shared_data):
    src = open_video(shared_data("visp-cube", "frames"))
    assert (src.width, src.height) == (640, 480) and src.frame_count == 218


def test_still_image_and_array(tmp_path):
    img = np.zeros((10, 20, 3), np.uint8)
    img[2, 3] = (0, 0, 255)  # BGR red
    cv2.imwrite(str(tmp_path / "one.png"), img)
    src = open_video(tmp_path / "one.png")
    assert isinstance(src, StillSource)
    assert tuple(src.read().image[2, 3]) == (255, 0, 0)  # RGB red
    arr = StillSource(np.full((4, 5), 7, np.uint8))
    assert arr.read().image.shape == (4, 5, 3)


@pytest.mark.parametrize("spec", ["/nonexistent/video.mp4", "no-such-folder"])
def test_missing_source_says_what_to_give(spec):
    with pytest.raises(VideoError, match="not found"):
        open_video(spec)


def test_empty_folder_and_bad_still(tmp_path):
    with pytest.raises(VideoError, match="no images"):
        FolderSource(tmp_path)
    with pytest.raises(VideoError, match="uint8"):
        StillSource(np.zeros((4, 4), float))


def test_grabber_paces_a_recording_and_keeps_the_latest(tmp_path):
    src = StillSource(np.zeros((4, 4, 3), np.uint8), fps=50)
    seen = []
    grabber = FrameGrabber(src, on_frame=lambda f: seen.append(f.index)).start()
    try:
        time.sleep(0.5)
        latest = grabber.latest()
        assert latest is not None and latest.index == seen[-1]
        # paced at 50 fps: about 25 frames in 0.5 s, not thousands
        assert 10 <= len(seen) <= 40
        assert 20 <= grabber.measured_fps <= 80
    finally:
        grabber.stop()
    assert grabber.error is None


def test_a_replayed_recording_says_where_it_is_on_the_image():
    """stamp_replay_time: a dark box at the bottom-left corner with the time within the loop; the rest
    of the image untouched, the frame itself not modified; grey frames too."""
    from app.video import stamp_replay_time

    im = np.full((256, 512, 3), 90, np.uint8)
    out = stamp_replay_time(im, 40.3, 28.6)  # the second loop: 11.7 s into it
    changed = np.any(out != 90, axis=2)
    ys, xs = np.nonzero(changed)
    assert changed.sum() > 200 and ys.min() > 256 - 30 and xs.max() < 160  # only the corner
    assert np.all(im == 90)
    assert stamp_replay_time(im[:, :, 0], 1.0, 28.6).shape == (256, 512)
