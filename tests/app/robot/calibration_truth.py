"""What the robot calibration tests know from the scene's truth: which edges of the robot an operator would
click (seen, long enough, and one clear step in the image: not two edges side by side), where the tool's tip
really is, and how far the robot drawn through a calibrated base lies from the rendered one."""

from __future__ import annotations

import numpy as np

from app.render.raycast import SceneCaster
from core.robot.calibration import features_at

__all__ = ["clickable_edges", "crisp", "drawn_error_px", "scene_points", "operator_segment"]


class _Body:
    def __init__(self, model):
        self.model = model


def crisp(image, a, b, min_step: float = 8.0, window_px: float = 5.0, other: float = 0.6, need: int = 4) -> bool:
    """True when the image shows one clear step edge along the pixels a → b, as an operator would see one to
    click: across it, at 4 of 5 points of its middle, the strongest grey-level gradient lies on the line
    (within 0.75 px, at least ``min_step`` a pixel) and none ``other`` as strong lies 2 to ``window_px`` px off."""
    import cv2

    img = np.asarray(image, np.float32)
    img = img.mean(axis=2) if img.ndim == 3 else img
    a, b = np.asarray(a, float), np.asarray(b, float)
    d = (b - a) / np.linalg.norm(b - a)
    n = np.array([-d[1], d[0]])
    offs = np.arange(-window_px, window_px + 0.01, 0.5)
    far = np.abs(offs) >= 2.0
    good = 0
    for s in np.linspace(0.2, 0.8, 5):
        pts = (a + s * (b - a) + offs[:, None] * n).astype(np.float32)
        prof = cv2.remap(img, pts[:, :1], pts[:, 1:], cv2.INTER_LINEAR)[:, 0]
        g = np.abs(np.gradient(prof, 0.5))
        k = int(np.argmax(g))
        good += bool(abs(offs[k]) <= 0.75 and g[k] >= min_step and not np.any(g[far] > other * g[k]))
    return good >= need


def clickable_edges(scene, model, q, config, camera, image, T_world_base, t_s=0.0, min_px=25.0, bodies=None):
    """The robot's features at q an operator would click in ``image`` (the camera's view of the truth): a list
    of (RobotFeature, a (2,), b (2,)) — the longest stretch of each visible feature that no body or other link
    hides, inside the image, at least ``min_px`` long, and ``crisp`` there (any, for ``image`` None).
    ``bodies``: the scene's bodies' (model, pose) at t_s, default every scene body."""
    links = model.link_breps(q, T_world_base)
    if bodies is None:
        bodies = [(b.model, b.pose_at(t_s)) for b in scene.bodies]
    caster = SceneCaster([_Body(m) for m, _ in bodies] + [_Body(b) for _, b, _ in links],
                         [T for _, T in bodies] + [T for _, _, T in links])  # fmt: skip
    out = []
    for f, seg, visible in features_at(model, q, T_world_base, camera.center, config):
        if not visible or np.any(camera.depth(seg) <= 0):
            continue
        s = np.linspace(0.03, 0.97, 30)
        X = seg[0] + s[:, None] * (seg[1] - seg[0])
        p = camera.project(X)
        inside = (p[:, 0] > 4) & (p[:, 0] < camera.width - 5) & (p[:, 1] > 4) & (p[:, 1] < camera.height - 5)
        ok = inside & ~caster.occluded(camera.center, X, body=len(bodies) + f.shape, tol_m=1e-4)
        best, run, start = 0, 0, 0
        for i, o in enumerate(ok):
            run = run + 1 if o else 0
            if run > best:
                best, start = run, i - run + 1
        if best < 4:
            continue
        a, b = p[start], p[start + best - 1]
        if np.linalg.norm(b - a) >= min_px and (image is None or crisp(image, a, b)):
            out.append((f, a, b))
    return out


def operator_segment(a, b, rng, sigma_px: float = 0.7) -> np.ndarray:
    """Two clicks along the edge a → b as an operator makes them: at a quarter and three quarters, each off
    the edge by a normal error of ``sigma_px``."""
    d = np.asarray(b, float) - np.asarray(a, float)
    n = np.array([-d[1], d[0]]) / np.linalg.norm(d)
    return np.array([a + 0.25 * d, a + 0.75 * d]) + rng.normal(0.0, sigma_px, 2)[:, None] * n


def _seg_distance(P, seg):
    a, b = seg
    d = b - a
    t = np.clip((P - a) @ d / max(float(d @ d), 1e-12), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - P, axis=1)


def drawn_error_px(model, qs, camera, T_true, T_drawn) -> float:
    """The largest distance (pixels) between the robot drawn through ``T_drawn`` and the rendered one (through
    ``T_true``), over every visible edge and silhouette at the configurations qs (k, n): each feature's drawn
    segment sampled against the true one and back."""
    worst = 0.0
    s = np.linspace(0.0, 1.0, 11)[:, None]
    for k, q in enumerate(qs):
        true = {f: seg for f, seg, v in features_at(model, q, T_true, camera.center, k) if v}
        drawn = {f: seg for f, seg, v in features_at(model, q, T_drawn, camera.center, k) if v}
        for f in true.keys() & drawn.keys():
            if np.any(camera.depth(true[f]) <= 0) or np.any(camera.depth(drawn[f]) <= 0):
                continue
            A, B = camera.project(true[f]), camera.project(drawn[f])
            worst = max(worst, _seg_distance(A[0] + s * (A[1] - A[0]), B).max())
            worst = max(worst, _seg_distance(B[0] + s * (B[1] - B[0]), A).max())
    return float(worst)


def scene_points(scene, t_s: float = 0.0) -> np.ndarray:
    """The corners of the scene's table and boxes (known and unknown) at t_s (N, 3): where a camera's
    calibration is judged."""
    boxes = [b for b in scene.bodies if b.kind in ("table", "box")]
    return np.vstack([b.model.vertices @ b.pose_at(t_s)[:3, :3].T + b.pose_at(t_s)[:3, 3] for b in boxes])
