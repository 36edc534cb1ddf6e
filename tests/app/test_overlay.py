"""Overlay geometry: projection through C with clipping, dashing, and the pixel world mapping."""

from __future__ import annotations

import numpy as np
import pytest

from app.overlay import (
    LineBatch,
    PixelWorld,
    circle_marker,
    clip_segments_depth,
    clip_segments_rect,
    cross_markers,
    dash_segments,
    nearest_segment,
    project_wireframe,
)
from core.brep import BRep
from core.camera import Camera
from core.transforms import make_T, rot_x, rot_z


def _camera(w=512, h=256):
    K = np.array([[500.0, 0, 255.5], [0, 500.0, 127.5], [0, 0, 1]])
    return Camera.from_intrinsics(K, make_T(rot_x(-2.0), [0, 0.3, 2.0]), w, h)


def test_pixel_world_round_trip_through_a_viewer_ray():
    pw = PixelWorld(640, 480, k=0.01)
    rng = np.random.default_rng(0)
    uv = rng.uniform([0, 0], [639, 479], size=(20, 2))
    X = pw.to_world(uv)
    assert X.shape == (20, 3) and np.allclose(X[:, 2], 0)
    eye = np.array([2.0, 1.0, -7.0])
    for p, x in zip(uv, X):
        got = pw.pixel_from_ray(eye, (x - eye) / np.linalg.norm(x - eye))
        assert np.allclose(got, p, atol=1e-9)
    assert pw.pixel_from_ray(eye, [0, 0, -1.0]) is None  # pointing away from the image
    assert pw.pixel_from_ray(eye, [1.0, 0, 0]) is None  # parallel to it


@pytest.mark.parametrize("aspect", [0.5, 1.0, 2.0, 3.0])
def test_fit_camera_shows_the_whole_image_centred(aspect):
    pw = PixelWorld(512, 256, k=0.01)
    fov = np.radians(50)
    pos, look, up = pw.fit_camera(aspect, fov, margin=1.0)
    assert np.allclose(look, pw.image_center) and np.allclose(up, [0, -1, 0])
    d = look[2] - pos[2]
    half_h = d * np.tan(fov / 2)
    half_w = half_h * aspect
    # the image just fits: one of the two extents is exactly matched, the other inside
    need_w, need_h = 256 * 0.01, 128 * 0.01
    assert half_w >= need_w - 1e-9 and half_h >= need_h - 1e-9
    assert min(half_w - need_w, half_h - need_h) == pytest.approx(0, abs=1e-9)
    with pytest.raises(ValueError, match="aspect"):
        pw.fit_camera(0.0, fov)


def test_projected_box_edges_end_at_projected_vertices():
    cam = _camera()
    box = BRep.box(0.3, 0.2, 0.1)
    T = make_T(rot_z(0.4), [0.05, -0.02, 0.0])
    pw = project_wireframe(cam, box, T)
    assert pw.seg_uv.shape[1:] == (2, 2) and len(pw.seg_uv) == 12  # all inside the image
    V = cam.project_obj(T, box.vertices)
    for seg, e in zip(pw.seg_uv, pw.edge_index):
        assert np.allclose(seg, V[box.edges[e]], atol=1e-9)
    # seen from above and in front: at least the 4 top edges are visible, the bottom-back ones hidden
    assert 6 <= pw.visible.sum() <= 9 and (~pw.visible).sum() >= 3


def test_cylinder_has_two_silhouettes_and_rims():
    cam = _camera()
    pw = project_wireframe(cam, BRep.cylinder(0.05, 0.15), make_T(np.eye(3), [0, 0, 0]), n_circle=24)
    assert (pw.kind == "silhouette").sum() == 2
    assert (pw.kind == "rim").sum() == 48
    assert np.all(pw.edge_index[pw.kind != "edge"] == -1)


def test_rect_clip_cuts_at_the_border_and_drops_outside():
    seg = np.array([[[-50.0, 10.0], [50.0, 10.0]], [[200.0, 200.0], [300.0, 300.0]], [[5.0, 5.0], [20.0, 30.0]]])
    out, idx = clip_segments_rect(seg, 100, 100, margin_px=0.5)
    assert list(idx) == [0, 2]
    assert np.allclose(out[0], [[-0.5, 10.0], [50.0, 10.0]])
    assert np.allclose(out[1], seg[2])


def test_depth_clip_keeps_only_what_is_in_front():
    cam = _camera()
    c = cam.center
    ahead = c + 2.0 * cam.optical_axis
    behind = c - 1.0 * cam.optical_axis
    S = np.array([[ahead, ahead + [0.1, 0, 0]], [behind, behind + [0.1, 0, 0]], [behind, ahead]])
    out, idx = clip_segments_depth(cam, S, min_depth_m=0.01)
    assert list(idx) == [0, 2]
    assert np.allclose(out[0], S[0])
    assert cam.depth(out[1]) == pytest.approx([0.01, 2.0])


def test_dashes_cover_the_segment_in_pieces():
    seg = np.array([[[0.0, 0.0], [25.0, 0.0]]])
    d, idx = dash_segments(seg, dash_px=6, gap_px=4)
    assert np.allclose(d[:, 0, 0], [0, 10, 20]) and np.allclose(d[:, 1, 0], [6, 16, 25])
    assert np.all(idx == 0)
    with pytest.raises(ValueError, match="dash_px"):
        dash_segments(seg, dash_px=0)


def test_line_batch_colours_hidden_dimmed_and_world_shape():
    cam = _camera()
    pw = project_wireframe(cam, BRep.box(0.3, 0.2, 0.1), np.eye(4))
    batch = LineBatch()
    batch.add_wireframe(pw, (200, 100, 0))
    seg, col = batch.arrays()
    assert len(seg) > len(pw.seg_uv)  # dashes add pieces
    assert {tuple(c) for c in col} == {(200, 100, 0), (110, 55, 0)}
    P, C = batch.world(PixelWorld(512, 256, 0.01), z=-0.001)
    assert P.shape == (len(seg), 2, 3) and C.shape == (len(seg), 2, 3) and np.allclose(P[..., 2], -0.001)
    removed = LineBatch()
    removed.add_wireframe(pw, (1, 2, 3), hidden="removed")
    assert len(removed) == pw.visible.sum()


def test_markers_and_nearest_segment():
    assert cross_markers(np.array([[10.0, 20.0], [0, 0]]), 3).shape == (4, 2, 2)
    circ = circle_marker([5.0, 5.0], 2.0, n=8)
    assert np.allclose(np.linalg.norm(circ[:, 0] - 5.0, axis=1), 2.0)
    segs = np.array([[[0.0, 0.0], [10.0, 0.0]], [[0.0, 5.0], [10.0, 5.0]]])
    assert nearest_segment(segs, [4.0, 4.0]) == (1, pytest.approx(1.0))
    assert nearest_segment(segs, [-3.0, 0.0]) == (0, pytest.approx(3.0))  # to the endpoint
    assert nearest_segment(np.zeros((0, 2, 2)), [0, 0])[0] == -1
