import numpy as np
import pytest

from core.calibration import calibrate_dlt, calibrate_turret, kabsch
from core.camera import Camera
from core.geometry import signed_distance
from core.rangefinder import RangeFinderSpec, aim, beam_point
from core.transforms import make_T, random_rotation, rot_x, rot_z

from .test_camera import random_camera
from .vgg_house import load_house


def calibration_object(rng, cam, n=12):
    """Non-coplanar points in front of the camera with their exact pixels."""
    uv = np.column_stack([rng.uniform(20, cam.width - 20, n), rng.uniform(20, cam.height - 20, n)])
    return cam.backproject(uv, rng.uniform(1.5, 2.5, n)), uv


def test_dlt_is_exact_without_noise():
    rng = np.random.default_rng(0)
    cam, _ = random_camera(rng)
    X, uv = calibration_object(rng, cam)
    est, rms = calibrate_dlt(X, uv, cam.width, cam.height)
    assert rms < 1e-6
    np.testing.assert_allclose(est.C, cam.C, atol=1e-7)
    np.testing.assert_allclose(est.center, cam.center, atol=1e-6)


def test_refinement_lowers_the_reprojection_error_and_reports_residuals():
    rng = np.random.default_rng(1)
    cam, _ = random_camera(rng)
    X, uv = calibration_object(rng, cam, 30)
    noisy = uv + rng.normal(0.0, 1.0, uv.shape)
    result = calibrate_dlt(X, noisy, cam.width, cam.height)
    est, rms = result
    assert result.residuals_px.shape == (30, 2) and result.errors_px.shape == (30,)
    assert rms == pytest.approx(np.sqrt(np.mean(result.errors_px**2)))
    assert rms <= result.linear_rms_px + 1e-12
    # The RMS of 2D residuals after fitting 11 parameters to 60 coordinates is about
    # σ·√2·√(1 − 11/60) ≈ 1.28 px for σ = 1 px.
    assert 1.0 < rms < 1.5
    # It predicts unseen points to within a couple of pixels.
    Xt, uvt = calibration_object(rng, cam, 50)
    assert np.median(est.reprojection_errors(Xt, uvt)) < 1.5


def test_weighted_refinement_trusts_the_precise_points():
    """Precise points (σ = 0.1 px) beside rough ones (σ = 2 px): weighting by 1/σ gives a C nearer the
    truth than treating them alike, on average over trials (maximum likelihood vs not)."""
    rng = np.random.default_rng(7)
    cam, _ = random_camera(rng)
    errs = {"equal": [], "weighted": []}
    for _ in range(20):
        X, uv = calibration_object(rng, cam, 14)
        sigma = np.where(np.arange(14) < 10, 0.1, 2.0)
        noisy = uv + rng.normal(0.0, 1.0, uv.shape) * sigma[:, None]
        Xt, _ = calibration_object(rng, cam, 30)
        for key, s in (("equal", None), ("weighted", sigma)):
            est, _ = calibrate_dlt(X, noisy, cam.width, cam.height, sigma_px=s)
            errs[key].append(np.sqrt(np.mean(np.sum((est.project(Xt) - cam.project(Xt)) ** 2, axis=1))))
    assert np.mean(errs["weighted"]) < 0.5 * np.mean(errs["equal"])
    X, uv = calibration_object(rng, cam, 8)
    with pytest.raises(ValueError, match="sigma_px must hold 8 positive"):
        calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.ones(7))
    with pytest.raises(ValueError, match="sigma_px must hold 8 positive"):
        calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.r_[np.ones(7), 0.0])


def test_calibration_bad_input():
    rng = np.random.default_rng(2)
    cam, _ = random_camera(rng)
    X, uv = calibration_object(rng, cam)
    with pytest.raises(ValueError, match="at least 6"):
        calibrate_dlt(X[:5], uv[:5], 512, 256)
    with pytest.raises(ValueError, match="pair one to one"):
        calibrate_dlt(X, uv[:-1], 512, 256)
    Xp = X.copy()
    Xp[:, 2] = 0.0
    with pytest.raises(ValueError, match="coplanar"):
        calibrate_dlt(Xp, uv, 512, 256)
    Xl = np.outer(np.arange(8.0), [1.0, 2.0, 3.0])
    with pytest.raises(ValueError, match="collinear"):
        calibrate_dlt(Xl, uv[:8], 512, 256)
    bad = uv.copy()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        calibrate_dlt(X, bad, 512, 256)
    with pytest.raises(ValueError, match=r"shape \(N, 3\)"):
        calibrate_dlt(X[:, :2], uv, 512, 256)


def test_vgg_house_dlt_reproduces_each_view(shared_data):
    """Real data: DLT from each view's matched corners and 3D points reproduces the given P."""
    house = load_house(shared_data("vgg-house"))
    report = []
    for v in range(10):
        X, uv = house.point_pairs(v)
        est, rms = calibrate_dlt(X, uv, 768, 576)
        given = house.camera(v)
        diff = np.linalg.norm(est.project(house.points) - given.project(house.points), axis=1)
        report.append((v, len(X), rms, float(np.max(diff))))
        assert np.all(est.depth(X) > 0)
        assert rms < 1.0, f"view {v}: RMS {rms:.3f} px"
        assert np.max(diff) < 1.0, f"view {v}: our C and the given P differ by {np.max(diff):.3f} px"
    print("\nview  points  rms_px  max |C − P| over all 3D points (px)")
    for v, n, rms, d in report:
        print(f"{v:4d}  {n:6d}  {rms:6.3f}  {d:6.3f}")


def test_vgg_house_interpretation_planes_contain_the_3d_lines(shared_data):
    """Real data: each view's interpretation planes of the matched 2D lines contain the matched 3D lines."""
    house = load_house(shared_data("vgg-house"))
    angles, offsets, px = [], [], []
    for v in range(10):
        cam = house.camera(v)
        L3, L2 = house.line_pairs(v)
        for seg3, seg2 in zip(L3, L2):
            plane = cam.interpretation_plane(seg2)
            direction = (seg3[1] - seg3[0]) / np.linalg.norm(seg3[1] - seg3[0])
            angles.append(np.degrees(np.arcsin(abs(plane.n @ direction))))
            offsets.append(np.abs(signed_distance(plane, seg3)).max())
            l = Camera.image_line(seg2)
            px.append(np.abs(np.column_stack([cam.project(seg3), np.ones(2)]) @ l).max())
    angles, offsets, px = map(np.array, (angles, offsets, px))
    print(
        f"\n{len(angles)} matched lines: median angle line/plane {np.median(angles):.3f}°, "
        f"median endpoint offset {np.median(offsets):.4f} (house units), median image distance {np.median(px):.3f} px"
    )
    assert np.median(px) < 0.6
    assert np.median(angles) < 0.5


def test_kabsch_recovers_a_rigid_transform():
    rng = np.random.default_rng(3)
    T = make_T(random_rotation(rng), rng.normal(size=3))
    X_b = rng.normal(size=(6, 3))
    X_a = X_b @ T[:3, :3].T + T[:3, 3]
    np.testing.assert_allclose(kabsch(X_b, X_a), T, atol=1e-12)
    with pytest.raises(ValueError, match="collinear"):
        kabsch(np.outer(np.arange(4.0), [1, 1, 0]), np.outer(np.arange(4.0), [1, 1, 0]))


def _turret_measurements(rng, T_world_turret, n, spec, noise=True):
    X = np.column_stack([rng.uniform(-0.6, 0.6, n), rng.uniform(-0.2, 0.8, n), rng.uniform(0.0, 0.3, n)])
    pan, tilt, rho = aim(T_world_turret, X)
    if noise:
        pan = np.round(pan / spec.step_rad) * spec.step_rad  # the turret lands on a step
        tilt = np.round(tilt / spec.step_rad) * spec.step_rad
        X = beam_point(T_world_turret, pan, tilt, rho)  # the point actually hit
        rho = rho + spec.sigma_range_m * rng.normal(size=n)
    return pan, tilt, rho, X


def test_turret_calibration_exact_and_noisy():
    rng = np.random.default_rng(4)
    spec = RangeFinderSpec()
    T = make_T(rot_z(1.5) @ rot_x(0.1), [0.2, -1.45, 0.75])
    pan, tilt, rho, X = _turret_measurements(rng, T, 5, spec, noise=False)
    cal = calibrate_turret(pan, tilt, rho, X)
    np.testing.assert_allclose(cal.T_world_turret, T, atol=1e-10)
    assert cal.rms_m < 1e-10
    # Noisy: the refined estimate is at least as good as Kabsch on average, and its
    # covariance predicts the translation scatter.
    errs_ref, errs_lin, covs = [], [], []
    for _ in range(200):
        pan, tilt, rho, X = _turret_measurements(rng, T, 8, spec)
        cal = calibrate_turret(pan, tilt, rho, X, spec)
        errs_ref.append(cal.T_world_turret[:3, 3] - T[:3, 3])
        covs.append(cal.cov)
        lin = kabsch(
            rho[:, None] * np.column_stack([np.cos(tilt) * np.cos(pan), np.cos(tilt) * np.sin(pan), np.sin(tilt)]), X
        )
        errs_lin.append(lin[:3, 3] - T[:3, 3])
    errs_ref, errs_lin = np.array(errs_ref), np.array(errs_lin)
    assert np.mean(np.sum(errs_ref**2, 1)) <= 1.05 * np.mean(np.sum(errs_lin**2, 1))
    assert cal.residuals_m.shape == (8, 3) and cal.cov.shape == (6, 6)
    # The rms error is a few millimetres, as the 5 mm range noise implies.
    assert 0.5e-3 < np.sqrt(np.mean(np.sum(errs_ref**2, 1))) < 10e-3


def test_turret_calibration_bad_input():
    with pytest.raises(ValueError, match="pair one to one"):
        calibrate_turret(np.zeros(3), np.zeros(3), np.ones(2), np.eye(3))
    with pytest.raises(ValueError, match="missed shot"):
        calibrate_turret(np.zeros(3), np.zeros(3), np.array([1.0, np.nan, 1.0]), np.eye(3))
    with pytest.raises(ValueError, match="at least 3"):
        calibrate_turret(np.zeros(2), np.zeros(2), np.ones(2), np.eye(3)[:2])
