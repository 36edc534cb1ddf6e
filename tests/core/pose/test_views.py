"""One pose from clicks in two views (``core.pose.refine_views``): the second view fixes the depth along
the first view's line of sight, which one view's clicks fix worst; σ says so and covers the error."""

import numpy as np
import pytest

from core.brep import BRep
from core.pose import ViewClicks, refine, refine_views
from core.pose.synthetic import PAPER_BOX_M, box_problem, paper_box_pose, paper_camera, side_camera
from core.transforms import pose_error


def _two_views(rng, sigma_px: float):
    """A box on the table clicked in both views (every visible edge, twice each)."""
    while True:
        T = paper_box_pose(rng)
        try:
            a = box_problem(rng, paper_camera(), T, PAPER_BOX_M, sigma_px)
            b = box_problem(rng, side_camera(), T, PAPER_BOX_M, sigma_px)
        except ValueError:
            continue
        return T, a, b


def _start(rng, T):
    T0 = T.copy()
    T0[:3, 3] += rng.normal(0.0, 0.02, 3)
    return T0


def _along_sight(camera, T, vec3):
    d = T[:3, 3] - camera.center
    return float(np.dot(vec3, d / np.linalg.norm(d)))


def test_exact_clicks_in_two_views_give_the_true_pose():
    rng = np.random.default_rng(1)
    T, a, b = _two_views(rng, 0.0)
    res = refine_views(
        [ViewClicks(a.camera, a.segs_uv, a.edges_obj), ViewClicks(b.camera, b.segs_uv, b.edges_obj)], _start(rng, T)
    )
    deg, m = pose_error(res.T_world_obj, T)
    assert deg < 1e-6 and m < 1e-8
    assert res.views == (0,) * len(a.segs_uv) + (1,) * len(b.segs_uv)
    assert res.kinds == ("segment",) * (len(a.segs_uv) + len(b.segs_uv))


def test_one_view_through_refine_views_is_refine():
    rng = np.random.default_rng(2)
    T, a, _ = _two_views(rng, 1.0)
    T0 = _start(rng, T)
    one = refine(a.camera, T0, segs_uv=a.segs_uv, edges_obj=a.edges_obj, loss="huber")
    via = refine_views([ViewClicks(a.camera, a.segs_uv, a.edges_obj)], T0, loss="huber")
    assert np.array_equal(one.T_world_obj, via.T_world_obj) and np.array_equal(one.cov, via.cov)


def test_a_view_with_points_only_joins_one_with_edges():
    """View 2 gives two clicked vertices (too few alone); with view 1's edges they fit one pose."""
    rng = np.random.default_rng(3)
    T, a, b = _two_views(rng, 0.0)
    V = BRep.box(*PAPER_BOX_M).vertices[:2]
    pts = b.camera.project_obj(T, V)
    res = refine_views(
        [ViewClicks(a.camera, a.segs_uv, a.edges_obj), ViewClicks(b.camera, points_uv=pts, points_obj=V)],
        _start(rng, T),
    )
    assert pose_error(res.T_world_obj, T)[1] < 1e-8
    assert res.views[-2:] == (1, 1) and res.kinds[-2:] == ("point", "point")


def test_the_second_view_cuts_the_depth_error_and_sigma_covers_it():
    rng = np.random.default_rng(4)
    err1, err2, sd1, sd2 = [], [], [], []
    cam1 = paper_camera()
    for _ in range(60):
        T, a, b = _two_views(rng, 1.0)
        T0 = _start(rng, T)
        one = refine_views([ViewClicks(a.camera, a.segs_uv, a.edges_obj)], T0)
        two = refine_views(
            [ViewClicks(a.camera, a.segs_uv, a.edges_obj), ViewClicks(b.camera, b.segs_uv, b.edges_obj)], T0
        )
        for res, err, sd in ((one, err1, sd1), (two, err2, sd2)):
            d = T[:3, 3] - cam1.center
            d /= np.linalg.norm(d)
            err.append(_along_sight(cam1, T, res.T_world_obj[:3, 3] - T[:3, 3]))
            sd.append(float(np.sqrt(d @ res.cov[:3, :3] @ d)))
    err1, err2, sd1, sd2 = map(np.asarray, (err1, err2, sd1, sd2))
    rms1, rms2 = np.sqrt(np.mean(err1**2)), np.sqrt(np.mean(err2**2))
    assert rms2 < rms1 / 3, (rms1, rms2)  # several-fold
    assert np.median(sd2) < np.median(sd1) / 3
    for err, sd in ((err1, sd1), (err2, sd2)):  # σ is the error's scale: ~95 % within 2σ
        assert np.mean(np.abs(err) <= 2 * sd) >= 0.85
        assert 0.5 < np.sqrt(np.mean((err / sd) ** 2)) < 1.5


def test_bad_views_are_named():
    rng = np.random.default_rng(5)
    T, a, b = _two_views(rng, 0.0)
    good = ViewClicks(a.camera, a.segs_uv, a.edges_obj)
    with pytest.raises(ValueError, match=r"^view 2: .*sigma_px"):
        refine_views([good, ViewClicks(b.camera, b.segs_uv, b.edges_obj, sigma_px=[1.0, 2.0])], T)
    with pytest.raises(ValueError, match=r"^view 2: camera must be a core.camera.Camera"):
        refine_views([good, ViewClicks(b.camera.C, b.segs_uv, b.edges_obj)], T)
    with pytest.raises(ValueError, match="at least one view"):
        refine_views([], T)
    with pytest.raises(ValueError, match="view 1 must be a ViewClicks"):
        refine_views([(a.camera, a.segs_uv)], T)


def test_the_clicks_order_is_the_callers_whatever_the_view():
    """seg_index places each view's segments in the caller's order: the result's per-click arrays follow
    it, and the pose is the one the views give in view order."""
    rng = np.random.default_rng(5)
    T, a, b = _two_views(rng, 1.0)
    T0 = _start(rng, T)
    na, nb = len(a.segs_uv), len(b.segs_uv)
    by_view = refine_views(
        [
            ViewClicks(a.camera, a.segs_uv, a.edges_obj, sigma_px=1.0),
            ViewClicks(b.camera, b.segs_uv, b.edges_obj, sigma_px=2.0),
        ],
        T0,
    )
    order = rng.permutation(na + nb)  # the caller clicked them in this order
    at = np.argsort(order)  # where each view's click stands
    mixed = refine_views(
        [
            ViewClicks(a.camera, a.segs_uv, a.edges_obj, sigma_px=1.0, seg_index=at[:na]),
            ViewClicks(b.camera, b.segs_uv, b.edges_obj, sigma_px=2.0, seg_index=at[na:]),
        ],
        T0,
    )
    assert np.allclose(mixed.T_world_obj, by_view.T_world_obj, atol=1e-9)
    assert np.allclose(mixed.click_residuals_px[at], by_view.click_residuals_px, atol=1e-6)
    assert mixed.views == tuple(by_view.views[k] for k in order)
    assert np.allclose(np.asarray(mixed.sigma_px)[at], by_view.sigma_px)
    with pytest.raises(ValueError, match="for every view or for none"):
        refine_views(
            [
                ViewClicks(a.camera, a.segs_uv, a.edges_obj, seg_index=range(na)),
                ViewClicks(b.camera, b.segs_uv, b.edges_obj),
            ],
            T0,
        )
    with pytest.raises(ValueError, match="exactly once"):
        refine_views(
            [
                ViewClicks(a.camera, a.segs_uv, a.edges_obj, seg_index=range(na)),
                ViewClicks(b.camera, b.segs_uv, b.edges_obj, seg_index=range(nb)),
            ],
            T0,
        )


def test_a_prior_joins_the_views_and_its_shared_share_is_added_back():
    """A PosePrior with a shared covariance (the camera's, common to it and the clicks): fused without it,
    added to the result, said in cov_parts."""
    from core.pose import PosePrior

    rng = np.random.default_rng(6)
    T, a, b = _two_views(rng, 1.0)
    views = [ViewClicks(a.camera, a.segs_uv[:1], a.edges_obj[:1]), ViewClicks(b.camera, b.segs_uv[:1], b.edges_obj[:1])]
    P = np.diag([4e-6, 4e-6, 4e-6, 1e-4, 1e-4, 1e-4])
    shared = P / 4
    res = refine_views(views, T, prior=PosePrior(T, P, shared_cov=shared, name="found pose"))
    assert set(res.cov_parts) == {"found pose and clicks", "camera calibration"}
    assert np.allclose(res.cov, res.cov_parts["found pose and clicks"] + shared)
    assert np.all(np.diag(res.cov_parts["found pose and clicks"]) < np.diag(P - shared))  # the clicks helped
    alone = refine_views([ViewClicks(a.camera)], T, prior=PosePrior(T, P))
    assert np.allclose(alone.cov, P) and alone.rms_px == 0.0 and np.array_equal(alone.T_world_obj, T)


def test_each_cameras_calibration_share_is_added_and_the_shares_add():
    """Clicks in two cameras: each camera's C moved along its covariance, the other held; the two
    calibrations' errors are independent, so the shares add (the two-camera σ had left them out)."""
    from core.pose.uncertainty import with_views_camera_uncertainty

    rng = np.random.default_rng(4)
    T, a, b = _two_views(rng, 0.3)
    views = [
        ViewClicks(a.camera, a.segs_uv, a.edges_obj, sigma_px=0.3),
        ViewClicks(b.camera, b.segs_uv, b.edges_obj, sigma_px=0.3),
    ]
    res = refine_views(views, T)
    covs = []
    for cam in (a.camera, b.camera):
        d = rng.normal(size=12) * 1e-3 * np.abs(cam.C).ravel()
        covs.append(np.outer(d, d) + np.diag((2e-4 * np.abs(cam.C).ravel()) ** 2))
    both = with_views_camera_uncertainty(res, views, covs)
    front = with_views_camera_uncertainty(res, views, [covs[0], None])
    side = with_views_camera_uncertainty(res, views, [None, covs[1]])
    share = both.cov_parts["camera calibration"]
    assert np.allclose(share, front.cov_parts["camera calibration"] + side.cov_parts["camera calibration"])
    assert np.all(np.linalg.eigvalsh(share) > -1e-15) and np.trace(share) > 0
    assert np.allclose(both.cov, res.cov + share)
    assert with_views_camera_uncertainty(res, views, [None, None]) is res
