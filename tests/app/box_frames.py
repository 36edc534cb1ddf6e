"""A fixture shared by the camera-file and pose-export tests: rendered frames of a box to track."""

import cv2
import numpy as np
import pytest


@pytest.fixture(scope="module")
def box_frames(tmp_path_factory):
    """Three rendered 320×240 frames of a box, its .cao and first pose (.pos)."""
    from app.models_io import write_cao
    from app.vision.synthetic import render_poses
    from core.brep import BRep
    from core.camera import Camera
    from core.transforms import exp_so3, log_so3, make_T

    d = tmp_path_factory.mktemp("camfiles")
    K = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])
    box = BRep.box(0.2, 0.13, 0.08)
    poses = [make_T(exp_so3([2.2, 0.4, 0.3]), [0.002 * k, 0.0, 0.9]) for k in range(3)]
    (d / "frames").mkdir()
    for k, img in enumerate(render_poses(Camera.from_intrinsics(K, np.eye(4), 320, 240), box, poses, noise_sigma=1.0)):
        cv2.imwrite(str(d / "frames" / f"image{k:04d}.png"), img)
    write_cao(box, d / "box.cao")
    T0 = poses[0]
    (d / "box.pos").write_text("\n".join(f"{x:.12f}" for x in np.r_[T0[:3, 3], log_so3(T0[:3, :3])]))
    model = (
        "<model><type>perspectiveProjWithoutDistortion</type><px>"
        "{f}</px><py>{f}</py><u0>159.5</u0><v0>119.5</v0></model>"
    )
    (d / "rig.xml").write_text(
        "<root>"
        + "".join(
            f"<camera><name>{n}</name><image_width>{w}</image_width><image_height>{h}</image_height>{model.format(f=f)}</camera>"
            for n, w, h, f in (("wide", 320, 240, 300.0), ("tele", 320, 240, 420.0), ("tele", 640, 480, 840.0))
        )
        + "</root>"
    )
    return d
