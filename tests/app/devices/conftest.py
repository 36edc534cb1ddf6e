"""Fixtures of the device tests: the workcell scene, fast emulated sites, drivers with short deadlines."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
import pytest

from app.devices.drivers.rangefinder import RangeFinder
from app.devices.drivers.turret import Turret
from app.devices.site import EmulatedSite
from app.scene import default_scene_path, load_scene
from core.rangefinder import aim

FAST_SITE = dict(
    measure_delay_s=0.002, delay_per_m_s=0.0, no_target_delay_s=0.01, rangefinder_baud=0, turret_baud=0, seed=0
)
FAST_DRIVER = dict(attempt_timeout_s=0.25, retries=2, reconnect_timeout_s=1.0)


@pytest.fixture(scope="session")
def workcell():
    return load_scene(default_scene_path())


def exact_scene(scene, sigma_m: float = 0.0, speed_steps_s: float = 4000.0):
    """The scene with a noiseless (or given σ) range finder and a fast turret."""
    return replace(
        scene,
        rangefinder=replace(scene.rangefinder, sigma_range_m=sigma_m),
        turret=replace(scene.turret, speed_steps_s=speed_steps_s),
    )


@pytest.fixture
def make_site(workcell):
    """make_site(sigma_m=0, transport='inprocess', speed_steps_s=4000, **EmulatedSite options) -> (site, rf_url,
    turret_url)."""
    sites = []

    def make(sigma_m: float = 0.0, transport: str = "inprocess", links=(None, None), speed_steps_s=4000.0, **options):
        site = EmulatedSite(exact_scene(workcell, sigma_m, speed_steps_s), **(FAST_SITE | options))
        sites.append(site)
        urls = site.serve_inprocess() if transport == "inprocess" else site.serve_pty(*links)
        return site, urls[0], urls[1]

    yield make
    for site in sites:
        site.close()


@pytest.fixture
def drivers():
    """drivers(rf_url, turret_url, **options) -> (RangeFinder, Turret), closed at teardown."""
    made = []

    def make(rf_url, turret_url, rf_options=None, turret_options=None):
        rf = RangeFinder(rf_url, **(FAST_DRIVER | (rf_options or {})))
        made.append(rf)
        tu = Turret(turret_url, **(FAST_DRIVER | (turret_options or {})))
        made.append(tu)
        return rf, tu

    yield make
    for d in made:
        d.close()


def box_point(scene, body="unknown_box", X_obj=None):
    """A point (3,) of a body in the world (default: the centre of its bounding box)."""
    model = scene.body(body).model
    X_obj = model.bounds().mean(axis=0) if X_obj is None else np.asarray(X_obj, dtype=float)
    T = scene.body(body).pose_at(0.0)
    return T[:3, :3] @ X_obj + T[:3, 3]


def facing_face(scene, body="unknown_box"):
    """The body's face the turret sees best, unoccluded: (centroid_world (3,), normal_world (3,), range_m).

    Derived from the scene's geometry (so the tests follow scene edits): the face whose outward
    normal points most toward the turret and whose centroid is the first hit from the turret.
    """
    from app.render.raycast import BeamCaster

    b = scene.body(body)
    T = b.pose_at(0.0)
    origin = scene.turret.T_world_turret[:3, 3]
    C = b.model.face_centroids() @ T[:3, :3].T + T[:3, 3]
    N = b.model.face_normals() @ T[:3, :3].T
    to_turret = origin - C
    order = np.argsort(-np.einsum("ij,ij->i", N, to_turret / np.linalg.norm(to_turret, axis=1)[:, None]))
    rc = BeamCaster(scene)
    for k in order:
        dist, hit = rc.cast(origin, C[k] - origin)
        if hit == body and abs(dist - np.linalg.norm(C[k] - origin)) < 1e-6:
            return C[k], N[k], float(dist)
    raise AssertionError(f"no face of {body} is visible from the turret in this scene")


def aim_steps(scene, X_world):
    """Turret steps (pan, tilt) that put the beam on a world point."""
    pan, tilt, _ = aim(scene.turret.T_world_turret, X_world)
    step = scene.turret.step_rad
    return int(np.round(float(pan) / step)), int(np.round(float(tilt) / step))


@pytest.fixture
def rf_bench(workcell, make_site, drivers):
    """A noiseless site with the beam on the unknown box's facing face: (site, rf, turret, exact range)."""
    site, rf_url, tu_url = make_site()
    rf, tu = drivers(rf_url, tu_url)
    X, _, _ = facing_face(workcell)
    tu.move_to_steps(*aim_steps(workcell, X))
    dist, body = site.rangefinder.true_range(time.monotonic())
    assert body == "unknown_box"
    return site, rf, tu, round(dist, 4)
