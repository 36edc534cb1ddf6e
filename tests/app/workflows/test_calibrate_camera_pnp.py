"""Calibrate camera with the lens known: the camera's pose from ≥ 4 clicked known points (PnP), or
the full C from ≥ 6 (DLT), as the operator chooses; ``mcit serve --intrinsics FILE`` gives the lens.

The known points are the workcell's true corners (the table's and the known box's, at 16 s) seen
through the scene's true camera, clicked with σ = 0.5 px of noise; the lens file is the one
``mcit calibrate-intrinsics`` writes (app.vision.intrinsics_cli.write_camera_file).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import chi2

from app.db import Database, seed_from_scene
from app.ui.serve import scene_with_intrinsics
from app.vision.intrinsics_cli import Calibration, write_camera_file
from app.vision.pnp import solve_pnp
from app.workflows import CalibrateCamera, Site, WorkflowError
from core.camera import Camera
from core.transforms import log_so3

T_S = 16.0
SIGMA_PX = 0.5


def _write_lens(path, K, w, h, distortion=None):
    cal = Calibration(
        np.asarray(K, float),
        np.zeros(5) if distortion is None else np.asarray(distortion, float),
        0.06,
        w,
        h,
        (0, 1, 2),
        3,
        "plumb_bob",
    )
    write_camera_file(cal, path)
    return path


def _true_corners(scene, t_s=T_S):
    """The known bodies' corners at t_s that the true camera sees inside the image, (N, 3)."""
    cam = scene.camera
    V = np.vstack([b.model.vertices @ b.pose_at(t_s)[:3, :3].T + b.pose_at(t_s)[:3, 3] for b in scene.known])
    uv = cam.project(V)
    return V[(cam.depth(V) > 0) & cam.in_image(uv, 2.0)]


def _pose_error(T_est, T_true):
    """The truth's offset from the estimate in the solver's perturbation (δω, δt):
    R_true = exp(δω) R̂, t_true = t̂ + δt."""
    return np.r_[log_so3(T_true[:3, :3] @ T_est[:3, :3].T), T_true[:3, 3] - T_est[:3, 3]]


def _projected_sigma(r, K, V):
    """Each point's pixel σ (worst direction) through the solved pose's covariance, first order."""
    from core.transforms import exp_so3

    R, t = r.T_cam_world[:3, :3], r.T_cam_world[:3, 3]

    def proj(x):
        h = (V @ (exp_so3(x[:3]) @ R).T + t + x[3:]) @ K.T
        return h[:, :2] / h[:, 2:3]

    J = np.stack([(proj(e) - proj(-e)) / 2e-7 for e in np.eye(6) * 1e-7], axis=-1)  # (N, 2, 6)
    cov = J @ r.cov_pose @ J.transpose(0, 2, 1)
    return np.sqrt(np.linalg.eigvalsh(cov)[:, -1])


@pytest.mark.parametrize("n", [4, 5, 8])
def test_pnp_pose_within_its_stated_sigma(scene, n):
    """40 draws of n corners, clicked with σ = 0.5 px: the true pose lies within the stated covariance
    (its χ² with 6 degrees of freedom below the 95 % quantile in ≥ 85 % of draws, below 99.9 % in all
    but one), and the solved C reprojects every true corner within a few σ."""
    cam = scene.camera
    K, T_true = cam.decompose()
    V = _true_corners(scene)
    assert len(V) >= 12
    rng = np.random.default_rng(n)
    chis, worst_px, ratios = [], [], []
    for _ in range(40):
        X = V[rng.choice(len(V), n, replace=False)]
        uv = cam.project(X) + rng.normal(0, SIGMA_PX, (n, 2))
        r = solve_pnp(K, X, uv, cam.width, cam.height, sigma_px=np.full(n, SIGMA_PX))
        d = _pose_error(r.T_cam_world, T_true)
        chis.append(float(d @ np.linalg.solve(r.cov_pose, d)))
        err = np.linalg.norm(r.camera.project(V) - cam.project(V), axis=1)
        worst_px.append(err.max())
        ratios.append(np.max(err / _projected_sigma(r, K, V)))
        assert r.cov.shape == (12, 12) and np.all(np.isfinite(r.cov))
        assert r.residuals_px.shape == (n, 2) and np.isclose(r.rms_px, np.sqrt(np.mean(r.errors_px**2)))
        # C = K [R | t], normalised as Camera does
        assert np.allclose(r.camera.C, K @ r.T_cam_world[:3], atol=1e-9)
    chis = np.array(chis)
    print(
        f"\nPnP from {n} points: χ² median {np.median(chis):.1f} (6 dof: 5.3), "
        f"{np.mean(chis < chi2.ppf(0.95, 6)):.0%} under the 95 % quantile; all corners reprojected within "
        f"median {np.median(worst_px):.2f} px, max {np.max(worst_px):.2f} px"
    )
    assert np.mean(chis < chi2.ppf(0.95, 6)) >= 0.85
    assert np.sum(chis > chi2.ppf(0.999, 6)) <= 1
    # every true corner reprojected within 4 of its stated σ (through C's covariance) in ≥ 90 % of draws
    print(f"  corners' reprojection error / stated σ: median of each draw's worst {np.median(ratios):.1f}")
    assert np.mean(np.array(ratios) < 4.0) >= 0.9


def test_pnp_refuses_fewer_than_4_or_collinear_points(scene):
    cam = scene.camera
    K, _ = cam.decompose()
    V = _true_corners(scene)
    with pytest.raises(ValueError, match="at least 4"):
        solve_pnp(K, V[:3], cam.project(V[:3]), cam.width, cam.height)
    line = V[0] + np.outer(np.linspace(0, 1, 5), V[1] - V[0])
    with pytest.raises(ValueError, match="on one line"):
        solve_pnp(K, line, cam.project(line), cam.width, cam.height)


def test_a_wrong_lens_shows_as_worse_residuals(scene):
    """The same 8 clicks solved with the true K and with K's focal length 5 % off: the wrong lens
    leaves residuals several times larger (the operator sees them)."""
    cam = scene.camera
    K, _ = cam.decompose()
    V = _true_corners(scene)
    rng = np.random.default_rng(8)
    X = V[rng.choice(len(V), 8, replace=False)]
    uv = cam.project(X) + rng.normal(0, SIGMA_PX, (8, 2))
    right = solve_pnp(K, X, uv, cam.width, cam.height, sigma_px=np.full(8, SIGMA_PX))
    Kw = K.copy()
    Kw[0, 0] *= 1.05
    Kw[1, 1] *= 1.05
    wrong = solve_pnp(Kw, X, uv, cam.width, cam.height, sigma_px=np.full(8, SIGMA_PX))
    print(f"\n8 points: RMS {right.rms_px:.2f} px with the true K, {wrong.rms_px:.2f} px with f 5 % off")
    assert right.rms_px < 0.8
    assert wrong.rms_px > 3 * right.rms_px and wrong.rms_px > 1.5


# ---------------------------------------------------------------------- the workflow
@pytest.fixture
def lens_site(scene, tmp_path):
    """The workcell served with --intrinsics (its true K in an OpenCV file), a wrong C in the database."""
    K, _ = scene.camera.decompose()
    lens = _write_lens(tmp_path / "cam.yml", K, scene.camera.width, scene.camera.height)
    sc = scene_with_intrinsics(scene, lens)
    db = Database.open(tmp_path / "lens.sqlite")
    seed_from_scene(db, sc)
    site = Site(sc, db, clock=lambda: T_S, frames=None)
    H = np.array([[1.01, 0.0, 6.0], [0.0, 0.99, -4.0], [0.0, 0.0, 1.0]])  # a stale C, as in test_calibrate_camera.py
    site.set_camera(
        Camera(H @ scene.camera.C, scene.camera.width, scene.camera.height),
        rms_px=0.0,
        residuals_px=np.zeros((0, 2)),
        points={},
        client="test",
    )
    yield site
    db.close()


def _click_pairs(wf, site, true_cam, X_list, rng):
    for X in X_list:
        wf.choose_point(X, "corner")
        wf.click(true_cam.project(X[None])[0] + rng.normal(0, SIGMA_PX, 2))


def test_with_the_lens_known_5_points_solve_the_pose_by_pnp_and_say_so(lens_site, scene):
    site, true_cam = lens_site, scene.camera
    wf = CalibrateCamera(site, client="alice", snap=False, sigma_px=SIGMA_PX)
    assert wf.method == "pnp" and np.allclose(wf.K, true_cam.decompose()[0])
    assert [v for _, v in wf.choices("set_method")] == ["pnp", "dlt"]
    assert "set_method" in wf.current_step().enabled and "Solve by" in wf.next_step
    V = _true_corners(scene)
    rng = np.random.default_rng(5)
    X = V[[0, 3, 5, 9, 12]]
    _click_pairs(wf, site, true_cam, X[:3], rng)
    assert "1 more needed for the camera's pose with the lens known (PnP)" in wf.next_step
    n_cal = len(site.db.calibrations("camera"))
    with pytest.raises(WorkflowError, match=r"3 points paired; the camera's pose needs at least 4"):
        wf.solve()
    assert len(site.db.calibrations("camera")) == n_cal and wf.result is None
    _click_pairs(wf, site, true_cam, X[3:], rng)
    assert "solve" in wf.current_step().enabled
    wf.solve()
    assert wf.solved_by == "pnp"
    assert wf.message.startswith("Solved the camera's pose from 5 points with the lens known (PnP): RMS ")
    assert wf.next_step.startswith("Solved the camera's pose from 5 points with the lens known (PnP)")
    s = wf.summary()
    assert s["solved_by"] == "Pose, lens known (PnP)" and len(s["points"]) == 5 and s["std_position_mm"] > 0
    weak = wf.weaknesses()
    assert any("only 5 points (10 coordinates) for the pose's 6 unknowns: enough to solve" in w for w in weak)
    assert len(site.db.calibrations("camera")) == n_cal  # nothing written before Accept
    wf.accept()
    cal = site.db.calibrations("camera")[-1]
    assert cal.method == "pnp" and cal.data["solved_by"] == "pnp" and np.allclose(cal.data["K"], wf.K)
    assert site.db.history()[-1].method == "pnp"
    assert "(PnP" in wf.message
    assert site.calibration_covs[0].shape == (12, 12)
    err = np.linalg.norm(site.camera.project(V) - true_cam.project(V), axis=1)
    assert err.max() < 2.0, err.max()


def test_the_operator_can_choose_the_dlt_and_the_record_says_so(lens_site, scene):
    site, true_cam = lens_site, scene.camera
    wf = CalibrateCamera(site, client="alice", snap=False, sigma_px=SIGMA_PX)
    V = _true_corners(scene)
    rng = np.random.default_rng(6)
    _click_pairs(wf, site, true_cam, V[:5], rng)
    wf.solve()
    assert wf.solved_by == "pnp"
    wf.set_method("dlt")  # the result goes: Solve again by the chosen method
    assert wf.result is None and wf.state == "pick_model" and wf.choice_value("set_method") == "dlt"
    assert "solve" not in wf.current_step().enabled and "1 more needed for the full camera matrix (DLT)" in wf.next_step
    with pytest.raises(WorkflowError, match=r"needs at least 6 \(11 unknowns in C\).*4 are enough for the pose alone"):
        wf.solve()
    _click_pairs(wf, site, true_cam, V[5:9], rng)
    wf.solve()
    assert wf.solved_by == "dlt" and wf.message.startswith("Solved the full camera matrix from 9 points (DLT): RMS ")
    wf.remove_pair(0)  # delete any point: the same table, the same Solve
    wf.solve()
    assert len(wf.summary()["points"]) == 8
    wf.accept()
    cal = site.db.calibrations("camera")[-1]
    assert cal.method == "dlt" and cal.data["solved_by"] == "dlt" and "K" not in cal.data
    with pytest.raises(WorkflowError, match="Solve by is one of pnp, dlt"):
        CalibrateCamera(site, method="p3p")


def test_a_wrong_lens_file_is_flagged_before_accept(scene, tmp_path):
    """Served with a lens file whose focal length is 5 % off: PnP from 8 points leaves residuals the
    workflow flags (Accept asks once more), and says to compare with the full camera matrix."""
    K, _ = scene.camera.decompose()
    Kw = K.copy()
    Kw[0, 0] *= 1.05
    Kw[1, 1] *= 1.05
    sc = scene_with_intrinsics(scene, _write_lens(tmp_path / "wrong.yml", Kw, scene.camera.width, scene.camera.height))
    db = Database.open(tmp_path / "w.sqlite")
    seed_from_scene(db, sc)
    try:
        site = Site(sc, db, clock=lambda: T_S, frames=None)
        wf = CalibrateCamera(site, snap=False, sigma_px=SIGMA_PX)
        V = _true_corners(scene)
        _click_pairs(wf, site, scene.camera, V[:8], np.random.default_rng(1))
        wf.solve()
        assert wf.result.rms_px > 1.5
        assert any("fit the known lens poorly" in w for w in wf.weaknesses())
        wf.set_method("dlt")
        wf.solve()  # the full C absorbs the wrong focal length
        assert wf.result.rms_px < 1.0 and not any("lens" in w for w in wf.weaknesses())
    finally:
        db.close()


def test_without_the_lens_only_the_dlt_is_offered(site, scene):
    """The workcell's inline K is its nominal start-up camera: no lens file, so no PnP (as before)."""
    wf = CalibrateCamera(site, snap=False)
    assert wf.K is None and wf.method == "dlt" and wf.choices("set_method") == []
    assert "set_method" not in wf.current_step().enabled and "Solve by" not in wf.next_step
    with pytest.raises(WorkflowError, match="lens is not known here.*--intrinsics FILE"):
        wf.set_method("pnp")
    V = _true_corners(scene)
    _click_pairs(wf, site, scene.camera, V[:5], np.random.default_rng(2))
    with pytest.raises(
        WorkflowError,
        match=r"5 points paired; the full camera matrix needs at least 6 \(11 unknowns in C\): pair more$",
    ):
        wf.solve()
    assert "1 more needed for the full camera matrix (DLT)" in wf.next_step


# ---------------------------------------------------------------------- mcit serve --intrinsics
def test_serve_takes_the_lens_file(scene, tmp_path):
    from app.cli import build_parser
    from app.ui.serve import build_interface

    K, T = scene.camera.decompose()
    w, h = scene.camera.width, scene.camera.height
    args = build_parser().parse_args(
        ["serve", "--intrinsics", str(_write_lens(tmp_path / "c.yml", K, w, h)), "--camera-name", "x"]
    )
    assert args.intrinsics.name == "c.yml" and args.camera_name == "x"
    # a lens with distortion: the scene's frames are undistorted with it; the pose stays the scene's
    dist = [-0.2, 0.05, 0.001, -0.001, 0.0]
    sc = scene_with_intrinsics(scene, _write_lens(tmp_path / "d.yml", K * [[1.01], [1.01], [1]], w, h, dist))
    assert sc.lens is not None and sc.camera_block()["intrinsics_file"].endswith("d.yml")
    assert np.allclose(sc.camera.decompose()[1], T, atol=1e-9) and np.isclose(
        sc.camera.decompose()[0][0, 0], 1.01 * K[0, 0]
    )
    assert scene.lens is None and "K" in scene.camera_block()  # the scene itself is unchanged
    with pytest.raises(ValueError, match=r"calibrated on 640×480 images but the scene's camera is 512×256"):
        scene_with_intrinsics(scene, _write_lens(tmp_path / "big.yml", K, 640, 480))
    with pytest.raises(ValueError, match="nope.yml"):
        scene_with_intrinsics(scene, tmp_path / "nope.yml")
    bad = build_parser().parse_args(["serve", "--camera-name", "left", "--db", str(tmp_path / "x.sqlite")])
    with pytest.raises(ValueError, match="--camera-name chooses a camera in the --intrinsics file"):
        build_interface(bad)
