"""The operator's traps (issue 27, item 5), each met again in a real browser by visible controls, keys and
canvas clicks alone: what the page says now where it misled a new operator before.

* Designate on a frame frozen long before: the target says the frame's age and that the scene may have
  changed since, not "range finder agrees" alone.
* Seconds back counts from the frame on screen, and says when it reaches past the frames kept.
* Calibrate turret: a click on the table 24 video px from a box corner is a point on the table, not the corner.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from app.video import StillSource

from .harness import Interface, click_control, press, wait_until, workflow_shown

pytestmark = pytest.mark.e2e

OLD_FRAME_S = 11.0  # older than the age past which a frozen frame is said to be old (10 s)
CLOCK_RATE = 10.0  # the fast camera's clock: seconds of its stamps per second


class FastClockStill(StillSource):
    """A still whose frames carry the stamps of a camera clock running CLOCK_RATE times faster than the wall's (a
    source's own stamps, as a ROS 2 image's header gives them): the frame age mcit says is taken from the frames'
    stamps, so a frame is OLD_FRAME_S old after OLD_FRAME_S / CLOCK_RATE seconds."""

    def __init__(self, image):
        super().__init__(image, fps=20)
        self._t0 = time.time()

    def _stamp(self) -> float:
        return self._t0 + CLOCK_RATE * (time.time() - self._t0)


def _table_point(site, fx: float = 0.25, fy: float = -0.3) -> np.ndarray:
    """A point of the table's top where nothing stands (in the database and in the truth)."""
    table = site.object("table")
    T = table.T_world_obj
    return T[:3, :3] @ np.array([fx, fy, float(table.model.vertices[:, 2].max())]) + T[:3, 3]


def _newest_after(panel, stamp: float) -> float:
    """How long after ``stamp`` (unix s) the newest frame of the page's video was taken."""
    newest = panel.feed.grabber.latest()
    return -1.0 if newest is None or newest.stamp is None else float(newest.stamp) - float(stamp)


@pytest.fixture
def fast_clock_interface(scene, frame, tmp_path):
    """The interface with devices that answer at once, on a still whose camera clock runs fast."""
    ui = Interface(scene, {scene.views[0].name: FastClockStill(frame)}, tmp_path / "site.sqlite", devices="fast")
    yield ui
    ui.close()


def test_designate_on_an_old_frozen_frame_says_its_age(browser, fast_clock_interface):
    ui = fast_clock_interface
    site = ui.site
    page = ui.open(browser)
    panel = page.panel
    press(page, "Designate target")
    wf = workflow_shown(page, "designate")
    wait_until(lambda: wf.frame is not None and wf.frame.stamp is not None, what="the frozen frame")
    # the live video runs on while the operator looks at the frozen frame (OLD_FRAME_S by the camera's clock)
    wait_until(
        lambda: _newest_after(panel, wf.frame.stamp) > OLD_FRAME_S,
        timeout_s=60,
        what=f"the live video {OLD_FRAME_S:.0f} s past the frozen frame",
    )
    ui.click_pixel(page, site.camera.project(_table_point(site)[None])[0])
    wait_until(lambda: len(wf.targets) == 1 and wf.progress is None, timeout_s=60, what="the target", panel=panel)
    t = wf.targets[0]
    assert t.object == "table" and t.rangefinder_X is not None
    page.get_by_text("the scene may have changed since", exact=False).first.wait_for(timeout=60_000)
    said = page.get_by_text("the scene may have changed since", exact=False).first.inner_text()
    age = float(said.split("this frame is ")[1].split(" s old")[0])
    assert OLD_FRAME_S <= age <= _newest_after(panel, wf.frame.stamp) + 1.0  # (said when the target was kept)
    assert not wf.message.startswith("The range finder agrees")  # no agreement with what the frame shows


def _seconds_back(page, value: str) -> None:
    """Type ``value`` in the Seconds back box and press Enter."""
    box = page.get_by_text("Seconds back", exact=True).first.locator("xpath=ancestor::div[2]").locator("input").last
    click_control(box)
    box.fill(value)
    page.keyboard.press("Enter")


def test_seconds_back_counts_from_the_frame_on_screen_and_says_when_clamped(browser, interface):
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    # the frames kept reach 1.5 s back from the newest (a page opened at once after the start froze a frame only 0.3 s
    # after the first: Seconds back 1 then took the oldest kept, rightly said to reach past the frames kept)
    wait_until(
        lambda: (hit := panel.feed.recent.back_from(time.monotonic(), 2.0)) is not None and hit[1] >= 1.5,
        timeout_s=60,
        what="1.5 s of the live video kept",
    )
    page.keyboard.press("f")  # Freeze the newest frame
    wait_until(lambda: panel.frozen is not None, what="the frozen frame", panel=panel)
    on_screen = panel.frozen
    # the live video runs on, 3 s past the frame on screen
    wait_until(lambda: _newest_after(panel, on_screen.stamp) > 3.0, timeout_s=60, what="the live video 3 s on")
    _seconds_back(page, "1")
    wait_until(lambda: panel.frozen is not on_screen, what="the frame 1 s back frozen", panel=panel)
    back = on_screen.stamp - panel.frozen.stamp
    assert 0.5 <= back <= 1.5, f"the frame frozen is {back:.1f} s before the one on screen, not 1 s"
    page.get_by_text("a frame that long before the frame on screen", exact=False).first.wait_for(timeout=60_000)
    # 12 s before it: the kept frames (12 s before the newest) do not reach so far, and the page says so
    one_back = panel.frozen
    _seconds_back(page, "12")
    wait_until(lambda: panel.frozen is not one_back, what="the oldest kept frame frozen", panel=panel)
    page.get_by_text("reaches past the frames kept", exact=False).first.wait_for(timeout=60_000)
    assert on_screen.stamp - panel.frozen.stamp < 12.0 - 0.5
    # a workflow's click made on this frame: another Seconds back is refused, and the box says the frame on screen
    press(page, "Calibrate camera")
    wf = workflow_shown(page, "calibrate_camera")
    kept = panel.frozen
    ui.click_pixel(page, ui.site.camera.project(ui.site.object("table").vertices_world()[:1])[0])
    wait_until(lambda: "remove_last" in wf.current_step().enabled, what="the click taken", panel=panel)
    box = page.get_by_text("Seconds back", exact=True).first.locator("xpath=ancestor::div[2]").locator("input").last
    _seconds_back(page, "3")
    wait_until(lambda: "Cancel before freezing another frame" in panel.error, what="the refusal", panel=panel)
    wait_until(lambda: box.input_value() == "12", what="the box back at 12 s, the frame on screen's")
    assert panel.frozen is kept


def test_calibrate_turret_a_click_on_the_table_near_a_box_corner_is_the_table(browser, device_interface):
    ui = device_interface
    site = ui.site
    cam = site.camera
    page = ui.open(browser)
    panel = page.panel
    scale = panel.viewport.image_px_per_screen_px()
    off_px = 24.0  # video pixels from the box's corner, as the operator's click
    assert off_px / scale > 20.0  # more than 20 screen pixels: not on the corner as the operator sees it
    known = []  # every corner and face centre the workflow may pick, projected
    for obj in site.objects():
        known += list(obj.vertices_world())
        if obj.model.faces:
            T = obj.T_world_obj
            known += list(obj.model.face_centroids() @ T[:3, :3].T + T[:3, 3])
    known_uv = cam.project(np.array(known))
    target = None
    for X in site.object("parallelepiped").vertices_world():
        c = cam.project(X[None])[0]
        for ang in np.linspace(0, 2 * np.pi, 24, endpoint=False):
            p = c + off_px * np.array([np.cos(ang), np.sin(ang)])
            origin, ray = cam.rays(p.reshape(1, 2))
            hit = site.raycast(origin, ray[0])
            nearest = np.linalg.norm(known_uv - p, axis=1).min()
            if hit is not None and hit.name == "table" and nearest > off_px - 0.5:  # the box's corner is the nearest
                target = p
                break
        if target is not None:
            break
    assert target is not None
    press(page, "Calibrate turret")
    wf = workflow_shown(page, "calibrate_turret")
    ui.click_pixel(page, target)
    wait_until(lambda: wf.pending_label, what="the picked point", panel=panel)
    assert wf.pending_label == "a point on table", wf.pending_label
    page.get_by_text("Target: a point on table", exact=False).first.wait_for(timeout=60_000)


def _refine_box(ui, page, scene, beside_px: float):
    """Update pose of the box by four edges clicked ``beside_px`` beside where the video shows them (away from
    the drawn edge), Solve (P), the candidate nearest the truth chosen, Refine: the workflow."""
    import itertools

    from core.transforms import pose_error

    from .harness import select_by_click

    panel, site = page.panel, ui.site
    cam = site.camera
    obj = site.object("parallelepiped")
    T_true = scene.body("parallelepiped").pose_at(ui.frame_t_s)
    drawn = cam.project(obj.model.edge_segments(obj.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
    true = cam.project(obj.model.edge_segments(T_true).reshape(-1, 3)).reshape(-1, 2, 2)

    def visible(T):
        w = obj.model.wireframe(cam.center, T)
        return [int(k) for k, v, kind in zip(w.edge_index, w.visible, w.kind) if v and kind == "edge"]

    shown = visible(obj.T_world_obj)
    k_sel = max(shown, key=lambda i: np.linalg.norm(drawn[i, 1] - drawn[i, 0]))
    select_by_click(page, "parallelepiped", lambda: ui.click_pixel(page, drawn[k_sel].mean(axis=0)))
    press(page, "Update pose")
    wf = workflow_shown(page, "update_pose")
    vis = [k for k in visible(T_true) if k in shown]
    V, E = obj.model.vertices, obj.model.edges
    axis = {k: int(np.abs(V[E[k][1]] - V[E[k][0]]).argmax()) for k in vis}
    triple = next(
        t
        for t in itertools.combinations(vis, 3)
        if len({axis[k] for k in t}) == 3 and not set(E[t[0]]) & set(E[t[1]]) & set(E[t[2]])
    )
    for k in list(triple) + [k for k in vis if k not in triple][:1]:
        a, b = true[k]
        n = np.array([-(b - a)[1], (b - a)[0]]) / np.linalg.norm(b - a)
        n = n if (a + b) @ n / 2 > (drawn[k].mean(axis=0) @ n) else -n  # beside it, away from the drawn edge
        ui.click_pixel(page, a + 0.3 * (b - a) + beside_px * n)
        ui.click_pixel(page, a + 0.7 * (b - a) + beside_px * n)
        ui.click_pixel(page, drawn[k].mean(axis=0))  # "this is model edge k", clicked on the overlay
        wait_until(lambda: len(wf.edge_ids) and wf.edge_ids[-1] == k, what=f"edge {k} assigned", panel=panel)
    page.keyboard.press("p")  # Solve (P)
    wait_until(lambda: len(wf.candidates) > 0, 300, "P3L candidates", panel=panel)  # first use: compiled
    best = min(range(len(wf.candidates)), key=lambda i: pose_error(wf.candidates[i], T_true)[0])
    if best != wf.chosen:
        click_control(page.get_by_label("Candidate", exact=True).first)
        click_control(page.get_by_role("option", name=next(t for t, v in wf.choices("choose_candidate") if v == best)))
        wait_until(lambda: wf.chosen == best, what="the candidate chosen", panel=panel)
    press(page, "Refine")
    wait_until(lambda: wf.refined is not None, 300, "the refinement", panel=panel)
    assert pose_error(wf.refined.T_world_obj, T_true)[1] < 0.01  # the clicks give the true pose
    return wf


def test_a_snap_that_moved_a_click_onto_the_true_edge_is_not_weak(browser, interface, scene):
    """Update pose by four edges clicked 2.5 px beside where the video shows them: each snap moves its click
    more than 2 px onto the edge, and Accept does not ask about the snaps (it asked "snap moved it 2.6 px")."""
    ui = interface
    page = ui.open(browser)
    panel = page.panel
    wf = _refine_box(ui, page, scene, beside_px=2.5)
    snaps = [sn for sn in wf.seg_snaps if sn is not None]
    assert len(snaps) == 4 and all(sn.applied for sn in snaps)
    assert max(sn.moved_px for sn in snaps) > 2.0  # the snaps moved the clicks more than the old gate's 2 px
    wait_until(lambda: "accept" in wf.current_step().enabled, what="Accept offered", panel=panel)
    press(page, "Accept")
    wait_until(lambda: wf.accepted or panel.asking == "accept", what="the accept or its question", panel=panel)
    asked = "" if wf.accepted else str(panel.warning)
    assert "snap" not in asked, asked
    assert page.get_by_text("snap moved", exact=False).count() == 0


def test_the_result_is_visible_at_1280x720_without_scrolling(browser, interface, scene):
    """After Refine at 1280×720 the pose's σ is on screen beside the buttons (the Result section, σ and
    residuals, was below the fold)."""
    ui = interface
    page = ui.open(browser, viewport={"width": 1280, "height": 720})
    _refine_box(ui, page, scene, beside_px=0.0)
    said = page.get_by_text("σ translation (mm)", exact=False)
    said.first.wait_for(state="attached", timeout=60_000)

    def on_screen() -> bool:
        for i in range(said.count()):
            box = said.nth(i).bounding_box()
            if box is not None and said.nth(i).is_visible() and 0 <= box["y"] and box["y"] + box["height"] <= 720:
                return True
        return False

    wait_until(on_screen, 30, "the σ on screen without scrolling", panel=page.panel)


SWEEP_S, TURN_DEG_S = 1.5, 4.0  # the turning view: 6° one way in 1.5 s, then back


def _turning_view(image):
    """A video of ``image`` turning continuously about its bottom centre (a continuously moving sequence: every
    frame differs from the one 0.3 s before by 1.2°), to and fro; ``angle(t)`` its angle (degrees) at monotonic
    time t."""
    import time

    import cv2

    from app.video import StillSource

    class Turning(StillSource):
        t0 = time.monotonic()

        @classmethod
        def angle(cls, t: float) -> float:
            phase = (t - cls.t0) % (2 * SWEEP_S)
            return TURN_DEG_S * (phase if phase < SWEEP_S else 2 * SWEEP_S - phase) - 3.0

        def _read(self):
            h, w = self._image.shape[:2]
            M = cv2.getRotationMatrix2D((w / 2, h), self.angle(time.monotonic()), 1.0)
            return cv2.warpAffine(self._image, M, (w, h), borderMode=cv2.BORDER_REFLECT)

    return Turning(image, fps=8)  # every frame kept by the scrubber (one every 0.1 s at most)


def test_a_pose_found_on_a_continuously_moving_video_is_not_said_to_be_moving(browser, scene, frame, tmp_path):
    """The whole view turns continuously (a moving sequence) while the box stands still: the pose a double click
    finds is not "moving", and Accept does not ask about it (every frame was "moving", every Accept asked twice)."""
    import time

    import cv2

    from .harness import Interface, select_by_click

    video = _turning_view(frame)
    ui = Interface(scene, video, tmp_path / "site.sqlite")
    try:
        page = ui.open(browser)
        panel, site, cam = page.panel, ui.site, ui.site.camera
        obj = site.object("parallelepiped")
        drawn = cam.project(obj.model.edge_segments(obj.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
        w = obj.model.wireframe(cam.center, obj.T_world_obj)
        k = next(int(k) for k, v, kind in zip(w.edge_index, w.visible, w.kind) if v and kind == "edge")
        select_by_click(page, "parallelepiped", lambda: ui.click_pixel(page, drawn[k].mean(axis=0)))
        body = scene.body("parallelepiped")
        centre = cam.project_obj(body.pose_at(ui.frame_t_s), body.model.vertices).mean(axis=0)
        # mid-sweep: the frame clicked on and the one 0.3 s before it differ by a turn of 1.2°
        wait_until(lambda: 0.5 < (time.monotonic() - video.t0) % SWEEP_S < 0.9, 10, "mid-sweep")
        M = cv2.getRotationMatrix2D((cam.width / 2, cam.height), video.angle(time.monotonic()), 1.0)
        ui.double_click_pixel(page, M[:, :2] @ centre + M[:, 2])  # where the video shows the box now
        wait_until(
            lambda: panel.session.workflow is not None and getattr(panel.session.workflow.search, "found", None),
            300,  # the search's first use compiles it
            "the pose found by the double click",
            panel=panel,
        )
        wf = panel.session.workflow
        wait_until(lambda: "your click" in wf.message, 60, "the search's message", panel=panel)
        assert "was moving" not in wf.message, wf.message
        page.get_by_text("your click (searched", exact=False).first.wait_for(timeout=60_000)
        wait_until(lambda: "accept" in wf.current_step().enabled, what="Accept offered", panel=panel)
        press(page, "Accept")
        wait_until(lambda: wf.accepted or panel.asking == "accept", what="the accept or its question", panel=panel)
        asked = "" if wf.accepted else str(panel.warning)
        assert "was moving" not in asked, asked
    finally:
        ui.close()
