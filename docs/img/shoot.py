"""Take the screenshots of docs/interface.md and the README: each workflow in a real headless
browser, a 1280×720 window (the smallest the panel is laid out for).

Run from the project root: ``.venv/bin/python docs/img/shoot.py`` (needs /usr/bin/chromium).
Clicks are snapped to the image (the interface's default); ``snap.png`` is zoomed onto the box.
The interface runs on the bundled scene at t = 16 s of its motion (the known box has moved),
with a fresh database and emulated devices. The operator's clicks are computed from the scene's
truth (as the recorded operator script does), sent through the same workflow calls the browser's
clicks make, and the browser shows the result. Images are reduced to 256 colours to stay small.
"""

from __future__ import annotations

import dataclasses
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

import tests.e2e.harness as harness  # noqa: E402
from tests.e2e.harness import FRAME_T_S, Interface, launch  # noqa: E402

OUT = ROOT / "docs" / "img"
harness.VIEWPORT = {"width": 1280, "height": 720}


def save(ui, page, name: str) -> None:
    from PIL import Image

    time.sleep(1.2)
    path = OUT / f"{name}.png"
    page.screenshot(path=str(path))
    img = Image.open(path).convert("RGB")
    img.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(path, optimize=True)
    print(f"{path.relative_to(ROOT)}: {path.stat().st_size // 1024} KiB")


def pose_edges(site, obj, T_true) -> list[int]:
    """Edges visible at both poses, a well-posed P3L triple first (three directions, no common vertex)."""
    import itertools

    def visible(T):
        wf = obj.model.wireframe(site.camera.center, T)
        return {int(k) for k, v, kind in zip(wf.edge_index, wf.visible, wf.kind) if v and kind == "edge"}

    vis = sorted(visible(T_true) & visible(obj.T_world_obj))
    V, E = obj.model.vertices, obj.model.edges
    axis = {k: int(np.abs(V[E[k][1]] - V[E[k][0]]).argmax()) for k in vis}
    triple = next(
        t
        for t in itertools.combinations(vis, 3)
        if len({axis[k] for k in t}) == 3 and not set(E[t[0]]) & set(E[t[1]]) & set(E[t[2]])
    )
    return list(triple) + [k for k in vis if k not in triple][:2]


def click(page, name: str) -> None:
    """Press the visible button whose label starts with ``name`` ("Solve" for "Solve (R)"); an
    Accept that asks once more (a weak result) is pressed again."""
    import re

    button = page.get_by_role("button", name=re.compile("^" + re.escape(name))).first
    try:
        button.wait_for(state="visible", timeout=10000)
    except Exception:
        wf = page.panel.session.workflow
        print("no button", name, "|", wf and wf.next_step, "|", page.panel.error, "|", wf and wf.message)
        raise
    button.click()
    time.sleep(0.6)
    if name == "Accept" and page.get_by_role("button", name="Accept anyway").first.is_visible():
        page.get_by_role("button", name="Accept anyway").first.click()
        time.sleep(0.4)
    if name == "Cancel" and page.get_by_role("button", name=re.compile("^Cancel: confirm")).first.is_visible():
        page.get_by_role("button", name=re.compile("^Cancel: confirm")).first.click()  # clicks made: asked once more
        time.sleep(0.4)


def main() -> int:
    from playwright.sync_api import sync_playwright

    from app.devices import open_devices
    from app.render.renderer import render_frame
    from app.scene import default_scene_path, load_scene

    scene = load_scene(default_scene_path())
    fast = dataclasses.replace(scene, turret=dataclasses.replace(scene.turret, speed_steps_s=1e5))
    devices = open_devices(
        fast,
        clock=lambda: FRAME_T_S,
        site_options=dict(
            rangefinder_baud=0, turret_baud=0, measure_delay_s=0.002, delay_per_m_s=0.0, no_target_delay_s=0.0
        ),
    )
    frame = render_frame(scene, FRAME_T_S)
    frame = np.repeat(frame[:, :, None], 3, axis=2) if frame.ndim == 2 else frame
    ui = Interface(scene, frame, Path(tempfile.mkdtemp(prefix="mcit-shots-")) / "site.sqlite", devices=devices)
    site, cam = ui.site, ui.site.camera
    rng = np.random.default_rng(0)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = ui.open(browser)
            panel = page.panel
            save(ui, page, "overview")

            # Calibrate camera: table corners (two planes: its top and its front face) and the box's
            # corners where the video shows them.
            click(page, "Calibrate camera")
            wf = panel.session.workflow
            table = site.object("table")
            Vt = table.vertices_world()
            front = [k for k in range(len(Vt)) if Vt[k, 1] < table.T_world_obj[1, 3]]
            for k in sorted(set(front) | set(np.argsort(Vt[:, 2])[-4:])):
                wf.choose_vertex("table", int(k))
                wf.click(cam.project(Vt[k]) + rng.normal(0, 0.7, 2))
            wf.solve()
            panel.dirty = True
            ui.server.wake()
            save(ui, page, "calibrate_camera")
            click(page, "Cancel")

            # Update pose with automatic matching: four edges clicked (snapped to the image, the raw
            # clicks dashed beside them), no model edge said; Auto match shows the best assignment.
            box = site.object("parallelepiped")
            T_true = scene.body("parallelepiped").pose_at(FRAME_T_S)
            drawn = cam.project(box.model.edge_segments(box.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
            true = cam.project(box.model.edge_segments(T_true).reshape(-1, 3)).reshape(-1, 2, 2)
            ui.click_pixel(page, drawn[1].mean(axis=0))
            click(page, "Update pose")
            wf = panel.session.workflow
            click(page, "Auto match")  # fewer than 3 edges: automatic assignment on
            for k in pose_edges(site, box, T_true)[:4]:
                a, b = true[k]
                ui.click_pixel(page, a + 0.3 * (b - a) + rng.normal(0, 2.0, 2))
                ui.click_pixel(page, a + 0.7 * (b - a) + rng.normal(0, 2.0, 2))
            lo, hi = true.reshape(-1, 2).min(axis=0) - 12, true.reshape(-1, 2).max(axis=0) + 12
            panel.zoom_rect = (*lo, *hi)
            panel.need_fit = True
            ui.server.wake()
            save(ui, page, "snap")
            click(page, "Auto match")
            deadline = time.monotonic() + 20
            while wf.matches is None and time.monotonic() < deadline:
                time.sleep(0.2)
            save(ui, page, "update_pose_auto_match")
            click(page, "Fit view")
            click(page, "Cancel")

            # Update pose from one double click on the moved box where the frame shows it: Find, the
            # pose found shown as a ghost with its fit and σ, ready to Accept.
            click(page, "Update pose")
            wf = panel.session.workflow
            on_box = cam.project_obj(T_true, box.model.vertices).mean(axis=0)
            x, y = ui.screen_of(page, on_box)
            page.locator("canvas").nth(1).dblclick(position={"x": x, "y": y})
            deadline = time.monotonic() + 30
            while getattr(wf, "found", None) is None and time.monotonic() < deadline:
                time.sleep(0.2)
            save(ui, page, "update_pose_one_click")
            click(page, "Cancel")

            # Update pose by hand: click edges, say which model edge each is, solve, refine.
            old = wf
            click(page, "Update pose")
            deadline = time.monotonic() + 10
            while panel.session.workflow is old and time.monotonic() < deadline:
                time.sleep(0.1)
            wf = panel.session.workflow
            for i, k in enumerate(pose_edges(site, box, T_true)):
                a, b = true[k]
                ui.click_pixel(page, a + 0.25 * (b - a) + rng.normal(0, 0.7, 2))
                ui.click_pixel(page, a + 0.75 * (b - a) + rng.normal(0, 0.7, 2))
                deadline = time.monotonic() + 10  # the clicks are handled in order, on the panel's worker
                while len(wf.segs) <= i and time.monotonic() < deadline:
                    time.sleep(0.05)
                wf.assign_edge(k)
            panel.dirty = True  # calls into the workflow (not the panel's) do not mark the panel for a redraw
            ui.server.wake()
            click(page, "Solve")
            save(ui, page, "update_pose_candidates")
            best = min(range(len(wf.candidates)), key=lambda i: np.linalg.norm(wf.candidates[i][:3, 3] - T_true[:3, 3]))
            wf.choose_candidate(best)
            panel.dirty = True
            click(page, "Refine")
            save(ui, page, "update_pose_refined")
            click(page, "Accept")

            # Track the box from its (now true) database pose: the tracked pose, the edge points found.
            click(page, "Track")
            deadline = time.monotonic() + 10
            while panel.session.workflow.frames < 5 and time.monotonic() < deadline:
                time.sleep(0.1)
            panel.zoom_rect = (*(lo - 30), *(hi + 30))
            panel.need_fit = True
            ui.server.wake()
            save(ui, page, "track")
            click(page, "Accept")
            click(page, "Fit view")

            # Model object: the unknown box, three faces clicked and measured through the emulated devices.
            body = scene.body("unknown_box")
            Tb, model = body.pose_at(FRAME_T_S), body.model
            normals, cents = model.face_normals(), model.face_centroids()
            c_obj = (cam.center - Tb[:3, 3]) @ Tb[:3, :3]
            faces = [k for k in range(len(model.faces)) if normals[k] @ (c_obj - cents[k]) > 0]
            click(page, "Model object")
            wf = panel.session.workflow
            for i, k in enumerate(faces):
                f = model.faces[k]
                for a, b in zip(f, f[1:] + f[:1]):
                    uv = cam.project(model.vertices[[a, b]] @ Tb[:3, :3].T + Tb[:3, 3])
                    if np.linalg.norm(uv[1] - uv[0]) > 12:
                        wf.add_segment(
                            np.array([uv[0] + 0.2 * (uv[1] - uv[0]), uv[0] + 0.8 * (uv[1] - uv[0])])
                            + rng.normal(0, 0.7, (2, 2))
                        )
                wf.measure()
                if i < len(faces) - 1:
                    wf.next_face()
            panel.dirty = True
            ui.server.wake()
            click(page, "Solve")
            save(ui, page, "model_object")
            click(page, "Accept")

            # Designate a target on the box's top face.
            click(page, "Designate target")
            top = T_true[:3, :3] @ np.array([0.05, 0.02, 0.132]) + T_true[:3, 3]
            ui.click_pixel(page, cam.project(top))
            save(ui, page, "designate")
            click(page, "Done")

            click(page, "History")
            save(ui, page, "history")
            click(page, "Close")

            page.get_by_text("3D world").click()
            time.sleep(1.0)
            save(ui, page, "world3d")
            browser.close()
    finally:
        ui.close()
        devices.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
