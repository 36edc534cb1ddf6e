"""The Site's named writes and its change feed: who changed what, through this site or another process."""

from __future__ import annotations

import numpy as np
import pytest

from app.db import ConflictError, Database
from core.brep import BRep
from core.transforms import make_T


def moved(obj, dx_m):
    return make_T(obj.T_world_obj[:3, :3], obj.T_world_obj[:3, 3] + [dx_m, 0.0, 0.0])


def test_the_feed_starts_empty_on_an_existing_history(site, db):
    assert len(db.history()) > 0  # the seeded objects
    assert site.change_seq == db.history()[-1].id
    assert site.changes_since(0) == []


def test_every_write_through_the_site_is_announced_with_who_and_what(site, db):
    seq0 = site.change_seq
    obj = site.object("parallelepiped")
    rev = site.revision
    rec = site.update_pose(obj, moved(obj, 0.05), None, method="test", client="alice")
    assert site.revision > rev and rec.version == obj.version + 1
    assert np.allclose(site.object("parallelepiped").T_world_obj, moved(obj, 0.05))
    site.set_status("parallelepiped", "stale", client="bob")
    site.add_object(
        "box_1",
        "box",
        BRep.box(0.1, 0.2, 0.3),
        np.eye(4),
        method="test",
        client="alice",
        dims={"x": 0.1},
        sigmas={"x": 0.001},
    )
    site.set_camera(site.camera, rms_px=0.3, residuals_px=np.zeros(4), points={}, client="carol")
    undo = site.undo(rec.id, client="bob")
    changes = site.changes_since(seq0)
    assert [(c.who, c.what, c.object_name) for c in changes] == [
        ("alice", "moved parallelepiped", "parallelepiped"),
        ("bob", "marked parallelepiped stale", "parallelepiped"),
        ("alice", "added box_1", "box_1"),
        ("carol", "calibrated the camera front", None),  # named beside the side camera (not plain "camera")
        (
            "bob",
            f"removed parallelepiped (undid change #{rec.id}, its addition)",
            "parallelepiped",
        ),  # change #{rec.id}: the seed's add
    ]
    assert [c.seq for c in changes] == [h.id for h in db.history()[-5:]]
    assert site.change_seq == undo.id == changes[-1].seq
    assert site.changes_since(changes[2].seq) == changes[3:]
    assert all(c.when > 0 for c in changes)


def test_a_refused_write_changes_nothing_and_announces_nothing(site, db):
    obj = site.object("parallelepiped")
    site.update_pose(obj, moved(obj, 0.01), None, method="test", client="alice")
    seq, rev, n = site.change_seq, site.revision, len(db.history())
    with pytest.raises(ConflictError):  # obj is the snapshot before alice's write
        site.update_pose(obj, moved(obj, 0.02), None, method="test", client="bob")
    with pytest.raises(ValueError, match="already exists"):
        site.add_object("parallelepiped", "box", BRep.box(0.1, 0.1, 0.1), np.eye(4), method="test", client="bob")
    assert (site.change_seq, site.revision, len(db.history())) == (seq, rev, n)
    assert site.changes_since(seq) == []


def test_another_process_changes_are_announced_once_polled(site, db):
    other = Database.open(db.path, client="mcit db")  # a second connection: as another process's
    try:
        seq0 = site.change_seq
        obj = other.get("parallelepiped")
        other.update_pose(
            obj.id,
            moved(site.object("parallelepiped"), 0.03),
            None,
            expected_version=obj.version,
            method="command line",
            client="dave",
        )
        undo = other.undo(other.history()[-1].id, client="dave")
        assert site.changes_since(seq0) == []  # not seen yet
        assert site.poll()
        changes = site.changes_since(seq0)
        assert [(c.who, c.what) for c in changes] == [
            ("dave", "moved parallelepiped"),
            ("dave", f"undid change #{undo.undoes} (parallelepiped)"),
        ]
        assert not site.poll() and site.changes_since(seq0) == changes  # read once
    finally:
        other.close()


def test_undoing_a_calibration_is_announced_and_used(site, db):
    cam0 = site.camera
    C1 = cam0.C * 1.0
    C1[0, 3] += 1e-3
    site.set_camera(
        type(cam0)(C1, cam0.width, cam0.height), rms_px=0.3, residuals_px=np.zeros(4), points={}, client="carol"
    )
    site.set_camera(cam0, rms_px=0.2, residuals_px=np.zeros(4), points={}, client="carol")
    last = db.history()[-1]
    site.undo(last.id, client="alice")
    assert np.allclose(site.camera.C, C1)  # the calibration before the undone one is in use again
    assert site.changes_since(last.id)[0].what == f"undid change #{last.id} (camera front calibration)"
    undo = db.history()[-1]
    site.undo(undo.id, client="alice")  # the undo undone: a redo of the calibration
    assert np.allclose(site.camera.C, cam0.C)
    assert (
        site.changes_since(undo.id)[0].what
        == f"redid change #{last.id} (camera front calibration; undid undo #{undo.id})"
    )
