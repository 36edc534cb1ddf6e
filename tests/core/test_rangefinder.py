import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.camera import Camera
from core.rangefinder import (
    RangeFinderSpec,
    RangeScan,
    T_turret_rf,
    aim,
    aim_at_pixel,
    beam_direction,
    beam_point,
    beam_point_cov,
    beam_ray,
    quantize_angle,
)
from core.transforms import invert_T, make_T, rot_x, rot_z

T_WORLD_TURRET = make_T(rot_z(np.pi / 2), [0.2, -1.45, 0.75])  # the workcell's: looking along world +y


def test_axes_convention():
    np.testing.assert_allclose(beam_direction(0.0, 0.0), [1, 0, 0], atol=1e-15)  # forward
    np.testing.assert_allclose(beam_direction(np.pi / 2, 0.0), [0, 1, 0], atol=1e-15)  # pan + = left
    np.testing.assert_allclose(beam_direction(0.0, np.pi / 2), [0, 0, 1], atol=1e-15)  # tilt + = up
    np.testing.assert_allclose(
        beam_direction(0.3, -0.2), [np.cos(-0.2) * np.cos(0.3), np.cos(-0.2) * np.sin(0.3), np.sin(-0.2)]
    )


@given(st.floats(-3.0, 3.0), st.floats(-1.5, 1.5), st.floats(0.1, 10.0))
@settings(max_examples=80, deadline=None)
def test_rf_frame_and_spherical_form_agree_and_aim_inverts(pan, tilt, rho):
    X_turret = (T_turret_rf(pan, tilt) @ [0.0, 0.0, rho, 1.0])[:3]
    np.testing.assert_allclose(X_turret, rho * beam_direction(pan, tilt), atol=1e-12)
    X_world = beam_point(T_WORLD_TURRET, pan, tilt, rho)
    p, t, r = aim(T_WORLD_TURRET, X_world)
    assert r == pytest.approx(rho)
    np.testing.assert_allclose(beam_point(T_WORLD_TURRET, p, t, r), X_world, atol=1e-12)
    if abs(tilt) < 1.5:  # away from the zenith pan is unique (mod 2π)
        assert np.angle(np.exp(1j * (p - pan))) == pytest.approx(0.0, abs=1e-9)
        assert t == pytest.approx(tilt, abs=1e-9)


def test_rf_frame_is_a_proper_rotation_with_z_along_the_beam():
    T = T_turret_rf(0.4, -0.3)
    np.testing.assert_allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-15)
    assert np.linalg.det(T[:3, :3]) == pytest.approx(1.0)
    np.testing.assert_allclose(T[:3, 2], beam_direction(0.4, -0.3), atol=1e-15)
    # x_rf points to the right of the beam (−y of the turret at home), y_rf down.
    np.testing.assert_allclose(T_turret_rf(0, 0)[:3, 0], [0, -1, 0], atol=1e-15)
    np.testing.assert_allclose(T_turret_rf(0, 0)[:3, 1], [0, 0, -1], atol=1e-15)


def test_vectorised_beams_and_misses():
    pan = np.array([0.0, 0.1, 0.2])
    X = beam_point(T_WORLD_TURRET, pan, 0.0, np.array([1.0, np.nan, 2.0]))
    assert X.shape == (3, 3) and np.isnan(X[1]).all() and np.isfinite(X[[0, 2]]).all()
    origin, d = beam_ray(T_WORLD_TURRET, pan, -0.1)
    np.testing.assert_allclose(origin, [0.2, -1.45, 0.75])
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    with pytest.raises(ValueError, match="NaN"):
        beam_direction(np.nan, 0.0)
    with pytest.raises(ValueError, match="origin"):
        aim(T_WORLD_TURRET, T_WORLD_TURRET[:3, 3])


@pytest.mark.parametrize(
    "X, says",
    [
        ([np.nan, 1.0, 1.0], r"X_world must be finite, got shape \(3,\) with 1 NaN/inf value\(s\)"),
        ([[1.0, 2.0, 0.5], [np.inf, 0.0, 0.0]], r"X_world must be finite, got shape \(2, 3\) with 1 NaN/inf"),
        ([[1.0, 2.0, -np.inf]], r"X_world must be finite"),
        ([1.0, 2.0], r"X_world must have shape \(3,\), got \(2,\)"),
        (np.ones((2, 2, 3)), r"X_world must have shape \(N, 3\), got \(2, 2, 3\)"),
    ],
)
def test_aim_refuses_points_that_are_not_finite(X, says):
    with pytest.raises(ValueError, match=says):
        aim(T_WORLD_TURRET, X)


@pytest.mark.parametrize("where", [(0, 3), (1, 1), (2, 0)])
def test_aim_refuses_a_turret_pose_that_is_not_finite(where):
    T = T_WORLD_TURRET.copy()
    T[where] = np.nan
    with pytest.raises(ValueError, match="T_world_turret contains NaN or inf"):
        aim(T, [1.0, 2.0, 0.5])


def test_aim_of_one_point_and_of_several_agree():
    rng = np.random.default_rng(0)
    X = T_WORLD_TURRET[:3, 3] + rng.uniform(-3.0, 3.0, (5, 3))
    pan, tilt, rho = aim(T_WORLD_TURRET, X)
    assert pan.shape == tilt.shape == rho.shape == (5,)
    for k in range(5):
        np.testing.assert_allclose(
            [v for v in aim(T_WORLD_TURRET, X[k])], [pan[k], tilt[k], rho[k]], rtol=0, atol=1e-12
        )
    np.testing.assert_allclose(beam_point(T_WORLD_TURRET, pan, tilt, rho), X, atol=1e-12)


def test_quantize_angle():
    step = RangeFinderSpec().step_rad
    assert quantize_angle(2.4 * step, step) == pytest.approx(2 * step)
    assert np.degrees(step) == pytest.approx(0.0514)


def test_beam_point_covariance_matches_monte_carlo():
    rng = np.random.default_rng(0)
    spec = RangeFinderSpec(sigma_range_m=0.005, sigma_angle_rad=0.002)
    pan, tilt, rho = 0.3, -0.4, 1.8
    cov = beam_point_cov(T_WORLD_TURRET, pan, tilt, rho, spec)[0]
    n = 20000
    X = beam_point(
        T_WORLD_TURRET,
        pan + spec.sigma_angle * rng.normal(size=n),
        tilt + spec.sigma_angle * rng.normal(size=n),
        rho + spec.sigma_range_m * rng.normal(size=n),
    )
    np.testing.assert_allclose(np.cov(X.T), cov, atol=0.05 * np.abs(cov).max())
    assert RangeFinderSpec().sigma_angle == pytest.approx(RangeFinderSpec().step_rad / np.sqrt(12))


def test_range_scan_validation_and_points():
    scan = RangeScan([0.0, 0.1, 0.2], [0.0, 0.0, 0.0], [1.0, np.nan, 1.2])
    assert len(scan) == 3 and scan.hits.tolist() == [True, False, True]
    assert np.isnan(scan.points(T_WORLD_TURRET)[1]).all()
    with pytest.raises(ValueError, match="differ in length"):
        RangeScan([0.0], [0.0, 0.1], [1.0])
    with pytest.raises(ValueError, match="positive"):
        RangeScan([0.0], [0.0], [-1.0])


def _table_camera():
    K = np.array([[500.0, 0.0, 255.5], [0.0, 500.0, 127.5], [0.0, 0.0, 1.0]])
    T_world_cam = make_T(rot_x(-np.radians(115.0)), [0.0, -1.45, 0.75])  # looks down at the table
    return Camera.from_intrinsics(K, invert_T(T_world_cam), 512, 256)


def _measure_plane(n, d, T_world_turret, sigma=0.0, rng=None):
    """A range finder that sees only the plane n·X + d = 0."""

    def measure(pan, tilt):
        o, u = beam_ray(T_world_turret, pan, tilt)
        denom = n @ u
        if abs(denom) < 1e-12:
            return None
        rho = -(n @ o + d) / denom
        if rho <= 0:
            return None
        return rho + (sigma * rng.normal() if sigma else 0.0)

    return measure


@pytest.mark.parametrize("quantized", [False, True])
def test_aim_at_pixel_converges_despite_parallax(quantized):
    cam = _table_camera()
    n, d = np.array([0.0, 0.0, 1.0]), 0.0  # the table top z = 0
    spec = RangeFinderSpec()
    measure = _measure_plane(n, d, T_WORLD_TURRET)
    for uv in ([256.0, 128.0], [60.0, 40.0], [450.0, 220.0]):
        res = aim_at_pixel(
            cam,
            T_WORLD_TURRET,
            uv,
            measure,
            depth_guess_m=1.0,
            step_rad=spec.step_rad if quantized else None,
            tol_px=0.05,
        )
        assert res.converged
        tol = 0.6 if quantized else 0.05  # one turret step ≈ 1.8 mm ≈ 0.4 px at 2 m
        assert res.error_px < tol
        assert abs(res.X_world[2]) < 1e-9  # the measured point is on the table
        # A naive aim (straight at the pixel's ray at the guessed depth) misses by the parallax.
        c, r = cam.rays(np.array([uv]))
        p, t, _ = aim(T_WORLD_TURRET, c + 1.0 * r[0])
        naive = beam_point(T_WORLD_TURRET, p, t, measure(p, t))
        assert np.linalg.norm(cam.project(naive) - uv) > 5.0


def test_aim_at_pixel_reports_no_return():
    cam = _table_camera()
    res = aim_at_pixel(cam, T_WORLD_TURRET, [256.0, 128.0], lambda p, t: None, max_iter=4)
    assert not res.converged and np.isnan(res.range_m) and np.isnan(res.X_world).all()
