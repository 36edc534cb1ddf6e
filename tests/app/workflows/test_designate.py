"""Designate a target: the clicked pixel's ray meets the database's surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import DesignateTarget, WorkflowError


def test_click_on_the_box_top_gives_the_point_on_its_face(site):
    box = site.object("parallelepiped")
    X_true = box.T_world_obj[:3, :3] @ np.array([0.05, -0.03, 0.132]) + box.T_world_obj[:3, 3]
    wf = DesignateTarget(site)
    t = wf.click(site.camera.project(X_true))
    assert t.object == "parallelepiped"
    assert np.allclose(t.X_world, X_true, atol=1e-6)
    assert np.allclose(t.normal, box.T_world_obj[:3, 2], atol=1e-9)  # the top face's normal
    assert t.range_m == pytest.approx(np.linalg.norm(X_true - site.camera.center))
    assert t.text() == " ".join(f"{v:.4f}" for v in X_true)
    assert wf.marks().targets.shape == (1, 2)


def test_table_then_nothing(site):
    wf = DesignateTarget(site)
    table = site.object("table")
    lo, hi = table.model.bounds()
    X = table.T_world_obj[:3, :3] @ np.array([0.8 * lo[0], 0.8 * hi[1], hi[2]]) + table.T_world_obj[:3, 3]  # a far corner
    assert wf.click(site.camera.project(X)).object == "table"
    assert np.allclose(wf.targets[-1].X_world, X, atol=1e-6)
    with pytest.raises(WorkflowError, match="sees no object"):
        wf.click([256.0, 0.0])  # above the table's far edge
    assert len(wf.targets) == 1
    wf.accept()
    assert wf.finished
