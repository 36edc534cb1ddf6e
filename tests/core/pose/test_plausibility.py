"""core.pose.plausibility: a fitted pose is refused for its RMS, an object behind the camera or off the image."""

from __future__ import annotations

import numpy as np

from core.brep import BRep
from core.pose import plausibility
from core.pose.synthetic import PAPER_BOX_M, paper_box_pose, paper_camera


def test_a_box_on_the_table_in_view_is_plausible_and_each_failure_is_named():
    cam = paper_camera()
    box = BRep.box(*PAPER_BOX_M)
    T = paper_box_pose(np.random.default_rng(0))
    assert plausibility(cam, box, T) == ""
    assert plausibility(cam, box, T, 0.5, 3.0) == ""
    assert plausibility(cam, box, T, 4.0, 3.0) == "RMS 4.0 px, more than the 3.0 px allowed"
    assert plausibility(cam, box, T, float("nan"), 3.0).startswith("RMS nan px")  # a NaN RMS is no fit
    behind = T.copy()
    behind[:3, 3] = cam.center - 2.0 * (T[:3, 3] - cam.center)  # mirrored through the optical centre
    assert plausibility(cam, box, behind) == "it puts the object behind the camera"
    straddling = T.copy()
    straddling[:3, 3] = cam.center + 0.01 * (T[:3, 3] - cam.center)  # around the centre: some vertices behind
    assert plausibility(cam, box, straddling) == "it puts the object behind the camera"
    aside = T.copy()
    aside[:3, 3] += [-40.0, 0.0, 0.0]  # in front of the camera, tens of metres to the side
    assert plausibility(cam, box, aside) == "it puts the object outside the image"


def test_a_model_without_vertices_is_checked_by_its_bounds():
    cam = paper_camera()
    cyl = BRep.cylinder(0.05, 0.2)
    T = paper_box_pose(np.random.default_rng(1))
    assert plausibility(cam, cyl, T) == ""
    aside = T.copy()
    aside[:3, 3] += [40.0, 0.0, 0.0]
    assert plausibility(cam, cyl, aside) == "it puts the object outside the image"
