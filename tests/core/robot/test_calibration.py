"""The robot's base from clicked edges of its links (core.robot.calibration): exact clicks give the true base
from a start centimetres and degrees off, silhouettes included; σ matches the spread of noisy solutions;
automatic matching takes a segment only when one feature fits; the tool's tip corners."""

import numpy as np
import pytest

from core.camera import Camera
from core.robot.calibration import (
    BaseClick,
    RobotFeature,
    feature_line,
    features_at,
    match_segment,
    refine_base,
    tip_corners,
)
from core.transforms import exp_so3, invert_T, make_T, pose_error, rot_z, transform_points
from tests.core.robot.arms import ur_like

K = np.array([[500.0, 0, 255.5], [0, 500.0, 127.5], [0, 0, 1]])


def _look_at(eye, target, up=(0.0, 0.0, 1.0)):
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    return invert_T(make_T(np.column_stack([x, np.cross(z, x), z]), eye))


CAM = Camera.from_intrinsics(K, _look_at([0.35, -1.55, 0.7], [0.0, 0.0, 0.1]), 512, 256)
MODEL = ur_like()
CLOSED = 0.001
CONFIGS = np.radians(
    [[-90, -40, 55, -180, -120, -15, 0], [-70, -30, 40, -105, -130, -70, 0], [-120, -70, 130, -160, -35, 35, 0]]
)
CONFIGS[:, -1] = CLOSED
T_TRUE = make_T(rot_z(np.radians(3.0)), [0.02, -0.01, 0.0])


def _offset(T, deg=(0.5, -0.8, 2.5), m=(0.02, -0.015, 0.005)):
    return T @ make_T(exp_so3(np.radians(deg)), m)


def _clicks(configs, T, kinds=("edge", "silhouette"), sigma=0.0, rng=None, camera=CAM):
    """Two pixels along every visible feature of the robot at the base T, in the image (with noise σ px across)."""
    out = []
    for k, q in enumerate(configs):
        for f, seg, visible in features_at(MODEL, q, T, camera.center, config=k):
            if not visible or f.kind not in kinds or np.any(camera.depth(seg) <= 0):
                continue
            uv = camera.project(seg[0] + np.array([[0.25], [0.75]]) * (seg[1] - seg[0]))
            if np.any(uv < 0) or np.any(uv[:, 0] > camera.width) or np.any(uv[:, 1] > camera.height):
                continue
            if np.linalg.norm(uv[1] - uv[0]) < 10:
                continue
            if sigma:
                d = uv[1] - uv[0]
                n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
                uv = uv + rng.normal(0.0, sigma, 2)[:, None] * n
            out.append(BaseClick(uv, f, max(sigma, 0.1)))
    return out


def test_exact_clicks_give_the_true_base_from_centimetres_and_degrees_off():
    clicks = _clicks(CONFIGS[:2], T_TRUE)
    assert {c.feature.kind for c in clicks} == {"edge", "silhouette"} and len(clicks) > 12
    fit = refine_base(MODEL, CONFIGS[:2], clicks, [CAM], _offset(T_TRUE))
    deg, m = pose_error(fit.T_world_base, T_TRUE)
    assert deg < 1e-6 and m < 1e-8, (deg, m)
    assert fit.rms_px < 1e-6 and fit.lines_base.shape == (len(clicks), 2, 3)
    assert fit.result.residuals_px.shape == (2 * len(clicks),) and fit.cov.shape == (6, 6)


def test_silhouettes_alone_converge_to_the_tangent_planes():
    """Generators recomputed at each estimate: at the solution each clicked line's interpretation plane is
    tangent to its cylinder, which the first round's generators (seen from the start) are not."""
    clicks = _clicks(CONFIGS, T_TRUE, kinds=("silhouette",))
    T0 = _offset(T_TRUE)
    fit = refine_base(MODEL, CONFIGS, clicks, [CAM], T0)
    deg, m = pose_error(fit.T_world_base, T_TRUE)
    assert deg < 1e-6 and m < 1e-8 and fit.rounds > 2
    c_base = transform_points(invert_T(fit.T_world_base), CAM.center[None])[0]
    for c, line in zip(clicks, fit.lines_base):
        _, brep, T_bs = MODEL.link_breps(CONFIGS[c.feature.config])[c.feature.shape]
        solid = brep.solids[c.feature.index // 2]
        n = np.cross(line[0] - c_base, line[1] - c_base)  # the plane through the centre and the generator
        n /= np.linalg.norm(n)
        axis = transform_points(T_bs, np.array([solid.p0, solid.p1]))
        assert np.abs((axis - c_base) @ n) == pytest.approx([solid.r0, solid.r1], abs=1e-9)


def test_sigma_matches_the_spread_of_noisy_solutions():
    rng = np.random.default_rng(0)
    errors, covs = [], []
    for _ in range(40):
        clicks = _clicks(CONFIGS, T_TRUE, sigma=0.3, rng=rng)
        fit = refine_base(MODEL, CONFIGS, clicks, [CAM], _offset(T_TRUE))
        errors.append(np.r_[fit.T_world_base[:3, 3] - T_TRUE[:3, 3]])
        covs.append(fit.cov[:3, :3])
    spread = np.std(np.array(errors), axis=0)
    stated = np.sqrt(np.diag(np.mean(covs, axis=0)))
    assert np.all(spread / stated > 0.6) and np.all(spread / stated < 1.6), (spread, stated)
    assert 1000 * np.max(stated) < 3.0  # the three poses fix the base to millimetres from 0.3 px clicks


def test_a_camera_calibration_share_widens_sigma():
    clicks = _clicks(CONFIGS, T_TRUE, sigma=0.0)
    alone = refine_base(MODEL, CONFIGS, clicks, [CAM], T_TRUE)
    cov_C = np.eye(12) * 1e-8 * np.abs(CAM.C).max() ** 2
    both = refine_base(MODEL, CONFIGS, clicks, [CAM], T_TRUE, camera_covs=[cov_C])
    assert np.all(np.diag(both.cov) > np.diag(alone.cov))
    assert set(both.result.cov_parts) == {"clicks", "camera calibration"}


def test_clicks_in_two_cameras_share_the_base():
    side = Camera.from_intrinsics(K, _look_at([1.7, 0.2, 0.7], [0.0, 0.0, 0.1]), 512, 256)
    front = _clicks(CONFIGS[:1], T_TRUE)
    other = [BaseClick(c.seg_uv, c.feature, c.sigma_px, view=1) for c in _clicks(CONFIGS[:1], T_TRUE, camera=side)]
    fit = refine_base(MODEL, CONFIGS[:1], front + other, [CAM, side], _offset(T_TRUE))
    deg, m = pose_error(fit.T_world_base, T_TRUE)
    assert deg < 1e-6 and m < 1e-8


def test_bad_input_is_refused_in_one_line():
    clicks = _clicks(CONFIGS[:1], T_TRUE)
    with pytest.raises(ValueError, match="no clicked edges"):
        refine_base(MODEL, CONFIGS, [], [CAM], T_TRUE)
    with pytest.raises(ValueError, match="configuration 5"):
        refine_base(MODEL, CONFIGS, [BaseClick(clicks[0].seg_uv, RobotFeature(5, 0, "edge", 0))], [CAM], T_TRUE)
    with pytest.raises(ValueError, match="camera 2"):
        refine_base(MODEL, CONFIGS, [BaseClick(clicks[0].seg_uv, clicks[0].feature, view=2)], [CAM], T_TRUE)
    with pytest.raises(ValueError, match="6 degrees of freedom|do not fix"):
        refine_base(MODEL, CONFIGS, clicks[:2], [CAM], T_TRUE)
    with pytest.raises(ValueError, match="kind is one of"):
        RobotFeature(0, 0, "rim", 0)
    with pytest.raises(ValueError, match="has no edge 99"):
        feature_line(MODEL, CONFIGS[0], RobotFeature(0, 7, "edge", 99), np.zeros(3))


def test_features_at_lists_edges_with_their_visibility_and_both_silhouettes():
    feats = features_at(MODEL, CONFIGS[0], T_TRUE, CAM.center)
    shapes = MODEL.link_breps(CONFIGS[0])
    boxes = [k for k, (_, b, _) in enumerate(shapes) if len(b.edges)]
    cylinders = [k for k, (_, b, _) in enumerate(shapes) if b.solids]
    edges = [f for f, _, _ in feats if f.kind == "edge"]
    assert len(edges) == 12 * len(boxes)
    assert 0 < sum(v for f, _, v in feats if f.kind == "edge") < len(edges)  # some edges face away
    assert sum(f.kind == "silhouette" for f, _, _ in feats) == 2 * len(cylinders)
    c_base = transform_points(invert_T(T_TRUE), CAM.center[None])[0]
    for f, seg, _ in feats:  # the same lines as feature_line gives in the base frame
        assert np.allclose(transform_points(T_TRUE, feature_line(MODEL, CONFIGS[0], f, c_base)), seg)


def _visible(q, T):
    """The robot's visible features at q and base T in front of CAM: (features, world segments (F, 2, 3))."""
    got = [(f, s) for f, s, v in features_at(MODEL, q, T, CAM.center) if v and np.all(CAM.depth(s) > 0)]
    return [f for f, _ in got], np.array([s for _, s in got])


def test_match_segment_takes_the_one_feature_the_base_s_uncertainty_allows():
    q, sharp = CONFIGS[0], np.diag([1e-6] * 3 + [np.radians(0.05) ** 2] * 3)  # the base known to 1 mm, 0.05°
    feats, W = _visible(q, T_TRUE)
    P = CAM.project(W.reshape(-1, 3)).reshape(-1, 2, 2)
    L = np.linalg.norm(P[:, 1] - P[:, 0], axis=1)
    i = int(np.argmax(L))  # the longest feature in the image
    click = P[i, 0] + np.array([[0.3], [0.7]]) * (P[i, 1] - P[i, 0])
    j, d2 = match_segment(click, W, CAM, T_TRUE, sharp)
    assert j == i and d2[i] < 1e-6
    n = np.array([-(P[i, 1] - P[i, 0])[1], (P[i, 1] - P[i, 0])[0]]) / L[i]
    assert match_segment(click + 30 * n, W, CAM, T_TRUE, sharp)[0] != i  # 30 px off: not it
    vague = np.diag([0.05**2] * 3 + [np.radians(5.0) ** 2] * 3)  # 5 cm, 5°: several features could be it
    j, d2 = match_segment(click, W, CAM, T_TRUE, vague)
    assert j is None and np.sum(d2 < 13.8) > 1
    assert match_segment(click, np.zeros((0, 2, 3)), CAM, T_TRUE, sharp)[0] is None


def test_match_segment_is_never_wrong_when_the_estimate_is_as_far_off_as_its_covariance_says():
    """A click on each feature, matched at estimates drawn from the covariance about the truth: the old matcher
    (nearest within 20 px, twice as near as the next) took another feature here for a base 2.5 cm and 2° off."""
    rng = np.random.default_rng(3)
    cov = np.diag([0.008**2] * 3 + [np.radians(0.8) ** 2] * 3)
    right = wrong = 0
    for q in CONFIGS:
        feats, W = _visible(q, T_TRUE)
        P = CAM.project(W.reshape(-1, 3)).reshape(-1, 2, 2)
        for _ in range(8):
            d = rng.multivariate_normal(np.zeros(6), cov)
            T_est = make_T(exp_so3(d[3:]), d[:3] + T_TRUE[:3, 3] - exp_so3(d[3:]) @ T_TRUE[:3, 3]) @ T_TRUE
            feats_est, W_est = _visible(q, T_est)
            for f, p in zip(feats, P):
                if np.linalg.norm(p[1] - p[0]) < 25 or f not in feats_est:
                    continue
                click = p[0] + np.array([[0.25], [0.75]]) * (p[1] - p[0]) + rng.normal(0, 0.7, (2, 1))
                j, _ = match_segment(click, W_est, CAM, T_est, cov, sigma_px=0.7)
                right += j is not None and feats_est[j] == f
                wrong += j is not None and feats_est[j] != f
    assert wrong == 0 and right > 50, (wrong, right)


def test_tip_corners_are_the_closed_fingertips_end_corners():
    q = CONFIGS[0]
    X, shapes, vertices = tip_corners(MODEL, q)
    assert X.shape == (4, 3) and len(shapes) == len(vertices) == 4
    T_tool = MODEL.tool_pose(q)
    local = transform_points(invert_T(T_tool), X)
    assert np.allclose(local[:, 2], 0.0, atol=1e-9)  # at the tool's end (the fingertips reach the TCP)
    assert np.allclose(np.sort(np.abs(local[:, 0])), 0.01) and np.allclose(np.abs(local[:, 1]), 0.015 + CLOSED)
    placed = MODEL.link_breps(q)
    for x, k, v in zip(X, shapes, vertices):
        _, brep, T = placed[k]
        assert np.allclose(transform_points(T, brep.vertices[v][None])[0], x)
