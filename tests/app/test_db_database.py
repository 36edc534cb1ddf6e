"""The site's database in one process: objects, versions and conflicts, history, undo, calibrations."""

import sqlite3
import threading

import numpy as np
import pytest

from app.db import (
    ConflictError,
    Database,
    DatabaseUnavailable,
    NotFoundError,
    ObjectRecord,
    default_db_path,
    dimensions_of,
    seed_from_scene,
)
from app.scene import default_scene_path, load_scene
from core.brep import BRep
from core.transforms import make_T, random_rotation, rot_z


@pytest.fixture
def db(tmp_path):
    d = Database.open(tmp_path / "site.sqlite", client="test")
    yield d
    d.close()


def _pose(rng):
    return make_T(random_rotation(rng), rng.normal(size=3))


def test_a_new_file_gets_the_schema_wal_and_foreign_keys(tmp_path):
    path = tmp_path / "sub" / "dir" / "site.sqlite"
    with Database.open(path) as d:
        assert d.schema_version == 3
        conn = d._conn()
        assert conn.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        assert conn.execute("PRAGMA foreign_keys").fetchone()[0] == 1
        assert conn.execute("PRAGMA synchronous").fetchone()[0] == 2  # FULL
        assert conn.execute("PRAGMA application_id").fetchone()[0] == 0x4D434954
    assert path.is_file()


def test_default_path_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path))
    assert default_db_path() == tmp_path / "mcit" / "mcit.sqlite"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert str(default_db_path()).endswith(".local/share/mcit/mcit.sqlite")


def test_seed_from_the_bundled_scene(db):
    scene = load_scene(default_scene_path())
    out = seed_from_scene(db, scene)
    known = [b.name for b in scene.bodies if b.status == "known"]
    assert out["objects"] == known and [o.name for o in db.objects()] == known
    for o in db.objects():
        body = scene.body(o.name)
        assert o.status == "known" and o.version == 1 and o.model == body.model
        assert np.array_equal(o.T_world_obj, body.T_world_obj)
    cam = db.latest_calibration("camera")
    assert np.allclose(cam.data["C"], scene.camera.C) and cam.data["width"] == scene.camera.width
    assert np.allclose(db.latest_calibration("turret").data["T_world_turret"], scene.turret.T_world_turret)
    box = db.get("parallelepiped")
    assert box.dims == pytest.approx({"size_x": 0.35, "size_y": 0.231, "size_z": 0.132})
    with pytest.raises(ValueError, match="already holds a site"):
        seed_from_scene(db, scene)
    base = db.latest_calibration("robot_base")  # the robot's base as the drawing puts it, not calibrated yet
    assert base.data["nominal"] and np.allclose(base.data["T_world_base"], scene.robot.nominal_base)
    assert len(db.history()) == len(known) + 3


def test_dimensions_of_shapes():
    assert dimensions_of(BRep.cylinder(0.05, 0.2), "cylinder") == {"radius": 0.05, "height": 0.2}
    assert dimensions_of(BRep.cone(0.05, 0.02, 0.2), "cone") == {
        "radius_bottom": 0.05,
        "radius_top": 0.02,
        "height": 0.2,
    }
    assert dimensions_of(BRep.box(0.1, 0.2, 0.3), "box") == pytest.approx({"size_x": 0.1, "size_y": 0.2, "size_z": 0.3})
    assert dimensions_of(BRep.box(0.1, 0.2, 0.3), "polyhedron") == {}


def test_add_get_and_records_are_read_only(db):
    rng = np.random.default_rng(0)
    T = _pose(rng)
    cov = np.diag(np.arange(1.0, 7.0)) * 1e-6
    rec = db.add_object(
        "box1",
        "box",
        BRep.box(0.1, 0.2, 0.3),
        T,
        cov=cov,
        dims={"size_x": 0.1},
        sigmas={"size_x": 0.002},
        status="modelled",
        clicks=np.zeros((3, 2)),
        measurements={"range_m": [1.0, np.nan]},
    )
    assert isinstance(rec, ObjectRecord) and rec.version == 1 and rec.status == "modelled"
    for got in (db.get("box1"), db.get(rec.id), db.objects()[0]):
        assert np.array_equal(got.T_world_obj, T) and np.array_equal(got.cov, cov)
        assert (
            got.model == BRep.box(0.1, 0.2, 0.3) and got.sigmas["size_x"] == 0.002 and got.dimensions["size_x"] == 0.1
        )
    with pytest.raises(ValueError):
        rec.T_world_obj[0, 0] = 2.0
    with pytest.raises(TypeError):
        rec.dims["size_x"] = 1.0
    h = db.history("box1")[0]
    assert h.action == "add" and h.clicks == [[0.0, 0.0]] * 3 and h.measurements["range_m"][0] == 1.0
    assert np.isnan(h.measurements["range_m"][1]) and h.before is None and h.after["status"] == "modelled"
    with pytest.raises(NotFoundError, match="no object 'nothing'"):
        db.get("nothing")


def test_identical_models_share_one_row(db):
    a = db.add_object("a", "box", BRep.box(1, 1, 1), np.eye(4))
    b = db.add_object("b", "box", BRep.box(1, 1, 1), np.eye(4))
    c = db.add_object("c", "box", BRep.box(1, 1, 2), np.eye(4))
    assert a.model_id == b.model_id != c.model_id
    assert db._conn().execute("SELECT count(*) FROM models").fetchone()[0] == 2


BAD_ADDS = [
    (dict(name=""), "name"),
    (dict(name=" x"), "name"),
    (dict(kind=""), "kind"),
    (dict(status="lost"), "status"),
    (dict(T_world_obj=np.eye(3)), "T_world_obj"),
    (dict(T_world_obj=np.diag([1, 1, -1, 1.0])), "T_world_obj"),
    (dict(cov=np.eye(5)), "6×6"),
    (dict(cov=np.triu(np.ones((6, 6)))), "symmetric"),
    (dict(dims={"r": "wide"}), "dims"),
    (dict(sigmas={"r": -1.0}), "sigmas"),
    (dict(model="box"), "BRep"),
    (dict(clicks=object()), "cannot store"),
]


@pytest.mark.parametrize("change, match", BAD_ADDS)
def test_bad_input_is_refused_and_nothing_is_written(db, change, match):
    args = dict(name="x", kind="box", model=BRep.box(1, 1, 1), T_world_obj=np.eye(4))
    extra = {k: change.pop(k) for k in list(change) if k not in args}
    args.update(change)
    with pytest.raises(ValueError, match=match):
        db.add_object(**args, **extra)
    assert db.objects() == [] and db.history() == []


def test_duplicate_name_is_refused(db):
    db.add_object("x", "box", BRep.box(1, 1, 1), np.eye(4))
    with pytest.raises(ValueError, match="already exists"):
        db.add_object("x", "box", BRep.box(1, 1, 2), np.eye(4))
    assert len(db.objects()) == 1 and len(db.history()) == 1


def test_update_pose_records_what_the_method_used(db):
    rng = np.random.default_rng(1)
    rec = db.add_object("box1", "box", BRep.box(0.1, 0.2, 0.3), np.eye(4), status="stale")
    T = _pose(rng)
    new = db.update_pose(
        rec.id,
        T,
        np.eye(6) * 1e-6,
        expected_version=rec.version,
        method="p3l+refine",
        client="viser:7",
        clicks={"segments_uv": np.ones((3, 2, 2))},
        residuals=np.array([0.5, -0.25]),
        note="after the robot moved it",
    )
    assert new.version == 2 and new.status == "known" and np.array_equal(new.T_world_obj, T)
    h = db.history(rec.id)[-1]
    assert (h.action, h.method, h.client, h.version, h.note) == (
        "update",
        "p3l+refine",
        "viser:7",
        2,
        "after the robot moved it",
    )
    assert np.array_equal(h.before["T_world_obj"], np.eye(4)) and np.array_equal(h.after["T_world_obj"], T)
    assert h.before["status"] == "stale" and h.after["status"] == "known"
    assert np.array_equal(h.clicks["segments_uv"], np.ones((3, 2, 2))) and h.residuals == [0.5, -0.25]


def test_second_writer_with_a_stale_version_gets_a_conflict(tmp_path):
    path = tmp_path / "site.sqlite"
    with Database.open(path, client="op1") as one, Database.open(path, client="op2") as two:
        rec = one.add_object("box1", "box", BRep.box(1, 1, 1), np.eye(4))
        seen_by_1, seen_by_2 = one.get("box1"), two.get("box1")
        one.update_pose(seen_by_1, make_T(np.eye(3), [1, 0, 0]), expected_version=seen_by_1.version, method="m")
        with pytest.raises(ConflictError, match="changed since you read it") as info:
            two.update_pose(seen_by_2, make_T(np.eye(3), [0, 2, 0]), expected_version=seen_by_2.version, method="m")
        assert (info.value.expected_version, info.value.actual_version) == (1, 2)
        now = two.get(rec.id)
        assert now.version == 2 and np.allclose(now.T_world_obj[:3, 3], [1, 0, 0])
        assert [h.client for h in two.history()] == ["op1", "op1"]
        # after reloading, the second operator's change goes through
        two.update_pose(now, make_T(np.eye(3), [0, 2, 0]), expected_version=now.version, method="m")
        assert one.objects()[0].version == 3 and np.allclose(one.objects()[0].T_world_obj[:3, 3], [0, 2, 0])


def test_a_failure_inside_a_transaction_writes_nothing(db, monkeypatch):
    rec = db.add_object("box1", "box", BRep.box(1, 1, 1), np.eye(4))

    def broken_log(*args, **kwargs):
        raise sqlite3.OperationalError("disk I/O error (simulated)")

    monkeypatch.setattr(db, "_log", broken_log)
    with pytest.raises(DatabaseUnavailable, match="reported an error .*disk I/O error"):
        db.update_pose(rec.id, make_T(np.eye(3), [1, 2, 3]), expected_version=1, method="m")
    monkeypatch.undo()
    after = db.get(rec.id)
    assert after.version == 1 and np.array_equal(after.T_world_obj, np.eye(4)) and len(db.history()) == 1
    # a group of changes is all or nothing
    with pytest.raises(RuntimeError, match="operator cancelled"):
        with db.transaction():
            db.add_object("box2", "box", BRep.box(1, 1, 1), np.eye(4))
            db.set_status(rec.id, "stale")
            raise RuntimeError("operator cancelled")
    assert [o.name for o in db.objects()] == ["box1"] and db.get(rec.id).status == "modelled" and len(db.history()) == 1


def test_objects_sees_changes_made_through_another_connection(tmp_path):
    path = tmp_path / "site.sqlite"
    with Database.open(path) as reader, Database.open(path) as writer:
        a = writer.add_object("a", "box", BRep.box(1, 1, 1), np.eye(4))
        first = reader.objects()
        assert reader.objects()[0] is first[0]  # unchanged: the cached record
        writer.update_pose(a, make_T(rot_z(0.3), [0, 0, 1]), expected_version=1, method="m")
        writer.add_object("b", "cylinder", BRep.cylinder(0.05, 0.2), np.eye(4))
        objs = reader.objects()
        assert [o.name for o in objs] == ["a", "b"] and objs[0].version == 2 and objs[0].T_world_obj[2, 3] == 1.0
        assert objs[0].model is first[0].model  # the model was not parsed again
        writer.remove("b")
        assert [o.name for o in reader.objects()] == ["a"]


def test_undo_and_restore_any_earlier_pose(db):
    rng = np.random.default_rng(2)
    rec = db.add_object("box1", "box", BRep.box(1, 1, 1), np.eye(4), cov=np.eye(6))
    poses = [_pose(rng) for _ in range(3)]
    changes = []
    for T in poses:
        rec = db.update_pose(rec, T, None, expected_version=rec.version, method="m")
        changes.append(db.history(rec)[-1].id)
    u = db.undo(changes[1])  # back to the state before the second update: the first pose
    assert u.action == "undo" and u.undoes == changes[1] and u.version == 5
    now = db.get("box1")
    assert np.array_equal(now.T_world_obj, poses[0]) and now.cov is None
    db.restore(changes[2])
    assert np.array_equal(db.get("box1").T_world_obj, poses[2])
    db.undo(changes[0] - 1)  # undo of the "add": the object leaves
    assert db.objects() == []
    db.undo(db.history()[-1].id)  # undo the undo: it is back, with its last pose
    assert np.array_equal(db.get("box1").T_world_obj, poses[2])
    assert [h.action for h in db.history("box1")] == [
        "add",
        "update",
        "update",
        "update",
        "undo",
        "restore",
        "undo",
        "undo",
    ]
    with pytest.raises(ConflictError):
        db.undo(changes[0], expected_version=1)
    with pytest.raises(NotFoundError, match="no change #999"):
        db.undo(999)
    # what undoing a change discards too: that object's later changes, none of another's
    other = db.add_object("box2", "box", BRep.box(1, 1, 1), np.eye(4))
    assert [c.id for c in db.later_changes(changes[1])] == [h.id for h in db.history("box1")[3:]]
    assert db.later_changes(db.history(other)[-1].id) == []
    with pytest.raises(NotFoundError):
        db.later_changes(999)


def test_undo_of_a_removal_refuses_a_taken_name(db):
    a = db.add_object("a", "box", BRep.box(1, 1, 1), np.eye(4))
    removal = db.remove(a)
    assert removal.action == "remove" and db.objects() == []
    db.add_object("a", "box", BRep.box(2, 2, 2), np.eye(4))
    with pytest.raises(ValueError, match="another live object has that name"):
        db.undo(removal.id)
    assert len(db.objects()) == 1 and db.objects()[0].model == BRep.box(2, 2, 2)


def test_update_several_fields_and_status(db):
    rec = db.add_object("c", "cylinder", BRep.cylinder(0.05, 0.2), np.eye(4), dims={"radius": 0.05, "height": 0.2})
    new = db.update(
        rec,
        expected_version=1,
        method="remodel",
        model=BRep.cylinder(0.051, 0.19),
        dims={"radius": 0.051, "height": 0.19},
        sigmas={"radius": 0.001, "height": 0.002},
    )
    assert new.model == BRep.cylinder(0.051, 0.19) and new.model_id != rec.model_id and new.sigmas["height"] == 0.002
    stale = db.set_status("c", "stale", note="moved in the video")
    assert stale.status == "stale" and stale.version == 3
    db.undo(db.history("c")[1].id)
    assert db.get("c").model == BRep.cylinder(0.05, 0.2) and db.get("c").status == "modelled"
    with pytest.raises(ValueError, match="status"):
        db.set_status("c", "gone")


def test_calibrations_and_their_undo(db):
    assert db.latest_calibration("camera") is None
    C1, C2 = np.hstack([np.eye(3), np.zeros((3, 1))]), np.hstack([np.eye(3), np.ones((3, 1))])
    db.add_calibration("camera", {"C": C1, "width": 512, "height": 256}, np.array([0.1, -0.2]), method="dlt")
    db.add_calibration("camera", {"C": C2, "width": 512, "height": 256}, [0.3], method="dlt")
    db.add_calibration("turret", {"T_world_turret": np.eye(4)}, None, method="kabsch")
    latest = db.latest_calibration("camera")
    assert np.array_equal(latest.data["C"], C2) and latest.residuals == [0.3] and latest.method == "dlt"
    change = [h for h in db.history() if h.action == "calibration"][1]
    db.undo(change.id)
    assert np.array_equal(db.latest_calibration("camera").data["C"], C1)
    assert [c.kind for c in db.calibrations()] == ["camera", "camera", "turret", "camera"]
    assert db.later_changes(change.id) == []  # a calibration's change: no object's
    with pytest.raises(ValueError, match="first camera calibration"):
        db.undo([h for h in db.history() if h.action == "calibration"][0].id)
    with pytest.raises(ValueError, match="3×4"):
        db.add_calibration("camera", {"C": np.eye(3)})
    with pytest.raises(ValueError):
        db.add_calibration("turret", {"T_world_turret": np.eye(3)})


def test_threads_share_one_database_without_losing_updates(db):
    rec = db.add_object("shared", "box", BRep.box(1, 1, 1), np.eye(4))
    n_threads, n_each = 4, 10
    conflicts = []

    def work():
        done = 0
        while done < n_each:
            r = db.get(rec.id)
            T = np.array(r.T_world_obj)
            T[0, 3] += 1.0
            try:
                db.update_pose(r, T, expected_version=r.version, method="thread")
                done += 1
            except ConflictError:
                conflicts.append(1)

    threads = [threading.Thread(target=work) for _ in range(n_threads)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    final = db.get(rec.id)
    assert final.version == 1 + n_threads * n_each
    assert final.T_world_obj[0, 3] == n_threads * n_each  # no increment lost
    assert len(db.history(rec.id)) == 1 + n_threads * n_each
