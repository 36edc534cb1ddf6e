"""core.pose.refine_with_prior: a pose found on the image (with its covariance) refined together with
clicked edges, the maximum a posteriori pose."""

from __future__ import annotations

import numpy as np
import pytest

from core.pose import refine, refine_with_prior
from core.pose.residuals import perturb
from core.pose.synthetic import paper_problems


def table_cov(T, sd_xy=0.005, sd_psi_deg=3.0):
    """A prior of rank 3: x, y and the heading about the world's z free, the rest fixed (on the table)."""
    G = np.zeros((6, 3))
    G[0, 0] = G[1, 1] = 1.0
    G[3:, 2] = [0.0, 0.0, 1.0]
    return G @ np.diag([sd_xy**2, sd_xy**2, np.radians(sd_psi_deg) ** 2]) @ G.T


def test_without_clicks_the_prior_is_returned_with_its_covariance():
    pb = paper_problems(np.random.default_rng(0), 1)[0]
    P = np.diag([1e-6, 4e-6, 9e-6, 1e-4, 4e-4, 9e-4])
    res = refine_with_prior(pb.camera, pb.T_world_obj, P)
    assert np.allclose(res.T_world_obj, pb.T_world_obj) and np.allclose(res.cov, P, rtol=1e-9)
    assert res.kinds == () and res.rms_px == 0.0


def test_one_clicked_edge_corrects_the_heading_the_prior_leaves_loose():
    """A found pose 2° off in heading (σ 3°) and 3 mm off in x, y (σ 5 mm): one exactly clicked edge
    brings the heading and the position along the edge's normal back; the fixed directions (height,
    tilt) do not move; the covariance shrinks and stays symmetric positive definite."""
    rng = np.random.default_rng(1)
    fixed_moved = 0
    for pb in paper_problems(rng, 8):
        T_true = pb.T_world_obj
        T_prior = perturb(T_true, np.r_[0.003, -0.002, 0.0, 0.0, 0.0, np.radians(2.0)])
        P = table_cov(T_prior)
        res = refine_with_prior(pb.camera, T_prior, P, segs_uv=pb.segs_uv[:2], edges_obj=pb.edges_obj[:2], sigma_px=0.5)
        d_before = np.linalg.norm(T_prior[:3, 3] - T_true[:3, 3])
        d_after = np.linalg.norm(res.T_world_obj[:3, 3] - T_true[:3, 3])
        R_err = lambda T: np.degrees(np.arccos(np.clip((np.trace(T[:3, :3] @ T_true[:3, :3].T) - 1) / 2, -1, 1)))  # noqa: E731
        assert R_err(res.T_world_obj) < 0.5 * R_err(T_prior) or d_after < 0.5 * d_before
        fixed_moved = max(fixed_moved, abs(res.T_world_obj[2, 3] - T_prior[2, 3]))
        assert np.all(np.diag(res.cov) <= np.diag(P) + 1e-8 + 1e-12)  # fixed directions: fixed_std²
        assert np.allclose(res.cov, res.cov.T) and np.all(np.linalg.eigvalsh(res.cov) > 0)
    assert fixed_moved < 1e-4  # the height stays as the table has it


def test_with_many_clicks_and_a_loose_prior_it_is_the_plain_refinement():
    rng = np.random.default_rng(2)
    for pb in paper_problems(rng, 5):
        T0 = perturb(pb.T_world_obj, np.r_[0.01, 0.0, -0.01, 0.02, 0.0, 0.03])
        plain = refine(pb.camera, T0, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
        joint = refine_with_prior(pb.camera, T0, np.eye(6) * 1e4, segs_uv=pb.segs_uv, edges_obj=pb.edges_obj)
        assert np.allclose(joint.T_world_obj, plain.T_world_obj, atol=1e-6)
        assert np.allclose(joint.cov, plain.cov, rtol=1e-3, atol=1e-12)


@pytest.mark.parametrize(
    "cov, match", [(np.eye(5), "6, 6"), (np.full((6, 6), np.nan), "finite"), (-np.eye(6), "positive semi-definite")]
)
def test_bad_prior_is_refused(cov, match):
    pb = paper_problems(np.random.default_rng(3), 1)[0]
    with pytest.raises(ValueError, match=match):
        refine_with_prior(pb.camera, pb.T_world_obj, cov)
