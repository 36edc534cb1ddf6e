"""Acquisition through the emulators: scans of the bundled scene's box land on its true faces.

Noise as the scene says (σ_ρ = 5 mm), the turret's real step (0.0514°), the workcell's camera.
"""

import threading

import numpy as np
import pytest
import trimesh

from app.devices.acquisition import (
    AcquisitionCancelled,
    face_patch_scan,
    grid_in_polygon,
    inside_polygon,
    measure_at_pixel,
    profile_scan,
)
from app.devices.drivers.errors import DeviceDisconnected
from core.geometry import fit_plane_tls
from core.rangefinder import aim

from .conftest import facing_face

SIGMA = 0.005


@pytest.fixture
def noisy(workcell, make_site, drivers):
    site, rf_url, tu_url = make_site(sigma_m=SIGMA)
    rf, tu = drivers(rf_url, tu_url)
    return site, rf, tu


def body_surface_distance(scene, name, X):
    """Distance (N,) of world points to a body's true surface."""
    b = scene.body(name)
    V, F = b.model.triangles()
    T = b.pose_at(0.0)
    mesh = trimesh.Trimesh(V @ T[:3, :3].T + T[:3, 3], F, process=False)
    _, dist, _ = trimesh.proximity.closest_point(mesh, X)
    return dist


def face_polygon_uv(scene, name="unknown_box", shrink=0.7):
    """The image of the facing face, shrunk about its centroid: (K, 2) pixels, and the face's plane."""
    b = scene.body(name)
    T = b.pose_at(0.0)
    C, n, _ = facing_face(scene, name)
    normals = b.model.face_normals() @ T[:3, :3].T
    k = int(np.argmax(normals @ n))
    V = b.model.vertices[list(b.model.faces[k])] @ T[:3, :3].T + T[:3, 3]
    V = C + shrink * (V - C)
    return scene.camera.project(V), C, n


def test_profile_scan_of_the_box_lies_on_its_true_faces(workcell, noisy):
    site, rf, tu = noisy
    C, n, _ = facing_face(workcell)
    pan, tilt, _ = aim(workcell.turret.T_world_turret, C)
    progress = []
    scan = profile_scan(
        tu,
        rf,
        tilt_rad=float(tilt),
        pan_start_rad=float(pan) - 0.06,
        pan_stop_rad=float(pan) + 0.06,
        pan_step_rad=2 * tu.pan_step_rad,
        progress=progress.append,
    )
    assert len(scan) == len(progress) == progress[-1].total and progress[-1].done == len(scan)
    assert np.all(np.diff(scan.meta["pan_steps"]) == 2) and np.all(scan.tilt_rad == scan.tilt_rad[0])
    # each report carries the beam just measured: the caller can draw the spot and the points as they come
    beams = np.array([p.beam for p in progress])
    assert np.array_equal(beams[:, 0], scan.pan_rad) and np.array_equal(beams[:, 1], scan.tilt_rad)
    assert np.array_equal(beams[:, 2], scan.range_m, equal_nan=True)
    X = scan.points(workcell.turret.T_world_turret)
    on_box = body_surface_distance(workcell, "unknown_box", X) < 4 * SIGMA
    assert on_box.sum() >= 10  # the box spans a good part of the sweep
    d = body_surface_distance(workcell, "unknown_box", X[on_box])
    assert np.sqrt(np.mean(d**2)) < 1.5 * SIGMA
    # beyond the box the beam meets the table (or the other bodies): every hit is on some true surface
    nearest = np.min([body_surface_distance(workcell, b.name, X[scan.hits]) for b in workcell.bodies], axis=0)
    assert np.all(nearest < 4 * SIGMA)


def test_face_patch_scan_fits_the_true_face_plane(workcell, noisy):
    site, rf, tu = noisy
    poly, C, n = face_polygon_uv(workcell)
    progress = []
    scan = face_patch_scan(
        workcell.camera,
        workcell.turret.T_world_turret,
        tu,
        rf,
        polygon_uv=poly,
        spacing_px=3.0,
        progress=progress.append,
    )
    aiming = [p for p in progress if p.done == 0]
    assert aiming and all("aiming" in p.message and p.beam is not None for p in aiming)  # the centroid's iteration
    beams = np.array([p.beam for p in progress if p.done > 0])
    assert len(beams) == len(scan) and np.array_equal(beams[:, 2], scan.range_m, equal_nan=True)
    inside = scan.meta["inside"] & scan.hits
    assert inside.sum() >= 0.8 * len(scan) and inside.sum() >= 8
    assert scan.meta["uv_target"].shape == (len(scan), 2) and scan.meta["uv_hit"].shape == (len(scan), 2)
    X = scan.points(workcell.turret.T_world_turret)[inside]
    assert np.all(body_surface_distance(workcell, "unknown_box", X) < 4 * SIGMA)
    fit = fit_plane_tls(X)
    angle = np.degrees(np.arccos(min(1.0, abs(float(fit.plane.n @ n)))))
    assert angle < 15.0  # a few cm of face measured with 5 mm noise
    assert abs(float(fit.plane.n @ C + fit.plane.d)) < 0.01


def test_measure_at_a_clicked_pixel_puts_the_beam_there(workcell, noisy):
    site, rf, tu = noisy
    C, n, _ = facing_face(workcell)
    uv = workcell.camera.project(C[None])[0]
    progress = []
    pm = measure_at_pixel(
        workcell.camera, workcell.turret.T_world_turret, uv, tu, rf, shots=5, progress=progress.append
    )
    assert progress[-1].beam == (pm.pan_rad, pm.tilt_rad, pm.range_m)  # the final beam: the spot to show
    assert pm.hit and pm.aim.converged and pm.measurement.n_valid == 5
    assert np.linalg.norm(pm.X_world - C) < 0.015
    assert pm.X_world.shape == (3,) and pm.cov_world.shape == (3, 3)
    assert np.all(np.linalg.eigvalsh(pm.cov_world) > 0)
    assert np.sqrt(float(n @ pm.cov_world @ n)) < 0.01  # about σ_ρ along a beam nearly normal to the face
    assert tu.position_rad() == pytest.approx((pm.pan_rad, pm.tilt_rad))


def test_misses_are_nan_and_device_faults_surface(workcell, noisy):
    site, rf, tu = noisy
    scan = profile_scan(tu, rf, tilt_rad=0.5, pan_start_rad=-0.01, pan_stop_rad=0.01)  # 29° up: over everything
    assert len(scan) > 3 and not scan.hits.any() and np.isnan(scan.range_m).all()
    site.rangefinder.unplug(np.inf)
    with pytest.raises(DeviceDisconnected):
        profile_scan(tu, rf, tilt_rad=0.0, pan_start_rad=0.0, pan_stop_rad=0.01)


def test_scans_can_be_cancelled_and_keep_what_they_measured(workcell, noisy):
    site, rf, tu = noisy
    C, _, _ = facing_face(workcell)
    pan, tilt, _ = aim(workcell.turret.T_world_turret, C)
    cancel = threading.Event()

    def progress(p):
        if p.done == 3:
            cancel.set()

    with pytest.raises(AcquisitionCancelled, match="after 3 of") as info:
        profile_scan(
            tu,
            rf,
            tilt_rad=float(tilt),
            pan_start_rad=float(pan),
            pan_stop_rad=float(pan) + 0.05,
            progress=progress,
            cancel=cancel,
        )
    assert len(info.value.partial) == 3 and info.value.partial.hits.all()
    poly, _, _ = face_polygon_uv(workcell)
    cancel.set()
    with pytest.raises(AcquisitionCancelled):
        face_patch_scan(workcell.camera, workcell.turret.T_world_turret, tu, rf, polygon_uv=poly, cancel=cancel)


def test_grid_in_polygon():
    square = np.array([[10.0, 10.0], [30.0, 10.0], [30.0, 30.0], [10.0, 30.0]])
    g = grid_in_polygon(square, 5.0)
    assert g.shape == (16, 2)
    assert set(np.round(g[:, 0], 6)) == {12.5, 17.5, 22.5, 27.5}
    assert np.all(np.diff(g[:4, 0]) > 0) and np.all(np.diff(g[4:8, 0]) < 0)  # serpentine rows
    tri = grid_in_polygon(np.array([[0.0, 0.0], [40.0, 0.0], [0.0, 40.0]]), 4.0)
    assert np.all(tri.sum(axis=1) < 40.0)
    assert list(inside_polygon(square, [[20.0, 20.0], [10.0, 20.0], [31.0, 20.0], [20.0, 10.0 + 1e-3]])) == [
        True,
        False,
        False,
        True,
    ]
    concave = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [5.0, 2.0], [0.0, 10.0]])
    assert list(inside_polygon(concave, [[5.0, 1.0], [5.0, 5.0], [2.0, 3.0]])) == [True, False, True]
    with pytest.raises(ValueError, match="3 vertices"):
        grid_in_polygon(square[:2], 5.0)
    with pytest.raises(ValueError, match="spacing_px"):
        grid_in_polygon(square, 0.0)
