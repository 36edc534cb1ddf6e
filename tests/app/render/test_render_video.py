"""The prerecorded video: written with OpenCV, read back, deterministic; the workcell's committed file."""

import numpy as np
import pytest

from app.cli import main
from app.render import Renderer
from app.render.measure import edge_offsets, visible_edges
from app.render.video import read_frame, read_video_info, render_video
from app.scene import SceneError, default_scene_path, load_scene, scene_from_dict


def test_render_video_is_readable_and_deterministic(tmp_path, small_scene_dict):
    scene = scene_from_dict(small_scene_dict, tmp_path)
    seen = []
    info = render_video(scene, progress=lambda done, total: seen.append((done, total)))
    assert info.path == tmp_path / "clip.avi" and info.frame_count == scene.video.frame_count == 8
    assert (info.width, info.height) == (96, 64) and info.fps == pytest.approx(10.0)
    assert seen[-1] == (8, 8) and len(seen) == 8
    again = render_video(scene, tmp_path / "again.avi")
    assert again.path.read_bytes() == info.path.read_bytes()  # same scene, same bytes
    assert not list(tmp_path.glob("*.part.*"))
    # the decoded frames are the renderer's, up to the codec's loss
    r = Renderer(scene)
    for k in (0, 7):
        decoded = read_frame(info.path, k).astype(float)
        assert np.abs(decoded - r.render(scene.video.frame_time(k), k)).mean() < 3.0
    assert np.abs(read_frame(info.path, 7).astype(float) - read_frame(info.path, 0)).mean() > 1.0  # the box moved
    short = render_video(scene, tmp_path / "short.avi", frames=3)
    assert short.frame_count == 3
    assert render_video(scene, tmp_path / "short.mp4", frames=2).frame_count == 2  # mp4v by the extension
    with pytest.raises(ValueError, match="codec follows the extension"):
        render_video(scene, tmp_path / "clip.mov", frames=1)
    with pytest.raises(ValueError, match="no frame 5"):
        read_frame(short.path, 5)


def test_render_needs_a_video_block(tmp_path, small_scene_dict):
    d = small_scene_dict
    del d["video"]
    with pytest.raises(SceneError, match="no 'video' block"):
        render_video(scene_from_dict(d, tmp_path))
    with pytest.raises(ValueError, match="cannot open"):
        read_video_info(tmp_path / "nothing.avi")


def test_mcit_render_command(tmp_path, small_scene_dict):
    import json

    (tmp_path / "scene.json").write_text(json.dumps(small_scene_dict))
    assert main(["render", "--scene", str(tmp_path), "--frames", "2", "--out", str(tmp_path / "x.avi")]) == 0
    assert read_video_info(tmp_path / "x.avi").frame_count == 2
    assert main(["render", "--scene", str(tmp_path), "--frame", "0.5", "--out", str(tmp_path / "f.png")]) == 0
    import cv2

    assert cv2.imread(str(tmp_path / "f.png"), cv2.IMREAD_GRAYSCALE).shape == (64, 96)
    assert (
        main(["script", "--scene", str(default_scene_path()), "--out", str(tmp_path / "op.json"), "--seed", "3"]) == 0
    )
    assert json.loads((tmp_path / "op.json").read_text())["generator"]["seed"] == 3


@pytest.mark.parametrize("camera", ["front", "side"])
def test_the_workcell_video_is_committed_and_current(camera):
    scene = load_scene(default_scene_path())
    view = scene.view(camera)
    path = view.video.path
    assert path.is_file(), f"render it with: mcit render --scene scenes/workcell --camera {camera}"
    assert path.stat().st_size < 3e6
    info = read_video_info(path)
    assert info.frame_count == view.video.frame_count
    assert (info.width, info.height) == (512, 256) and info.fps == pytest.approx(view.video.fps)
    # It shows the current scene: a frame in the middle of the large motion matches a fresh render,
    # up to the codec (which smooths part of the sensor noise away) ...
    k = view.video.frame_index(13.5)
    renderer = Renderer(scene, camera=view.camera, lens=view.lens)
    t = view.video.frame_time(k)
    fresh = renderer.render(t, k).astype(float)
    decoded = read_frame(path, k).astype(float)
    assert np.abs(decoded - fresh).mean() < 2.2
    assert np.corrcoef(decoded.ravel(), fresh.ravel())[0, 1] > 0.99
    # ... and its edges are where C projects the true ones (bench/render.py: p95 0.14 px).
    offsets = [np.mean(edge_offsets(decoded, uv)) for _, _, uv in visible_edges(scene, renderer, t)]
    assert len(offsets) >= 10 and np.max(np.abs(offsets)) < 0.4
