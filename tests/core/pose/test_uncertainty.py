"""The camera calibration's share of a refined pose's covariance (core.pose.uncertainty): the
predicted share against the scatter of poses refined through cameras drawn from the DLT's
covariance (seeded Monte Carlo)."""

from __future__ import annotations

import numpy as np
import pytest

from core.calibration import calibrate_dlt, perturbed_camera
from core.pose import refine
from core.pose.synthetic import paper_problems
from core.pose.uncertainty import pose_delta, with_camera_uncertainty


def _dlt_cov(rng, cam, sigma_px=0.5):
    X = np.column_stack([rng.uniform(-0.5, 0.5, 13), rng.uniform(-0.5, 0.5, 13), rng.uniform(-0.2, 0.3, 13)])
    X = X + cam.center + 2.0 * cam.C[2, :3]  # around the working distance, in front of the camera
    uv = cam.project(X) + rng.normal(0, sigma_px, (13, 2))
    return calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.full(13, sigma_px)).cov


def test_camera_share_of_a_pose_matches_the_scatter():
    rng = np.random.default_rng(11)
    pb = paper_problems(rng, 1, sigma_px=0.0)[0]
    cam = pb.camera
    cov = _dlt_cov(rng, cam)
    kw = dict(segs_uv=pb.segs_true_uv, edges_obj=pb.edges_obj)
    r = refine(cam, pb.T_world_obj, **kw, sigma_px=0.15)
    out = with_camera_uncertainty(r, cam, cov, **kw)
    assert set(out.cov_parts) == {"clicks", "camera calibration"}
    assert np.allclose(out.cov, out.cov_parts["clicks"] + out.cov_parts["camera calibration"])
    assert np.array_equal(out.T_world_obj, r.T_world_obj)  # the pose itself does not change
    share = out.cov_parts["camera calibration"]
    d = np.array(
        [
            pose_delta(
                refine(
                    perturbed_camera(cam, rng.multivariate_normal(np.zeros(12), cov, check_valid="ignore")),
                    r.T_world_obj,
                    **kw,
                    sigma_px=0.15,
                ).T_world_obj,
                r.T_world_obj,
            )
            for _ in range(300)
        ]
    )
    observed = np.array([np.sqrt(d[:, :3].var(axis=0).sum()), np.sqrt(d[:, 3:].var(axis=0).sum())])
    predicted = np.sqrt([np.trace(share[:3, :3]), np.trace(share[3:, 3:])])
    assert observed == pytest.approx(predicted, rel=0.2)
    assert with_camera_uncertainty(r, cam, None, **kw) is r
    with pytest.raises(ValueError, match="camera_cov .* must be a finite symmetric"):
        with_camera_uncertainty(r, cam, np.eye(3), **kw)
