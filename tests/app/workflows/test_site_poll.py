"""Site.poll is one cheap query when nothing changed (no object read, no snapshot rebuilt), and
re-reads only what moved when something did; objects() after a local write keeps the unchanged
snapshots."""

from __future__ import annotations

import numpy as np

import app.workflows.site as site_module
from app.db import Database
from core.transforms import make_T


def _count_rebuilds(monkeypatch):
    built = []
    original = site_module._record_to_object

    def spy(rec):
        built.append(rec.name)
        return original(rec)

    monkeypatch.setattr(site_module, "_record_to_object", spy)
    return built


def test_poll_with_no_change_reads_no_object(site, db, monkeypatch):
    before = site.objects()
    site.poll()
    built = _count_rebuilds(monkeypatch)
    reads = []
    original = db.objects
    monkeypatch.setattr(db, "objects", lambda: reads.append(1) or original())
    revision = site.revision
    for _ in range(3):
        assert site.poll() is False
    assert reads == [] and built == [] and site.revision == revision
    assert all(a is b for a, b in zip(site.objects(), before))


def test_poll_rebuilds_only_the_changed_object(site, db, tmp_path, monkeypatch):
    before = {o.name: o for o in site.objects()}
    site.poll()
    built = _count_rebuilds(monkeypatch)
    other = Database.open(db.path)  # another process's connection, as `mcit db` would be
    obj = before["parallelepiped"]
    other.update_pose(
        obj.id,
        obj.T_world_obj @ make_T(np.eye(3), [0.02, 0, 0]),
        None,
        expected_version=obj.version,
        method="test",
        client="other",
    )
    other.close()
    revision = site.revision
    assert site.poll() is True and site.revision == revision + 1
    assert built == ["parallelepiped"]
    after = {o.name: o for o in site.objects()}
    assert after["parallelepiped"].version == obj.version + 1
    assert all(after[n] is before[n] for n in before if n != "parallelepiped")


def test_objects_after_a_local_write_rebuild_only_the_written_object(site, monkeypatch):
    before = {o.name: o for o in site.objects()}
    built = _count_rebuilds(monkeypatch)
    obj = before["parallelepiped"]
    site.update_pose(obj, obj.T_world_obj @ make_T(np.eye(3), [0.02, 0, 0]), None, method="test", client="test")
    after = {o.name: o for o in site.objects()}
    assert built == ["parallelepiped"]
    assert all(after[n] is before[n] for n in before if n != "parallelepiped")
    assert site.poll() in (True, False) and built == ["parallelepiped"]  # poll does not rebuild them again
