import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.camera import Camera, as_segment
from core.geometry import signed_distance
from core.transforms import invert_T, make_T, random_rotation, transform_points

K0 = np.array([[500.0, 0.0, 255.5], [0.0, 500.0, 127.5], [0.0, 0.0, 1.0]])


def random_camera(rng, K=K0, w=512, h=256):
    """A camera at a random pose looking at the world origin from 1–3 m."""
    R_world_cam = random_rotation(rng)
    center = -R_world_cam[:, 2] * rng.uniform(1.0, 3.0)  # the origin is ahead on the optical axis
    T_world_cam = make_T(R_world_cam, center)
    return Camera.from_intrinsics(K, invert_T(T_world_cam), w, h), T_world_cam


def points_in_front(rng, cam, n=10):
    uv = np.column_stack([rng.uniform(0, cam.width, n), rng.uniform(0, cam.height, n)])
    return cam.backproject(uv, rng.uniform(0.5, 4.0, n)), uv


seeds = st.integers(0, 2**32 - 1)
scales = st.floats(1e-6, 1e6).flatmap(lambda m: st.sampled_from([m, -m]))


@given(seeds, scales)
@settings(max_examples=60, deadline=None)
def test_any_scale_and_sign_of_C_gives_the_same_camera(seed, scale):
    rng = np.random.default_rng(seed)
    cam, _ = random_camera(rng)
    other = Camera(scale * cam.C, cam.width, cam.height)
    np.testing.assert_allclose(other.C, cam.C, atol=1e-12)
    X, uv = points_in_front(rng, cam)
    assert np.all(other.depth(X) > 0)
    np.testing.assert_allclose(other.project(X), uv, atol=1e-7)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_project_backproject_round_trip_and_depth_is_metric(seed):
    rng = np.random.default_rng(seed)
    cam, T_world_cam = random_camera(rng)
    X, uv = points_in_front(rng, cam)
    np.testing.assert_allclose(cam.project(X), uv, atol=1e-8)
    # Depth is the z coordinate in the camera frame, in metres.
    X_cam = transform_points(invert_T(T_world_cam), X)
    np.testing.assert_allclose(cam.depth(X), X_cam[:, 2], atol=1e-10)
    np.testing.assert_allclose(cam.center, T_world_cam[:3, 3], atol=1e-10)


@given(seeds)
@settings(max_examples=60, deadline=None)
def test_rays_pass_through_the_pixel(seed):
    rng = np.random.default_rng(seed)
    cam, _ = random_camera(rng)
    X, uv = points_in_front(rng, cam)
    c, d = cam.rays(uv)
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_allclose(cam.project(c + 2.0 * d), uv, atol=1e-8)
    assert np.all(cam.depth(c + d) > 0)  # rays point forward
    # Each ray lies on the paper's two pixel planes (eq. 4).
    m_u, a_u, m_v, a_v = cam.pixel_planes(uv)
    P = c + 1.7 * d
    np.testing.assert_allclose(np.einsum("ij,ij->i", m_u, P) + a_u, 0.0, atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,ij->i", m_v, P) + a_v, 0.0, atol=1e-9)


@given(seeds, scales)
@settings(max_examples=60, deadline=None)
def test_interpretation_plane_contains_centre_and_edge(seed, scale):
    rng = np.random.default_rng(seed)
    cam = Camera(scale * random_camera(rng)[0].C, 512, 256)
    X, _ = points_in_front(rng, cam, 2)
    seg = cam.project(X)
    if np.linalg.norm(seg[1] - seg[0]) < 1e-3:
        return
    plane = cam.interpretation_plane(seg)
    assert np.linalg.norm(plane.n) == pytest.approx(1.0)
    assert abs(signed_distance(plane, cam.center)) < 1e-9
    np.testing.assert_allclose(signed_distance(plane, X), 0.0, atol=1e-9)
    # Sign convention: positive for points seen to the right of p1 → p2 on the screen.
    direction = seg[1] - seg[0]
    right = np.array([-direction[1], direction[0]])  # (u right, v down): rotate +90° on screen
    right /= np.linalg.norm(right)
    probe = cam.backproject((seg.mean(axis=0) + 5.0 * right)[None], 2.0)[0]
    assert signed_distance(plane, probe) > 0


def test_image_line_is_pixel_distance():
    l = Camera.image_line(np.array([[0.0, 0.0], [10.0, 0.0]]))
    assert l @ [3.0, 2.0, 1.0] == pytest.approx(2.0)  # below on screen = right of a rightward segment


@given(seeds)
@settings(max_examples=40, deadline=None)
def test_from_intrinsics_decompose_round_trip(seed):
    rng = np.random.default_rng(seed)
    K = np.array(
        [
            [rng.uniform(300, 900), rng.uniform(-20, 20), rng.uniform(200, 400)],
            [0.0, rng.uniform(300, 900), rng.uniform(100, 300)],
            [0.0, 0.0, 1.0],
        ]
    )
    cam, T_world_cam = random_camera(rng, K)
    K2, T_cam_world = Camera(-7.0 * cam.C, 512, 256).decompose()
    np.testing.assert_allclose(K2, K, rtol=1e-9, atol=1e-7)
    np.testing.assert_allclose(T_cam_world, invert_T(T_world_cam), atol=1e-9)


def test_mirrored_camera_needs_in_front():
    """A camera whose image is mirrored w.r.t. its world frame (det C[:, :3] < 0 with the scene in
    front): the det rule puts the scene behind; in_front= fixes it."""
    rng = np.random.default_rng(0)
    cam, _ = random_camera(rng)
    X, _ = points_in_front(rng, cam)
    F = np.diag([-1.0, 1.0, 1.0, 1.0])  # reflect the world: X' = F X
    C_mirror = cam.C @ F
    Xm = X * [-1.0, 1.0, 1.0]
    assert np.all(Camera(C_mirror, 512, 256).depth(Xm) < 0)
    fixed = Camera(C_mirror, 512, 256, in_front=Xm)
    assert np.all(fixed.depth(Xm) > 0)
    np.testing.assert_allclose(fixed.project(Xm), cam.project(X), atol=1e-8)


def test_in_image_and_reprojection_errors():
    cam = Camera.from_intrinsics(K0, np.eye(4), 512, 256)
    mask = cam.in_image(np.array([[0, 0], [511, 255], [-0.6, 10], [100, 255.6]]))
    assert mask.tolist() == [True, True, False, False]
    X = np.array([[0.0, 0.0, 2.0]])
    assert cam.reprojection_errors(X, np.array([[258.5, 131.5]]))[0] == pytest.approx(5.0)


def test_bad_input_raises_clear_errors():
    C = Camera.from_intrinsics(K0, np.eye(4), 512, 256).C
    with pytest.raises(ValueError, match=r"shape \(3, 4\)"):
        Camera(np.eye(3), 512, 256)
    with pytest.raises(ValueError, match="NaN"):
        Camera(np.full((3, 4), np.nan), 512, 256)
    with pytest.raises(ValueError, match="singular"):
        Camera(np.zeros((3, 4)), 512, 256)
    with pytest.raises(ValueError, match="singular"):
        Camera(np.array([[1.0, 0, 0, 0], [0, 1, 0, 0], [1, 1, 0, 1]]), 512, 256)
    with pytest.raises(ValueError, match="positive finite integer"):
        Camera(C, 0, 256)
    with pytest.raises(ValueError, match="coincide"):
        as_segment(np.array([[3.0, 4.0], [3.0, 4.0]]))
    with pytest.raises(ValueError, match=r"shape \(2, 2\)"):
        Camera.image_line(np.zeros(4))
    with pytest.raises(ValueError, match=r"shape \(N, 2\)"):
        Camera(C, 512, 256).rays(np.zeros(3))
    with pytest.raises(ValueError, match="upper triangular"):
        Camera.from_intrinsics(K0.T, np.eye(4), 512, 256)
