"""The camera's and the model's stated priors in a pose's σ (core.pose.uncertainty, issue 27): the first-order
shares against the scatter of poses refined when the truth is drawn from those priors (seeded Monte Carlo),
and how they grow with the priors."""

from __future__ import annotations

import numpy as np
import pytest

from core.camera import Camera
from core.pose import refine
from core.pose.refine import ViewClicks
from core.pose.synthetic import paper_problems
from core.pose.uncertainty import (
    MODEL_EXTENT_PER_EDGE,
    intrinsics_prior_cov,
    pose_delta,
    with_camera_uncertainty,
    with_views_camera_uncertainty,
)
from core.transforms import make_T


def _problem():
    """The paper's box and camera, its edges clicked at their projected ends (so that a moved edge's clicks are
    where the Monte Carlo projects them)."""
    pb = paper_problems(np.random.default_rng(5), 1, sigma_px=0.0)[0]
    segs = np.stack([pb.camera.project_obj(pb.T_world_obj, e) for e in pb.edges_obj])
    return pb, dict(segs_uv=segs, edges_obj=pb.edges_obj)


def _spread(d: np.ndarray) -> np.ndarray:
    """RMS of the translation (m) and of the rotation (rad) of pose deltas (K, 6)."""
    return np.array([np.sqrt(d[:, :3].var(axis=0).sum()), np.sqrt(d[:, 3:].var(axis=0).sum())])


def _predicted(share: np.ndarray) -> np.ndarray:
    return np.sqrt([np.trace(share[:3, :3]), np.trace(share[3:, 3:])])


def test_the_camera_prior_of_a_file_matches_the_scatter_of_poses_through_cameras_drawn_from_it():
    pb, kw = _problem()
    cam = pb.camera
    K, T_cam_world = cam.decompose()
    r = refine(cam, pb.T_world_obj, **kw, sigma_px=0.2)
    f_rel, c_px = 0.003, 1.0
    share = with_camera_uncertainty(r, cam, intrinsics_prior_cov(cam, f_rel, c_px), **kw).cov_parts[
        "camera calibration"
    ]
    rng = np.random.default_rng(1)
    d = []
    for _ in range(200):  # the true camera drawn from the prior; mcit believes the file's
        Kt = K.copy()
        Kt[0, 0] *= 1 + f_rel * rng.standard_normal()
        Kt[1, 1] *= 1 + f_rel * rng.standard_normal()
        Kt[:2, 2] += c_px * rng.standard_normal(2)
        true_cam = Camera.from_intrinsics(Kt, T_cam_world, cam.width, cam.height)
        segs = np.stack([true_cam.project_obj(pb.T_world_obj, e) for e in pb.edges_obj])
        d.append(
            pose_delta(refine(cam, r.T_world_obj, segs_uv=segs, edges_obj=pb.edges_obj).T_world_obj, r.T_world_obj)
        )
    assert _spread(np.array(d)) == pytest.approx(_predicted(share), rel=0.2)
    # first order: the share grows as the prior's square
    twice = with_camera_uncertainty(r, cam, intrinsics_prior_cov(cam, 2 * f_rel, 2 * c_px), **kw)
    assert np.allclose(twice.cov_parts["camera calibration"], 4 * share, rtol=0.02, atol=1e-14)


def test_the_model_prior_matches_the_scatter_of_poses_of_models_drawn_from_it():
    pb, kw = _problem()
    cam = pb.camera
    r = refine(cam, pb.T_world_obj, **kw, sigma_px=0.2)
    sigma_m = 0.002
    view = ViewClicks(cam, sigma_px=0.2, **kw)
    flat = np.zeros((2, 3))  # the model's bounds given as a point: its per-edge share alone (its scale's: below)
    out = with_views_camera_uncertainty(r, [view], [None], model_sigma_m=sigma_m, model_bounds_m=flat)
    share = out.cov_parts["model"]
    assert np.allclose(out.cov, r.cov + share)
    rng = np.random.default_rng(2)
    d = []
    _, edge = np.unique(pb.edges_obj.reshape(len(pb.edges_obj), -1), axis=0, return_inverse=True)
    for _ in range(
        200
    ):  # each true model edge off by its own offset (an edge clicked twice, once); mcit believes the model
        true_edges = pb.edges_obj + rng.normal(0, sigma_m, (edge.max() + 1, 1, 3))[edge.ravel()]
        segs = np.stack([cam.project_obj(pb.T_world_obj, e) for e in true_edges])
        d.append(
            pose_delta(refine(cam, r.T_world_obj, segs_uv=segs, edges_obj=pb.edges_obj).T_world_obj, r.T_world_obj)
        )
    assert _spread(np.array(d)) == pytest.approx(_predicted(share), rel=0.2)
    half = with_views_camera_uncertainty(r, [view], [None], model_sigma_m=sigma_m / 2, model_bounds_m=flat)
    half = half.cov_parts["model"]
    assert np.allclose(half, share / 4, rtol=0.02, atol=1e-12)
    assert with_views_camera_uncertainty(r, [view], [None], model_sigma_m=0.0) is r


def test_a_model_whose_length_is_off_is_covered_by_its_scale_share_alone():
    """A ruler's error moves every edge along one dimension together: as independent offsets per edge it averages
    away over many edges (ViSP's castle). A model of 200 edges through a 20 × 13 × 8 cm box (origin at a corner)
    whose true extent along one axis is 2σ longer than the model says: the pose's error is within 2σ on every axis
    with the model's scale share, beyond 3.5σ on some axis without it; and the share is the refined pose's own
    move with the model scaled by ±1σ along each axis (first order)."""
    pb, _ = _problem()
    cam, T = pb.camera, pb.T_world_obj
    dims = np.array([0.2, 0.13, 0.08])
    E = np.random.default_rng(3).uniform(0, 1, (200, 2, 3)) * dims
    sigma_m = 0.0003
    s_ext = MODEL_EXTENT_PER_EDGE * sigma_m / dims  # each extent's relative σ

    def fit(scale: np.ndarray):  # clicks on the true object (the model scaled by ``scale`` about its centre)
        segs = np.stack([cam.project_obj(T, e) for e in dims / 2 + (E - dims / 2) * scale])
        return refine(cam, T, segs_uv=segs, edges_obj=E, sigma_px=0.02)

    r = fit(np.ones(3))
    view = ViewClicks(cam, np.stack([cam.project_obj(T, e) for e in E]), E, sigma_px=0.02)
    bounds = np.array([np.zeros(3), dims])
    full = with_views_camera_uncertainty(r, [view], [None], model_sigma_m=sigma_m, model_bounds_m=bounds)
    flat = with_views_camera_uncertainty(r, [view], [None], model_sigma_m=sigma_m, model_bounds_m=np.zeros((2, 3)))
    worst_without = 0.0
    for k in range(3):
        e = pose_delta(fit(1 + 2 * s_ext * np.eye(3)[k]).T_world_obj, T)
        assert np.all(np.abs(e) <= 2 * np.sqrt(np.diag(full.cov)))
        worst_without = max(worst_without, float(np.max(np.abs(e) / np.sqrt(np.diag(flat.cov)))))
    assert worst_without > 3.5
    moves = np.array(
        [0.5 * (pose_delta(fit(1 + d).T_world_obj, T) - pose_delta(fit(1 - d).T_world_obj, T)) for d in np.diag(s_ext)]
    )
    scale_share = full.cov_parts["model"] - flat.cov_parts["model"]
    assert np.allclose(scale_share, moves.T @ moves, rtol=0.05, atol=1e-3 * np.abs(scale_share).max())


def test_the_scale_share_does_not_depend_on_where_the_model_frame_s_origin_lies():
    """The same object and clicks, its model written with its frame's origin 2 m away (a mesh exported in site
    coordinates) and its pose moved to match: the same pose σ. Scaled about the origin, as first written, the
    far origin's lever turned a 0.4 mm ruler error into centimetres."""
    pb, _ = _problem()
    cam, T = pb.camera, pb.T_world_obj
    dims = np.array([0.2, 0.13, 0.08])
    E = np.random.default_rng(4).uniform(0, 1, (60, 2, 3)) * dims
    shift = np.array([2.0, -1.0, 0.5])  # the model's points in a frame whose origin lies 2 m from them
    T_far = T @ make_T(np.eye(3), -shift)
    segs = np.stack([cam.project_obj(T, e) for e in E])
    covs = []
    for Tm, Em in ((T, E), (T_far, E + shift)):
        r = refine(cam, Tm, segs_uv=segs, edges_obj=Em, sigma_px=0.3)
        view = ViewClicks(cam, segs, Em, sigma_px=0.3)
        bounds = np.array([Em.reshape(-1, 3).min(axis=0), Em.reshape(-1, 3).max(axis=0)])
        covs.append(with_views_camera_uncertainty(r, [view], [None], model_sigma_m=0.0003, model_bounds_m=bounds))

    # the same σ of the model's centre in the world (δX = δt + δr × R X, pose_delta's frame) and of its rotation
    def centre_cov(res, c_obj):
        Rc = res.T_world_obj[:3, :3] @ c_obj
        G = np.hstack([np.eye(3), -np.array([[0, -Rc[2], Rc[1]], [Rc[2], 0, -Rc[0]], [-Rc[1], Rc[0], 0]])])
        return G @ res.cov_parts["model"] @ G.T

    near, far = centre_cov(covs[0], dims / 2), centre_cov(covs[1], dims / 2 + shift)
    assert np.allclose(far, near, rtol=0.02, atol=1e-3 * np.abs(near).max())
    assert np.allclose(covs[1].cov_parts["model"][3:, 3:], covs[0].cov_parts["model"][3:, 3:], rtol=0.02)


def test_the_intrinsics_prior_moves_only_what_a_lens_has():
    """C = K [R | t] with R, t exact: the prior's covariance has rank 4 (fx, fy, u0, v0), and moving C by one of
    its principal steps keeps the camera's centre."""
    pb, _ = _problem()
    cov = intrinsics_prior_cov(pb.camera, 0.01, 2.0)
    w = np.linalg.eigvalsh(cov)
    assert int(np.sum(w > 1e-9 * w.max())) == 4
    from core.calibration import perturbed_camera, principal_steps

    for step in principal_steps(cov):
        assert np.allclose(perturbed_camera(pb.camera, step).center, pb.camera.center, atol=1e-9)
