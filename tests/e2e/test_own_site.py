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
    """The frames as a camera sees the box: rendered by the project's renderer (``app.render``: exact area coverage,
    Lambert shading, blur σ = 0.8 px, noise σ = 2 grey levels). Issue 27: these frames were once OpenCV's filled
    polygons, which cover every pixel their outline touches: a box drawn ~1 px larger than its pose projects, whose
    one-click pose came out 5.4 mm nearer the camera (0.9°) while fitting the image within 0.3 px; the renderer's
    box gives 0.03° / 0.04 mm (headless, ``app.vision.search.search_pose`` on the same click)."""
    import cv2

    from app.vision.synthetic import render_poses
    from core.camera import Camera

    cam = Camera.from_intrinsics(K, np.eye(4), 640, 480)
    image = render_poses(cam, BOX, [T_CAM_OBJ], noise_sigma=2.0, blur_sigma_px=0.8)[0]
    for path in folder.iterdir():
        cv2.imwrite(str(path), image)


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
        # far closer than the import (1 cm off), and within the stated σ (issue 27: the camera file's and the
        # model's priors included); see _shaded_frames for the 0.9° / 5.4 mm once measured here
        e = np.r_[ui.db.get("box").T_world_obj[:3, 3] - T_CAM_OBJ[:3, 3]]
        assert m < 0.002 and deg < 0.3
        assert np.all(np.abs(e) <= 3 * sd[:3])
    finally:
        ui.close()
