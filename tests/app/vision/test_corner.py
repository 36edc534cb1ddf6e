"""app.vision.corner: clicked corners refined to the image, on rendered frames with known corners."""

import numpy as np
import pytest

from app.vision.corner import snap_corner, snap_corner_edges, snap_corner_subpix
from app.vision.synthetic import render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import make_T, rot_x, rot_z

K = np.array([[500.0, 0.0, 159.5], [0.0, 500.0, 119.5], [0.0, 0.0, 1.0]])


@pytest.fixture(scope="module")
def rendered():
    """A box seen from above and aside (three faces), its frame, and each visible corner's edges."""
    cam = Camera.from_intrinsics(K, np.eye(4), 320, 240)
    box = BRep.box(0.2, 0.13, 0.08)
    T = make_T(rot_x(np.radians(-120)) @ rot_z(np.radians(35)), [0.0, 0.04, 1.1])
    frame = render_poses(cam, box, [T], noise_sigma=2.0, blur_sigma_px=0.5, seed=3)[0]
    wf = box.wireframe(cam.center, T)
    visible = {int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"}
    corners = []
    for v in range(len(box.vertices)):
        ends = [int(j if i == v else i) for k, (i, j) in enumerate(box.edges.tolist()) if k in visible and v in (i, j)]
        if len(ends) >= 2:
            uv = cam.project_obj(T, box.vertices[[v] + ends])
            corners.append((uv[0], uv[1:] - uv[0]))
    assert len(corners) >= 6
    return frame, corners


def test_edges_intersection_is_sub_pixel_and_beats_the_clicks(rendered):
    frame, corners = rendered
    rng = np.random.default_rng(0)
    raw, snapped = [], []
    for truth, D in corners:
        for _ in range(5):
            click = truth + rng.normal(0, 1.0, 2)
            res = snap_corner_edges(frame, click, D, np.linalg.norm(D, axis=1))
            assert res.ok, res.reason
            assert res.method == "edges" and len(res.lines_uv) >= 2 and np.isfinite(res.sigma_px)
            assert res.moved_px == pytest.approx(np.linalg.norm(res.uv - click))
            raw.append(np.linalg.norm(click - truth))
            snapped.append(np.linalg.norm(res.uv - truth))
    assert np.median(snapped) < 0.1 and max(snapped) < 0.2
    assert np.mean(snapped) < np.mean(raw) / 5


def test_subpix_finds_corners_less_precisely_and_snap_corner_falls_back_on_it(rendered):
    frame, corners = rendered
    rng = np.random.default_rng(1)
    errs = []
    for truth, _ in corners:
        click = truth + rng.normal(0, 1.0, 2)
        res = snap_corner_subpix(frame, click)
        if res.ok:
            errs.append(np.linalg.norm(res.uv - truth))
        both = snap_corner(frame, click)  # no edge directions: cornerSubPix answers
        assert both.method == "subpix"
    assert len(errs) >= len(corners) - 1 and np.median(errs) < 0.4
    truth, D = corners[0]
    assert snap_corner(frame, truth + 0.5, D).method == "edges"


def test_no_corner_is_refused_and_the_click_kept(rendered):
    frame, corners = rendered
    flat = np.full_like(frame, 90)
    truth, D = corners[0]
    for res in (snap_corner_edges(flat, truth, D), snap_corner_subpix(flat, truth), snap_corner(flat, truth, D)):
        assert not res.ok and res.reason and np.array_equal(res.uv, truth) and res.moved_px == 0.0
    # two directions a few degrees apart fix no point
    res = snap_corner_edges(frame, truth, np.array([D[0], D[0] + [0.0, 0.02 * np.linalg.norm(D[0])]]))
    assert not res.ok and ("parallel" in res.reason or "found" in res.reason)
    near_border = snap_corner_subpix(frame, [1.0, 1.0])
    assert not near_border.ok and "border" in near_border.reason


def test_bad_input_raises():
    img = np.zeros((50, 60), np.uint8)
    with pytest.raises(ValueError, match="finite pixel"):
        snap_corner_subpix(img, [np.nan, 3.0])
    with pytest.raises(ValueError, match="non-zero"):
        snap_corner_edges(img, [20.0, 20.0], [[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(ValueError, match="lengths_px"):
        snap_corner_edges(img, [20.0, 20.0], [[0.0, 1.0], [1.0, 0.0]], [10.0])


def test_the_fit_at_the_snapped_corner_is_small_on_a_true_corner_and_large_off_one(rendered):
    """``fit_px``: how well the image fits a corner where it was snapped (the snap gates judge it, not how far
    the click moved): the edges' RMS about their lines on a true corner well under 0.5 px; cornerSubPix's
    gradient-line distance smaller at the corner than at a point on an edge beside it."""
    frame, corners = rendered
    rng = np.random.default_rng(1)
    for truth, D in corners:
        res = snap_corner_edges(frame, truth + rng.normal(0, 1.5, 2), D, np.linalg.norm(D, axis=1))
        assert res.ok and 0.0 < res.fit_px < 0.5, res.fit_px
    truth, D = corners[0]
    sub = snap_corner_subpix(frame, truth + [0.8, -0.6])
    assert sub.ok and np.isfinite(sub.fit_px)
    refused = snap_corner_subpix(frame, np.array([5.0, 5.0]))  # the background: no corner, no fit
    assert not refused.ok and np.isnan(refused.fit_px)
