"""Camera files as other tools write them (issue 15.3): ROS camera_info YAML, the OpenCV calibration
tutorial's keys, ViSP files of several cameras, ``--camera-name``; every failure one line naming the file."""

import cv2
import numpy as np
import pytest

from app.camera_io import read_intrinsics, read_opencv_yml
from tests.app.box_frames import box_frames  # noqa: F401 - a fixture

K_ROS = [[700.1, 0.0, 320.5], [0.0, 701.2, 240.5], [0.0, 0.0, 1.0]]
D_ROS = [-0.1, 0.05, 0.001, -0.0005, 0.0]

# What ROS's camera_calibration writes (ost.yaml): no %YAML directive, untagged rows/cols/data maps.
OST_YAML = """image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix:
  rows: 3
  cols: 3
  data: [700.1, 0, 320.5, 0, 701.2, 240.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients:
  rows: 1
  cols: 5
  data: [-0.1, 0.05, 0.001, -0.0005, 0]
rectification_matrix:
  rows: 3
  cols: 3
  data: [1, 0, 0, 0, 1, 0, 0, 0, 1]
projection_matrix:
  rows: 3
  cols: 4
  data: [690.0, 0, 321, 0, 0, 695, 241, 0, 0, 0, 1, 0]
"""

# camera_calibration_parsers' OpenCV flavour: the directive and !!opencv-matrix tags.
OST_OPENCV = """%YAML:1.0
image_width: 640
image_height: 480
camera_name: narrow_stereo
camera_matrix: !!opencv-matrix
  rows: 3
  cols: 3
  dt: d
  data: [700.1, 0, 320.5, 0, 701.2, 240.5, 0, 0, 1]
distortion_model: plumb_bob
distortion_coefficients: !!opencv-matrix
  rows: 1
  cols: 5
  dt: d
  data: [-0.1, 0.05, 0.001, -0.0005, 0]
"""

# A sensor_msgs/CameraInfo message dumped to YAML (ROS 2: lower-case k, d; ROS 1: K, D).
ROS2_INFO = """header:
  stamp:
    sec: 0
    nanosec: 0
  frame_id: camera
height: 480
width: 640
distortion_model: plumb_bob
d: [-0.1, 0.05, 0.001, -0.0005, 0.0]
k: [700.1, 0.0, 320.5, 0.0, 701.2, 240.5, 0.0, 0.0, 1.0]
r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
p: [690.0, 0.0, 321.0, 0.0, 0.0, 695.0, 241.0, 0.0, 0.0, 0.0, 1.0, 0.0]
binning_x: 0
binning_y: 0
roi:
  x_offset: 0
  y_offset: 0
  height: 0
  width: 0
  do_rectify: false
"""


@pytest.mark.parametrize(
    "text",
    [OST_YAML, OST_OPENCV, ROS2_INFO, ROS2_INFO.replace("\nd:", "\nD:").replace("\nk:", "\nK:")],
    ids=["ost.yaml", "ost-opencv", "ros2-camera-info", "ros1-camera-info"],
)
def test_ros_camera_info(tmp_path, text):
    f = tmp_path / "ost.yaml"
    f.write_text(text)
    intr = read_intrinsics(f)
    np.testing.assert_allclose(intr.K, K_ROS)
    assert (intr.width, intr.height) == (640, 480)
    np.testing.assert_allclose(intr.distortion, D_ROS)
    assert intr.distortion_model == "plumb_bob" and intr.has_distortion
    assert intr.name == ("narrow_stereo" if "camera_name" in text else None)
    assert read_intrinsics(f, camera_name="narrow_stereo" if "camera_name" in text else None).K[0, 0] == 700.1


def _write_fs(path, **nodes):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in nodes.items():
        fs.write(k, v)
    fs.release()


@pytest.mark.parametrize("suffix", [".yml", ".xml", ".json"])
def test_opencv_tutorial_keys(tmp_path, suffix):
    """The calibration tutorial's out_camera_data: Camera_Matrix, image_Width, Distortion_Coefficients."""
    K = np.array([[657.467, 0.0, 319.5], [0.0, 657.467, 239.5], [0.0, 0.0, 1.0]])
    D = np.array([[-0.418], [0.507], [0.0], [0.0], [-0.578]])
    f = tmp_path / f"out_camera_data{suffix}"
    _write_fs(
        f,
        calibration_Time="Sat Dec  1 10:00:00 2026",
        nr_of_frames=25,
        image_Width=640,
        image_Height=480,
        board_Width=9,
        board_Height=6,
        square_Size=50.0,
        FixAspectRatio=1.0,
        flags=2,
        Camera_Matrix=K,
        Distortion_Coefficients=D,
        Avg_Reprojection_Error=0.39,
    )
    intr = read_intrinsics(f)
    np.testing.assert_array_equal(intr.K, K)
    np.testing.assert_array_equal(intr.distortion, D.ravel())
    assert (intr.width, intr.height) == (640, 480) and intr.distortion_model == "opencv"
    np.testing.assert_array_equal(read_opencv_yml(f), K)
    # the tutorial's fisheye calibration: four coefficients of the equidistant model
    _write_fs(f, image_Width=640, image_Height=480, fisheye_model=1, Camera_Matrix=K, Distortion_Coefficients=D[:4])
    assert read_intrinsics(f).distortion_model == "equidistant"


@pytest.mark.parametrize("n", [4, 5, 8, 12, 14])
def test_every_opencv_distortion_length_is_returned(tmp_path, n):
    f = tmp_path / "cam.yml"
    D = np.arange(1, n + 1, dtype=float).reshape(1, n) * 1e-3
    _write_fs(f, camera_matrix=np.array(K_ROS), distortion_coefficients=D, image_width=640, image_height=480)
    intr = read_intrinsics(f)
    np.testing.assert_array_equal(intr.distortion, D.ravel())


VISP_MULTI = """<?xml version="1.0"?>
<root>
  <camera><name>Camera</name><image_width>640</image_width><image_height>480</image_height>
    <model><type>perspectiveProjWithoutDistortion</type><px>600</px><py>600</py><u0>320</u0><v0>240</v0></model>
    <model><type>perspectiveProjWithDistortion</type><px>605</px><py>605</py><u0>321</u0><v0>241</v0><kud>-0.2</kud><kdu>0.21</kdu></model>
  </camera>
  <camera><name>Camera</name><image_width>320</image_width><image_height>240</image_height>
    <model><type>perspectiveProjWithoutDistortion</type><px>300</px><py>300</py><u0>160</u0><v0>120</v0></model>
  </camera>
  <camera><name>CameraLeft</name><image_width>320</image_width><image_height>240</image_height>
    <model><type>perspectiveProjWithDistortion</type><px>310</px><py>311</py><u0>161</u0><v0>121</v0><kud>-0.1</kud><kdu>0.1</kdu></model>
  </camera>
</root>
"""


def test_visp_file_of_several_cameras(tmp_path):
    f = tmp_path / "camera.xml"
    f.write_text(VISP_MULTI)
    with pytest.raises(ValueError, match=r"camera\.xml: 3 cameras in the file .*--camera-name"):
        read_intrinsics(f)
    left = read_intrinsics(f, camera_name="CameraLeft")
    assert left.name == "CameraLeft" and left.K[0, 0] == 310 and left.distortion.tolist() == [-0.1, 0.1]
    assert left.distortion_model == "visp"
    with pytest.raises(ValueError, match="2 cameras"):  # one name, two sizes: the size chooses
        read_intrinsics(f, camera_name="Camera")
    assert read_intrinsics(f, camera_name="Camera", image_size=(320, 240)).K[0, 0] == 300
    big = read_intrinsics(f, camera_name="Camera", image_size=(640, 480))
    assert big.K[0, 0] == 600 and not big.has_distortion  # the model without distortion is preferred
    with pytest.raises(ValueError, match=r"no camera named 'Camera' for 800×600 images; it has: Camera 640×480"):
        read_intrinsics(f, camera_name="Camera", image_size=(800, 600))
    with pytest.raises(
        ValueError, match=r"no camera named 'Right'; it has: Camera 640×480; Camera 320×240; CameraLeft"
    ):
        read_intrinsics(f, camera_name="Right")


def test_yaml_file_of_several_cameras(tmp_path):
    f = tmp_path / "rig.yaml"
    f.write_text(
        "cam0:\n  camera_name: left\n  camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n"
        "  image_width: 640\n  image_height: 480\n"
        "cam1:\n  camera_name: right\n  camera_matrix: {rows: 3, cols: 3, data: [510, 0, 321, 0, 510, 241, 0, 0, 1]}\n"
        "  resolution: [800, 600]\n"
    )
    with pytest.raises(
        ValueError, match=r"rig\.yaml: 2 cameras in the file \(cam0, cam1\); choose one with --camera-name"
    ):
        read_intrinsics(f)
    right = read_intrinsics(f, camera_name="right")
    assert right.K[0, 0] == 510 and (right.width, right.height) == (800, 600) and right.name == "right"
    assert read_intrinsics(f, camera_name="cam0").K[0, 0] == 500  # by its key too


def test_real_visp_files_with_a_name(shared_data):
    # the tracker settings' camera has no name: asking for one is refused, naming the file
    cube = shared_data("visp-cube", "cube.xml")
    assert read_intrinsics(cube, image_size=(640, 480)).K[0, 0] == pytest.approx(547.7367575)
    with pytest.raises(ValueError, match=r"cube\.xml: no camera named 'Camera'; it has: \(no name\) no size"):
        read_intrinsics(cube, camera_name="Camera")


_K9 = "camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, 500, 240, 0, 0, 1]}\n"
BAD = [
    ("cam.yaml", "a: [1, 2\nb: }{", "not valid YAML (line 2: "),
    ("cam.yaml", "a: [1, 2\nb: }{", "; give the calibration file OpenCV (cv::FileStorage"),  # and what to do
    ("cam.yml", "%YAML:1.0\na: [1, 2\nb: }{", "OpenCV cannot parse it (line 3"),  # OpenCV's dialect: its reader
    ("cam.yaml", "k: '<array type: double[9]>'\n", "echoed without its arrays"),
    ("cam.yaml", b"\xff\xfe\x00k: [1]", "not a text file"),
    ("cam.yaml", "image_width: 640\nimage_height: 480\n", "no camera matrix (looked for camera_matrix"),
    ("cam.yaml", "foo: 1\n", "found foo); give the calibration file OpenCV"),
    ("cam.yaml", "camera_matrix: {rows: 3, cols: 3}\n", "a matrix needs 'data'"),
    (
        "cam.yaml",
        "camera_matrix: {rows: 3, cols: 3, data: [1, 2, 3]}\n",
        "is not 3×3 numbers: give rows × cols numbers",
    ),
    ("cam.yaml", "K: [500, 0, 320, 0, 500, 240]\n", "9 numbers expected (3×3), got 6"),
    (
        "cam.yaml",
        "camera_matrix: {rows: 3, cols: 3, data: [500, 0, 320, 0, -5, 240, 0, 0, 1]}\n",
        "focal lengths must be positive",
    ),
    ("cam.yaml", _K9 + "image_width: 640\n", "states the image width but not the height"),
    ("cam.yaml", _K9 + "image_width: 640.5\nimage_height: 480\n", "'image_width' is not a whole number of pixels"),
    ("cam.yaml", _K9 + "image_width: 0\nimage_height: 480\n", "the image width must be a positive number of pixels"),
    ("cam.yaml", _K9 + "distortion_coefficients: {rows: 1, cols: 3, data: [0.1, 0, 0]}\n", "holds 3 coefficients"),
    ("cam.yaml", _K9 + "distortion_model: equidistant\nD: [0.1, 0, 0, 0, 0]\n", "equidistant (fisheye) model has 4"),
    ("cam.yaml", _K9 + "camera_name: left\n", "the camera in it is named 'left', not 'right'"),
    ("cam.yaml", "", "the file is empty"),
    ("cam.yaml", "# only a comment\n", "holds no named values"),
    ("cam.yaml", "- 1\n- 2\n", "holds no named values"),
    ("cam.xml", "<root><camera><name>a</name><px>1</px></camera></root>", "<camera> 'a': missing <py>"),
    ("cam.txt", "500 0 0", "unknown intrinsics format"),
]


@pytest.mark.parametrize("name, text, expected", BAD, ids=[b[2][:30] for b in BAD])
def test_every_failure_is_one_line_naming_the_file(tmp_path, name, text, expected):
    f = tmp_path / name
    f.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(ValueError) as info:
        read_intrinsics(f, camera_name="right" if "named 'left'" in expected else None)
    msg = str(info.value)
    assert msg.startswith(str(f)) and "\n" not in msg, msg
    assert expected in msg, msg
    with pytest.raises(ValueError, match="no such intrinsics file"):
        read_intrinsics(tmp_path / "absent.yaml")


def test_mcit_track_camera_name(box_frames, capsys):
    from app.cli import main

    d = box_frames
    args = [
        "track",
        str(d / "frames"),
        "--model",
        str(d / "box.cao"),
        "--pose",
        str(d / "box.pos"),
        "--out",
        str(d / "t.avi"),
        "--intrinsics",
        str(d / "rig.xml"),
    ]
    assert main(args) == 1  # a file that cannot be used: status 1 (app/exit_status.py)
    err = capsys.readouterr().err
    assert "rig.xml: 2 cameras for 320×240 images (wide 320×240; tele 320×240); choose one with --camera-name" in err
    assert err.count("\n") == 1
    # the name, then the video's frame size, choose the 320×240 'tele' camera: the box is tracked
    assert main(args + ["--camera-name", "tele"]) == 0
    assert "tracked 3 frames" in capsys.readouterr().out
    assert main(args + ["--camera-name", "zoom"]) == 1
    assert "rig.xml: no camera named 'zoom'" in capsys.readouterr().err
    # a file calibrated on other images than the video's is refused, naming both sizes
    (d / "big.yaml").write_text(
        "image_width: 640\nimage_height: 480\ncamera_name: tele\n"
        "camera_matrix: {rows: 3, cols: 3, data: [840, 0, 319.5, 0, 840, 239.5, 0, 0, 1]}\n"
    )
    assert main(args[:-1] + [str(d / "big.yaml")]) == 1
    assert (
        "big.yaml: the camera was calibrated on 640×480 images but the video's frames are 320×240"
        in capsys.readouterr().err
    )
    # --camera-name without --intrinsics says what it is for: a command line to fix, status 2
    assert main(["track", str(d / "frames"), "--scene", "x", "--camera-name", "tele"]) == 2
    assert "--camera-name chooses a camera in the --intrinsics file" in capsys.readouterr().err


def test_scene_camera_name(box_frames):
    from app.scene import SceneError, _camera

    d = box_frames
    pose = {"xyz": [0, 0, 0], "rpy_deg": [0, 0, 0]}
    cam = _camera(
        {"intrinsics_file": "rig.xml", "camera_name": "tele", "width": 640, "height": 480, "T_world_cam": pose},
        d,
        "camera",
    )
    assert cam.width == 640 and cam.decompose()[0][0, 0] == pytest.approx(840.0)
    with pytest.raises(SceneError, match="3 cameras in the file"):
        _camera({"intrinsics_file": "rig.xml", "T_world_cam": pose}, d, "camera")
    with pytest.raises(SceneError, match="camera.camera_name: names a camera in 'intrinsics_file'"):
        _camera(
            {"K": np.eye(3).tolist(), "camera_name": "tele", "width": 640, "height": 480, "T_world_cam": pose},
            d,
            "camera",
        )


@pytest.mark.parametrize("name", ["cam.yaml", "cam.xml"])
def test_an_unreadable_file_is_one_line(tmp_path, name, monkeypatch):
    import pathlib
    import xml.etree.ElementTree as ET

    f = tmp_path / name
    f.write_text(OST_YAML if name.endswith("yaml") else VISP_MULTI)

    def denied(*args, **kwargs):
        raise PermissionError(13, "Permission denied", str(f))

    monkeypatch.setattr(pathlib.Path, "read_bytes", denied)  # as chmod 0 would (the tests may run as root)
    monkeypatch.setattr(ET, "parse", denied)
    with pytest.raises(
        ValueError, match=r"cam\.(yaml|xml): cannot be read \(Permission denied\); check the file's permissions"
    ):
        read_intrinsics(f)


# --- a lens or camera matrix no camera has (attack review): refused, saying which number and why ---


def _camera_file(tmp_path, fmt: str, fx: float = 700.0, k1: float = 0.0):
    """A 640×480 camera with focal length fx and radial distortion k1 (ViSP: kud), as each tool writes it."""
    K = [fx, 0, 320, 0, fx, 240, 0, 0, 1]
    if fmt == "visp":
        f = tmp_path / "camera.xml"
        f.write_text(
            f"<root><camera><name>Camera</name><image_width>640</image_width><image_height>480</image_height>"
            f"<model><type>perspectiveProjWithDistortion</type><px>{fx!r}</px><py>{fx!r}</py>"
            f"<u0>320</u0><v0>240</v0><kud>{k1!r}</kud><kdu>0</kdu></model></camera></root>"
        )
    elif fmt == "opencv":
        f = tmp_path / "calib.yml"
        _write_fs(
            f,
            image_width=640,
            image_height=480,
            camera_matrix=np.array(K, float).reshape(3, 3),
            distortion_coefficients=np.array([[k1, 0, 0, 0, 0]], float),
        )
    else:
        f = tmp_path / "ost.yaml"
        f.write_text(
            f"image_width: 640\nimage_height: 480\ncamera_name: cam\ncamera_matrix: {{rows: 3, cols: 3, data: "
            f"{[float(v) for v in K]}}}\ndistortion_model: plumb_bob\ndistortion_coefficients: {{rows: 1, cols: 5, "
            f"data: [{k1!r}, 0, 0, 0, 0]}}\n"
        )
    return f


FORMATS = ["visp", "opencv", "ros"]


@pytest.mark.parametrize("fmt", FORMATS)
def test_a_huge_k1_is_refused_as_a_lens_that_leaves_the_frame_black(tmp_path, fmt):
    f = _camera_file(tmp_path, fmt, k1=1e6)
    with pytest.raises(ValueError) as info:
        read_intrinsics(f)
    msg = str(info.value)
    name = "kud" if fmt == "visp" else "k1"
    assert msg.startswith(
        f"the lens distortion in {f} ({name}=1e+06) stretches the image so far that undistorted frames "
        "would show it in only "
    ), msg
    assert msg.endswith("of their area: check the file's distortion coefficients") and "\n" not in msg, msg


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("k1", [-0.5, -2.0, -1e300])
def test_a_lens_that_folds_within_the_image_is_refused(tmp_path, fmt, k1):
    # r(1 + k1 r²) turns back at r = 1/√(-3 k1): for k1 = -0.5 (fx = 700) 381 px from the centre, short of the
    # 640×480 image's corners 400 px away: their pixels are seen by no ray
    f = _camera_file(tmp_path, fmt, k1=k1)
    with pytest.raises(ValueError) as info:
        read_intrinsics(f)
    msg = str(info.value)
    assert "\n" not in msg and msg.startswith(f"the lens distortion in {f} ("), msg
    if k1 != -1e300:  # a fold so sharp that nearly every pixel leaves the frame is said as such
        assert msg.endswith("folds the image over itself within the image: check the file's distortion coefficients"), (
            msg
        )


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("k1", [-0.3, -0.1, 0.0, 0.1, 0.3])
def test_real_lenses_load_and_their_border_undistorts_and_round_trips(tmp_path, fmt, k1):
    from app.undistort import lens_of

    intr = read_intrinsics(_camera_file(tmp_path, fmt, k1=k1))
    if k1 == 0.0:
        assert not intr.has_distortion
        return
    lens = lens_of(intr)
    border = np.array(
        [[u, v] for u in np.linspace(0, 639, 17) for v in (0.0, 479.0)]
        + [[u, v] for v in np.linspace(0, 479, 13) for u in (0.0, 639.0)]
    )
    ideal = lens.undistort(border)
    assert np.isfinite(ideal).all()
    np.testing.assert_allclose(lens.distort(ideal), border, atol=1e-5)


@pytest.mark.parametrize("fmt", FORMATS)
@pytest.mark.parametrize("fx, says", [(1e300, "fx=1e+300 px"), (1e8, "fx=1e+08 px"), (1.0, "fx=1 px")])
def test_an_absurd_focal_length_is_refused_as_such(tmp_path, fmt, fx, says):
    f = _camera_file(tmp_path, fmt, fx=fx)
    with pytest.raises(ValueError) as info:
        read_intrinsics(f)
    msg = str(info.value)
    assert msg.startswith(f"{f}") and "\n" not in msg and "coplanar" not in msg, msg
    assert f"{says} is not a focal length a lens gives for 640×480 images (between 6.4 and 6.4e+06 px" in msg, msg
    assert msg.endswith("check the file's camera matrix"), msg


def test_an_absurd_focal_length_without_an_image_size(tmp_path):
    f = tmp_path / "cam.yaml"
    f.write_text("camera_matrix: {rows: 3, cols: 3, data: [1e300, 0, 320, 0, 700, 240, 0, 0, 1]}\n")
    with pytest.raises(ValueError, match=r"fx=1e\+300 px is not a focal length a lens gives for images of any size"):
        read_opencv_yml(f)
    with pytest.raises(ValueError, match=r"for 640×480 images"):
        read_intrinsics(f, image_size=(640, 480))


@pytest.mark.parametrize(
    "data, says",
    [
        (
            "[700, 0, 1e300, 0, 700, 240, 0, 0, 1]",
            "the principal point (u0, v0) = (1e+300, 240) px lies far outside 640×480 images",
        ),
        ("[700, 0, 320, 0, 700, -5000, 0, 0, 1]", "the principal point (u0, v0) = (320, -5000) px lies far outside"),
        ("[700, 1e300, 320, 0, 700, 240, 0, 0, 1]", "the skew K[0, 1]=1e+300 is larger than the focal lengths"),
    ],
)
def test_an_absurd_principal_point_or_skew_is_refused_as_such(tmp_path, data, says):
    f = tmp_path / "cam.yaml"
    f.write_text(f"image_width: 640\nimage_height: 480\ncamera_matrix: {{rows: 3, cols: 3, data: {data}}}\n")
    with pytest.raises(ValueError) as info:
        read_intrinsics(f)
    assert says in str(info.value) and str(info.value).startswith(str(f)), str(info.value)


def test_serve_intrinsics_with_an_absurd_focal_length_names_it(tmp_path):
    from app.scene import default_scene_path, load_scene
    from app.ui.serve import scene_with_intrinsics

    scene = load_scene(default_scene_path())
    f = tmp_path / "cam.yaml"
    w, h = scene.camera.width, scene.camera.height
    f.write_text(
        f"image_width: {w}\nimage_height: {h}\ncamera_matrix: {{rows: 3, cols: 3, data: [1e300, 0, {w / 2}, 0, "
        f"1e300, {h / 2}, 0, 0, 1]}}\n"
    )
    with pytest.raises(ValueError) as info:
        scene_with_intrinsics(scene, f)
    assert "fx=1e+300 px is not a focal length" in str(info.value) and "coplanar" not in str(info.value)
