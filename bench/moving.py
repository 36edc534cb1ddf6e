"""Was the object moving in the frozen frame? The old test (changed pixels inside it) against the new one (its
corners' motion against the view's, ``app.vision.change.object_motion_px``).

Run: .venv/bin/python bench/moving.py

Setup: the workcell's video as ``Site.frame_at`` reads it (scenes/workcell), the parallelepiped's bounding box
at each time projected through the scene's camera (what the one-click search's "was moving" looks at), each
frame against the one 0.3 s before it (``MOTION_GAP_S``):

* the box in transit (12.6, 13.4, 14.5 s) and standing still (16 s);
* the still frame at 16 s against itself turned about the image's centre or its bottom centre and zoomed (a
  continuously moving sequence: a hand-held, turning or zooming camera), where the box does not move against
  what is around it;
* the unknown box, standing still while the parallelepiped passes beside it (13.4 s).

Printed per case: the old test's changed share inside the box and its verdict (the share above
``CHANGED_SHARE``, and fewer than half of the ring 2× farther out changed), the new motion (px) and its verdict
(above ``MOVING_PX``), and the truth.
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def main() -> int:
    import cv2

    from app.db import Database, seed_from_scene
    from app.scene import default_scene_path, load_scene
    from app.vision.change import CHANGED_SHARE, MOVING_PX, changed_share, inside, object_motion_px
    from app.workflows import Site

    scene = load_scene(default_scene_path())
    with tempfile.TemporaryDirectory() as tmp:
        db = Database.open(Path(tmp) / "site.sqlite")
        seed_from_scene(db, scene)
        site = Site(scene, db, clock=lambda: 0.0)
        cam = site.camera

        def outline(name: str, t: float) -> np.ndarray:
            body = scene.body(name)
            lo, hi = body.model.bounds()
            B = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
            T = body.pose_at(t)
            return cam.project(B @ T[:3, :3].T + T[:3, 3])

        def old_verdict(a, b, uv) -> tuple[float, bool]:
            share = changed_share(a, b, inside(uv), follow_camera=True)
            if share <= CHANGED_SHARE:
                return share, False
            c = uv.mean(axis=0)
            ring = c + 2.0 * (uv - c)
            ring = ring[
                (ring[:, 0] > 8) & (ring[:, 1] > 8) & (ring[:, 0] < cam.width - 9) & (ring[:, 1] < cam.height - 9)
            ]
            around = [changed_share(a, b, p[None], follow_camera=True) for p in ring]
            return share, not (around and sum(x > CHANGED_SHARE for x in around) > len(around) / 2)

        cases = []
        for t in (12.6, 13.4, 14.5, 16.0):
            cases.append(
                (f"box at {t} s", site.frame_at(t - 0.3), site.frame_at(t), outline("parallelepiped", t), t < 15)
            )
        still = site.frame_at(16.0)
        h, w = still.shape[:2]
        box = outline("parallelepiped", 16.0)
        for where, centre in (("centre", (w / 2, h / 2)), ("bottom", (w / 2, h))):
            for angle, scale in ((1.2, 1.0), (3.0, 1.0), (0.0, 1.02), (1.5, 1.02)):
                turned = cv2.warpAffine(still, cv2.getRotationMatrix2D(centre, angle, scale), (w, h))
                cases.append((f"view {angle}° ×{scale} ({where})", turned, still, box, False))
        cases.append(
            ("unknown box, 13.4 s", site.frame_at(13.1), site.frame_at(13.4), outline("unknown_box", 13.4), False)
        )
        print(f"{'case':<28} {'old share':>9} {'old says':>9} {'motion px':>9} {'new says':>9} {'truth':>7}")
        for name, a, b, uv, truth in cases:
            share, old = old_verdict(a, b, uv)
            motion = object_motion_px(a, b, uv)
            new = motion is not None and motion > MOVING_PX
            shown = "—" if motion is None else f"{motion:.2f}"
            word = {True: "moving", False: "still"}
            print(f"{name:<28} {share:>9.2f} {word[old]:>9} {shown:>9} {word[new]:>9} {word[truth]:>7}")
        db.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
