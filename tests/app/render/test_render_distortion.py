"""Rendering through a lens, and the overlay on that video once undistorted (issue 15, item 1).

The workcell rendered as a camera with lens distortion would film it, encoded as the scene's video
(Motion-JPEG), read back and undistorted on arrival as ``mcit serve`` does (``UndistortedSource``):
its edges lie within 0.2 px of where C — the overlay's model — projects the true edges. The same
frame not undistorted is pixels off."""

import dataclasses

import numpy as np
import pytest

from app.render import Renderer
from app.render.measure import edge_offsets, visible_edges
from app.render.video import render_video
from app.scene import VideoSpec, default_scene_path, load_scene
from app.undistort import LensDistortion, UndistortedSource
from app.video import open_video


@pytest.fixture(scope="module")
def workcell():
    return load_scene(default_scene_path())


def _lens(scene, model, coeffs):
    K = scene.camera.decompose()[0]
    return LensDistortion(K, coeffs, model, scene.camera.width, scene.camera.height)


def test_overlay_on_a_distorted_rendered_video_lies_on_the_true_edges(workcell, tmp_path):
    t = 16.0
    lens = _lens(workcell, "rational_polynomial", [-0.3, 0.12, 0.001, -0.0015, -0.02, 0.01, 0.002, 0.001])
    assert "px at the corners" in lens.describe() and float(lens.describe().split(", ")[1].split(" px")[0]) > 20
    scene = dataclasses.replace(workcell, lens=lens, video=VideoSpec(tmp_path / "v.avi", 1.0 / t, 2 * t))
    render_video(scene, frames=2)  # frame 1 is at t = 16 s
    with UndistortedSource(open_video(tmp_path / "v.avi"), lens) as source:
        source.read()
        frame = source.read().image[:, :, 0].astype(float)
    with open_video(tmp_path / "v.avi") as plain:  # the same video not undistorted: the control
        plain.read()
        raw_frame = plain.read().image[:, :, 0].astype(float)
    edges = list(visible_edges(workcell, Renderer(workcell), t))
    assert len(edges) >= 15
    on = np.array([np.mean(edge_offsets(frame, uv)) for _, _, uv in edges])
    off = np.array([np.mean(edge_offsets(raw_frame, uv, half_px=4.0)) for _, _, uv in edges])
    print(
        f"{len(edges)} edges: undistorted within {np.abs(on).max():.3f} px (mean |offset| {np.abs(on).mean():.3f}); "
        f"not undistorted up to {np.nanmax(np.abs(off)):.2f} px"
    )
    assert np.abs(on).max() < 0.2, on
    assert np.nanmax(np.abs(off)) > 1.5  # without undistortion the overlay misses the edges


@pytest.mark.parametrize("model,coeffs", [("visp", [-0.25, 0.27]), ("equidistant", [0.08, -0.04, 0.01, 0.0])])
def test_visp_and_fisheye_lenses_render_and_undistort_onto_C(workcell, model, coeffs):
    t = 16.0
    lens = _lens(workcell, model, coeffs)
    r = Renderer(dataclasses.replace(workcell, lens=lens))
    assert r.lens is lens and Renderer(workcell).lens is None
    clean, _ = r.render_float(t)
    und = lens.undistort_image(clean.astype(np.float32))
    edges = list(visible_edges(workcell, Renderer(workcell), t))
    worst = max(abs(np.mean(edge_offsets(und, uv))) for _, _, uv in edges)
    print(f"{model}: {len(edges)} edges within {worst:.3f} px")
    assert worst < 0.1, worst
