"""``mcit db list | show | history --json`` and ``mcit db show-calibration [--json]``: each document parsed
and checked against what the database holds (app/db/describe.py, docs/database.md)."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app.cli import main
from app.db import Database
from core.camera import Camera
from core.transforms import exp_so3, invert_T, make_T, rot_z

POSE_KEYS = {"T", "xyz_m", "quat_xyzw", "rotvec_rad", "sigma", "cov"}
RECORD_KEYS = {"object", "object_id", "kind", "status", "version", "frame", "who", "method", "time", "time_iso"}
RECORD_KEYS |= POSE_KEYS
CALIBRATION_KEYS = {
    "calibration_id",
    "kind",
    "camera",
    "time",
    "time_iso",
    "who",
    "method",
    "pose",
    "rms_px",
    "rms_m",
    "measurements",
    "nominal",
    "width",
    "height",
    "C",
    "K",
    "resolution_arcsec",
    "pan_limits_steps",
    "tilt_limits_steps",
}
COV = np.diag([4e-6, 9e-6, 1e-6, 1e-4, 4e-4, 9e-4])  # (δt, δr): σ 2, 3, 1 mm and 0.01, 0.02, 0.03 rad


def _json(capsys, *argv):
    assert main(list(argv)) == 0
    out = capsys.readouterr().out
    return json.loads(out)


@pytest.fixture()
def site(tmp_path, capsys):
    """The workcell seeded, the box moved once with a covariance, the side camera, the turret and the robot's base
    calibrated (as the workflows store them)."""
    db = str(tmp_path / "site.sqlite")
    assert main(["db", "init", "--db", db]) == 0
    with Database.open(db) as d:
        box = d.get("parallelepiped")
        T = make_T(exp_so3([0.0, 0.0, 0.3]), [0.12, 0.2, 0.0])
        d.update_pose(box.id, T, COV, expected_version=box.version, method="p3l+refine", client="viser:3")
        side = Camera.from_intrinsics(
            np.array([[480.0, 0, 250.0], [0, 482.0, 130.0], [0, 0, 1]]), make_T(rot_z(0.2), [0.1, -0.2, 1.9]), 512, 256
        )
        d.add_calibration(
            "camera:side",
            {"C": side.C, "width": 512, "height": 256, "rms_px": 0.61, "view": "side", "X_world": np.zeros((7, 3))},
            np.zeros(7),
            method="dlt",
            client="viser:1",
        )
        turret_cov = np.diag([1e-6, 4e-6, 9e-6, 1e-4, 4e-4, 9e-4])  # (ω rad, v m) in the turret frame
        d.add_calibration(
            "turret",
            {"T_world_turret": make_T(rot_z(np.pi / 2), [0.2, -1.5, 0.65]), "rms_m": 0.0021, "cov": turret_cov}
            | {"range_m": [1.0, 1.1, 1.2, 1.3, 1.4]},
            np.zeros(5),
            method="turret: ranges on known surfaces",
            client="viser:2",
        )
        d.add_calibration(
            "robot_base",
            {"T_world_base": make_T(rot_z(0.03), [-0.351, 0.046, 0.001]), "nominal": False, "cov": COV}
            | {"rms_px": 0.8, "camera": "front", "edges": [{}] * 11},
            np.zeros(11),
            method="robot edges",
            client="viser:4",
        )
    capsys.readouterr()
    return db


def test_list_json_is_every_object_as_the_database_has_it(site, capsys):
    doc = _json(capsys, "db", "list", "--json", "--db", site)
    assert doc["format"] == "mcit-objects/1" and doc["database"].endswith("site.sqlite")
    with Database.open(site) as d:
        objs = d.objects()
    assert [r["object"] for r in doc["objects"]] == [o.name for o in objs]
    for r, o in zip(doc["objects"], objs):
        assert set(r) == RECORD_KEYS and r["frame"] == "world"
        assert (r["object_id"], r["version"], r["status"], r["kind"]) == (o.id, o.version, o.status, o.kind)
        np.testing.assert_allclose(r["T"], o.T_world_obj, atol=1e-15)
        np.testing.assert_allclose(r["xyz_m"], o.T_world_obj[:3, 3], atol=1e-15)
        np.testing.assert_allclose(Rotation.from_quat(r["quat_xyzw"]).as_matrix(), o.T_world_obj[:3, :3], atol=1e-12)
    box = next(r for r in doc["objects"] if r["object"] == "parallelepiped")
    assert box["version"] == 2 and box["who"] == "viser:3" and box["method"] == "p3l+refine"
    np.testing.assert_allclose(box["sigma"]["xyz_m"], [0.002, 0.003, 0.001])
    np.testing.assert_allclose(box["sigma"]["rot_rad"], [0.01, 0.02, 0.03])
    assert next(r for r in doc["objects"] if r["object"] == "table")["sigma"] is None  # seeded: no covariance


def test_show_json_adds_model_dimensions_and_history(site, capsys):
    doc = _json(capsys, "db", "show", "parallelepiped", "--json", "--db", site)
    with Database.open(site) as d:
        o = d.get("parallelepiped")
        changes = len(d.history(o.id))
    assert doc["format"] == "mcit-object/1" and set(doc) >= RECORD_KEYS
    assert doc["model"] == {
        "model_id": o.model_id,
        "vertices": len(o.model.vertices),
        "edges": len(o.model.edges),
        "faces": len(o.model.faces),
        "solids": 0,
        "circles": 0,
        "source": o.source,
    }
    assert doc["dims_m"] == dict(o.dims) and doc["dims_m"]["size_x"] == pytest.approx(0.35)
    assert set(doc["sigma_dims_m"]) == set(o.dims) and doc["changes"] == changes == 2
    assert doc["created"] == o.created_at and doc["time"] == o.updated_at > o.created_at
    # by id, the same document
    assert _json(capsys, "db", "show", str(o.id), "--json", "--db", site) == doc


def test_history_json_is_the_history_with_each_pose_after_its_change(site, capsys):
    doc = _json(capsys, "db", "history", "--json", "--db", site)
    with Database.open(site) as d:
        hist = d.history()
        kinds = {c.id: c.kind for c in d.calibrations()}
    assert doc["format"] == "mcit-history/1" and doc["object"] is None
    assert [c["change"] for c in doc["changes"]] == [c.id for c in hist]
    for c, h in zip(doc["changes"], hist):
        assert (c["action"], c["who"], c["method"], c["version"]) == (h.action, h.client, h.method, h.version)
        assert c["calibration_kind"] == (kinds[h.calibration_id] if h.calibration_id else None)
        assert (c["pose"] is None) == (h.action == "calibration")
    assert [c["calibration_kind"] for c in doc["changes"] if c["calibration_kind"]] == [
        "camera",
        "turret",
        "robot_base",
        "camera:side",
        "turret",
        "robot_base",
    ]
    moved = doc["changes"][-4]  # the box's update, before the three calibrations
    assert moved["object"] == "parallelepiped" and moved["action"] == "update" and moved["version"] == 2
    np.testing.assert_allclose(moved["pose"]["xyz_m"], [0.12, 0.2, 0.0])
    np.testing.assert_allclose(moved["pose"]["sigma"]["xyz_m"], [0.002, 0.003, 0.001])
    first = _json(capsys, "db", "history", "parallelepiped", "--json", "--db", site)
    assert first["object"] == "parallelepiped" and [c["version"] for c in first["changes"]] == [1, 2]
    assert [c["change"] for c in _json(capsys, "db", "history", "--limit", "2", "--json", "--db", site)["changes"]] == [
        hist[-2].id,
        hist[-1].id,
    ]


def test_show_calibration_json_is_each_kinds_latest(site, capsys):
    doc = _json(capsys, "db", "show-calibration", "--json", "--db", site)
    assert doc["format"] == "mcit-calibrations/1"
    cals = doc["calibrations"]
    assert [c["kind"] for c in cals] == ["camera", "camera:side", "turret", "robot_base"]
    assert all(set(c) == CALIBRATION_KEYS for c in cals)
    with Database.open(site) as d:
        latest = {k: d.latest_calibration(k) for k in ("camera", "camera:side", "turret", "robot_base")}
    assert [c["calibration_id"] for c in cals] == [latest[c["kind"]].id for c in cals]
    # a camera: C as stored, K and the camera's pose in the world from it (its centre is C's null vector)
    for c in cals[:2]:
        cam = Camera(np.asarray(latest[c["kind"]].data["C"]), 512, 256)
        K, T_cam_world = cam.decompose()
        np.testing.assert_allclose(c["C"], cam.C)
        np.testing.assert_allclose(c["K"], K)
        np.testing.assert_allclose(c["pose"]["xyz_m"], cam.center, atol=1e-9)
        np.testing.assert_allclose(c["pose"]["T"], invert_T(T_cam_world), atol=1e-12)
        assert (c["width"], c["height"]) == (512, 256)
    side = cals[1]
    assert (side["camera"], side["rms_px"], side["measurements"], side["who"]) == ("side", 0.61, 7, "viser:1")
    np.testing.assert_allclose(side["K"], [[480.0, 0, 250.0], [0, 482.0, 130.0], [0, 0, 1]], atol=1e-9)
    # the turret: its σ turned from (ω, v) in the turret frame to the world's (δt, δr); a quarter turn about z
    # swaps x and y
    turret = cals[2]
    assert turret["rms_m"] == 0.0021 and turret["measurements"] == 5 and turret["C"] is None
    np.testing.assert_allclose(turret["pose"]["xyz_m"], [0.2, -1.5, 0.65])
    np.testing.assert_allclose(turret["pose"]["sigma"]["xyz_m"], [0.02, 0.01, 0.03])
    np.testing.assert_allclose(turret["pose"]["sigma"]["rot_rad"], [0.002, 0.001, 0.003])
    base = cals[3]
    assert base["nominal"] is False and base["measurements"] == 11 and base["camera"] == "front"
    np.testing.assert_allclose(base["pose"]["xyz_m"], [-0.351, 0.046, 0.001])
    np.testing.assert_allclose(base["pose"]["sigma"]["rot_rad"], [0.01, 0.02, 0.03])


@pytest.mark.parametrize(
    "what, kinds",
    [
        ("camera", ["camera", "camera:side"]),
        ("side", ["camera:side"]),
        ("turret", ["turret"]),
        ("robot-base", ["robot_base"]),
        ("robot_base", ["robot_base"]),
        ("1", ["camera"]),  # by number: the seed's camera, older than the latest
    ],
)
def test_show_calibration_picks(site, capsys, what, kinds):
    doc = _json(capsys, "db", "show-calibration", what, "--json", "--db", site)
    assert [c["kind"] for c in doc["calibrations"]] == kinds


def test_show_calibration_text(site, capsys):
    assert main(["db", "show-calibration", "--db", site]) == 0
    out = capsys.readouterr().out
    assert "camera 'side'" in out and "by viser:1, dlt; RMS 0.61 px from 7 points" in out
    assert "K: fx 480.00 px, fy 482.00 px, centre (250.00, 130.00) px" in out
    assert "robot base: " in out and "RMS 0.80 px from 11 edges" in out and "nominal" not in out
    assert "turret in the world: position (0.2000, -1.5000, 0.6500) m" in out and "RMS 2.1 mm from 5 ranges" in out
    assert out.count("T_world_cam:") == 2 and "T_world_turret:" in out and "T_world_base:" in out


def test_show_calibration_of_none(tmp_path, capsys):
    db = str(tmp_path / "empty.sqlite")
    Database.open(db).close()
    assert _json(capsys, "db", "show-calibration", "--json", "--db", db)["calibrations"] == []
    assert main(["db", "show-calibration", "--db", db]) == 0 and "no calibrations" in capsys.readouterr().out
    assert main(["db", "show-calibration", "turret", "--db", db]) == 1
    err = capsys.readouterr().err
    assert err.startswith("mcit db show-calibration: error: ") and "has no turret calibration" in err
