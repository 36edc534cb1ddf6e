"""Your own site in the browser: ``mcit site new`` from a ViSP camera file and an image folder, the box imported
1 cm off from a pose file, ``mcit serve --site``. In chromium the panel says what a camera-only site cannot do, and
the operator updates the box's pose by one double click on the video: it comes nearer the frames' truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from app.cli import main
from core.transforms import pose_error
from tests.app.test_own_site import BOX, T_CAM_OBJ, K, files  # noqa: F401 - the site's files, a fixture

from .flows import Operator
from .harness import ServedInterface, wait_until
from .test_workflows_pose import _start_update_pose

pytestmark = pytest.mark.e2e


def _shaded_frames(folder) -> None:
    """The frames as a camera sees the box: its faces filled, lit by their normal, on a darker table (the
    fixture's drawn edges alone are a line drawing, which no camera makes)."""
    import cv2

    from core.camera import Camera

    cam = Camera.from_intrinsics(K, np.eye(4), 640, 480)
    rng = np.random.default_rng(0)
    image = np.full((480, 640), 70.0)
    R, t = T_CAM_OBJ[:3, :3], T_CAM_OBJ[:3, 3]
    faces = [np.asarray(f) for f in BOX.faces]
    centres = BOX.face_centroids() @ R.T + t
    normals = BOX.face_normals() @ R.T
    for k in np.argsort(-centres[:, 2]):  # far faces first
        if normals[k] @ centres[k] >= 0:  # facing away
            continue
        uv = cam.project_obj(T_CAM_OBJ, BOX.vertices[faces[k]])
        light = np.array([0.45, -0.5, -0.74]) / np.linalg.norm([0.45, -0.5, -0.74])  # camera frame: upper left
        grey = 110.0 + 140.0 * abs(float(normals[k] @ light))
        # sub-pixel corners (16ths), anti-aliased: a polygon rounded to whole pixels is a box 1 px off its pose
        cv2.fillConvexPoly(image, np.round(16 * uv).astype(np.int32), grey, lineType=cv2.LINE_AA, shift=4)
    image = cv2.GaussianBlur(image, (0, 0), 0.8) + rng.normal(0.0, 2.0, image.shape)
    for path in folder.iterdir():
        cv2.imwrite(str(path), np.clip(image, 0, 255).astype(np.uint8))


def test_an_own_camera_only_site_is_served_and_its_object_updated_by_a_double_click(browser, files):  # noqa: F811
    _shaded_frames(files / "frames")
    site = files / "site"
    assert main(["site", "new", str(site), "--camera", str(files / "cam.xml"), "--video", str(files / "frames")]) == 0
    off = T_CAM_OBJ.copy()
    off[0, 3] += 0.01  # imported 1 cm off: the video shows where it is
    (files / "pose.json").write_text(json.dumps({"T_world_obj": off.tolist()}))
    assert main(["db", "import", str(files / "box.cao"), "--site", str(site), "--pose", str(files / "pose.json")]) == 0
    ui = ServedInterface(["--site", str(site)])
    try:
        page = ui.open(browser, viewport={"width": 1280, "height": 720})
        page.get_by_text("Not on this site", exact=False).first.wait_for(timeout=60_000)
        assert page.get_by_role("button", name="Calibrate turret").count() == 0
        assert page.get_by_role("button", name="Model object").count() == 0
        op = Operator(ui, page)
        obj = ui.site.object("box")
        wf = _start_update_pose(op, page, obj, ui.site.camera)
        op.double_click(ui.site.camera.project_obj(T_CAM_OBJ, obj.model.vertices).mean(axis=0))
        wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses", panel=page.panel)
        op.accept(wf)
        wait_until(lambda: ui.db.get("box").version == obj.version + 1, what="the pose written")
        deg, m = pose_error(ui.db.get("box").T_world_obj, T_CAM_OBJ)  # the world is the camera's frame here
        sd = np.sqrt(np.diag(ui.db.get("box").cov))
        print(
            f"written {deg:.3f}° / {1000 * m:.2f} mm from the frames' truth; σ {1000 * sd[:3]} mm {np.degrees(sd[3:])}°"
        )
        # closer than the import (1 cm off). Measured 0.9° / 5.4 mm against a stated σ of 0.19° / 0.59 mm on this
        # rendered box: a σ that does not cover the error (issue 27, item 1), kept in the closing note
        assert m < 0.007 and deg < 1.5
        page.close()
    finally:
        ui.close()
