"""The calibrations' share of a model's σ (core.modeling.uncertainty) and the DLT's covariance:
each predicted σ against the scatter of models built through calibrations drawn from the stated
covariances (seeded Monte Carlo, tolerances sized for the trial count)."""

from __future__ import annotations

import numpy as np
import pytest

from core.brep import BRep
from core.calibration import calibrate_dlt, perturbed_camera, perturbed_turret
from core.modeling import model_box, model_cylinder, model_polyhedron
from core.modeling.simulate import SimWorld, look_at_setup, simulate_box, simulate_polyhedron, simulate_revolution
from core.modeling.uncertainty import result_vector, with_calibration_uncertainty
from core.transforms import make_T, rot_z

from .conftest import BOX_SIZE, TABLE, cylinder_scene


def _turret_cov(rng, deg=0.4, mm=4.0):
    """A correlated turret covariance (rotation vector, translation) of about the workcell's size."""
    A = rng.normal(size=(6, 6))
    cov = A @ A.T
    s = np.diag([np.radians(deg)] * 3 + [mm / 1000.0] * 3)
    d = np.sqrt(np.diag(cov))
    return s @ (cov / np.outer(d, d)) @ s


def _camera_cov(rng, cam, X, sigma_px=1.0):
    """The DLT's covariance for 13 clicked points at σ = ``sigma_px``."""
    uv = cam.project(X) + rng.normal(0, sigma_px, (len(X), 2))
    return calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.full(len(X), sigma_px)).cov


def _calibration_points(rng):
    return np.column_stack([rng.uniform(-0.4, 0.4, 13), rng.uniform(-0.4, 0.4, 13), rng.uniform(0.0, 0.3, 13)])


def test_dlt_covariance_predicts_the_scatter_of_projections():
    rng = np.random.default_rng(3)
    cam, _ = cylinder_scene(1.4)[:2]
    X = _calibration_points(rng)
    r = calibrate_dlt(X, cam.project(X), cam.width, cam.height, sigma_px=np.ones(len(X)))
    assert r.cov.shape == (12, 12) and np.allclose(r.cov, r.cov.T)
    c = r.camera.C.ravel() / np.linalg.norm(r.camera.C)
    assert abs(c @ r.cov @ c) < 1e-12 * np.trace(r.cov)  # the scale gauge: nothing along C
    Y = np.array([[0.1, -0.2, 0.05], [-0.3, 0.25, 0.2], [0.0, 0.0, 0.1]])
    # prediction: first order through C's entries
    J, h, p0 = [], 1e-7, cam.project(Y).ravel()
    for j in range(12):
        e = np.zeros(12)
        e[j] = h
        J.append((perturbed_camera(cam, e).project(Y).ravel() - p0) / h)
    pred = np.sqrt(np.diag(np.array(J).T @ r.cov @ np.array(J)))
    uv0 = cam.project(X)
    samples = np.array(
        [
            calibrate_dlt(X, uv0 + rng.normal(0, 1.0, uv0.shape), cam.width, cam.height).camera.project(Y).ravel()
            for _ in range(500)
        ]
    )
    ratio = samples.std(axis=0) / pred
    assert np.all(np.abs(ratio - 1) < 0.15), ratio


def test_dlt_covariance_grows_when_the_clicks_are_worse_than_stated():
    rng = np.random.default_rng(4)
    cam, _ = cylinder_scene(1.4)[:2]
    X = _calibration_points(rng)
    uv = cam.project(X) + rng.normal(0, 3.0, (len(X), 2))  # 3 px clicks, stated 1 px
    stated = calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.full(len(X), 3.0))
    wrong = calibrate_dlt(X, uv, cam.width, cam.height, sigma_px=np.ones(len(X)))
    assert wrong.variance_factor > 3.0
    assert np.trace(wrong.cov) == pytest.approx(np.trace(stated.cov) * wrong.variance_factor / 9.0, rel=1e-6)
    assert calibrate_dlt(X, uv, cam.width, cam.height, refine=False).cov is None


def test_without_covariances_the_model_is_unchanged(box_scene):
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, np.random.default_rng(0))
    base = model_box(cam, faces, TABLE)
    out = with_calibration_uncertainty(lambda c, T: model_box(c, faces, TABLE), cam, T_wt, result=base)
    assert out is base


def test_turret_share_of_a_cylinder_matches_the_scatter():
    """The range data taken by the true turret, the model built through a turret calibration drawn
    from its covariance: the spread of radius, height and axis is the predicted turret share."""
    rng = np.random.default_rng(5)
    cam, T_wt, sol, world = cylinder_scene(1.3, offset=(0.003, -0.004))
    sil, scans = simulate_revolution(cam, world, sol, None, exact_edges=True)
    cov = _turret_cov(rng)

    def build(c, T):
        return model_cylinder(c, "tangential", silhouettes_uv=sil, scans=scans, T_world_turret=T, support=TABLE)

    r = with_calibration_uncertainty(build, cam, T_wt, turret_cov=cov)
    share = r.details["sigma_parts"]["turret calibration"]
    assert set(r.details["sigma_parts"]) == {"measurements", "turret calibration"}
    for k in ("radius", "height", "axis_position"):
        assert r.sigmas[k] == pytest.approx(np.hypot(r.details["sigma_parts"]["measurements"][k], share[k]))
    base = r.details["cov_measurements"]
    assert np.allclose(r.cov - base, (r.cov - base).T) and np.all(np.linalg.eigvalsh(r.cov - base) > -1e-15)
    out = []
    for _ in range(300):
        m = build(cam, perturbed_turret(T_wt, rng.multivariate_normal(np.zeros(6), cov)))
        a = r.axis.direction
        mid = m.axis.point + 0.5 * m.dimensions["height"] * m.axis.direction
        mid0 = r.axis.point + 0.5 * r.dimensions["height"] * a
        d = (np.eye(3) - np.outer(a, a)) @ (mid - mid0)
        out.append([m.dimensions["radius"], m.dimensions["height"], *d])
    out = np.array(out)
    observed = {
        "radius": out[:, 0].std(),
        "height": out[:, 1].std(),
        "axis_position": np.sqrt(out[:, 2:].var(axis=0).sum()),
    }
    for k, v in observed.items():
        assert v == pytest.approx(share[k], rel=0.2), (k, v, share[k])
    # the turret moves the whole object: the axis position, far more than the sizes
    assert share["axis_position"] > 10 * share["radius"]


def test_camera_share_of_a_box_matches_the_scatter(box_scene):
    """Clicks made through the true camera, the box built through a DLT's C drawn from its
    covariance: the spread of the sizes and position is the predicted camera share."""
    rng = np.random.default_rng(6)
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, None, step_quantize=False)
    ccov = _camera_cov(rng, cam, _calibration_points(rng), sigma_px=1.0)

    def build(c, T):
        return model_box(c, faces, TABLE)

    r = with_calibration_uncertainty(build, cam, T_wt, camera_cov=ccov)
    share = r.details["sigma_parts"]["camera calibration"]
    out = np.array(
        [
            result_vector(
                build(perturbed_camera(cam, rng.multivariate_normal(np.zeros(12), ccov, check_valid="ignore")), T_wt), r
            )
            for _ in range(300)
        ]
    )
    names = list(r.cov_names)
    for k in ("size_x", "size_y", "size_z"):
        assert out[:, names.index(k)].std() == pytest.approx(share[k], rel=0.2), k
    pos = out[:, [names.index(k) for k in ("x", "y", "z")]]
    assert np.sqrt(pos.var(axis=0).sum()) == pytest.approx(share["position"], rel=0.2)


def test_box_quantities_follow_the_reference_axes(box_scene):
    """A moved box whose frame came out with its axes in another order or sign reads the same."""
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, np.random.default_rng(1))
    r = model_box(cam, faces, TABLE)
    R = r.T_world_obj[:3, :3]
    swapped = r.T_world_obj.copy()
    swapped[:3, :3] = R[:, [1, 0, 2]] * [1.0, -1.0, 1.0]  # x ↔ y, one flipped: still right-handed
    dims = {"size_x": r.dimensions["size_y"], "size_y": r.dimensions["size_x"], "size_z": r.dimensions["size_z"]}
    from dataclasses import replace

    other = replace(r, T_world_obj=swapped, dimensions=dims)
    assert np.allclose(result_vector(other, r), result_vector(r, r), atol=1e-12)


def test_bad_covariances_are_refused(box_scene):
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, np.random.default_rng(0))
    with pytest.raises(ValueError, match="turret_cov .* must be a finite symmetric"):
        with_calibration_uncertainty(lambda c, T: model_box(c, faces, TABLE), cam, T_wt, turret_cov=np.eye(3))
    with pytest.raises(ValueError, match="camera_cov .* must be a finite symmetric"):
        with_calibration_uncertainty(
            lambda c, T: model_box(c, faces, TABLE), cam, T_wt, camera_cov=np.full((12, 12), np.nan)
        )


def test_turret_share_of_a_polyhedron_matches_the_scatter():
    """A pyramid on the table (vertices from face planes and clicked edges): its edges' and
    position's turret share against models built through turret poses drawn from the covariance."""
    rng = np.random.default_rng(8)
    brep = BRep.pyramid(np.array([[-0.08, -0.08], [0.08, -0.08], [0.08, 0.08], [-0.08, 0.08]]), np.array([0, 0, 0.06]))
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.05]), 1.2, elevation_deg=35.0)
    Bw = brep.transformed(make_T(rot_z(0.6), [0.01, 0.02, 0.0]))
    fp, fc, es = simulate_polyhedron(cam, SimWorld(T_wt, polyhedra=(Bw,)), Bw, None)
    cov = _turret_cov(rng)

    def build(c, T):  # the range points mapped through T instead of the true turret pose
        M = T @ np.linalg.inv(T_wt)
        pts = {f: P @ M[:3, :3].T + M[:3, 3] for f, P in fp.items()}
        covs = {f: M[:3, :3] @ S @ M[:3, :3].T for f, S in fc.items()}
        return model_polyhedron(
            c, brep.faces, face_points=pts, face_point_covs=covs, edge_segments=es, support=TABLE, support_faces=[0]
        )

    r = with_calibration_uncertainty(build, cam, T_wt, turret_cov=cov)
    share = r.details["sigma_parts"]["turret calibration"]
    keys = [k for k in r.dimensions if k.startswith("edge_")][:3] + ["height"]
    draws = [build(cam, perturbed_turret(T_wt, rng.multivariate_normal(np.zeros(6), cov))) for _ in range(300)]
    for k in keys:
        assert np.std([m.dimensions[k] for m in draws]) == pytest.approx(share[k], rel=0.2), k
    centre = np.array([m.vertices_world.mean(axis=0) for m in draws])
    assert np.sqrt(centre.var(axis=0).sum()) == pytest.approx(share["position"], rel=0.2)


def test_a_model_that_cannot_be_rebuilt_through_a_moved_calibration_says_so(box_scene):
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, np.random.default_rng(0))
    calls = []

    def build(c, T):  # the nominal build works; any other turret pose fails as a degenerate construction would
        calls.append(1)
        if len(calls) > 1:
            raise ValueError("the constructed corners do not fix the box")
        return model_box(c, faces, TABLE)

    with pytest.raises(ValueError, match="moved by 1σ .*calibrate the turret again"):
        with_calibration_uncertainty(build, cam, T_wt, turret_cov=np.eye(6) * 1e-6)
