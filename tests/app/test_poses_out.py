"""Poses out (issue 15.6): ``mcit db export-poses`` (JSON, CSV, ViSP .pos) and ``mcit track --pos-out``."""

import csv
import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from app.cli import main
from app.db import Database
from app.db.export import export_poses, quat_xyzw
from app.vision.sequence import read_visp_pose
from core.brep import BRep
from core.camera import Camera
from core.transforms import exp_so3, invert_T, log_so3, make_T
from tests.app.box_frames import box_frames  # noqa: F401 - a fixture

K = np.array([[800.0, 0.0, 320.0], [0.0, 800.0, 240.0], [0.0, 0.0, 1.0]])
T_WORLD_CAM = make_T(exp_so3([2.0, 0.3, -0.4]), [0.5, -1.2, 1.1])
T_BOX = make_T(exp_so3([0.1, -0.2, 0.9]), [0.4, 0.3, 0.05])
T_CYL = make_T(exp_so3([0.0, 0.0, -2.5]), [-0.2, 0.6, 0.0])
COV = np.diag([1e-6, 4e-6, 9e-6, 1e-4, 4e-4, 9e-4])


@pytest.fixture
def db(tmp_path):
    d = Database.open(tmp_path / "site.sqlite", client="test")
    d.add_object("box1", "box", BRep.box(0.2, 0.1, 0.05), T_BOX, cov=COV, status="known", method="seed", client="test")
    d.add_object("cyl", "polyhedron", BRep.box(0.1, 0.1, 0.3), T_CYL, status="modelled", method="seed", client="test")
    d.update_pose("box1", T_BOX, COV, expected_version=1, method="p3l+refine", client="viser:2")
    d.add_calibration(
        "camera",
        {"C": Camera.from_intrinsics(K, invert_T(T_WORLD_CAM), 640, 480).C, "width": 640, "height": 480},
        None,
        method="dlt",
        client="test",
    )
    yield d
    d.close()


def test_quaternion_convention():
    R = exp_so3([0.3, -1.2, 2.9])
    q = quat_xyzw(R)
    assert q[3] >= 0 and np.isclose(np.linalg.norm(q), 1.0)
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), R, atol=1e-12)
    assert quat_xyzw(np.eye(3)) == [0.0, 0.0, 0.0, 1.0]


def test_json_export(db, tmp_path):
    out = tmp_path / "poses.json"
    assert export_poses(db, out) == [out]
    doc = json.loads(out.read_text())
    assert doc["format"] == "mcit-poses/1" and doc["frame"] == "world"
    by = {r["object"]: r for r in doc["objects"]}
    assert set(by) == {"box1", "cyl"}
    b = by["box1"]
    np.testing.assert_allclose(b["T"], T_BOX, atol=1e-12)
    np.testing.assert_allclose(b["xyz_m"], T_BOX[:3, 3], atol=1e-12)
    np.testing.assert_allclose(Rotation.from_quat(b["quat_xyzw"]).as_matrix(), T_BOX[:3, :3], atol=1e-12)
    np.testing.assert_allclose(b["rotvec_rad"], log_so3(T_BOX[:3, :3]), atol=1e-12)
    np.testing.assert_allclose(b["sigma"]["xyz_m"], [1e-3, 2e-3, 3e-3])
    np.testing.assert_allclose(b["sigma"]["rot_rad"], [1e-2, 2e-2, 3e-2])
    assert b["version"] == 2 and b["who"] == "viser:2" and b["method"] == "p3l+refine" and b["status"] == "known"
    assert b["time_iso"].endswith("Z") and abs(b["time"] - db.get("box1").updated_at) < 1e-9
    assert by["cyl"]["sigma"] is None and by["cyl"]["cov"] is None and by["cyl"]["version"] == 1


def test_camera_frame_and_pos(db, tmp_path):
    T_cam_world = invert_T(T_WORLD_CAM)
    export_poses(db, tmp_path / "cam.json", frame="camera", names=["box1"])
    doc = json.loads((tmp_path / "cam.json").read_text())
    assert doc["frame"] == "camera" and len(doc["objects"]) == 1
    T_c = T_cam_world @ T_BOX
    np.testing.assert_allclose(doc["objects"][0]["T"], T_c, atol=1e-9)
    # σ turned into the camera frame: a diagonal covariance of the world stays of the same total
    s = np.array(doc["objects"][0]["sigma"]["xyz_m"])
    assert np.sum(s**2) == pytest.approx(1.4e-5)
    # ViSP .pos: cMo by default, read back by mcit track's reader
    export_poses(db, tmp_path / "box1.pos", names=["box1"])
    np.testing.assert_allclose(read_visp_pose(tmp_path / "box1.pos"), T_c, atol=1e-9)
    assert len((tmp_path / "box1.pos").read_text().split()) == 6
    files = export_poses(db, tmp_path / "poses" / "{name}.pos", frame="world")
    assert sorted(f.name for f in files) == ["box1.pos", "cyl.pos"]
    np.testing.assert_allclose(read_visp_pose(tmp_path / "poses" / "cyl.pos"), T_CYL, atol=1e-9)


def test_csv_export(db, tmp_path):
    export_poses(db, tmp_path / "p.csv")
    rows = {r["object"]: r for r in csv.DictReader(open(tmp_path / "p.csv"))}
    b = rows["box1"]
    np.testing.assert_allclose([float(b[k]) for k in ("x_m", "y_m", "z_m")], T_BOX[:3, 3], atol=1e-15)
    q = [float(b[k]) for k in ("qx", "qy", "qz", "qw")]
    np.testing.assert_allclose(Rotation.from_quat(q).as_matrix(), T_BOX[:3, :3], atol=1e-12)
    assert float(b["sigma_rz_rad"]) == pytest.approx(0.03) and b["version"] == "2" and b["who"] == "viser:2"
    assert rows["cyl"]["sigma_x_m"] == "" and rows["cyl"]["status"] == "modelled"


def test_export_errors_write_nothing(db, tmp_path):
    with pytest.raises(ValueError, match=r"a ViSP \.pos holds one pose; name one object, or put \{name\} in the path"):
        export_poses(db, tmp_path / "all.pos")
    with pytest.raises(ValueError, match="no object named 'nope' in the database; it has box1, cyl"):
        export_poses(db, tmp_path / "x.json", names=["nope"])
    with pytest.raises(ValueError, match=r"cannot tell the format from the suffix \.txt"):
        export_poses(db, tmp_path / "x.txt")
    empty = Database.open(tmp_path / "empty.sqlite")
    empty.add_object("a", "box", BRep.box(0.1, 0.1, 0.1), np.eye(4), method="seed")
    with pytest.raises(ValueError, match="has no camera calibration, so poses cannot be given in the camera frame"):
        export_poses(empty, tmp_path / "a.pos")
    empty.close()
    assert sorted(p.name for p in tmp_path.iterdir() if p.suffix in (".pos", ".json", ".txt")) == []


def _disk_full_on(n_write: int, monkeypatch):
    """Path.write_text failing as a full disk does, half-way through its ``n_write``-th call."""
    import errno
    import pathlib

    real, calls = pathlib.Path.write_text, []

    def write_text(self, text, *args, **kwargs):
        calls.append(self)
        if len(calls) == n_write:
            real(self, text[: len(text) // 2], *args, **kwargs)
            raise OSError(errno.ENOSPC, "No space left on device")
        return real(self, text, *args, **kwargs)

    monkeypatch.setattr(pathlib.Path, "write_text", write_text)


@pytest.mark.parametrize(
    "out, n_write, failed",
    [("poses.json", 1, "poses.json"), ("poses.csv", 1, "poses.csv"), ("{name}.pos", 2, "cyl.pos")],
)
def test_a_full_disk_writes_nothing_and_leaves_no_temporary(db, tmp_path, monkeypatch, out, n_write, failed):
    folder = tmp_path / "out"
    folder.mkdir()
    kept = folder / "poses.json"
    kept.write_text("the previous export\n")
    _disk_full_on(n_write, monkeypatch)
    with pytest.raises(OSError) as info:
        export_poses(db, folder / out, frame="world")
    assert info.value.filename == str(folder / failed)  # the file, not its temporary
    assert info.value.strerror == "No space left on device"
    assert sorted(p.name for p in folder.iterdir()) == ["poses.json"]  # the .pos of box1, written first, too
    assert kept.read_text() == "the previous export\n"


def test_mcit_db_export_poses(db, tmp_path, capsys):
    path = str(db.path)
    assert main(["db", "export-poses", str(tmp_path / "p.json"), "--db", path]) == 0
    assert f"wrote {tmp_path / 'p.json'}" in capsys.readouterr().out
    assert (
        main(["db", "export-poses", str(tmp_path / "b.pos"), "--object", "box1", "--frame", "world", "--db", path]) == 0
    )
    np.testing.assert_allclose(read_visp_pose(tmp_path / "b.pos"), T_BOX, atol=1e-9)
    assert main(["db", "export-poses", str(tmp_path / "b.pos"), "--db", path]) == 1
    err = capsys.readouterr().err
    assert err.startswith("mcit db export-poses: error:") and err.count("\n") == 1


def test_mcit_track_pos_out(box_frames, tmp_path, capsys):
    d = box_frames
    args = [
        "track",
        str(d / "frames"),
        "--model",
        str(d / "box.cao"),
        "--pose",
        str(d / "box.pos"),
        "--intrinsics",
        str(d / "rig.xml"),
        "--camera-name",
        "tele",
        "--out",
        str(tmp_path / "t.avi"),
        "--csv",
        str(tmp_path / "t.csv"),
    ]
    assert main(args + ["--pos-out", str(tmp_path / "pos" / "box.%04d.pos")]) == 0
    assert "3 .pos files" in capsys.readouterr().out
    rows = list(csv.DictReader(open(tmp_path / "t.csv")))
    for k, row in enumerate(rows):
        T = read_visp_pose(tmp_path / "pos" / f"box.{k:04d}.pos")  # ViSP cMo: the camera is the world here
        np.testing.assert_allclose(T[:3, 3], [float(row[c]) for c in ("tx_m", "ty_m", "tz_m")], atol=1e-6)
        np.testing.assert_allclose(
            log_so3(T[:3, :3]), [float(row[c]) for c in ("rx_rad", "ry_rad", "rz_rad")], atol=1e-6
        )
    # a plain path: the last tracked frame's pose, which restarts tracking (--pose reads it)
    assert main(args + ["--pos-out", str(tmp_path / "last.pos")]) == 0
    assert "pose of frame 2" in capsys.readouterr().out
    np.testing.assert_allclose(
        read_visp_pose(tmp_path / "last.pos"), read_visp_pose(tmp_path / "pos" / "box.0002.pos"), atol=1e-9
    )
    assert main(args + ["--pos-out", str(tmp_path / "bad.%s.%d.pos")]) == 2
    assert "one %d (e.g. %04d) for the frame number expected" in capsys.readouterr().err
