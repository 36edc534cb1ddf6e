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
