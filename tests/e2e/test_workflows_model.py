"""Model object in a real browser, with the emulated range finder and turret on their serial protocols:
the paper's box (Table III.1: two faces' sides clicked, each face measured, two profiles scanned) and
cylinder (Table III.2: two silhouettes, two profiles, a fitting method chosen) completed by visible
controls, shortcut keys and canvas clicks alone; the database's new object checked against the
scene's truth.

Measured on this project's 2-core machine (``pytest -s`` prints them; one action is one canvas click,
one button or one key, a dropdown choice counting two clicks: open, pick; seconds from Model object to
the object in the database, the emulated devices answering at once, load average 6–13 from the
other engineers' runs):

* box, 2 faces (4 sides each) measured + 2 profiles, Solve, Accept: 22 actions (16 canvas clicks,
  6 controls/keys), 6.1–11.4 s; no weakness asked; |error| of the sides 0.39 / 0.17 mm and
  the height 0.17 mm (σ 0.63 / 0.74 / 1.63 mm), pose 0.09°, centre 0.3 mm
* cylinder, Shape chosen, 2 silhouettes, 2 profiles, tangential planes solved, fused solved, Accept:
  15 actions (4 canvas clicks, 11 controls/keys; 11 without the tangential detour), 3.5–5.6 s;
  radius −0.2 mm (σ 0.6), height −0.7 mm (σ 1.9), axis 0.3 mm off
"""

from __future__ import annotations

import re
import time

import numpy as np
import pytest

from core.transforms import pose_error
from tests.app.workflows.test_snapping import line_distance  # distances of points to an edge's line

from .harness import assert_prompt_controls, click_control, close_notifications, press, wait_until

pytestmark = pytest.mark.e2e


class Operator:
    """The operator's hands on one page: every action counted, the time from the first one."""

    def __init__(self, ui, page):
        self.ui, self.page = ui, page
        self.clicks = 0  # on the video
        self.controls = 0  # buttons, keys, dropdown opens and picks
        self.t0 = time.monotonic()
        self.steps: list[str] = []
        self.error_before = ""  # the panel's error line before the last action (a new one is this action's)

    @property
    def wf(self):
        return self.page.panel.session.workflow

    def check(self) -> None:
        """The instruction's controls are on the page (the browser half of the state walk)."""
        wf = self.wf
        if wf is not None and not wf.finished:
            self.steps.append(f"{wf.current_step().name}@{time.monotonic() - self.t0:.1f}")
        assert_prompt_controls(self.page)

    def click(self, uv) -> None:
        self.error_before = self.page.panel.error
        self.ui.click_pixel(self.page, uv)
        self.clicks += 1

    def press(self, label: str) -> None:
        self.error_before = self.page.panel.error
        press(self.page, label)
        self.controls += 1

    def key(self, key: str) -> None:
        self.error_before = self.page.panel.error
        self.page.keyboard.press(key)
        self.controls += 1

    def choose(self, dropdown: str, option: str) -> None:
        """Open the dropdown labelled ``dropdown`` and pick ``option`` (two clicks)."""
        click_control(self.page.get_by_role("combobox", name=dropdown))
        click_control(self.page.get_by_role("option", name=option, exact=True))
        self.controls += 2

    def wait(self, result, what: str, timeout_s: float = 30.0, seen: set | None = None) -> None:
        """Wait until ``result()`` (or an error in the panel), no measurement runs, and the page shows
        the new step; ``seen`` collects the progress texts the panel showed meanwhile."""
        panel = self.page.panel

        def failed() -> bool:
            return bool(panel.error) and panel.error != self.error_before

        def done() -> bool:
            wf = self.wf
            if seen is not None and "Measuring" in panel.gui_title.content:
                seen.add(panel.gui_title.content.split("Measuring… ")[-1].split(".")[0])
            busy = (panel.worker is not None and panel.worker.is_alive()) or getattr(wf, "progress", None) is not None
            return (bool(result()) or failed()) and not busy

        wait_until(done, timeout_s, what)
        assert not failed(), f"{what}: {panel.error}"
        time.sleep(0.1)  # the redraw loop sends the new step's controls

    def summary(self, name: str, t_start: float) -> str:
        return (
            f"{name}: {self.clicks + self.controls} operator actions ({self.clicks} canvas clicks, {self.controls} "
            f"controls/keys), {time.monotonic() - t_start:.1f} s; steps {' → '.join(self.steps)}"
        )


def _project(cam, X):
    return cam.project(np.atleast_2d(X)).reshape(-1, 2)


def _facing_faces(cam, model, T):
    normals, cents = model.face_normals(), model.face_centroids()
    c_obj = (cam.center - T[:3, 3]) @ T[:3, :3]
    return [k for k in range(len(model.faces)) if normals[k] @ (c_obj - cents[k]) > 0]


def _face_sides_uv(cam, model, T, k, min_px: float = 12.0):
    """The sides of face k as the video shows them (projected through the scene's camera), long ones."""
    f = list(model.faces[k])
    out = []
    for a, b in zip(f, f[1:] + f[:1]):
        uv = _project(cam, model.vertices[[a, b]] @ T[:3, :3].T + T[:3, 3])
        if np.linalg.norm(uv[1] - uv[0]) >= min_px:
            out.append(uv)
    return out


def _rz(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    R = np.eye(4)
    R[:2, :2] = [[c, -s], [s, c]]
    return R


def _box_against_truth(rec, body, T_true):
    """(dimension errors (3,) m, their σ (3,), rotation error °, centre error m) of the database's box
    against the truth, modulo the box's symmetry (its x/y axes may come out turned by 90°)."""
    got = np.array([rec.dims[k] for k in ("size_x", "size_y", "size_z")])
    sig = np.array([rec.sigmas[k] for k in ("size_x", "size_y", "size_z")])
    lo, hi = body.model.bounds()
    truth = hi - lo
    best = None
    for k in range(4):  # the box's frame turned about its vertical axis: the same box
        T = rec.T_world_obj @ _rz(90.0 * k)
        deg = pose_error(T, T_true)[0]
        if best is None or deg < best[0]:
            perm = [1, 0, 2] if k % 2 else [0, 1, 2]
            best = (deg, got[perm], sig[perm])
    deg, got_p, sig_p = best
    lo_e, hi_e = rec.model.bounds()
    centre = rec.T_world_obj[:3, :3] @ ((lo_e + hi_e) / 2) + rec.T_world_obj[:3, 3]
    centre_true = T_true[:3, :3] @ ((lo + hi) / 2) + T_true[:3, 3]
    return got_p - truth, sig_p, deg, float(np.linalg.norm(centre - centre_true))


def _start_model_object(op, shape: str) -> float:
    """Start → Shape → Model object; the time of the Model object press."""
    page = op.page
    if page.get_by_role("combobox", name="Shape").input_value() != shape:
        op.choose("Shape", shape)
    t = time.monotonic()
    op.press("Model object")
    wait_until(
        lambda: (
            op.wf is not None and op.wf.name == "model_object" and op.page.panel.workflow_controls.built_for is op.wf
        ),
        what="the Model object workflow",
    )
    assert op.wf.shape == shape
    op.check()
    return t


def _accept(op, what: str) -> list[str]:
    """Accept, and Accept anyway when the result is weak; the weaknesses stated (none: [])."""
    wf = op.wf
    weak = wf.weaknesses()
    op.press("Accept")
    if weak:
        op.page.get_by_role("button", name="Accept anyway").wait_for(state="visible", timeout=60_000)
        op.page.get_by_text("Weak result", exact=False).first.wait_for(timeout=60_000)
        assert not wf.accepted  # asked once more: nothing written yet
        op.press("Accept anyway")
    wait_until(lambda: wf.accepted, 10.0, what)
    return weak


def test_model_a_box_by_clicking_two_faces_and_scanning(browser, device_interface, scene):
    ui = device_interface
    page = ui.open(browser)
    cam = ui.site.camera
    body = scene.body("unknown_box")
    T_true = body.pose_at(ui.frame_t_s)
    assert body.name not in {o.name for o in ui.db.objects()}  # unknown to the database
    n_objects = len(ui.db.objects())
    op = Operator(ui, page)
    close_notifications(page)
    t_start = _start_model_object(op, "box")
    wf = op.wf
    # the two lit vertical faces (the top face alone would leave the box's turn open)
    faces = [
        k
        for k in _facing_faces(cam, body.model, T_true)
        if abs((T_true[:3, :3] @ body.model.face_normals()[k])[2]) < 0.5
    ]
    assert len(faces) == 2
    for i, k in enumerate(faces):
        sides = _face_sides_uv(cam, body.model, T_true, k)
        n = sum(len(f["segs"]) for f in wf.faces)
        for a, b in sides:  # the clicks are handled in the order they arrive
            op.click(a + 0.2 * (b - a))
            op.click(a + 0.8 * (b - a))
        wait_until(lambda: sum(len(f["segs"]) for f in wf.faces) == n + len(sides), what=f"face {i + 1}'s sides")
        assert len(wf.faces) == i + 1 and len(wf.faces[-1]["segs"]) == len(sides) >= 3, page.panel.error
        for j, (seg, side) in enumerate(zip(wf.faces[-1]["segs"], sides)):  # each click on its side (else the patch
            # spills onto another surface and the face's plane comes out tilted: a loaded run failed so once)
            off = line_distance(np.reshape(seg, (2, 2)), side)
            assert max(off) < 4.0, f"face {i + 1}'s side {j + 1} taken {np.round(off, 1)} px off its edge: {seg}"
        op.check()
        assert "Measure face" in wf.next_step
        if i == 0:
            op.key("m")  # Measure face by its shortcut (the focus is on the video)
        else:
            op.press("Measure face")
        op.wait(lambda: wf.faces[-1]["points"] is not None, f"face {i + 1} measured")
        assert wf.faces[-1]["points"] is not None and len(wf.faces[-1]["points"]) >= 10, page.panel.error
        op.check()
        if i == 0:  # the next face is reachable: the instruction says to click its sides
            assert (
                "another visible face" in wf.next_step
                and "solve" not in wf.current_step().enabled
                and wf.current_step().clicks
            )
    assert len(wf.box_faces()) == 2
    seen: set = set()
    op.press("Scan profile")
    op.wait(lambda: len(wf.scans) == 2, "the profiles", seen=seen)
    assert len(wf.scans) == 2 and all(s.hits.sum() >= 20 for s in wf.scans), page.panel.error
    op.check()
    # Measure face's shortcut now (both faces measured, its button hidden): refused, said, nothing written
    page.keyboard.press("m")
    page.get_by_text("Measure face does not apply now").first.wait_for(timeout=60_000)
    assert len(ui.db.objects()) == n_objects and len(wf.box_faces()) == 2 and wf.progress is None
    op.key("r")  # Solve
    op.wait(lambda: wf.result is not None, "the box")
    op.check()
    page.get_by_role("button", name=re.compile("^Accept")).wait_for(state="visible", timeout=60_000)
    assert len(ui.db.objects()) == n_objects  # nothing written before Accept
    weak = _accept(op, "the box written")
    rec = ui.db.get(wf.object_name)
    print("\n" + op.summary("box", t_start), "| weak:", weak or "none", "| progress seen:", sorted(seen))
    assert rec.kind == "box" and rec.status == "modelled"
    assert ui.db.history(rec.name)[-1].client.startswith("browser-")
    derr, sig, deg, dist = _box_against_truth(rec, body, T_true)
    print(
        f"box: |error| width/depth/height {np.abs(derr) * 1000} mm, σ {sig * 1000} mm; pose {deg:.2f}°, "
        f"centre {dist * 1000:.1f} mm"
    )
    assert np.all(np.abs(derr) <= 3 * sig) and np.all(np.abs(derr) < 0.004)
    assert deg < 2.0 and dist < 0.005


def test_model_a_cylinder_by_clicking_its_silhouettes(browser, device_interface, scene):
    ui = device_interface
    page = ui.open(browser, viewport={"width": 1280, "height": 720})  # the other viewport the docs quote
    cam = ui.site.camera
    body = scene.body("unknown_cylinder")
    T_true = body.pose_at(ui.frame_t_s)
    solid = body.model.solids[0]
    n_objects = len(ui.db.objects())
    op = Operator(ui, page)
    close_notifications(page)
    t_start = _start_model_object(op, "cylinder")
    wf = op.wf
    eye = (cam.center - T_true[:3, 3]) @ T_true[:3, :3]  # the camera in the cylinder's frame
    sil = [_project(cam, g @ T_true[:3, :3].T + T_true[:3, 3]) for g in solid.silhouette(eye)]
    sil = [s if s[0, 1] > s[1, 1] else s[::-1] for s in sil]  # bottom → top (v grows downwards)
    sil = sorted(sil, key=lambda s: s[:, 0].mean())  # left, then right
    for j, (bottom, top) in enumerate(sil):
        assert ("left" if j == 0 else "right") in wf.next_step
        op.click(bottom)  # its ends: the silhouette keeps its clicked height
        op.click(top)
        wait_until(lambda: len(wf.silhouettes) == j + 1, what=f"silhouette {j + 1}")
        op.check()
    seen: set = set()
    op.key("p")  # Scan profile by its shortcut (the focus is on the video)
    op.wait(lambda: len(wf.scans) == 2, "the profiles", seen=seen)
    assert len(wf.scans) == 2 and all(s.hits.sum() >= 10 for s in wf.scans), page.panel.error
    op.check()
    # the Method chooser: fused by default; the paper's tangential planes chosen, solved, then fused again
    method = page.get_by_role("combobox", name="Method")
    assert method.input_value() == "fused (all measurements)"
    op.choose("Method", "tangential planes (camera + range finder)")
    wait_until(lambda: wf.method == "tangential", what="the method chosen")
    op.press("Solve")
    op.wait(lambda: wf.result is not None, "the tangential fit")
    assert wf.result.method == "tangential"
    r_tangential = wf.result.dimensions["radius"]
    op.check()
    op.choose("Method", "fused (all measurements)")
    wait_until(lambda: wf.method == "fused" and wf.result is None, what="fused chosen")
    op.check()
    op.press("Solve")
    op.wait(lambda: wf.result is not None, "the fused fit")
    op.check()
    assert len(ui.db.objects()) == n_objects
    weak = _accept(op, "the cylinder written")
    rec = ui.db.get(wf.object_name)
    print("\n" + op.summary("cylinder", t_start), "| weak:", weak or "none", "| progress seen:", sorted(seen))
    assert rec.kind == "cylinder" and rec.status == "modelled" and "fused" in ui.db.history(rec.name)[-1].method
    dr, dh = rec.dims["radius"] - solid.r0, rec.dims["height"] - solid.height
    sr, sh = rec.sigmas["radius"], rec.sigmas["height"]
    axis = float(np.linalg.norm(rec.T_world_obj[:2, 3] - T_true[:2, 3]))
    print(
        f"cylinder: radius {rec.dims['radius'] * 100:.2f} cm (error {dr * 1000:.1f} mm, σ {sr * 1000:.1f} mm; "
        f"tangential {r_tangential * 100:.2f} cm), height {rec.dims['height'] * 100:.2f} cm "
        f"(error {dh * 1000:.1f} mm, σ {sh * 1000:.1f} mm), axis {axis * 1000:.1f} mm off"
    )
    assert abs(dr) <= 3 * sr and abs(dh) <= 3 * sh
    assert abs(dr) < 0.004 and abs(dh) < 0.01 and axis < 0.006
    # the cylinder just modelled is selected (Update pose, Track … apply to it next)
    wait_until(lambda: page.panel.session.selected == rec.name, what="the new cylinder selected")
