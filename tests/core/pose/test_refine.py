"""core.pose.refine: the paper's small-motion least squares, iterated to the pixel ML estimate."""

from __future__ import annotations

import numpy as np
import pytest

from core.pose import refine
from core.pose.residuals import perturb
from core.pose.synthetic import paper_problems, random_lines_problem
from core.transforms import exp_so3, pose_error


def moved(rng, T, rot_deg, trans_m):
    """T moved by a rotation of rot_deg about a random axis (about its origin) and trans_m along a random direction."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    d = rng.normal(size=3)
    d /= np.linalg.norm(d)
    return perturb(T, np.r_[trans_m * d, np.radians(rot_deg) * axis])


def test_noise_free_small_motion_is_recovered_exactly():
    rng = np.random.default_rng(0)
    for pb in paper_problems(rng, 10):
        res = refine(pb.camera, moved(rng, pb.T_world_obj, 10.0, 0.05), segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
        deg, m = pose_error(res.T_world_obj, pb.T_world_obj)
        assert deg < 1e-5 and m < 1e-7
        assert res.converged and res.iterations >= 1 and res.rms_px < 1e-6
        assert res.cov.shape == (6, 6) and res.residuals_px.shape == (18,)
        assert res.segment_residuals_px.shape == (9, 2) and res.point_residuals_px.shape == (0, 2)
        assert res.kinds == ("segment",) * 9 and res.click_residuals_px.shape == (9,)
        assert np.allclose(res.cov, res.cov.T) and np.all(np.linalg.eigvalsh(res.cov) > 0)


def test_converges_from_45_degrees_and_20_cm():
    """The paper's single linear step holds to ~18° and 5 cm; iterated with damping it goes much further."""
    rng = np.random.default_rng(1)
    ok = 0
    problems = paper_problems(rng, 40)
    for pb in problems:
        res = refine(pb.camera, moved(rng, pb.T_world_obj, 45.0, 0.20), segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
        deg, m = pose_error(res.T_world_obj, pb.T_world_obj)
        ok += deg < 1e-5 and m < 1e-7
    assert ok >= 0.9 * len(problems)


def test_points_and_segments_mix_and_points_alone_suffice():
    rng = np.random.default_rng(2)
    pb = random_lines_problem(rng, 2)
    P = rng.uniform(-0.3, 0.3, (4, 3))
    uv = pb.camera.project_obj(pb.T_world_obj, P)
    T0 = moved(rng, pb.T_world_obj, 5.0, 0.02)
    mixed = refine(pb.camera, T0, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj, points_uv=uv[:1], points_obj=P[:1])
    assert mixed.kinds == ("segment", "segment", "point") and mixed.residuals_px.shape == (6,)
    assert pose_error(mixed.T_world_obj, pb.T_world_obj)[0] < 1e-5
    points = refine(pb.camera, T0, points_uv=uv, points_obj=P)
    assert pose_error(points.T_world_obj, pb.T_world_obj)[1] < 1e-8
    assert np.isfinite(points.sigma_est_px) and np.isnan(mixed.sigma_est_px)  # 8 vs 6 residuals


def test_covariance_matches_the_scatter_of_noisy_estimates():
    """At σ = 1 px the estimates scatter as the reported covariance says (ML: Cramér–Rao)."""
    rng = np.random.default_rng(3)
    pb0 = paper_problems(rng, 1)[0]
    deltas, covs = [], []
    for _ in range(300):
        segs = pb0.segs_true_uv + rng.normal(size=pb0.segs_uv.shape)
        res = refine(pb0.camera, pb0.T_world_obj, segs_uv=segs, edges_obj=pb0.edges_obj, sigma_px=1.0)
        T = res.T_world_obj
        dr = _log_rotation(T[:3, :3] @ pb0.T_world_obj[:3, :3].T)
        deltas.append(np.r_[T[:3, 3] - pb0.T_world_obj[:3, 3], dr])
        covs.append(res.cov)
    emp = np.cov(np.array(deltas).T)
    cov = np.mean(covs, axis=0)
    ratio = np.diag(emp) / np.diag(cov)
    assert np.all((ratio > 0.75) & (ratio < 1.3)), ratio
    assert abs(np.trace(emp[:3, :3]) / np.trace(cov[:3, :3]) - 1) < 0.15
    assert abs(np.trace(emp[3:, 3:]) / np.trace(cov[3:, 3:]) - 1) < 0.15


def test_huber_downweights_a_wrong_click():
    rng = np.random.default_rng(4)
    pb = paper_problems(rng, 1, sigma_px=0.5)[0]
    segs = pb.segs_uv.copy()
    segs[4, 1] += np.array([0.0, 25.0])  # one clicked pixel 25 px off its edge
    T0 = moved(rng, pb.T_world_obj, 3.0, 0.02)
    l2 = refine(pb.camera, T0, segs_uv=segs, edges_obj=pb.edges_obj)
    hub = refine(pb.camera, T0, segs_uv=segs, edges_obj=pb.edges_obj, loss="huber", huber_px=2.0)
    assert 4 in hub.downweighted and hub.weights[4] < 0.2
    assert l2.downweighted == () and np.all(l2.weights == 1.0)
    assert hub.click_residuals_px[4] > 15.0  # the wrong click stands out
    err_l2, err_hub = pose_error(l2.T_world_obj, pb.T_world_obj), pose_error(hub.T_world_obj, pb.T_world_obj)
    assert err_hub[0] < 0.5 * err_l2[0] and err_hub[1] < 0.5 * err_l2[1]


def test_sigma_estimate_reflects_the_click_noise():
    rng = np.random.default_rng(5)
    est = [
        refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj).sigma_est_px
        for pb in paper_problems(rng, 40, sigma_px=2.0)
    ]
    assert 1.7 < np.sqrt(np.mean(np.square(est))) < 2.3


def test_three_concurrent_edges_leave_the_depth_free():
    rng = np.random.default_rng(6)
    pb = paper_problems(rng, 1)[0]
    ends = [set(map(tuple, np.round(e, 9))) for e in pb.edges_obj]
    triple = next(
        t
        for t in np.array(np.meshgrid(*[range(9)] * 3)).reshape(3, -1).T
        if len({*t}) == 3 and ends[t[0]] & ends[t[1]] & ends[t[2]]
    )
    idx = list(triple)
    with pytest.raises(ValueError, match="translation along"):
        refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_uv[idx], edges_obj=pb.edges_obj[idx])


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"loss": "cauchy"}, "loss must be"),
        ({"sigma_px": 0.0}, "positive"),
        ({"segs_uv": "two", "edges_obj": "two"}, "residuals"),
        ({"behind": True}, "behind the camera"),
        ({"T": np.eye(3)}, r"shape \(4, 4\)"),
    ],
)
def test_bad_input_raises(kwargs, match):
    rng = np.random.default_rng(7)
    pb = paper_problems(rng, 1)[0]
    T = kwargs.pop("T", pb.T_world_obj.copy())
    segs, edges = pb.segs_uv, pb.edges_obj
    if kwargs.pop("behind", False):
        T = pb.T_world_obj.copy()
        T[:3, 3] = 2 * pb.camera.center - T[:3, 3]  # the object mirrored behind the camera
    if kwargs.get("segs_uv") == "two":
        kwargs = {"segs_uv": segs[:2], "edges_obj": edges[:2]}
    with pytest.raises(ValueError, match=match):
        refine(pb.camera, T, **{"segs_uv": segs, "edges_obj": edges, **kwargs})


def _log_rotation(R):
    """Rotation vector (3,) of a small rotation matrix."""
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]) / 2.0
    angle = np.arcsin(min(1.0, np.linalg.norm(w)))
    return w if angle < 1e-12 else w / np.linalg.norm(w) * angle


def test_log_rotation_helper():
    r = np.array([0.01, -0.02, 0.005])
    assert np.allclose(_log_rotation(exp_so3(r)), r, atol=1e-12)


def test_per_click_sigma_weights_the_clicks_and_scales_the_covariance():
    """σ per click: a uniform array equals the scalar; with mixed σ (snapped and raw clicks) the
    covariance matches the scatter over trials and beats weighting every click alike."""
    from core.pose.synthetic import paper_problems

    rng = np.random.default_rng(11)
    pb = paper_problems(rng, 1, 0.0)[0]
    S = len(pb.segs_true_uv)
    one = refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_true_uv, edges_obj=pb.edges_obj, sigma_px=0.5)
    arr = refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_true_uv, edges_obj=pb.edges_obj, sigma_px=np.full(S, 0.5))
    np.testing.assert_allclose(arr.cov, one.cov, rtol=1e-12)
    assert arr.sigma_px.shape == (S,) and one.sigma_px == 0.5

    sigma = np.where(np.arange(S) % 3 == 0, 1.0, 0.15)  # a third raw clicks, the rest snapped
    errs_w, errs_u, covs = [], [], []
    for _ in range(300):
        noisy = pb.segs_true_uv + sigma[:, None, None] * rng.normal(size=pb.segs_true_uv.shape)
        w = refine(pb.camera, pb.T_world_obj, segs_uv=noisy, edges_obj=pb.edges_obj, sigma_px=sigma)
        u = refine(pb.camera, pb.T_world_obj, segs_uv=noisy, edges_obj=pb.edges_obj, sigma_px=1.0)
        errs_w.append(w.T_world_obj[:3, 3] - pb.T_world_obj[:3, 3])
        errs_u.append(u.T_world_obj[:3, 3] - pb.T_world_obj[:3, 3])
        covs.append(w.cov[:3, :3])
    errs_w, errs_u = np.array(errs_w), np.array(errs_u)
    predicted = np.trace(np.mean(covs, axis=0))
    observed = np.mean(np.sum(errs_w**2, axis=1))
    assert observed == pytest.approx(predicted, rel=0.2)
    assert observed < 0.8 * np.mean(np.sum(errs_u**2, axis=1))


def test_per_click_sigma_must_match_the_clicks():
    from core.pose.synthetic import paper_problems

    pb = paper_problems(np.random.default_rng(12), 1, 0.0)[0]
    with pytest.raises(ValueError, match="one per click"):
        refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_true_uv, edges_obj=pb.edges_obj, sigma_px=np.ones(2))
    with pytest.raises(ValueError, match="positive"):
        refine(
            pb.camera,
            pb.T_world_obj,
            segs_uv=pb.segs_true_uv,
            edges_obj=pb.edges_obj,
            sigma_px=np.zeros(len(pb.segs_true_uv)),
        )
