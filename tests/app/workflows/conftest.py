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
    return Site(scene, db, clock=lambda: 0.0)
