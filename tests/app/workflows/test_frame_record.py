"""The frame a workflow's clicks were made on (frozen by the panel) is named in what it writes."""

from __future__ import annotations

import numpy as np

from app.workflows import CalibrateCamera, UpdatePose
from app.workflows.base import FrameRef

from .test_update_pose import _moved, _operator_clicks, _visible_edges


def test_calibration_and_pose_update_name_the_frozen_frame(site, scene, db):
    frame = FrameRef(np.zeros((256, 512, 3), np.uint8), 16.25, 162, "scrubbed")
    cam = site.camera
    wf = CalibrateCamera(site, client="alice", snap=False)
    wf.use_frame(frame)
    table = site.object("table")
    X = np.vstack([table.vertices_world()[np.argsort(table.vertices_world()[:, 2])[-4:]]])
    for name, k in [("table", int(k)) for k in np.argsort(table.vertices_world()[:, 2])[-4:]] + [
        ("parallelepiped", k) for k in range(8)
    ]:
        wf.choose_vertex(name, k)
        wf.click(cam.project(site.object(name).vertices_world()[k]) + [0.2, -0.1])
    wf.solve()
    wf.accept()
    assert db.calibrations("camera")[-1].data["frame"] == {"t_s": 16.25, "index": 162, "source": "scrubbed"}
    assert len(X) == 4

    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 5.0, 0.01, 0.0)
    up = UpdatePose(site, client="alice", object_name="parallelepiped", snap=False)
    up.use_frame(frame)
    _operator_clicks(up, site, T_true, _visible_edges(site, obj.model, T_true)[:5], np.random.default_rng(0))
    up.refine()
    up.accept()
    assert db.history("parallelepiped")[-1].clicks["frame"] == {"t_s": 16.25, "index": 162, "source": "scrubbed"}
