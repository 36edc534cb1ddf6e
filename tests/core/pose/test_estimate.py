"""core.pose.estimate_pose: P3L on the first usable triple, every candidate refined with all clicks."""

from __future__ import annotations

import numpy as np
import pytest

from core.pose import PoseEstimate, estimate_pose, refine
from core.pose.synthetic import paper_problems
from core.transforms import pose_error


def paper_problem(seed, sigma_px=0.0):
    return paper_problems(np.random.default_rng(seed), 1, sigma_px)[0]


def _ends(edge):
    return set(map(tuple, np.round(edge, 9)))


def test_noise_free_estimate_is_exact_and_first_for_every_click_order():
    for seed in range(15):
        pb = paper_problem(seed)
        order = np.random.default_rng(seed).permutation(9)
        est = estimate_pose(pb.camera, pb.segs_uv[order], pb.edges_obj[order])
        assert isinstance(est, PoseEstimate)
        deg, m = pose_error(est.T_world_obj, pb.T_world_obj)
        assert deg < 1e-5 and m < 1e-7
        assert est.candidates[0].refined is est.result and est.candidates[0].source == "p3l"
        scores = [c.score_px for c in est.candidates]
        assert scores == sorted(scores)
        assert len(est.triple) == 3


def test_a_degenerate_first_triple_is_skipped():
    """Three edges through one vertex first (no depth from lines): P3L moves on to the next triple."""
    pb = paper_problem(20)
    ends = [_ends(e) for e in pb.edges_obj]
    first = next(
        (i, j, k) for i in range(9) for j in range(i + 1, 9) for k in range(j + 1, 9) if ends[i] & ends[j] & ends[k]
    )
    order = list(first) + [q for q in range(9) if q not in first]
    est = estimate_pose(pb.camera, pb.segs_uv[order], pb.edges_obj[order])
    assert est.skipped_triples[0][0] == (0, 1, 2) and "meet in one vertex" in est.skipped_triples[0][1]
    assert est.triple != (0, 1, 2)
    assert pose_error(est.T_world_obj, pb.T_world_obj)[0] < 1e-5


def test_noisy_estimate_is_near_the_truth_with_a_consistent_covariance():
    errs = []
    for seed in range(30, 50):
        pb = paper_problem(seed, sigma_px=1.0)
        est = estimate_pose(pb.camera, pb.segs_uv, pb.edges_obj)
        dt = est.T_world_obj[:3, 3] - pb.T_world_obj[:3, 3]
        errs.append(dt @ np.linalg.solve(est.cov[:3, :3], dt))  # squared Mahalanobis distance, 3 DoF
    assert 1.5 < np.mean(errs) < 5.0  # χ²(3) has mean 3


def test_prior_only_with_two_edges_and_a_point():
    pb = paper_problem(60)
    vertex = pb.edges_obj[5, 0]
    uv = pb.camera.project_obj(pb.T_world_obj, vertex[None])
    prior = pb.T_world_obj.copy()
    prior[:3, 3] += [0.03, -0.02, 0.0]
    est = estimate_pose(pb.camera, pb.segs_uv[:2], pb.edges_obj[:2], uv, vertex[None], T_prior=prior)
    assert est.triple is None and est.best.source == "prior"
    assert pose_error(est.T_world_obj, pb.T_world_obj)[1] < 1e-6


def test_prior_is_one_more_candidate_merged_when_it_reaches_a_listed_pose():
    pb = paper_problem(61, sigma_px=0.5)
    alone = estimate_pose(pb.camera, pb.segs_uv, pb.edges_obj)
    with_prior = estimate_pose(pb.camera, pb.segs_uv, pb.edges_obj, T_prior=pb.T_world_obj)
    from_prior = refine(pb.camera, pb.T_world_obj, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj).T_world_obj
    listed = [c for c in alone.candidates if c.refined is not None and pose_error(c.T_world_obj, from_prior)[0] < 1e-4]
    if listed:  # the prior reached a pose P3L already gave: merged, nothing new
        assert len(with_prior.candidates) == len(alone.candidates)
        assert "prior" not in [c.source for c in with_prior.candidates]
    else:
        assert "prior" in [c.source for c in with_prior.candidates]
    assert pose_error(with_prior.T_world_obj, pb.T_world_obj)[0] < 1.0


def test_too_few_edges_without_prior_raise():
    pb = paper_problem(62)
    with pytest.raises(ValueError, match="needs 3 edges"):
        estimate_pose(pb.camera, pb.segs_uv[:2], pb.edges_obj[:2])


def test_all_parallel_edges_raise_with_the_solver_reason():
    pb = paper_problem(63)
    V = pb.edges_obj[:, 1] - pb.edges_obj[:, 0]
    dirs = np.argmax(np.abs(V), axis=1)
    idx = np.flatnonzero(dirs == 2)  # the vertical edges only
    with pytest.raises(ValueError, match="parallel"):
        estimate_pose(pb.camera, pb.segs_uv[idx], pb.edges_obj[idx])


def test_candidates_of_further_triples_are_added_while_none_fits():
    """A triple whose candidates all refine to a poor fit (a local minimum) brings in the next one."""
    pb = paper_problem(64, sigma_px=0.5)
    single = estimate_pose(pb.camera, pb.segs_uv, pb.edges_obj)
    assert all(c.triple == single.triple for c in single.candidates)
    # No fit is good enough at 1e-9 px: the candidates of the first three usable triples are pooled.
    pooled = estimate_pose(pb.camera, pb.segs_uv, pb.edges_obj, fit_rms_px=1e-9, max_triples=3)
    poor = [tri for tri, reason in pooled.skipped_triples if "refine to RMS" in reason]
    assert poor == [(0, 1, 2), (0, 1, 3), (0, 1, 4)][: len(poor)] and len(poor) >= 2
    assert len(pooled.candidates) >= len(single.candidates)  # the same poses (merged) and maybe more
    assert pose_error(pooled.T_world_obj, single.T_world_obj)[0] < 1e-6  # the same best pose
