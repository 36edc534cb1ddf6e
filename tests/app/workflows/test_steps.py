"""The state walk: every workflow, driven through its states, declares a step whose instruction
names only controls that exist and are enabled there (issue 13: "an instruction can never name a
control that does not exist"), whose enabled controls all exist, and whose shortcuts do not clash.

The browser half (the page shows each named control, enabled) is ``assert_prompt_controls`` in the
browser tests (tests/e2e/harness.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import (
    WORKFLOWS,
    CalibrateCamera,
    CalibrateTurret,
    DesignateTarget,
    History,
    ModelObject,
    TrackObject,
    UpdatePose,
    WorkflowError,
)
from app.workflows.base import CANCEL, Control, Step

from .test_model_object import _click_face, _facing_faces
from .test_update_pose import _moved, _operator_clicks, _visible_edges


class Walk:
    """Checks each state a workflow passes through and remembers which were seen."""

    def __init__(self):
        self.seen: dict[str, set[str]] = {}

    def check(self, wf) -> Step:
        st = wf.current_step()  # asserts: enabled ⊆ controls, named ⊆ enabled
        actions = {c.action for c in wf.controls}
        assert st.enabled <= actions
        assert set(st.named()) <= st.enabled
        text = wf.prompt_text(markdown=False)
        assert "{" not in text and "}" not in text, f"{wf.name}/{st.name}: unrendered placeholder in {text!r}"
        assert text.strip(), f"{wf.name}/{st.name}: no instruction"
        for a in st.enabled:  # an enabled action is a real method the panel can call
            c = wf.control(a)
            if c.kind != "choice" or a in wf.actions:
                assert a in wf.actions, f"{wf.name}/{st.name}: control {a!r} calls no workflow action"
            if c.arg is not None:
                assert c.arg in st.enabled, f"{wf.name}/{st.name}: {c.label} needs its chooser {c.arg!r} enabled"
            if c.kind == "choice":
                assert wf.choices(a), f"{wf.name}/{st.name}: the chooser {c.label!r} is shown with no options"
        keys = [wf.control(a).key for a in st.enabled if wf.control(a).key]
        assert len(keys) == len(set(keys)), f"{wf.name}/{st.name}: two enabled controls share a key: {keys}"
        self.seen.setdefault(wf.name, set()).add(st.name)
        return st


@pytest.fixture
def walk():
    return Walk()


def test_controls_are_declared_once_with_keys_that_do_not_move_the_camera():
    for name, cls in WORKFLOWS.items():
        actions = [c.action for c in cls.controls]
        assert len(actions) == len(set(actions)), f"{name}: a control is declared twice"
        for c in cls.controls:
            assert isinstance(c, Control) and c.label
            if c.kind != "choice":
                assert c.action in cls.actions, f"{name}: control {c.label!r} calls no action"
            if c.arg is not None:
                assert cls.controls[[x.action for x in cls.controls].index(c.arg)].kind == "choice"
    with pytest.raises(ValueError, match="moves the viewer's camera"):
        Control("solve", "Solve", "W")
    with pytest.raises(ValueError, match="kind"):
        Control("solve", "Solve", kind="slider")
    assert CANCEL.button_label == "Cancel (Esc)"


def test_a_prompt_naming_a_disabled_control_is_caught(site):
    class Broken(DesignateTarget):
        def _step(self):
            return Step("broken", "Press {clear} now.", frozenset({"accept"}))

    wf = Broken(site)
    with pytest.raises(AssertionError, match="names"):
        wf.current_step()


def test_calibrate_camera_states(site, scene, walk):
    wf = CalibrateCamera(site, client="alice", snap=False)
    walk.check(wf)
    cam = site.camera
    table, box = site.object("table"), site.object("parallelepiped")
    wfv = box.model.wireframe(cam.center, box.T_world_obj)
    E = np.asarray(box.model.edges)
    vis = sorted(
        {int(v) for k, v_, kind in zip(wfv.edge_index, wfv.visible, wfv.kind) if v_ and kind == "edge" for v in E[k]}
    )
    top = np.argsort(table.vertices_world()[:, 2])[-4:]
    X = np.vstack([box.vertices_world()[vis], table.vertices_world()[top]])
    with pytest.raises(WorkflowError, match="no click to remove"):
        wf.remove_last()
    for _i, x in enumerate(X):
        wf.click(cam.project(x))
        walk.check(wf)
        wf.click(cam.project(x) + [0.3, -0.2])
        walk.check(wf)
    assert walk.check(wf).name == "pick_model" and "solve" in walk.check(wf).enabled
    wf.solve()
    assert walk.check(wf).name == "review"
    wf.remove_pair(0)
    walk.check(wf)
    wf.solve()
    walk.check(wf)
    wf.redo()
    walk.check(wf)
    wf.cancel()
    walk.check(wf)
    assert {"pick_model", "click_image", "review", "cancelled"} <= walk.seen["calibrate_camera"]


def test_calibrate_camera_states_with_the_lens_known(scene, tmp_path, walk):
    """Served with a lens file (mcit serve --intrinsics): the Solve by chooser, PnP from 4 points, DLT from 6."""
    from app.db import Database, seed_from_scene
    from app.ui.serve import scene_with_intrinsics
    from app.vision.intrinsics_cli import Calibration, write_camera_file
    from app.workflows import Site

    cam = scene.camera
    write_camera_file(
        Calibration(cam.decompose()[0], np.zeros(5), 0.1, cam.width, cam.height, (0,), 1, "plumb_bob"),
        tmp_path / "cam.yml",
    )
    sc = scene_with_intrinsics(scene, tmp_path / "cam.yml")
    db = Database.open(tmp_path / "lens.sqlite")
    seed_from_scene(db, sc)
    site = Site(sc, db, clock=lambda: 0.0, frames=None)
    wf = CalibrateCamera(site, client="alice", snap=False)
    assert "set_method" in walk.check(wf).named()
    V = np.vstack([site.object("parallelepiped").vertices_world(), site.object("table").vertices_world()])
    V = V[(cam.depth(V) > 0) & cam.in_image(cam.project(V), 2.0)]
    for x in V[:4]:
        wf.choose_point(x, "corner")
        walk.check(wf)
        wf.click(cam.project(x[None])[0] + [0.3, -0.2])
        walk.check(wf)
    assert "solve" in walk.check(wf).enabled
    wf.solve()
    assert walk.check(wf).name == "review" and "PnP" in wf.next_step
    wf.set_method("dlt")
    st = walk.check(wf)
    assert st.name == "pick_model" and "solve" not in st.enabled
    for x in V[4:6]:
        wf.choose_point(x, "corner")
        wf.click(cam.project(x[None])[0])
    wf.solve()
    assert walk.check(wf).name == "review" and "DLT" in wf.next_step
    wf.set_method("pnp")
    walk.check(wf)
    wf.remove_pair(0)
    walk.check(wf)
    wf.solve()
    walk.check(wf)
    wf.accept()
    walk.check(wf)
    db.close()
    assert {"pick_model", "click_image", "review", "accepted"} <= walk.seen["calibrate_camera"]


def test_update_pose_states_by_hand_and_by_auto_match(site, walk):
    obj = site.object("parallelepiped")
    T_true = _moved(obj.T_world_obj, 20.0, -0.05, 0.03)
    edges = _visible_edges(site, obj.model, T_true)
    rng = np.random.default_rng(3)
    wf = UpdatePose(site, client="alice", object_name="parallelepiped", snap=False)
    walk.check(wf)
    for k in edges[:3]:
        E = obj.model.vertices[obj.model.edges[k]]
        P = E @ T_true[:3, :3].T + T_true[:3, 3]
        uv = site.camera.project(P)
        wf.click(uv[0] + 0.3 * (uv[1] - uv[0]))
        walk.check(wf)
        wf.click(uv[0] + 0.7 * (uv[1] - uv[0]))
        walk.check(wf)
        wf.click(site.camera.project(obj.model.edge_segments(wf.T_current)[k]).mean(axis=0))
        walk.check(wf)
    wf.solve()
    assert walk.check(wf).name == "candidates"
    _operator_clicks(wf, site, T_true, edges[3:5], rng)
    walk.check(wf)
    wf.refine()
    st = walk.check(wf)
    assert st.name == "review" and "accept" in st.enabled
    wf.remove_click(0)
    walk.check(wf)
    wf.start_point()
    walk.check(wf)
    wf.remove_last()
    walk.check(wf)
    wf.accept()
    walk.check(wf)
    # automatic assignment, pressed once the first edge is clicked (as the instruction before the clicks says)
    wf2 = UpdatePose(site, client="bob", object_name="parallelepiped", snap=False)
    for k in edges[:1]:
        uv = site.camera.project(obj.model.vertices[obj.model.edges[k]] @ T_true[:3, :3].T + T_true[:3, 3])
        wf2.click(uv[0] + 0.25 * (uv[1] - uv[0]))
        wf2.click(uv[0] + 0.75 * (uv[1] - uv[0]))
    st = walk.check(wf2)
    assert st.name == "assign_edge" and "auto_match" in st.enabled
    wf2.auto_match()  # fewer than 3 edges: switches to automatic assignment, the edge clicked kept
    st = walk.check(wf2)
    assert st.name == "auto_click" and "edge 2" in st.prompt and len(wf2.segs) == 1
    wf2.remove_last()
    walk.check(wf2)
    for k in edges[:4]:
        uv = site.camera.project(obj.model.vertices[obj.model.edges[k]] @ T_true[:3, :3].T + T_true[:3, 3])
        wf2.click(uv[0] + 0.25 * (uv[1] - uv[0]))
        wf2.click(uv[0] + 0.75 * (uv[1] - uv[0]))
        walk.check(wf2)
    wf2.auto_match()  # four exact edges: the assignments that fit are shown
    assert walk.check(wf2).name == "match"
    wf2.confirm_match()
    walk.check(wf2)
    wf2.refine()
    assert walk.check(wf2).name == "review"
    wf2.cancel()
    walk.check(wf2)
    assert {
        "click_edge",
        "click_edge_end",
        "assign_edge",
        "candidates",
        "review",
        "refine_again",
        "click_point_model",
        "auto_click",
        "auto_ready",
        "match",
        "accepted",
        "cancelled",
    } <= walk.seen["update_pose"]


def test_model_object_states_box_and_cylinder(device_site, fast_scene, walk):
    site = device_site
    body = fast_scene.body("unknown_box")
    T = body.pose_at(0.0)
    wf = ModelObject(site, client="alice", shape="box", snap=False)
    walk.check(wf)
    rng = np.random.default_rng(0)
    faces = _facing_faces(site.camera, body.model, T)
    for k in faces[:2]:
        _click_face(wf, site.camera, body.model, T, k, rng)
        walk.check(wf)
        wf.measure()
        assert walk.check(wf).name == "face_measured"
    wf.scan()
    assert walk.check(wf).name == "scanned"
    wf.solve()
    assert walk.check(wf).name == "review"
    wf.cancel()
    walk.check(wf)
    cyl = fast_scene.body("unknown_cylinder")
    wf = ModelObject(site, client="alice", shape="cylinder", snap=False)
    walk.check(wf)
    lo, hi = cyl.model.bounds()
    Tc = cyl.pose_at(0.0)
    c, r = Tc[:3, 3], (hi[0] - lo[0]) / 2
    right = np.cross(site.camera.center - c, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    for side in (-1, 1):
        bottom = c + side * r * right + [0, 0, lo[2] + 0.02]
        top = c + side * r * right + [0, 0, hi[2] - 0.02]
        wf.click(site.camera.project(bottom))
        walk.check(wf)
        wf.click(site.camera.project(top))
        walk.check(wf)
    wf.scan()
    assert walk.check(wf).name == "solve"
    wf.set_method("tangential")
    walk.check(wf)
    wf.solve()
    assert walk.check(wf).name == "review"
    assert {
        "click_sides",
        "sides_clicked",
        "face_measured",
        "scanned",
        "review",
        "click_silhouettes",
        "scan",
        "solve",
        "click_end",
        "cancelled",
    } <= walk.seen["model_object"]


def test_calibrate_turret_designate_history_track_states(device_site, site, walk):
    wf = CalibrateTurret(device_site, client="alice")
    walk.check(wf)
    table = device_site.object("table")
    centre = table.vertices_world().mean(axis=0)
    centre[2] = table.vertices_world()[:, 2].max()
    wf.choose_point(centre, "table centre")
    assert walk.check(wf).name == "measure"
    wf.measure()
    walk.check(wf)
    wf.remove_measurement(0)
    walk.check(wf)
    wf.cancel()
    walk.check(wf)
    d = DesignateTarget(site, client="alice")
    walk.check(d)
    d.click(site.camera.project(centre))
    assert walk.check(d).name == "targets"
    d.accept()
    walk.check(d)
    site.set_status("table", "stale", client="alice")
    h = History(site, client="alice")
    assert walk.check(h).name == "browse"
    t = TrackObject(site, client="alice", object_name="parallelepiped")
    walk.check(t)
    t.pause()
    assert walk.check(t).name == "paused"
    t.resume()
    walk.check(t)
    t.cancel()
    walk.check(t)


def test_update_pose_one_click_states(video_site, scene, walk):
    """Update pose's one-click path (issue 17): the first click offers Find; found poses offer Accept
    (and the chooser when several fit); Remove last goes back to the click; Accept ends it."""
    from .test_update_pose import T_MOVED

    site = video_site
    site.t["t"] = T_MOVED
    wf = UpdatePose(site, client="alice", object_name="parallelepiped", snap=False)
    assert "find" not in walk.check(wf).enabled  # no click yet: nothing to find from
    T = scene.body("parallelepiped").pose_at(T_MOVED)
    wf.click(site.camera.project_obj(T, wf.obj.model.vertices).mean(axis=0))
    st = walk.check(wf)
    assert st.name == "click_edge_end" and "find" in st.named()
    wf.find()
    st = walk.check(wf)
    assert st.name == "found" and "accept" in st.named() and ("choose_candidate" in st.enabled) == (len(wf.found) > 1)
    wf.remove_last()  # the found poses and their click go
    assert walk.check(wf).name == "click_edge" and wf.pending is None
    wf.find(site.camera.project_obj(T, wf.obj.model.vertices).mean(axis=0))  # a double click
    wf.accept()
    assert walk.check(wf).name == "accepted"
    assert {"click_edge", "click_edge_end", "found", "accepted"} <= walk.seen["update_pose"]
