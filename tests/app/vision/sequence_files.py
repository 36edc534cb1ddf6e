"""A rendered sequence on disk as ``mcit track`` reads it: frames of a moving box, its model (.cao), the
camera's intrinsics (ViSP .xml) and the first pose (ViSP .pos, T_cam_obj: metres and a rotation vector)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from app.vision.synthetic import render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import exp_so3, log_so3, make_T

K = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])  # pixels; (0, 0) a pixel's centre
BOX = (0.2, 0.13, 0.08)  # metres


def poses(n: int) -> list[np.ndarray]:
    """T_cam_obj of the box in n frames: turning 0.8° and moving 3 mm a frame, 0.9 m in front of the camera."""
    R0 = exp_so3([2.2, 0.4, 0.3])
    return [
        make_T(exp_so3(np.radians(0.8) * k * np.array([0.0, 1.0, 0.3])) @ R0, [0.003 * k, 0.0, 0.9]) for k in range(n)
    ]


def write_sequence(d: Path, n: int):
    """n frames (noise σ 2 grey levels) in d/frames, d/box.cao, d/cam.xml, d/box.pos; (d, camera, box, truth)."""
    from app.models_io import write_cao

    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    box = BRep.box(*BOX)
    truth = poses(n)
    (d / "frames").mkdir()
    for k, img in enumerate(render_poses(cam, box, truth, noise_sigma=2.0)):
        cv2.imwrite(str(d / "frames" / f"image{k:04d}.png"), img)
    write_cao(box, d / "box.cao")
    (d / "cam.xml").write_text(
        "<?xml version='1.0'?><conf><camera><u0>159.5</u0><v0>119.5</v0><px>420</px><py>420</py></camera></conf>"
    )
    T0 = truth[0]
    (d / "box.pos").write_text("\n".join(f"{x:.12f}" for x in np.r_[T0[:3, 3], log_so3(T0[:3, :3])]))
    return d, cam, box, truth
