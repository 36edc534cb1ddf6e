"""app.vision.evaluate: the oriented chamfer distance of a posed model's edges to the image's edges."""

import numpy as np

from app.vision.evaluate import edge_distance, oriented_edges
from app.vision.synthetic import render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import exp_so3, make_T

K = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])


def test_true_pose_scores_near_zero_and_a_shifted_one_by_its_shift():
    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    box = BRep.box(0.2, 0.13, 0.08)
    T = make_T(exp_so3([2.2, 0.4, 0.3]), [0.0, 0.0, 0.9])
    img = render_poses(cam, box, [T], noise_sigma=2.0)[0]
    oe = oriented_edges(img)
    assert oe.dist.shape == (12, 240, 320)
    true = edge_distance(oe, cam, box, T)
    assert true.distances_px.shape == (len(true.uv),) and true.uv.shape[1] == 2
    assert true.mean_px < 0.5 and true.matched > 0.98
    # 3 px to the right in the image (6.4 mm at 0.9 m, f = 420 px)
    shifted = edge_distance(img, cam, box, make_T(T[:3, :3], T[:3, 3] + [3.0 * 0.9 / 420.0, 0.0, 0.0]))
    assert 1.5 < shifted.mean_px < 3.5
    far = edge_distance(oe, cam, box, make_T(T[:3, :3], T[:3, 3] + [0.5, 0.0, 0.0]))
    assert far.mean_px > 5.0 or len(far.uv) == 0


def test_texture_across_the_model_edges_does_not_count():
    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    # a vertical edge at u = 160.5 (a step) crossed by horizontal stripes (texture): only the step counts
    img = np.full((240, 320), 60, np.uint8)
    img[:, 161:] = 180
    img[::8, :] = 20
    seg = BRep(np.array([[0.0, -0.2, 0.0], [0.0, 0.2, 0.0]]), np.array([[0, 1]]))
    T = make_T(np.eye(3), [(160.5 - 159.5) / 420.0, 0.0, 1.0])  # the model line projects to u = 160.5
    d = edge_distance(img, cam, seg, T)
    assert d.mean_px < 0.7


def test_distances_read_around_the_samples_equal_the_whole_frame_transforms():
    from app.vision.profiles import bilinear
    from app.vision.track import sample_visible_edges

    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    box = BRep.box(0.2, 0.13, 0.08)
    T = make_T(exp_so3([2.2, 0.4, 0.3]), [0.0, 0.0, 0.9])
    img = render_poses(cam, box, [T], noise_sigma=2.0)[0]
    oe = oriented_edges(img)
    rng = np.random.default_rng(1)
    for _k in range(6):
        Tk = make_T(exp_so3(rng.normal(0.0, 0.05, 3)) @ T[:3, :3], T[:3, 3] + rng.normal(0.0, 0.01, 3))
        d = edge_distance(oe, cam, box, Tk, max_px=10.0)
        s = sample_visible_edges(cam, box, Tk, step_px=2.0)
        b = np.round((np.degrees(np.arctan2(s.normals[:, 1], s.normals[:, 0])) % 180.0) / oe.bin_deg).astype(int) % 12
        ref = np.array([bilinear(oe.dist[bi], np.array([u]), np.array([v]))[0] for bi, (u, v) in zip(b, s.uv)])
        assert np.allclose(d.distances_px, np.minimum(ref, 10.0), atol=1e-4)


def test_edges_are_computed_once_per_frame_contents():
    img = np.full((60, 80), 50, np.uint8)
    img[:, 40:] = 200
    assert oriented_edges(img) is oriented_edges(img.copy())
    other = img.copy()
    other[10:20, 10:20] = 120  # the same array changed: its edges are computed again
    assert oriented_edges(other) is not oriented_edges(img)
    assert oriented_edges(img, sigma_px=2.0) is not oriented_edges(img)
