"""app.vision.snap: clicked segments refined to the image's edges, on rendered frames with known edges."""

import numpy as np
import pytest

from app.vision.snap import fit_line_robust, snap_segment
from app.vision.synthetic import edge_contrast, render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import make_T, random_rotation

K = np.array([[500.0, 0.0, 159.5], [0.0, 500.0, 119.5], [0.0, 0.0, 1.0]])


def _scene(rng):
    """A box at a random pose whose visible faces are all seen at less than 75° (no slivers)."""
    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    box = BRep.box(0.2, 0.13, 0.08)
    while True:
        T = make_T(random_rotation(rng), [rng.uniform(-0.05, 0.05), rng.uniform(-0.03, 0.03), 1.2])
        c_obj = (cam.center - T[:3, 3]) @ T[:3, :3]
        v = c_obj - box.face_centroids()
        cosang = np.einsum("ij,ij->i", box.face_normals(), v) / np.linalg.norm(v, axis=1)
        if not np.any((cosang > 0) & (cosang < 0.26)):
            return cam, box, T


def _true_lines(cam, box, T, min_len_px=30.0, min_contrast=10.0):
    """The projected edges an operator would click: visible, long enough, with contrast."""
    contrast = edge_contrast(cam, box, T)
    out = []
    for k, seg in enumerate(box.edge_segments(T)):
        uv = cam.project(seg)
        if contrast[k] >= min_contrast and np.linalg.norm(uv[1] - uv[0]) >= min_len_px:
            out.append(uv)
    return out


def _line_dist(seg_uv, true_uv):
    l = np.cross(np.append(true_uv[0], 1.0), np.append(true_uv[1], 1.0))
    l /= np.linalg.norm(l[:2])
    return np.abs(np.column_stack([seg_uv, np.ones(2)]) @ l)


def test_snapped_segments_lie_on_the_true_edges():
    rng = np.random.default_rng(0)
    errs, raw = [], []
    scenes = [_scene(rng) for _ in range(4)]
    cam, box = scenes[0][:2]
    frames = render_poses(cam, box, [T for _, _, T in scenes], noise_sigma=2.0)
    for img, (_, _, T) in zip(frames, scenes):
        for uv in _true_lines(cam, box, T):
            click = uv[0] + np.array([[0.1], [0.9]]) * (uv[1] - uv[0]) + rng.normal(0, 2.0, (2, 2))
            res = snap_segment(img, click)
            assert res.ok, res.reason
            assert res.seg_uv.shape == (2, 2) and res.raw_seg_uv.shape == (2, 2) and res.edge_uv.shape[1] == 2
            assert np.allclose(res.raw_seg_uv, click)
            assert res.moved_px == pytest.approx(np.max(np.linalg.norm(res.seg_uv - click, axis=1)))
            assert 0.5 <= res.confidence <= 1.0 and res.rms_px < 1.0
            errs.append(_line_dist(res.seg_uv, uv).max())
            raw.append(_line_dist(click, uv).max())
    errs = np.array(errs)
    assert len(errs) >= 12
    assert np.median(errs) < 0.15 and np.percentile(errs, 90) < 0.3
    assert np.mean(errs) < np.mean(raw) / 5


def test_polarity_says_which_side_is_brighter():
    img = np.full((60, 80), 40, np.uint8)
    img[:, 41:] = 200  # brighter to the right (u > 40.5)
    down = snap_segment(img, np.array([[39.0, 10.0], [42.0, 50.0]]))  # p1 → p2 downwards: right of it is −u
    assert down.ok and down.polarity == -1
    assert np.allclose(down.seg_uv[:, 0], 40.5, atol=0.05)
    up = snap_segment(img, np.array([[42.0, 50.0], [39.0, 10.0]]))
    assert up.ok and up.polarity == 1


def test_refuses_where_there_is_no_edge():
    flat = np.full((60, 80), 128, np.uint8)
    res = snap_segment(flat, np.array([[10.0, 10.0], [60.0, 40.0]]))
    assert not res.ok and res.reason
    assert np.array_equal(res.seg_uv, res.raw_seg_uv)
    # a corner of two edges is not one straight edge along the whole segment
    img = np.full((80, 80), 40, np.uint8)
    img[40:, 40:] = 220
    bent = snap_segment(img, np.array([[10.0, 40.0], [70.0, 70.0]]), band_px=4.0)
    assert not bent.ok


def test_bad_input():
    img = np.zeros((20, 20), np.uint8)
    with pytest.raises(ValueError, match="coincide"):
        snap_segment(img, np.array([[5.0, 5.0], [5.0, 5.0]]))
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        snap_segment(img, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="positive"):
        snap_segment(img, np.array([[1.0, 1.0], [9.0, 9.0]]), band_px=0)
    with pytest.raises(ValueError, match="at least 2"):
        fit_line_robust(np.zeros((1, 2)), np.ones(1), 1.0)


def test_robust_line_fit_ignores_a_cluster_off_the_line():
    rng = np.random.default_rng(3)
    s = np.linspace(0, 50, 40)
    P = np.column_stack([s, 0.5 * s + 3.0]) + rng.normal(0, 0.1, (40, 2)) * [0, 1]
    P[:8] += [0.0, 6.0]  # a neighbouring edge near one end
    c, u, inl = fit_line_robust(P, np.ones(40), 1.0)
    assert inl[8:].all() and not inl[:8].any()
    assert abs(abs(u @ np.array([1.0, 0.5]) / np.hypot(1, 0.5)) - 1.0) < 1e-4
