"""Scene files: validation naming the field, the bundled workcell's set-up (the paper's), poses over time."""

import json

import numpy as np
import pytest

from app.operator.generate import still_windows
from app.scene import SceneError, default_scene_path, load_scene, parse_pose, pose_to_json, scene_from_dict
from core.rangefinder import aim
from core.transforms import make_T, pose_error, random_rotation


def minimal() -> dict:
    return {
        "format": "mcit-scene/1",
        "name": "tiny",
        "camera": {
            "width": 64,
            "height": 48,
            "K": [[50, 0, 31.5], [0, 50, 23.5], [0, 0, 1]],
            "T_world_cam": {"xyz": [0, -2, 0.5], "rpy_deg": [-100, 0, 0]},
        },
        "turret": {"T_world_turret": {"xyz": [0.2, -2, 0.5], "rpy_deg": [0, 0, 90]}},
        "bodies": [
            {"name": "table", "kind": "table", "model": {"box": [1, 1, 0.05]}, "pose": {"xyz": [0, 0, -0.05]}},
            {
                "name": "box",
                "kind": "box",
                "status": "unknown",
                "model": {"box": [0.1, 0.1, 0.1]},
                "pose": {"xyz": [0, 0, 0]},
                "motion": [{"t": 1.0, "pose": {"xyz": [0.1, 0, 0], "rpy_deg": [0, 0, 30]}}],
            },
        ],
        "video": {"file": "video.mp4", "fps": 10, "duration_s": 2},
    }


def check_error(tmp_path, mutate, match):
    d = minimal()
    mutate(d)
    with pytest.raises(SceneError, match=match):
        scene_from_dict(d, tmp_path)


def test_minimal_scene_loads_from_a_file(tmp_path):
    (tmp_path / "scene.json").write_text(json.dumps(minimal()))
    s = load_scene(tmp_path)
    assert [b.name for b in s.bodies] == ["table", "box"]
    assert [b.name for b in s.known] == ["table"] and [b.name for b in s.unknown] == ["box"]
    assert s.video.frame_count == 21 and s.video.frame_index(0.96) == 10 and s.video.path == tmp_path / "video.mp4"
    assert s.camera.width == 64 and s.render.aa_samples == 89


@pytest.mark.parametrize(
    "mutate, match",
    [
        (
            lambda d: d["bodies"][1].update(pose={"xyz": [0, 0], "rpy_deg": [0, 0, 0]}),
            r"bodies\[1\] \(box\)\.pose\.xyz",
        ),
        (
            lambda d: d["bodies"][1].update(pose=[[2, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
            r"bodies\[1\] \(box\)\.pose",
        ),
        (lambda d: d["bodies"][1].update(pose={"xyz": [0, 0, 0], "ypr": [0, 0, 0]}), "unknown pose keys"),
        (lambda d: d["bodies"][1].update(model={"sphere": [0.1]}), r"unknown model kind 'sphere'"),
        (lambda d: d["bodies"][1].update(model={"box": [0.1, -0.1, 0.1]}), r"model\.box.*\[1\]: must be >"),
        (lambda d: d["bodies"][1].update(model={"cylinder": [0.1]}), r"model\.cylinder.*list of 2 numbers"),
        (lambda d: d["bodies"][1].update(model={"cao": "absent.cao"}), "file not found"),
        (lambda d: d.pop("camera"), "missing field 'camera'"),
        (lambda d: d["bodies"][1].update(name="table"), r"bodies\[1\]\.name: duplicate body name 'table'"),
        (
            lambda d: d["bodies"][1]["motion"].append({"t": 0.5, "pose": {}}),
            r"motion\[1\]\.t: keyframe times must increase",
        ),
        (lambda d: d["bodies"][1]["motion"][0].update(t=0.0), r"motion\[0\]\.t"),
        (lambda d: d["bodies"][1].update(moton=[]), r"unknown field\(s\) \['moton'\]"),
        (lambda d: d.update(bodys=[]), r"unknown field\(s\) \['bodys'\]"),
        (lambda d: d["bodies"][1].update(status="maybe"), r"\.status: one of"),
        (lambda d: d.update(bodies={}), "a list of bodies expected"),
        (lambda d: (d.pop("turret"), d.update(rangefinder={})), "a range finder is carried by the turret"),
        (lambda d: d["camera"].update(C=np.eye(3, 4).tolist()), "exactly one of 'C'"),
        (lambda d: d["camera"].pop("width"), "missing field 'width'"),
        (lambda d: d["camera"].update(height=0), "positive integers"),
        (lambda d: d["camera"].update(K=[[50, 0, 31.5], [1, 50, 23.5], [0, 0, 1]]), "upper triangular"),
        (lambda d: d["camera"].pop("T_world_cam"), "missing field 'T_world_cam'"),
        (lambda d: d["turret"].update(pan_limits_steps=[10, 20]), r"turret\.pan_limits_steps"),
        (lambda d: d["turret"].update(resolution_arcsec=0), r"turret\.resolution_arcsec: must be >"),
        (lambda d: d.update(rangefinder={"min_range_m": 5.0, "max_range_m": 1.0}), "min_range_m .* below max_range_m"),
        (lambda d: d.update(rangefinder={"sigma_range_m": "5 mm"}), r"rangefinder\.sigma_range_m: a number"),
        (lambda d: d["bodies"][0].update(appearance={"albedo": 1.5}), r"appearance\.albedo: must be ≤ 1"),
        (lambda d: d["video"].update(fps=0), r"video\.fps: must be >"),
        (lambda d: d["video"].pop("file"), r"video: missing field 'file'"),
        (lambda d: d.update(render={"aa_samples": 0}), r"render\.aa_samples"),
        (lambda d: d.update(format="mcit-scene/0"), "'format' must be"),
    ],
)
def test_bad_input_names_the_field(tmp_path, mutate, match):
    check_error(tmp_path, mutate, match)


def test_comments_are_ignored(tmp_path):
    d = minimal()
    d["_comment"] = "hand-tuned"
    d["bodies"][0]["_note"] = "the table"
    assert scene_from_dict(d, tmp_path).name == "tiny"


def test_errors_name_the_file(tmp_path):
    d = minimal()
    d["bodies"][1]["model"] = {"torus": [1, 2]}
    (tmp_path / "scene.json").write_text(json.dumps(d))
    with pytest.raises(SceneError, match=r"scene\.json: bodies\[1\] \(box\)\.model: unknown model kind"):
        load_scene(tmp_path)
    (tmp_path / "scene.json").write_text("{not json")
    with pytest.raises(SceneError, match="not valid JSON"):
        load_scene(tmp_path)
    with pytest.raises(SceneError, match="no such scene file"):
        load_scene(tmp_path / "nowhere")


def test_camera_from_C_and_from_an_intrinsics_file(tmp_path, shared_data):
    s = scene_from_dict(minimal(), tmp_path)
    d = minimal()
    d["camera"] = {"width": 64, "height": 48, "C": (3.0 * s.camera.C).tolist()}
    np.testing.assert_allclose(scene_from_dict(d, tmp_path).camera.C, s.camera.C, atol=1e-12)
    xml = shared_data("visp-cube", "cube.xml")
    d = minimal()
    d["camera"] = {
        "width": 640,
        "height": 480,
        "intrinsics_file": str(xml),
        "T_world_cam": minimal()["camera"]["T_world_cam"],
    }
    K, _ = scene_from_dict(d, tmp_path).camera.decompose()
    np.testing.assert_allclose(K, [[547.7367575, 0, 338.7036994], [0, 542.0744058, 234.5083345], [0, 0, 1]], atol=1e-6)
    del d["camera"]["width"]
    with pytest.raises(SceneError, match="missing field 'width'"):  # cube.xml does not state the size
        scene_from_dict(d, tmp_path)


def test_intrinsics_file_with_distortion_gives_the_scene_its_lens(tmp_path):
    import cv2

    f = tmp_path / "cam.yml"
    fs = cv2.FileStorage(str(f), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", 64)
    fs.write("image_height", 48)
    fs.write("camera_matrix", np.array([[50.0, 0, 31.5], [0, 50, 23.5], [0, 0, 1]]))
    fs.write("distortion_coefficients", np.array([[-0.2, 0.05, 0, 0, 0]]))
    fs.release()
    d = minimal()
    d["camera"] = {"intrinsics_file": "cam.yml", "T_world_cam": minimal()["camera"]["T_world_cam"]}
    s = scene_from_dict(d, tmp_path)
    assert s.lens is not None and s.lens.model == "opencv" and (s.lens.width, s.lens.height) == (64, 48)
    np.testing.assert_array_equal(s.lens.coefficients, [-0.2, 0.05, 0, 0, 0])
    np.testing.assert_allclose(s.camera.decompose()[0], s.lens.K, atol=1e-9)  # C keeps the file's K
    d["camera"]["width"] = 128  # another size than the file's calibration
    with pytest.raises(SceneError, match=r"camera\.intrinsics_file: .*calibrated on 64×48"):
        scene_from_dict(d, tmp_path)


def test_cao_model_through_the_registered_reader(tmp_path, shared_data):
    cao = shared_data("visp-teabox", "teabox.cao")
    d = minimal()
    d["bodies"][1]["model"] = {"cao": str(cao)}
    box = scene_from_dict(d, tmp_path).body("box").model
    assert len(box.vertices) == 8 and len(box.edges) == 12
    assert sorted(np.round(np.ptp(box.vertices, axis=0), 3)) == [0.068, 0.08, 0.165]


def test_pose_round_trip_and_motion():
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = make_T(random_rotation(rng), rng.normal(size=3))
        np.testing.assert_allclose(parse_pose(pose_to_json(T), "p"), T, atol=1e-12)
    s = scene_from_dict(minimal(), ".")
    box = s.body("box")
    np.testing.assert_allclose(box.pose_at(-1.0), np.eye(4))
    half = box.pose_at(0.5)
    deg, m = pose_error(half, np.eye(4))
    assert abs(deg - 15.0) < 1e-9 and abs(m - 0.05) < 1e-12
    np.testing.assert_allclose(box.pose_at(5.0), box.motion[-1][1])
    assert box.is_static(1.0, 2.0) and not box.is_static(0.2, 0.4) and s.body("table").is_static(0, 100)


# ---------------------------------------------------------------------- the bundled workcell
@pytest.fixture(scope="module")
def workcell():
    return load_scene(default_scene_path())


def test_workcell_is_the_papers_set_up(workcell):
    s = workcell
    K, _ = s.camera.decompose()
    assert (s.camera.width, s.camera.height) == (512, 256)
    np.testing.assert_allclose([K[0, 0], K[1, 1]], [500.0, 500.0])
    dims = lambda b: sorted(np.round(np.ptp(s.body(b).model.vertices, axis=0), 4))  # noqa: E731
    assert dims("parallelepiped") == [0.132, 0.231, 0.35] and s.body("parallelepiped").status == "known"
    assert dims("unknown_box") == [0.09, 0.094, 0.14] and s.body("unknown_box").status == "unknown"
    cyl = s.body("unknown_cylinder")
    assert (
        cyl.status == "unknown" and cyl.model.solids[0].r0 == 0.051 and abs(cyl.model.solids[0].height - 0.166) < 1e-12
    )
    baseline = np.linalg.norm(s.turret.T_world_turret[:3, 3] - s.camera.center)
    assert 0.15 <= baseline <= 0.25
    assert {b.name for b in s.scenery} == {"floor", "back_wall"}
    assert (
        s.video is not None
        and s.video.path.name == "video.avi"
        and 10 <= s.video.fps <= 15
        and 20 <= s.video.duration_s <= 30
    )


def test_workcell_distances_view_and_reach(workcell):
    s = workcell
    c, t = s.camera.center, s.turret.T_world_turret
    for time_s in np.linspace(0.0, s.video.duration_s, 58):
        for b in s.known + s.unknown:
            T = b.pose_at(time_s)
            P = b.model.bounds()
            corners = np.array([[x, y, z] for x in P[:, 0] for y in P[:, 1] for z in P[:, 2]]) @ T[:3, :3].T + T[:3, 3]
            if b.name != "table":  # every object entirely in the picture, at every time
                assert s.camera.in_image(s.camera.project(corners), margin_px=2.0).all(), (b.name, time_s)
            centre = corners.mean(axis=0)
            dist_cam = np.linalg.norm(centre - c)
            dist_rf = np.linalg.norm(centre - t[:3, 3])
            if b.name == "parallelepiped":
                assert 1.8 <= dist_cam <= 2.1, time_s
            elif b.status == "unknown":
                assert 1.0 <= dist_rf <= 1.6 and 1.0 <= dist_cam <= 1.6, b.name
            pan, tilt, rho = aim(t, corners)
            assert all(s.turret.within_limits(p, q) for p, q in zip(pan, tilt)), b.name
            assert np.all(rho > s.rangefinder.min_range_m)


def test_workcell_objects_never_overlap_on_the_table(workcell):
    s = workcell
    objs = [b for b in s.known + s.unknown if b.name != "table"]
    for time_s in np.linspace(0.0, s.video.duration_s, 58):
        foot = []
        for b in objs:
            T = b.pose_at(time_s)
            P = b.model.bounds()
            foot.append((T[:2, 3], 0.5 * np.linalg.norm(P[1, :2] - P[0, :2])))  # bounding circle on the table
        for i in range(len(foot)):
            for j in range(i + 1, len(foot)):
                assert np.linalg.norm(foot[i][0] - foot[j][0]) > foot[i][1] + foot[j][1] + 0.02, (
                    objs[i].name,
                    objs[j].name,
                    time_s,
                )


def test_workcell_known_box_makes_one_large_then_small_motions(workcell):
    box = workcell.body("parallelepiped")
    assert [b.name for b in workcell.bodies if b.moves] == ["parallelepiped"]
    windows = still_windows(box, workcell.video.duration_s)
    motions = [pose_error(box.pose_at(b[0]), box.pose_at(a[0])) for a, b in zip(windows, windows[1:])]
    assert len(motions) >= 3
    assert motions[0][0] > 18.0 and motions[0][1] > 0.05  # beyond the small-motion method's domain
    for deg, m in motions[1:]:
        assert 1.0 < deg < 18.0 and 0.01 < m < 0.05
    assert windows[0] == (0.0, 12.0)
    assert all(b - a >= 2.5 for a, b in windows)


def test_the_bundled_lens_file_is_the_workcell_camera_s():
    """scenes/workcell/lens.yml (for trying the pose-only camera calibration: mcit serve --intrinsics
    scenes/workcell/lens.yml) holds the bundled camera's K and size, with no distortion."""
    import numpy as np

    from app.camera_io import read_intrinsics
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    lens = read_intrinsics(default_scene_path() / "lens.yml")
    K = scene.camera.decompose()[0]
    assert (lens.width, lens.height) == (scene.camera.width, scene.camera.height)
    assert np.allclose(lens.K, K, atol=1e-6) and not np.any(lens.distortion)
