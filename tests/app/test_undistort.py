"""app.undistort: lens models, their exact inverse, the remap maps, undistorted sources, mcit track and
mcit serve with a camera file that has lens distortion."""

import cv2
import numpy as np
import pytest

from app.camera_io import read_intrinsics
from app.undistort import LensDistortion, UndistortedSource, lens_of
from app.video import StillSource, VideoError

K = np.array([[600.0, 0.0, 319.5], [0.0, 605.0, 239.5], [0.0, 0.0, 1.0]])
LENSES = [
    ("opencv", [-0.3, 0.1, 0.001, -0.002]),
    ("opencv", [-0.3, 0.1, 0.001, -0.002, -0.02]),
    ("rational_polynomial", [-0.3, 0.1, 0.001, -0.002, -0.02, 0.01, 0.002, 0.001]),
    ("opencv", [-0.3, 0.1, 0.001, -0.002, -0.02, 0.01, 0.002, 0.001, 0.001, 0.0005, -0.001, 0.0002]),
    ("opencv", [-0.3, 0.1, 0.001, -0.002, -0.02, 0.01, 0.002, 0.001, 0.001, 0.0005, -0.001, 0.0002, 0.01, -0.005]),
    ("equidistant", [0.1, -0.05, 0.01, 0.0]),
    ("visp", [-0.2, 0.21]),
]


def _grid():
    u, v = np.meshgrid(np.arange(0.0, 640, 9.7), np.arange(0.0, 480, 7.1))
    return np.column_stack([u.ravel(), v.ravel()])


@pytest.mark.parametrize("model,coeffs", LENSES, ids=[f"{m}-{len(c)}" for m, c in LENSES])
def test_undistort_is_the_exact_inverse_and_the_maps_agree(model, coeffs):
    lens = LensDistortion(K, coeffs, model, 640, 480)
    uv = _grid()
    ideal = lens.undistort(uv)
    assert np.all(np.isfinite(ideal))
    np.testing.assert_allclose(lens.distort(ideal), uv, atol=1e-6)
    assert np.abs(ideal - uv).max() > 10.0  # a real lens: tens of pixels at the corners
    # the remap maps send each undistorted pixel to where the lens put it (fixed point: 1/32 px)
    mx, my = cv2.convertMaps(*lens.maps(), cv2.CV_32FC1)
    iu, iv = np.meshgrid(np.arange(0, 640, 13), np.arange(0, 480, 11))
    d = lens.distort(np.column_stack([iu.ravel(), iv.ravel()]))
    np.testing.assert_allclose(np.column_stack([mx[iv, iu].ravel(), my[iv, iu].ravel()]), d, atol=1 / 32)


def test_opencv_model_agrees_with_opencvs_own_undistortion():
    lens = LensDistortion(K, LENSES[1][1], "plumb_bob", 640, 480)
    uv = _grid()
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    ref = cv2.undistortPoints(uv[:, None, :], K, lens.coefficients, None, K, criteria=crit).reshape(-1, 2)
    np.testing.assert_allclose(lens.undistort(uv), ref, atol=1e-4)


def test_visp_model_is_visps_kud_formula():
    lens = LensDistortion(K, [-0.2, 0.21], "visp", 640, 480)
    x, y = 0.3, -0.2
    u, v = K[0, 2] + K[0, 0] * x, K[1, 2] + K[1, 1] * y
    s = 1 - 0.2 * (x * x + y * y)
    np.testing.assert_allclose(lens.distort([[u, v]]), [[K[0, 2] + K[0, 0] * x * s, K[1, 2] + K[1, 1] * y * s]])


def test_an_undistorted_image_puts_a_distorted_dot_back_where_C_sees_it():
    lens = LensDistortion(K, LENSES[1][1], "opencv", 640, 480)
    ideal = np.array([[80.0, 60.0], [560.0, 420.0], [319.5, 239.5], [600.0, 100.0]])
    img = np.zeros((480, 640), np.float32)
    for p in lens.distort(ideal):
        cv2.circle(img, tuple(int(round(c * 16)) for c in p), 5 * 16, 255.0, -1, cv2.LINE_AA, 4)
    img = cv2.GaussianBlur(img, (0, 0), 1.0)
    out = lens.undistort_image(img)
    for u, v in ideal:
        win = out[int(v) - 12 : int(v) + 13, int(u) - 12 : int(u) + 13]
        yy, xx = np.mgrid[-12:13, -12:13]
        c = np.array([(win * xx).sum(), (win * yy).sum()]) / win.sum() + [int(u), int(v)]
        assert np.linalg.norm(c - [u, v]) < 0.35, (u, v, c)  # a dot's centroid (not exactly its centre's image)


def test_bad_lenses_are_refused():
    with pytest.raises(ValueError, match="unknown lens distortion model 'kannala'"):
        LensDistortion(K, [0.1, 0, 0, 0], "kannala", 640, 480)
    with pytest.raises(ValueError, match="takes 4 or 5 or 8 or 12 or 14 coefficients, got 3"):
        LensDistortion(K, [0.1, 0, 0], "opencv", 640, 480)
    with pytest.raises(ValueError, match="takes 2 coefficients"):
        LensDistortion(K, [0.1], "visp", 640, 480)
    lens = LensDistortion(K, [0.1, 0, 0, 0], "opencv", 640, 480)
    with pytest.raises(ValueError, match="frame is 320×240 but the camera was calibrated on 640×480"):
        lens.undistort_image(np.zeros((240, 320, 3), np.uint8))


def _write_cam(path, D, model=None, size=(640, 480), K=K):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    fs.write("image_width", size[0])
    fs.write("image_height", size[1])
    fs.write("camera_matrix", K)
    fs.write("distortion_coefficients", np.asarray(D, float).reshape(1, -1))
    if model:
        fs.write("distortion_model", model)
    fs.release()


def test_lens_of_intrinsics_files(tmp_path):
    _write_cam(tmp_path / "a.yml", [0, 0, 0, 0, 0])
    assert lens_of(read_intrinsics(tmp_path / "a.yml")) is None  # zero distortion: nothing to do
    _write_cam(tmp_path / "b.yml", [0.1, -0.05, 0.01, 0.0], "equidistant")
    lens = lens_of(read_intrinsics(tmp_path / "b.yml"))
    assert lens.model == "fisheye" and (lens.width, lens.height) == (640, 480)
    (tmp_path / "c.xml").write_text(
        "<root><camera><name>c</name><model><type>perspectiveProjWithDistortion</type><px>600</px><py>605</py>"
        "<u0>319.5</u0><v0>239.5</v0><kud>-0.2</kud><kdu>0.21</kdu></model></camera></root>"
    )
    with pytest.raises(ValueError, match=r"c\.xml: states lens distortion but not the image size"):
        lens_of(read_intrinsics(tmp_path / "c.xml"))
    assert lens_of(read_intrinsics(tmp_path / "c.xml"), 640, 480).model == "visp"


def test_undistorted_source_remaps_every_frame_and_keeps_its_timing():
    lens = LensDistortion(K, LENSES[1][1], "opencv", 640, 480)
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.integers(0, 255, (480, 640, 3), dtype=np.uint8), (0, 0), 2.0)
    src = UndistortedSource(StillSource(img, fps=7.0), lens)
    assert (src.width, src.height, src.fps, src.live) == (640, 480, 7.0, False)
    f = src.read()
    assert f.index == 0 and f.t_s == 0.0
    np.testing.assert_array_equal(f.image, lens.undistort_image(img))
    assert not np.array_equal(f.image, img)
    with pytest.raises(VideoError, match="gives 320×240 frames but the camera was calibrated on 640×480"):
        UndistortedSource(StillSource(np.zeros((240, 320, 3), np.uint8)), lens)


def test_mcit_track_with_a_distorting_camera(tmp_path, capsys):
    """Frames rendered through a lens; the camera file states the lens; mcit track undistorts them
    and finds the poses as well as on a distortion-free camera."""
    from app.cli import main
    from app.models_io import write_cao
    from app.render.renderer import Renderer
    from app.vision.synthetic import one_body_scene
    from core.brep import BRep
    from core.camera import Camera
    from core.transforms import exp_so3, log_so3, make_T, pose_error

    Ks = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])
    D = [-0.28, 0.09, 0.0005, -0.001, -0.01]
    lens = LensDistortion(Ks, D, "opencv", 320, 240)
    cam = Camera.from_intrinsics(Ks, np.eye(4), 320, 240)
    box = BRep.box(0.2, 0.13, 0.08)
    R0 = exp_so3([2.2, 0.4, 0.3])
    truth = [
        make_T(exp_so3(np.radians(0.8) * k * np.array([0.0, 1.0, 0.3])) @ R0, [0.06 + 0.003 * k, 0.03, 0.8])
        for k in range(4)
    ]
    scene = one_body_scene(cam, box, truth)
    r = Renderer(scene, cam, lens=lens)
    (tmp_path / "frames").mkdir()
    for k in range(4):
        cv2.imwrite(str(tmp_path / "frames" / f"f{k}.png"), r.render(float(k), k))
    write_cao(box, tmp_path / "box.cao")
    (tmp_path / "box.pos").write_text("\n".join(f"{x:.12f}" for x in np.r_[truth[0][:3, 3], log_so3(truth[0][:3, :3])]))
    _write_cam(tmp_path / "cam.yml", D, "plumb_bob", (320, 240), Ks)
    args = [
        "track",
        str(tmp_path / "frames"),
        "--model",
        str(tmp_path / "box.cao"),
        "--intrinsics",
        str(tmp_path / "cam.yml"),
        "--pose",
        str(tmp_path / "box.pos"),
        "--out",
        str(tmp_path / "t.avi"),
    ]
    assert main(args + ["--csv", str(tmp_path / "t.csv")]) == 0, capsys.readouterr().err
    import csv

    def errors(csv_path):
        rows = list(csv.DictReader(open(csv_path)))
        assert len(rows) == 4
        return np.array(
            [
                [abs(float(row[k]) - T[i, 3]) for i, k in enumerate(("tx_m", "ty_m", "tz_m"))]
                for row, T in zip(rows, truth)
            ]
        )

    assert errors(tmp_path / "t.csv").max() < 2e-3
    # the same frames taken as distortion-free: the depth is several millimetres off
    _write_cam(tmp_path / "cam0.yml", [0, 0, 0, 0, 0], None, (320, 240), Ks)
    args0 = [a if a != str(tmp_path / "cam.yml") else str(tmp_path / "cam0.yml") for a in args]
    assert main(args0 + ["--csv", str(tmp_path / "t0.csv"), "--keep-going"]) == 0
    assert errors(tmp_path / "t0.csv")[:, 2].min() > 4e-3
    # clicked points are pixels of the recorded (distorted) frames
    X = box.vertices[[0, 1, 2, 3, 4, 5, 6, 7]]
    X = X[cam.depth(X @ truth[0][:3, :3].T + truth[0][:3, 3]) > 0]
    (tmp_path / "box.init").write_text(f"{len(X)}\n" + "\n".join(" ".join(str(c) for c in x) for x in X))
    clicks = lens.distort(cam.project_obj(truth[0], X))
    import argparse

    from app.vision.track_cli import _setup

    ns = argparse.Namespace(
        source=str(tmp_path / "frames"),
        model=str(tmp_path / "box.cao"),
        scene=None,
        body=None,
        intrinsics=str(tmp_path / "cam.yml"),
        camera_name=None,
        pose=None,
        start=0,
        init_points=str(tmp_path / "box.init"),
        init_clicks=[tuple(c) for c in clicks],
    )
    T = _setup(ns)[3]
    assert pose_error(T, truth[0])[0] < 0.05 and np.linalg.norm(T[:3, 3] - truth[0][:3, 3]) < 1e-3


def test_mcit_serve_undistorts_the_video_of_a_scene_whose_camera_file_has_distortion(tmp_path):
    """A scene whose camera is an intrinsics file with distortion: the interface shows (and clicks,
    snaps, tracks and draws the overlay on) the undistorted frames, with C unchanged."""
    import json
    import time

    from app.cli import build_parser
    from app.scene import default_scene_path
    from app.ui.serve import build_interface
    from tests.e2e.harness import free_port

    d = json.loads((default_scene_path() / "scene.json").read_text())
    front = d["cameras"][0]
    Kw = np.array(front["K"])
    D = [-0.3, 0.12, 0.001, -0.0015, -0.02]
    _write_cam(tmp_path / "cam.yml", D, "plumb_bob", (512, 256), Kw)
    d["cameras"] = [{"name": "front", "intrinsics_file": "cam.yml", "T_world_cam": front["T_world_cam"]}]
    (tmp_path / "scene.json").write_text(json.dumps(d))
    (tmp_path / "arm.urdf").write_bytes((default_scene_path() / "arm.urdf").read_bytes())  # the scene's robot
    (tmp_path / "frames").mkdir()
    rng = np.random.default_rng(1)
    raw = cv2.GaussianBlur(rng.integers(0, 255, (256, 512, 3), dtype=np.uint8), (0, 0), 2.0)
    cv2.imwrite(str(tmp_path / "frames" / "f0.png"), raw)
    args = build_parser().parse_args(
        [
            "serve",
            "--scene",
            str(tmp_path),
            "--video",
            str(tmp_path / "frames"),
            "--db",
            str(tmp_path / "site.sqlite"),
            "--no-devices",
            "--port",
            str(free_port()),
        ]
    )
    server, closers = build_interface(args)
    try:
        src = server.grabber.source
        assert isinstance(src, UndistortedSource) and "undistorted (opencv lens)" in src.description
        np.testing.assert_allclose(server.site.camera.decompose()[0], Kw, atol=1e-9)
        deadline = time.monotonic() + 10
        while server.grabber.latest() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        rgb = cv2.cvtColor(raw, cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(server.grabber.latest().image, src.lens.undistort_image(rgb))
    finally:
        server.server.stop()
        for close in closers:
            close()
