"""Update pose from one click (issue 17): click once on the moved box, Find, Accept; the click on
nothing refused with nothing written; Remove last; clicked edges refine from the found pose."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import Session, WorkflowError
from app.workflows.pose_presentation import unseen_outline
from core.transforms import pose_error

from .test_update_pose import T_MOVED, _true_segments, _visible_edges

BOX = "parallelepiped"


def _start(site):
    session = Session(site, client="alice")
    session.select(BOX)
    return session.start("update_pose")


def _on_box(site, scene):
    T = scene.body(BOX).pose_at(T_MOVED)
    return site.camera.project_obj(T, scene.body(BOX).model.vertices).mean(axis=0) + [4.0, 2.0], T


def _found(site, scene):
    """Update pose at the moved frame, one click on the box and Find: (workflow, click, true pose)."""
    site.t["t"] = T_MOVED
    wf = _start(site)
    uv, T_true = _on_box(site, scene)
    wf.click(uv)
    wf.find()
    return wf, uv, T_true


def test_one_click_find_accept_writes_the_true_pose_with_the_click(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    assert wf.next_step.startswith(f"Double-click {BOX} where it is now")
    uv, T_true = _on_box(site, scene)
    version = db.get(BOX).version
    wf.click(uv)
    st = wf.current_step()
    assert st.name == "click_edge_end" and "find" in st.enabled and wf.next_step.startswith("Find the pose")
    found = wf.find()
    st = wf.current_step()
    assert st.name == "found" and {"accept", "remove_last", "cancel"} <= st.enabled and wf.pending is None
    assert len(wf.marks().ghosts) == len(found) and wf.marks().circles.shape == (1, 2)
    deg, m = pose_error(found[0].T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005, (deg, m)
    assert wf.weaknesses() == []  # σ well under the thresholds
    assert wf.summary()["found"]["candidates"] == len(found)
    wf.accept()
    rec = db.get(BOX)
    assert rec.version == version + 1
    deg, m = pose_error(rec.T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005
    last = db.history(BOX)[-1]
    assert last.method == "search" and last.client == "alice"
    assert np.allclose(last.clicks["click_uv"], uv) and last.clicks["mode"] == "table"
    assert last.clicks["frame"] is None or "t_s" in last.clicks["frame"]


def test_a_click_on_the_table_finds_nothing_and_writes_nothing(video_site, scene, db):
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    n = len(db.history(BOX))
    wf.click(site.camera.project(np.array([[0.3, -0.3, 0.0]]))[0])
    with pytest.raises(
        WorkflowError,
        match=f"no pose of the {BOX} fits the image near your click.*or update it by "
        "clicking its edges. Nothing was written, and the click was dropped",
    ):
        wf.find()
    # the click that found nothing is dropped: the next click (or double click) starts afresh
    assert wf.current_step().name == "click_edge" and wf.found is None and wf.pending is None
    assert len(db.history(BOX)) == n
    wf.click([10.0, 10.0])
    with pytest.raises(WorkflowError, match="Find uses one click"):
        wf.find([20.0, 20.0])  # a click under way already


def test_remove_last_drops_the_found_poses_and_edges_refine_from_the_found_pose(video_site, scene, db):
    site = video_site
    wf, uv, T_true = _found(site, scene)
    wf.remove_last()  # the found poses go, and their click: back to the start
    assert wf.found is None and wf.current_step().name == "click_edge" and wf.pending is None
    wf.click(uv)
    wf.find()
    T_found = wf.candidates[0]
    obj = wf.obj
    edges = [
        k
        for k in _visible_edges(site, obj.model, T_true)
        if np.linalg.norm(np.diff(site.camera.project(obj.model.edge_segments(T_true)[k]), axis=0)) > 20
    ][:3]
    for seg, k in zip(_true_segments(site, obj.model, T_true, edges, np.random.default_rng(2), 0.5), edges):
        wf.click(seg[0])
        wf.click(seg[1])
        # which model edge: its drawing at the found pose (the estimate the overlay assigns on)
        wf.click(site.camera.project(obj.model.edge_segments(T_found)[k]).mean(axis=0))
    assert wf.edge_ids == edges
    r = wf.refine()
    assert pose_error(r.T_world_obj, T_true)[0] < 1.0
    wf.accept()
    last = db.history(BOX)[-1]
    assert last.method == "search+refine" and last.clicks["search"]["mode"] == "table"


def test_one_clicked_edge_refines_together_with_the_found_pose(video_site, scene, db):
    """A found pose 2° off in heading with a σ to match (as a partly hidden box can be found): one
    clicked edge, Refine (enabled from one edge, where clicks alone need three), and the pose comes back
    toward the truth, on the table, with a σ smaller than the found one's."""
    import dataclasses

    from core.pose.residuals import perturb

    site = video_site
    wf, _, T_true = _found(site, scene)
    c = wf.found[0]
    off = perturb(c.T_world_obj, np.r_[0.0, 0.0, 0.0, 0.0, 0.0, np.radians(2.0)])
    scale = (2.0 / float(np.max(c.std_r_deg))) ** 2  # the found pose's σ: 2° in heading
    c = dataclasses.replace(
        c,
        T_world_obj=off,
        cov=c.cov * scale,
        std_t_mm=c.std_t_mm * np.sqrt(scale),
        std_r_deg=c.std_r_deg * np.sqrt(scale),
    )
    wf.found[0] = c
    wf.candidates[0] = off
    obj = wf.obj
    k = max(
        _visible_edges(site, obj.model, T_true),
        key=lambda e: np.linalg.norm(np.diff(site.camera.project(obj.model.edge_segments(T_true)[e]), axis=0)),
    )
    seg = _true_segments(site, obj.model, T_true, [k], np.random.default_rng(3), 0.5)[0]
    wf.click(seg[0])
    wf.click(seg[1])
    assert "refine" not in wf.current_step().enabled  # not yet assigned
    wf.click(site.camera.project(obj.model.edge_segments(off)[k]).mean(axis=0))
    st = wf.current_step()
    assert wf.edge_ids == [k] and "refine" in st.enabled and "found pose" in wf.next_step
    r = wf.refine()
    before, after = pose_error(off, T_true)[0], pose_error(r.T_world_obj, T_true)[0]
    assert after < 0.5 * before, (before, after)
    assert abs(r.T_world_obj[2, 3] - off[2, 3]) < 1e-3  # still on the table
    assert np.max(r.std_r_deg) < 0.5 * np.max(c.std_r_deg)
    assert "refined with 1 edge:" in wf.message
    wf.accept()
    last = db.history(BOX)[-1]
    assert last.method == "search+refine" and last.clicks["edge_ids"] == [k]


def test_a_refine_after_find_keeps_the_camera_calibration_share_of_the_sigma(video_site, scene, db, monkeypatch):
    """With the camera calibrated in the database, its share of the found pose's σ is an error common
    to the found pose and the clicks (both seen through C): clicked edges refined together with the
    found pose do not average it away. The refined covariance is the combination of the image's
    shares plus the camera's, at least the camera's along every direction."""
    site = video_site
    C = site.camera.C
    d = np.random.default_rng(0).normal(size=12) * 2e-3 * np.abs(C).ravel()
    monkeypatch.setattr(type(site), "camera_cov", lambda self, view=None: np.outer(d, d))
    wf, _, T_true = _found(site, scene)
    c = wf.found[0]
    share = c.cov_camera
    assert share is not None and np.all(
        np.linalg.eigvalsh(c.cov - share) > -1e-12
    )  # the image's share stays a covariance
    obj = wf.obj
    rng = np.random.default_rng(4)
    for k in sorted(_visible_edges(site, obj.model, T_true))[:3]:
        seg = _true_segments(site, obj.model, T_true, [k], rng, 0.5)[0]
        wf.click(seg[0])
        wf.click(seg[1])
        wf.click(site.camera.project(obj.model.edge_segments(c.T_world_obj)[k]).mean(axis=0))
    r = wf.refine()
    assert set(r.cov_parts) == {"found pose and clicks", "camera calibration"}
    assert np.allclose(r.cov, r.cov_parts["found pose and clicks"] + share)
    w, U = np.linalg.eigh(share)
    u = U[:, -1]  # the camera's strongest direction: the refined variance along it is at least the share's
    assert u @ r.cov @ u >= w[-1] * (1 - 1e-9)


def test_a_cylinder_is_updated_from_one_double_click(video_site, scene, db):
    """An object with no straight edges (a modelled cylinder whose database pose is 8 cm off): Update
    pose offers only the one-click path — a double click where the video shows it, Accept — and the
    written axis is within 5 mm of the truth; a second click replaces the first rather than starting an
    edge."""
    from core.transforms import make_T

    site = video_site
    site.t["t"] = T_MOVED
    body = scene.body("unknown_cylinder")
    T_true = body.pose_at(T_MOVED)
    db.add_object(
        "cylinder_1",
        "cylinder",
        body.model,
        make_T(T_true[:3, :3], T_true[:3, 3] + [0.08, 0.0, 0.0]),
        status="modelled",
    )
    session = Session(site, client="alice")
    session.select("cylinder_1")
    wf = session.start("update_pose")
    assert wf.search_only and "no straight edges to click" in wf.next_step
    assert wf.current_step().enabled == {"cancel"}
    on = site.camera.project_obj(T_true, np.array([[0.0, 0.0, 0.09]]))[0]
    wf.click(on + [30.0, 0.0])
    wf.click(on)  # replaces the first click: no edge to start
    assert wf.segs == [] and np.allclose(wf.pending, on) and "find" in wf.current_step().enabled
    found = wf.find()
    assert {"accept"} <= wf.current_step().enabled and "start_point" not in wf.current_step().enabled
    wf.accept()
    rec = db.get("cylinder_1")
    axis_deg = np.degrees(np.arccos(np.clip(rec.T_world_obj[:3, 2] @ T_true[:3, 2], -1, 1)))
    assert axis_deg < 1.0 and np.linalg.norm(rec.T_world_obj[:3, 3] - T_true[:3, 3]) < 0.005, (
        axis_deg,
        rec.T_world_obj[:3, 3],
    )
    assert db.history("cylinder_1")[-1].method == "search" and len(found) >= 1


def test_a_pose_found_while_the_object_was_moving_is_said(video_site, scene, db):
    """The frozen frame caught the box in transit (13.4 s, 26 mm per 0.3 s): the pose found is where it
    passed. The frame shown 0.3 s before differs there, so the operator is told and Accept asks once
    more; at 16 s, where it stands still, nothing is said."""
    from app.workflows.base import FrameRef

    site = video_site
    box = scene.body(BOX)
    for t, moving in ((13.4, True), (T_MOVED, False)):
        site.t["t"] = t
        wf = _start(site)
        wf.use_frame(FrameRef(site.frame_at(t), t, previous=site.frame_at(t - 0.3)))
        T = box.pose_at(t)
        wf.click(site.camera.project_obj(T, box.model.vertices).mean(axis=0) + [4.0, 2.0])
        wf.find()
        said = [w for w in wf.weaknesses() if "was moving in this frame" in w]
        assert bool(said) == moving and ("was moving" in wf.message) == moving, (t, wf.message)
        wf.cancel()
    # the view itself moving (a hand-held camera: the frame 0.3 s before is the whole image 7 px off), the box
    # still: nothing is said (on the hand-held ViSP cube every frame was "moving", every Accept asked twice)
    import cv2

    site.t["t"] = T_MOVED
    image = site.frame_at(T_MOVED)
    before = cv2.warpAffine(
        image, np.float32([[1, 0, 6], [0, 1, -4]]), image.shape[1::-1], borderMode=cv2.BORDER_REFLECT
    )
    wf = _start(site)
    wf.use_frame(FrameRef(image, T_MOVED, previous=before))
    from app.vision.change import changed_share

    corners = site.camera.project_obj(box.pose_at(T_MOVED), box.model.vertices)
    assert changed_share(before, image, corners) > 0.08  # compared as they are, the box's pixels differ
    assert wf.moving_share(corners) < 0.08  # with the view's shift taken off, they do not
    wf.click(site.camera.project_obj(box.pose_at(T_MOVED), box.model.vertices).mean(axis=0) + [4.0, 2.0])
    wf.find()
    assert "was moving" not in wf.message and not any("was moving" in w for w in wf.weaknesses()), wf.message
    wf.cancel()


def test_a_refined_pose_whose_outline_misses_the_image_is_said(video_site, scene, db):
    """Clicks can fit a wrong pose exactly (edges assigned as in a mirror: a new operator got RMS
    0.45 px with the box drawn 40 px off). Refine then reads the frame: when little of the refined
    pose's outline lies on the image's edges it says so, and Accept asks once more. The true pose
    passes; the same pose 5 cm higher does not."""
    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    T_true = scene.body(BOX).pose_at(T_MOVED)
    assert unseen_outline(wf.snapper.frame(), site.camera, wf.obj.model, T_true) == ""
    high = T_true.copy()
    high[2, 3] += 0.05
    said = unseen_outline(wf.snapper.frame(), site.camera, wf.obj.model, high)
    assert "of the refined pose's outline lies on the image's edges" in said and "mirror" in said
    # through Refine: clicks of the true edges, assigned as they are: nothing said
    obj = wf.obj
    rng = np.random.default_rng(5)
    for k in sorted(_visible_edges(site, obj.model, T_true))[:4]:
        seg = _true_segments(site, obj.model, T_true, [k], rng, 0.3)[0]
        wf.add_segment(seg, k)
    wf.solve()
    wf.refine()
    assert wf.refined_unseen == "" and not any("outline" in w for w in wf.weaknesses())
    wf.refined_unseen = said  # as a wrong assignment leaves it: a weakness, so Accept asks once more
    assert said in wf.weaknesses()


def test_a_box_clicked_on_the_cylinder_is_said_not_to_single_out_a_pose(video_site, scene, db):
    """The box's model double-clicked on the cylinder: its two vertical edges lie on the cylinder's outline and
    several poses fit about as well (bench/search.py's wrong clicks: not refused). Accept asks once more, saying
    the click may not be on the box."""
    site = video_site
    site.t["t"] = 16.5
    box = scene.body("unknown_box")
    db.add_object("box_1", "box", box.model, box.pose_at(0.0), status="modelled", method="test")
    site.poll()
    session = Session(site, client="alice")
    session.select("box_1")
    wf = session.start("update_pose")
    cyl = scene.body("unknown_cylinder")
    wf.click(site.camera.project_obj(cyl.pose_at(16.5), np.array([[0.0, 0.0, 0.05]]))[0])
    try:
        wf.find()
    except WorkflowError:
        pytest.fail("the search now refuses this click outright: assert that refusal here instead")
    assert wf.search.near_ties() >= 4
    assert any("does not single out one pose of box_1" in w for w in wf.weaknesses())


def test_while_find_searches_the_step_says_so(video_site, scene, db, monkeypatch):
    """During the search the instruction says it is searching from the click (a new operator read the old
    "click a second point" prompt for 1-2 s and took the double click for a single click)."""
    import app.vision.search as ps  # imported by Find when it runs

    site = video_site
    site.t["t"] = T_MOVED
    wf = _start(site)
    uv, _ = _on_box(site, scene)
    wf.click(uv)
    seen = []
    real = ps.search_pose

    def watched(*args, progress=None, **kwargs):
        def spy(frac, what):
            progress(frac, what)
            seen.append((wf.current_step().name, wf.current_step().prompt, wf.current_step().clicks))

        return real(*args, progress=spy, **kwargs)

    monkeypatch.setattr(ps, "search_pose", watched)
    wf.find()
    assert seen and all(name == "searching" and not clicks for name, _, clicks in seen)
    assert "Searching for the pose of parallelepiped from your click" in seen[0][1]
    assert wf.current_step().name != "searching"


def test_a_double_click_after_the_found_poses_searches_again_from_it(video_site, scene, db):
    """Found poses, then a double click (its first click is an edge's first point by then): the found
    poses and that point go, the double click's point waits for Find, and Find finds the pose again (a new
    operator's second double click was split into two edge points, the second refused, Accept gone).
    Once an edge is clicked after the search, a double click is refused, nothing changed."""
    wf, uv, T_true = _found(video_site, scene)
    again = uv + [-6.0, 3.0]
    wf.click(again)  # the double click's first click
    assert wf.pending is not None and wf.found is not None
    wf.search_again(again)
    st = wf.current_step()
    assert wf.found is None and np.allclose(wf.pending, again) and "find" in st.enabled and "accept" not in st.enabled
    found = wf.find()
    assert np.allclose(wf.search_click, again)
    deg, m = pose_error(found[0].T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005, (deg, m)
    # an edge clicked after the search: a double click does not throw it away
    model = wf.obj.model
    k = _visible_edges(video_site, model, T_true)[0]
    seg = _true_segments(video_site, model, T_true, [k], np.random.default_rng(3), 0.5)[0]
    wf.click(seg[0])
    wf.click(seg[1])
    assert len(wf.segs) == 1
    with pytest.raises(WorkflowError, match="only while no edge has been clicked since the search"):
        wf.search_again(again)
    assert len(wf.segs) == 1 and wf.found is not None


def test_a_pose_found_while_the_whole_view_turns_is_not_said_to_be_moving(video_site, scene, db):
    """A continuously moving sequence (the view turning 2° and zooming 2 % about the image's centre between the
    frame 0.3 s before and the frozen one), the box still in the scene: the pose found is not "moving" (every
    frame of such a sequence was, and every Accept asked twice)."""
    import cv2

    from app.workflows.base import FrameRef

    site = video_site
    site.t["t"] = T_MOVED
    image = site.frame_at(T_MOVED)
    h, w = image.shape[:2]
    before = cv2.warpAffine(image, cv2.getRotationMatrix2D((w / 2, h / 2), 2.0, 1.02), (w, h))
    box = scene.body(BOX)
    wf = _start(site)
    wf.use_frame(FrameRef(image, T_MOVED, previous=before))
    assert wf.moving_share(site.camera.project_obj(box.pose_at(T_MOVED), box.model.vertices)) > 0.08
    wf.click(site.camera.project_obj(box.pose_at(T_MOVED), box.model.vertices).mean(axis=0) + [4.0, 2.0])
    wf.find()
    assert "was moving" not in wf.message and not any("was moving" in w for w in wf.weaknesses()), wf.message
    wf.cancel()
