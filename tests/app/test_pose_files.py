"""app.pose_files: an object's pose from a ViSP .pos, a 4×4 matrix, JSON or a ViSP .init and its pixels —
the frame each gives, a camera-frame pose taken to the world through a known camera pose, and the
one-line refusals that name the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.models_io import CaoError, read_init_pixels
from app.pose_files import read_camera_pose, read_pose_file, read_visp_pos
from core.brep import BRep
from core.camera import Camera
from core.transforms import exp_so3, invert_T, log_so3, make_T

K = np.array([[500.0, 0.0, 319.5], [0.0, 505.0, 239.5], [0.0, 0.0, 1.0]])
# the camera 1.2 m up and back, looking down at the table (its pose in the world, T_world_cam)
T_WORLD_CAM = make_T(exp_so3([-2.1, 0.15, 0.3]), [0.1, -0.9, 1.2])
CAMERA = Camera.from_intrinsics(K, invert_T(T_WORLD_CAM), 640, 480)
T_WORLD_OBJ = make_T(exp_so3([0.0, 0.0, 0.7]), [0.05, 0.1, 0.02])  # a box on the table, turned 40°
T_CAM_OBJ = invert_T(T_WORLD_CAM) @ T_WORLD_OBJ  # ViSP's cMo of that box
BOX = BRep.box(0.165, 0.068, 0.08)


def _matrix_text(T: np.ndarray, comment: str = "", digits: int = 17) -> str:
    rows = "\n".join(" ".join(f"{v:.{digits}g}" for v in row) for row in T)
    return (f"# {comment}\n" if comment else "") + rows + "\n"


def test_a_visp_pos_is_the_pose_in_the_camera_and_reaches_the_world_through_the_camera(tmp_path):
    p = tmp_path / "box.0.pos"
    p.write_text("\n".join(repr(float(v)) for v in np.r_[T_CAM_OBJ[:3, 3], log_so3(T_CAM_OBJ[:3, :3])]) + "\n")
    pose = read_pose_file(p)
    assert pose.frame == "camera" and "default" in pose.frame_from
    np.testing.assert_allclose(pose.T, T_CAM_OBJ, atol=1e-12)
    T, cov = pose.in_world(CAMERA)
    np.testing.assert_allclose(T, T_WORLD_OBJ, atol=1e-9)
    assert cov is None
    np.testing.assert_allclose(read_visp_pos(p), T_CAM_OBJ, atol=1e-12)
    # told it is a world pose, it is taken as it is
    np.testing.assert_allclose(read_pose_file(p, frame="world").in_world(None)[0], T_CAM_OBJ, atol=1e-12)


def test_a_cmo_matrix_file_becomes_t_world_obj_through_a_known_camera_pose(tmp_path):
    p = tmp_path / "cMo.txt"
    p.write_text(_matrix_text(T_CAM_OBJ, "cMo of the box, as vpHomogeneousMatrix::save writes it"))
    pose = read_pose_file(p)
    assert (pose.frame, pose.frame_from) == ("camera", "the file")
    np.testing.assert_allclose(pose.in_world(CAMERA)[0], T_WORLD_OBJ, atol=1e-9)
    # no comment: ViSP's cMo by default; the top 3×4 (12 numbers) is enough; commas and brackets separate
    p.write_text(str(T_CAM_OBJ[:3].tolist()))
    pose = read_pose_file(p)
    assert pose.frame == "camera" and "default" in pose.frame_from
    np.testing.assert_allclose(pose.in_world(CAMERA)[0], T_WORLD_OBJ, atol=1e-9)
    # a world pose, said by the file or by the flag
    q = tmp_path / "wMo.dat"
    q.write_text(_matrix_text(T_WORLD_OBJ, "T_world_obj"))
    assert read_pose_file(q).frame == "world"
    np.testing.assert_allclose(read_pose_file(q).in_world(None)[0], T_WORLD_OBJ, atol=1e-12)
    q.write_text(_matrix_text(T_WORLD_OBJ))
    assert read_pose_file(q, frame="world").frame_from == "--pose-frame"
    # six digits, as ViSP prints: accepted, made an exact rotation
    p.write_text(_matrix_text(T_CAM_OBJ, "cMo", digits=6))
    R = read_pose_file(p).T[:3, :3]
    assert np.abs(R.T @ R - np.eye(3)).max() < 1e-12 and abs(np.linalg.det(R) - 1) < 1e-12
    np.testing.assert_allclose(read_pose_file(p).in_world(CAMERA)[0], T_WORLD_OBJ, atol=1e-5)


def test_json_poses_are_in_the_world_unless_they_say(tmp_path):
    p = tmp_path / "pose.json"
    p.write_text(json.dumps(T_WORLD_OBJ.tolist()))
    pose = read_pose_file(p)
    assert pose.frame == "world"
    np.testing.assert_allclose(pose.in_world(None)[0], T_WORLD_OBJ, atol=1e-12)
    p.write_text(json.dumps({"xyz": [0.1, 0.2, 0.3], "rpy_deg": [0, 0, 90]}))
    T = read_pose_file(p).in_world(None)[0]
    np.testing.assert_allclose(T[:3, 3], [0.1, 0.2, 0.3])
    np.testing.assert_allclose(T[:3, 0], [0, 1, 0], atol=1e-12)
    p.write_text(json.dumps({"T_cam_obj": T_CAM_OBJ.tolist()}))
    pose = read_pose_file(p)
    assert (pose.frame, pose.frame_from) == ("camera", "the file")
    np.testing.assert_allclose(pose.in_world(CAMERA)[0], T_WORLD_OBJ, atol=1e-9)
    p.write_text(json.dumps({"T_world_obj": {"xyz": [1, 2, 3]}}))
    assert read_pose_file(p).frame == "world"


def _init_file(path, X, uv=None) -> None:
    """A ViSP .init: the points, then (as initFromPoints reads them) their pixels as 'row column'."""
    text = f"# model points\n{len(X)}\n" + "\n".join(" ".join(repr(float(c)) for c in x) for x in X) + "\n"
    if uv is not None:
        text += (
            f"# their pixels: i j (row, column)\n{len(uv)}\n"
            + "\n".join(f"{float(v)!r} {float(u)!r}" for u, v in uv)
            + "\n"
        )
    path.write_text(text)


def test_an_init_file_with_its_pixels_gives_the_pose_by_pnp(tmp_path):
    X = BOX.vertices[[0, 1, 2, 5, 6]]
    uv = CAMERA.project_obj(T_WORLD_OBJ, X)
    p = tmp_path / "box.init"
    _init_file(p, X, uv)
    X_read, uv_read = read_init_pixels(p)
    np.testing.assert_allclose(X_read, X)
    np.testing.assert_allclose(uv_read, uv)  # read as (u, v) from the file's (row, column)
    pose = read_pose_file(p, camera=CAMERA)
    assert pose.frame == "camera" and pose.details["rms_px"] < 1e-6 and pose.details["pixels_from"] == "the file"
    T, cov = pose.in_world(CAMERA)
    np.testing.assert_allclose(T, T_WORLD_OBJ, atol=1e-7)
    assert cov.shape == (6, 6) and np.all(np.linalg.eigvalsh(cov) > 0)
    # the pixels given apart (mcit track --init-clicks), for a file of points only
    _init_file(p, X)
    assert read_init_pixels(p)[1] is None
    pose = read_pose_file(p, camera=CAMERA, clicks=uv + np.random.default_rng(0).normal(0.0, 0.5, uv.shape))
    assert pose.details["pixels_from"] == "--init-clicks" and 0.1 < pose.details["rms_px"] < 1.5
    T, cov = pose.in_world(CAMERA)
    error = T[:3, 3] - T_WORLD_OBJ[:3, 3]  # within 4σ of its stated covariance, in the world frame
    assert np.linalg.norm(error) < 0.03 and np.all(np.abs(error) < 4 * np.sqrt(np.diag(cov)[:3]))


def test_pixels_written_the_other_way_round_are_refused_saying_so(tmp_path):
    """A swap of (u, v) still gives a pose a few pixels off: refused when the swapped pixels fit far better."""
    X = BOX.vertices[[0, 1, 2, 5, 6]]
    uv = CAMERA.project_obj(T_WORLD_OBJ, X)
    p = tmp_path / "box.init"
    _init_file(p, X, uv[:, ::-1])  # written 'u v' where ViSP's order is 'row column'
    with pytest.raises(ValueError, match=r"box\.init: .*0\.00 px with each pixel's two coordinates swapped: the file"):
        read_pose_file(p, camera=CAMERA)
    _init_file(p, X)
    with pytest.raises(ValueError, match=r"--init-clicks are U,V \(column, then row\); were they written the other"):
        read_pose_file(p, camera=CAMERA, clicks=uv[:, ::-1])
    noisy = uv + np.random.default_rng(1).normal(0.0, 3.0, uv.shape)  # clicks merely poor: taken, as before
    assert read_pose_file(p, camera=CAMERA, clicks=noisy).details["rms_px"] > 1.0


@pytest.mark.parametrize(
    "name, text, kwargs, match",
    [
        ("a.txt", _matrix_text(np.diag([2.0, 2.0, 2.0, 1.0])), {}, r"a\.txt: .*scaled or sheared.*not a rigid"),
        ("a.txt", _matrix_text(np.diag([1.0, 1.0, -1.0, 1.0])), {}, r"a\.txt: .*mirrored"),
        ("a.txt", _matrix_text(np.r_[np.eye(4)[:3], [[0, 0, 1, 1]]]), {}, r"a\.txt: the matrix's last row is 0 0 1 1"),
        ("a.txt", "1 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0\n", {}, r"a\.txt: .*holds 16 numbers .*got 15"),
        (
            "a.txt",
            "0.1 0.2 0.3 0 0 0\n",
            {},
            r"a\.txt: .*got 6; six numbers are a ViSP pose vector: name the file .pos",
        ),
        ("a.txt", "1 0 0 0 x\n", {}, r"a\.txt: .*holds numbers only"),
        ("a.txt", "# cMo and wMo\n" + _matrix_text(np.eye(4)), {}, r"a\.txt: its comments name both frames"),
        ("a.txt", "# wMo\n" + _matrix_text(np.eye(4)), {"frame": "camera"}, r"a\.txt: .*world frame but --pose-frame"),
        ("a.pos", "0 0 0.5\n", {}, r"a\.pos: a ViSP pose file holds six numbers .*got 3"),
        ("a.pos", _matrix_text(np.eye(4)), {}, r"a\.pos: .*got 16; 16 numbers are a 4×4 matrix"),
        ("a.pos", "0 0 nan 0 0 0", {}, r"a\.pos: .*not finite"),
        ("a.json", "{not json", {}, r"a\.json: not valid JSON"),
        ("a.json", '{"xyz": [0, 0, 0], "quat": [0, 0, 0, 1]}', {}, r"a\.json: a JSON pose is .*'quat'"),
        ("a.json", "[[1, 0, 0], [0, 1, 0], [0, 0, 1]]", {}, r"a\.json: a pose matrix is 4×4"),
        ("a.yaml", "x: 1", {}, r"a\.yaml: unknown pose file type '\.yaml'; give a ViSP \.pos"),
        ("a", "1 2 3", {}, r"unknown pose file type '\(no suffix\)'"),
        (
            "a.init",
            "4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n",
            {"camera": CAMERA},
            r"a\.init: .*not their pixels.*--init-clicks",
        ),
        (
            "a.init",
            "4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n",
            {"clicks": [[1, 2]] * 4},
            r"a\.init: .*needs the camera's calibration",
        ),
        ("a.init", "4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n", {"frame": "world"}, r"a\.init: .*drop --pose-frame world"),
        ("a.init", "4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3\n1 1\n2 2\n3 3\n", {}, r"a\.init:6: 3 image points .* 4 model"),
        ("a.init", "4\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n4\n1 1\n2 2\n3 3\n4 4\n9\n", {}, r"a\.init:11: more lines after"),
        ("a.pos", "0 0 0 0 0 0", {"clicks": [[1, 2]]}, r"a\.pos: clicked pixels \(--init-clicks\) go with an \.init"),
    ],
)
def test_bad_files_are_refused_in_one_line_naming_the_file(tmp_path, name, text, kwargs, match):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError, match=match) as info:
        read_pose_file(path, **kwargs)
    assert "\n" not in str(info.value) and str(path) in str(info.value)


def test_an_init_with_pixels_and_clicks_too_and_clicks_of_the_wrong_count_are_refused(tmp_path):
    X = BOX.vertices[[0, 1, 2, 5]]
    uv = CAMERA.project_obj(T_WORLD_OBJ, X)
    p = tmp_path / "box.init"
    _init_file(p, X, uv)
    with pytest.raises(ValueError, match="give them once"):
        read_pose_file(p, camera=CAMERA, clicks=uv)
    _init_file(p, X)
    with pytest.raises(ValueError, match=r"4 model points but 3 pixels"):
        read_pose_file(p, camera=CAMERA, clicks=uv[:3])
    with pytest.raises(CaoError, match=r"box\.init:1: the number of points is more than"):
        p.write_text("4\n0 0 0\n")
        read_pose_file(p, camera=CAMERA, clicks=uv)


def test_init_clicks_in_reverse_order_or_on_one_line_are_refused_and_good_ones_with_noise_taken(tmp_path):
    """A new user's four clicks in reverse order (RMS 30.9 px) and on one line (49.9 px) were each stored as a
    known pose; clicks by eye (1-3 px) are taken."""
    X = BOX.vertices[[0, 1, 2, 5, 6]]
    uv = CAMERA.project_obj(T_WORLD_OBJ, X)
    p = tmp_path / "box.init"
    _init_file(p, X)
    noisy = uv + np.random.default_rng(0).normal(0.0, 2.0, uv.shape)
    assert read_pose_file(p, camera=CAMERA, clicks=noisy).details["rms_px"] < 4.0
    for clicks in (uv[::-1], np.linspace([100.0, 100.0], [400.0, 400.0], len(X))):
        with pytest.raises(
            ValueError, match=r"box\.init: the points fit the --init-clicks with RMS .* more than 10 px"
        ):
            read_pose_file(p, camera=CAMERA, clicks=clicks)


def test_a_camera_frame_pose_needs_a_camera_that_is_not_mirrored(tmp_path):
    p = tmp_path / "cMo.txt"
    p.write_text(_matrix_text(T_CAM_OBJ))
    with pytest.raises(ValueError, match=r"cMo\.txt: a pose in the camera frame needs the camera.s calibration"):
        read_pose_file(p).in_world(None)
    in_front = T_WORLD_OBJ[:3, 3] * [-1.0, 1.0, 1.0]  # the box, in the mirrored world
    mirrored = Camera(CAMERA.C @ np.diag([-1.0, 1.0, 1.0, 1.0]), 640, 480, in_front=in_front)
    with pytest.raises(ValueError, match="mirrored"):
        read_pose_file(p).in_world(mirrored)


def test_missing_files_and_the_camera_pose_reader(tmp_path):
    with pytest.raises(ValueError, match=r"nowhere\.pos: no such pose file"):
        read_pose_file(tmp_path / "nowhere.pos")
    (tmp_path / "dir.txt").mkdir()
    with pytest.raises(ValueError, match=r"dir\.txt: not a file"):
        read_pose_file(tmp_path / "dir.txt")
    p = tmp_path / "cam.json"
    p.write_text(json.dumps({"xyz": [0, -1, 1], "rpy_deg": [-120, 0, 0]}))
    T = read_camera_pose(p)
    np.testing.assert_allclose(T[:3, 3], [0, -1, 1])
    (tmp_path / "cam.txt").write_text(_matrix_text(T_WORLD_CAM))
    np.testing.assert_allclose(read_camera_pose(tmp_path / "cam.txt"), T_WORLD_CAM, atol=1e-12)
    with pytest.raises(ValueError, match=r"cam\.pos: a camera's pose \(T_world_cam\) is a 4×4 matrix"):
        read_camera_pose(tmp_path / "cam.pos")


def test_mcit_track_reads_its_pose_through_the_same_reader(tmp_path):
    """mcit track --pose takes a cMo matrix file too (the reader app.pose_files), through its scene's camera."""
    import argparse

    from app.vision.track_cli import _setup

    p = tmp_path / "cMo.txt"
    p.write_text(_matrix_text(T_CAM_OBJ, "cMo"))
    from app.models_io import write_cao

    write_cao(BOX, tmp_path / "box.cao")
    scene = {
        "format": "mcit-scene/1",
        "camera": {"width": 640, "height": 480, "K": K.tolist(), "T_world_cam": T_WORLD_CAM.tolist()},
    }
    (tmp_path / "scene.json").write_text(json.dumps(scene))
    ns = argparse.Namespace(
        source="frames",
        model=str(tmp_path / "box.cao"),
        scene=str(tmp_path),
        body=None,
        intrinsics=None,
        camera_name=None,
        pose=str(p),
        pose_frame=None,
        start=0,
        init_points=None,
        init_clicks=None,
    )
    np.testing.assert_allclose(_setup(ns)[3], T_WORLD_OBJ, atol=1e-9)


def test_mcit_track_pos_out_writes_cmo_that_its_pose_reads_back(tmp_path):
    """--pos-out writes the tracked pose in the camera (cMo through the scene's C): read back by --pose it is
    the world pose tracked, where the camera is not the world."""
    from types import SimpleNamespace

    from app.vision.track_cli import _write_pos

    frames = [SimpleNamespace(index=0, lost=False, T_world_obj=T_WORLD_OBJ)]
    _write_pos(str(tmp_path / "last.pos"), frames, CAMERA)
    np.testing.assert_allclose(read_visp_pos(tmp_path / "last.pos"), T_CAM_OBJ, atol=1e-9)
    np.testing.assert_allclose(read_pose_file(tmp_path / "last.pos").in_world(CAMERA)[0], T_WORLD_OBJ, atol=1e-9)
