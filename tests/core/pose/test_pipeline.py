"""core.pose.pipeline: one ranking, the refinement from starts with the plausibility fallback, the
operator's starts and the session's estimates."""

import numpy as np
import pytest

from core.brep import BRep
from core.pose import PosePrior, Refused, ViewClicks, refine
from core.pose.pipeline import Estimates, Start, operator_starts, rank, refine_starts, within
from core.pose.residuals import perturb
from core.pose.synthetic import PAPER_BOX_M, paper_problems
from core.pose.uncertainty import with_camera_uncertainty
from core.transforms import pose_error


def _problem(seed=0, sigma=0.5):
    pb = paper_problems(np.random.default_rng(seed), 1, sigma)[0]
    return pb, [ViewClicks(pb.camera, pb.segs_uv, pb.edges_obj, sigma_px=sigma)]


def test_rank_orders_by_score_merges_the_same_pose_and_keeps_failures():
    T = np.eye(4)
    T[2, 3] = 2.0
    near = perturb(T, np.r_[0.001, 0, 0, 0, 0, 0])  # 1 mm: the same pose at (0.5°, 5 mm)
    far = perturb(T, np.r_[0.1, 0, 0, 0, 0, 0])
    poses, scores = [far, near, T, far], [3.0, 2.0, 1.0, np.inf]
    assert rank(poses, scores, within(0.5, 0.005)) == [2, 0, 3]  # near merged into T; the failed one kept, last
    assert rank(poses, scores, within(0.5, 0.005), limit=2) == [2, 0]
    assert rank([T, T], [1.0, 1.0], within(0.5, 0.005), tiebreak=[1, 0]) == [1]  # the tie: the better second


def test_refine_starts_offers_the_first_plausible_start_and_says_why_not_the_others():
    pb, views = _problem()
    model = BRep.box(*PAPER_BOX_M)
    behind = pb.T_world_obj.copy()
    behind[:3, 3] = 2 * pb.camera.center - behind[:3, 3]  # the box behind the camera
    starts = [Start(behind, "candidate 1", 0), Start(pb.T_world_obj, "candidate 2", 1)]
    out = refine_starts(views, starts, model=model, camera=pb.camera, max_rms_px=1.5)
    assert out.start == 1 and out.failures[0][0] == "candidate 1" and "behind the camera" in out.failures[0][1]
    direct = refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj, sigma_px=0.5)
    assert np.allclose(out.result.T_world_obj, direct.T_world_obj)
    parts = out.result.cov_parts  # the clicks' share, and the model's stated prior (issue 27)
    assert np.allclose(parts["clicks"], direct.cov) and np.allclose(out.result.cov, direct.cov + parts["model"])
    assert np.trace(parts["model"]) > 0
    none = refine_starts(views, starts, model=model, camera=pb.camera, max_rms_px=1e-6)  # nothing fits that well
    assert none.result is None and none.start is None and len(none.failures) == 2
    assert "more than the 0.0 px allowed" in none.failures[1][1]


def test_refine_starts_adds_the_camera_calibrations_share_unless_the_start_is_a_prior():
    pb, views = _problem(1)
    model = BRep.box(*PAPER_BOX_M)
    d = np.random.default_rng(0).normal(size=12) * 1e-3 * np.abs(pb.camera.C).ravel()
    cam_cov = np.outer(d, d) + np.diag((1e-4 * np.abs(pb.camera.C).ravel()) ** 2)
    plain = Start(pb.T_world_obj, "the database pose")
    out = refine_starts(views, [plain], model=model, camera=pb.camera, max_rms_px=2.0, camera_covs=[cam_cov])
    bare = refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj, sigma_px=0.5)
    want = with_camera_uncertainty(bare, pb.camera, cam_cov, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
    parts = out.result.cov_parts  # and the model's stated prior (issue 27)
    assert set(parts) == {"clicks", "camera calibration", "model"}
    assert np.allclose(out.result.cov, want.cov + parts["model"])
    prior = Start(pb.T_world_obj, "found pose 1", 0, PosePrior(pb.T_world_obj, np.eye(6) * 1e-4))
    out = refine_starts(views, [prior], model=model, camera=pb.camera, max_rms_px=2.0, camera_covs=[cam_cov])
    assert out.result.cov_parts == {}  # a prior measured through C holds the calibration's share already


def test_operator_starts_in_the_order_refine_tries_them():
    T = [np.eye(4) * (i + 1) for i in range(3)]
    db, last = np.eye(4) * 9, np.eye(4) * 8
    labels = lambda starts: [(s.label, s.index) for s in starts]  # noqa: E731
    assert labels(operator_starts([], None, None, db)) == [("from the database pose", None)]
    assert labels(operator_starts(T, 1, None, db)) == [("candidate 2", 1), ("candidate 1", 0), ("candidate 3", 2)]
    assert labels(operator_starts(T, 1, last, db))[0] == ("from the last refined pose", -1)
    measured = Start(T[0], "found pose 1", 0, PosePrior(T[0], np.eye(6)))
    assert operator_starts(T, 1, last, db, measured) == [measured]


def test_estimates_keep_the_pose_in_use_and_count_the_changes():
    pb, views = _problem(2)
    est = Estimates(pb.T_world_obj)
    assert np.array_equal(est.current, pb.T_world_obj)
    with pytest.raises(Refused, match="no candidates: Solve first"):
        est.choose(0)
    other = perturb(pb.T_world_obj, np.r_[0.01, 0, 0, 0, 0, 0.02])
    g = est.generation
    est.offer([pb.T_world_obj, other])
    assert est.chosen == 0 and est.generation == g + 1
    with pytest.raises(Refused, match="candidates 1..2, not 3"):
        est.choose(2)
    est.choose(1)
    assert np.array_equal(est.current, other)
    res = refine(pb.camera, other, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
    est.adopt(res, est.starts()[0])
    assert est.refined is res and est.chosen == 1 and np.array_equal(est.current, res.T_world_obj)
    est.clicks_changed()
    assert est.refined is None and np.allclose(est.last_refined, res.T_world_obj)
    assert est.starts()[0].label == "from the last refined pose"
    deg, m = pose_error(est.current, res.T_world_obj)
    assert deg == 0 and m == 0
    est.offer([])
    assert est.chosen is None and est.last_refined is None and np.array_equal(est.current, pb.T_world_obj)
