"""Browsers keep distinct names across restarts of mcit serve: browser-N goes on from the history's."""

from __future__ import annotations

from app.db import Database, seed_from_scene
from app.scene import default_scene_path, load_scene
from app.ui.server import _last_browser_number


def test_browser_numbers_go_on_from_the_history(tmp_path):
    db = Database.open(tmp_path / "site.sqlite")
    try:
        seed_from_scene(db, load_scene(default_scene_path()))
        assert _last_browser_number(db) == -1  # seeded: no browser yet
        box = db.get("parallelepiped")
        box = db.set_status(box, "stale", client="browser-7", expected_version=box.version)
        db.set_status(box, "known", client="browser-12x", expected_version=box.version)  # not a browser-N name
        assert _last_browser_number(db) == 7
    finally:
        db.close()
