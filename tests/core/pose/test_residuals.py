"""core.pose.residuals: the pixel residual model shared by the pose solvers, and its Jacobian."""

from __future__ import annotations

import numpy as np
import pytest

from core.pose.residuals import as_clicks, interpretation_planes, perturb, pose_distance_cost, residuals
from core.pose.synthetic import random_lines_problem
from core.transforms import exp_so3


def _problem(seed, n_edges=5, n_points=3):
    rng = np.random.default_rng(seed)
    pb = random_lines_problem(rng, n_edges)
    P = rng.uniform(-0.3, 0.3, (n_points, 3))
    return pb, P, pb.camera.project_obj(pb.T_world_obj, P)


def test_zero_at_the_truth_and_shapes():
    pb, P, uv = _problem(0)
    T = pb.T_world_obj
    r, J, feasible = residuals(
        pb.camera, T[:3, :3], T[:3, 3], as_clicks(pb.segs_uv, pb.edges_obj, uv, P), jacobian=True
    )
    assert r.shape == (2 * 5 + 2 * 3,) and J.shape == (16, 6) and feasible
    assert np.abs(r).max() < 1e-8


def test_segment_residual_is_the_signed_pixel_distance_to_the_projected_line():
    pb, _, _ = _problem(1, n_points=0)
    cam, T = pb.camera, pb.T_world_obj
    shifted = pb.segs_uv + np.array([3.0, -4.0])  # 5 px off, in a known direction
    r, _, _ = residuals(cam, T[:3, :3], T[:3, 3], as_clicks(shifted, pb.edges_obj))
    for k in range(len(pb.edges_obj)):
        model_line = cam.image_line(cam.project_obj(T, pb.edges_obj[k]))  # oriented π(A) → π(B)
        expected = [model_line @ np.append(q, 1.0) for q in shifted[k]]
        assert np.allclose(r[2 * k : 2 * k + 2], expected, atol=1e-9)


def test_jacobian_matches_finite_differences():
    for seed in range(5):
        pb, P, uv = _problem(seed)
        clicks = as_clicks(pb.segs_uv + 2.0, pb.edges_obj, uv - 1.5, P)  # non-zero residuals
        rng = np.random.default_rng(seed)
        T0 = perturb(pb.T_world_obj, np.r_[rng.normal(size=3) * 0.02, rng.normal(size=3) * 0.05])
        _, J, _ = residuals(pb.camera, T0[:3, :3], T0[:3, 3], clicks, jacobian=True)
        Jn = np.zeros_like(J)
        h = 1e-7
        for k in range(6):
            d = np.zeros(6)
            d[k] = h
            Tp, Tm = perturb(T0, d), perturb(T0, -d)
            rp = residuals(pb.camera, Tp[:3, :3], Tp[:3, 3], clicks)[0]
            rm = residuals(pb.camera, Tm[:3, :3], Tm[:3, 3], clicks)[0]
            Jn[:, k] = (rp - rm) / (2 * h)
        assert np.abs(J - Jn).max() < 1e-5 * np.abs(J).max()


def test_perturbation_convention():
    """R ← exp([δr]×) R, t ← t + δt: a posed point moves by δt + δr × (X' − t) to first order."""
    pb, _, _ = _problem(2)
    T = pb.T_world_obj
    delta = np.array([0.01, -0.02, 0.03, 0.4, -0.2, 0.1])
    Tn = perturb(T, delta)
    assert np.allclose(Tn[:3, :3], exp_so3(delta[3:]) @ T[:3, :3], atol=1e-14)
    assert np.allclose(Tn[:3, 3], T[:3, 3] + delta[:3])
    small = delta * 1e-6
    X = np.array([0.1, 0.2, -0.3])
    Xw = T[:3, :3] @ X + T[:3, 3]
    moved = perturb(T, small)[:3, :3] @ X + perturb(T, small)[:3, 3]
    assert np.allclose(moved - Xw, small[:3] + np.cross(small[3:], Xw - T[:3, 3]), atol=1e-12)


def test_interpretation_planes_match_the_camera():
    pb, _, _ = _problem(3)
    n, d = interpretation_planes(pb.camera, pb.segs_uv)
    for k, seg in enumerate(pb.segs_uv):
        plane = pb.camera.interpretation_plane(seg)
        assert np.allclose(n[k], plane.n, atol=1e-12) and np.isclose(d[k], plane.d, atol=1e-12)


def test_infeasible_when_a_clicked_point_is_behind_the_camera():
    pb, P, uv = _problem(4)
    T = pb.T_world_obj.copy()
    c = pb.camera.center
    # Reflect the object through the optical centre's depth: every point behind the camera.
    axis = pb.camera.optical_axis
    T_behind = T.copy()
    T_behind[:3, 3] = T[:3, 3] - 2 * ((T[:3, 3] - c) @ axis) * axis
    r, _, feasible = residuals(pb.camera, T_behind[:3, :3], T_behind[:3, 3], as_clicks(None, None, uv, P))
    assert not feasible and np.isnan(r).any()


def test_distance_cost_is_zero_on_the_segments_and_grows_when_an_edge_slides_along_its_line():
    pb, _, _ = _problem(5, n_points=0)
    clicks = as_clicks(pb.segs_uv, pb.edges_obj)
    assert pose_distance_cost(pb.camera, pb.T_world_obj, clicks) < 1e-9
    # Slide the object along one edge's direction: that edge stays on its line, clicks fall off it.
    V = pb.edges_obj[0, 1] - pb.edges_obj[0, 0]
    T = pb.T_world_obj.copy()
    T[:3, 3] += 2.0 * T[:3, :3] @ V
    r, _, _ = residuals(pb.camera, T[:3, :3], T[:3, 3], as_clicks(pb.segs_uv[:1], pb.edges_obj[:1]))
    assert np.abs(r).max() < 1e-6  # still on the infinite line
    assert pose_distance_cost(pb.camera, T, as_clicks(pb.segs_uv[:1], pb.edges_obj[:1])) > 1.0


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"segs_uv": np.zeros((2, 2, 2))}, "go together"),
        ({"points_uv": np.zeros((2, 2))}, "go together"),
        ({"segs_uv": np.zeros((2, 2, 2)), "edges_obj": np.ones((3, 2, 3))}, "match each segment"),
        ({"segs_uv": np.zeros((1, 2, 2)), "edges_obj": np.array([[[0, 0, 0], [1, 0, 0]]])}, "coinciding pixels"),
        ({"segs_uv": np.array([[[0, 0], [1, 1]]]), "edges_obj": np.ones((1, 2, 3))}, "coinciding endpoints"),
        ({"segs_uv": np.array([[[0, np.nan], [1, 1]]]), "edges_obj": np.ones((1, 2, 3))}, "NaN"),
        ({"points_uv": np.zeros((2, 3)), "points_obj": np.zeros((2, 3))}, r"\(N, 2\)"),
    ],
)
def test_bad_clicks_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        as_clicks(**kwargs)
