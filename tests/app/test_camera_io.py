"""Camera intrinsics files: ViSP .xml (both layouts) and OpenCV FileStorage .yml."""

import numpy as np
import pytest

from app.camera_io import read_intrinsics, read_opencv_yml, read_visp_xml


def test_visp_tracker_settings_of_the_real_cube(shared_data):
    K = read_visp_xml(shared_data("visp-cube", "cube.xml"))
    # The values printed in ../shared/data/README.md.
    np.testing.assert_allclose(
        K, [[547.7367575, 0, 338.7036994], [0, 542.0744058, 234.5083345], [0, 0, 1]], rtol=0, atol=1e-9
    )
    intr = read_intrinsics(shared_data("visp-cube", "cube.xml"))
    assert intr.width is None and intr.height is None and not intr.has_distortion


def test_visp_teabox(shared_data):
    K = read_visp_xml(shared_data("visp-teabox", "teabox.xml"))
    np.testing.assert_allclose(np.diag(K), [839.21470, 839.44555, 1.0])
    np.testing.assert_allclose(K[:2, 2], [325.66776, 243.69727])


VP_CAMERA = """<?xml version="1.0"?>
<root>
  <camera>
    <name>Camera</name>
    <image_width>640</image_width>
    <image_height>480</image_height>
    {models}
  </camera>
</root>
"""
NO_DIST = (
    "<model><type>perspectiveProjWithoutDistortion</type>"
    "<px>600.5</px><py>601.5</py><u0>320.25</u0><v0>240.75</v0></model>"
)
DIST = (
    "<model><type>perspectiveProjWithDistortion</type>"
    "<px>610</px><py>611</py><u0>321</u0><v0>241</v0><kud>-0.1</kud><kdu>0.1</kdu></model>"
)


def test_visp_camera_parser_layout_prefers_the_model_without_distortion(tmp_path):
    f = tmp_path / "cam.xml"
    f.write_text(VP_CAMERA.format(models=DIST + NO_DIST))
    intr = read_intrinsics(f)
    np.testing.assert_allclose(intr.K, [[600.5, 0, 320.25], [0, 601.5, 240.75], [0, 0, 1]])
    assert (intr.width, intr.height) == (640, 480) and not intr.has_distortion


def test_visp_distortion_only_is_reported(tmp_path):
    f = tmp_path / "cam.xml"
    f.write_text(VP_CAMERA.format(models=DIST))
    intr = read_intrinsics(f)
    assert intr.has_distortion and intr.distortion.tolist() == [-0.1, 0.1]
    assert intr.K[0, 0] == 610


def test_visp_errors_name_the_problem(tmp_path):
    f = tmp_path / "cam.xml"
    f.write_text(VP_CAMERA.format(models="<model><type>perspectiveProjWithoutDistortion</type><px>600</px></model>"))
    with pytest.raises(ValueError, match="missing <py>"):
        read_visp_xml(f)
    f.write_text("<root><camera><px>abc</px></camera></root>")
    with pytest.raises(ValueError, match="<px> is not a number"):
        read_visp_xml(f)
    f.write_text("<root><nothing/></root>")
    with pytest.raises(ValueError, match="no <camera>"):
        read_visp_xml(f)
    f.write_text("<root><camera>")
    with pytest.raises(ValueError, match="not well-formed.*; give the camera file ViSP or OpenCV wrote"):
        read_visp_xml(f)  # what to do, said (a new user's malformed file got the parser's words alone)
    two = "<root>" + "".join(f"<camera><name>{n}</name>{NO_DIST}</camera>" for n in ("a", "b")) + "</root>"
    f.write_text(two)
    with pytest.raises(ValueError, match="camera_name"):
        read_visp_xml(f)
    assert read_visp_xml(f, camera_name="b")[0, 0] == 600.5
    with pytest.raises(ValueError, match="no such file"):
        read_visp_xml(tmp_path / "absent.xml")


def _write_yml(path, **nodes):
    import cv2

    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in nodes.items():
        fs.write(k, v)
    fs.release()


def test_opencv_yml_round_trip(tmp_path):
    K = np.array([[512.5, 0.25, 300.0], [0.0, 513.5, 200.0], [0.0, 0.0, 1.0]])
    f = tmp_path / "calib.yml"
    _write_yml(f, image_width=640, image_height=480, camera_matrix=K, distortion_coefficients=np.zeros((5, 1)))
    np.testing.assert_array_equal(read_opencv_yml(f), K)
    intr = read_intrinsics(f)
    assert (intr.width, intr.height) == (640, 480)
    assert intr.distortion.shape == (5,) and not intr.has_distortion
    g = tmp_path / "other.yaml"
    _write_yml(g, K=2 * K, D=np.array([[0.1, 0, 0, 0]]))
    np.testing.assert_array_equal(read_opencv_yml(g), K)  # normalised so that K[2, 2] = 1
    assert read_intrinsics(g).has_distortion


def test_opencv_yml_errors(tmp_path):
    f = tmp_path / "calib.yml"
    _write_yml(f, something=np.eye(3))
    with pytest.raises(ValueError, match="no camera matrix"):
        read_opencv_yml(f)
    _write_yml(f, camera_matrix=np.array([[500.0, 0, 1], [3.0, 500, 2], [0, 0, 1]]))
    with pytest.raises(ValueError, match="upper triangular"):
        read_opencv_yml(f)
    _write_yml(f, camera_matrix=np.eye(2))
    with pytest.raises(ValueError, match="3×3"):
        read_opencv_yml(f)
    bad = tmp_path / "cam.txt"
    bad.write_text("500 0 0")
    with pytest.raises(ValueError, match="unknown intrinsics format"):
        read_intrinsics(bad)
