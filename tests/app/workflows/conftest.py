"""A real site for the workflow tests: the bundled scene seeded into a fresh SQLite database."""

from __future__ import annotations

import pytest

from app.db import Database, seed_from_scene
from app.scene import default_scene_path, load_scene
from app.workflows import Site


@pytest.fixture(scope="session")
def scene():
    return load_scene(default_scene_path())


@pytest.fixture
def db(tmp_path, scene):
    database = Database.open(tmp_path / "site.sqlite")
    seed_from_scene(database, scene)
    yield database
    database.close()


@pytest.fixture
def site(scene, db):
    # No video frames: these tests click poses the scene's video does not show (moved by hand),
    # so the clicks are used as clicked (snapping needs the frame they were made on).
    return Site(scene, db, clock=lambda: 0.0, frames=None)


@pytest.fixture
def video_site(scene, db):
    """The site with the scene's video: the frame at the scene clock's time (``video_site.t``)."""
    clock = {"t": 0.0}
    s = Site(scene, db, clock=lambda: clock["t"])
    s.t = clock
    return s


FAST_DEVICES = dict(rangefinder_baud=0, turret_baud=0, measure_delay_s=0.0, delay_per_m_s=0.0, no_target_delay_s=0.0)


@pytest.fixture(scope="session")
def fast_scene(scene):
    """The scene with a turret that moves (almost) instantly, for quick device tests."""
    import dataclasses

    return dataclasses.replace(scene, turret=dataclasses.replace(scene.turret, speed_steps_s=1e6))


@pytest.fixture
def devices(fast_scene):
    from app.devices import open_devices

    devs = open_devices(fast_scene, clock=lambda: 0.0, site_options=FAST_DEVICES)
    yield devs
    devs.close()


@pytest.fixture
def device_site(fast_scene, db, devices):
    return Site(fast_scene, db, devices=devices, clock=lambda: 0.0, frames=None)
