"""Benchmark of mcit's renderer (app.render): speed, and where rendered edges lie.

Run: .venv/bin/python bench/render.py [--times 0 16 27]

Setup: the bundled workcell scene (512 × 256, f = 500 px; its render block: Lambert shading,
89 anti-aliasing samples per edge pixel, optical blur σ 0.5 px, sensor noise σ 2 grey levels).

1. Time per frame (CPU seconds of this process, one thread) at each scene time.
2. Edge position: for every true model edge of the table and the objects seen unoccluded, at
   least 25 px long, projected through C, the offset of the image's edge from that line (the
   gradient-weighted centroid across it, 9 places over its middle half, app.render.measure);
   per edge the mean of the 9, then the median and the largest |mean| over edges, for the
   noise-free image; the final frames (blur + noise, uint8) of one second of the still scene
   (12 frames, each its own noise); the same frames decoded from the committed video
   (Motion-JPEG .avi); and, for comparison, the same frames through OpenCV's mp4v at the bitrate
   OpenCV gives it. The cylinder's silhouettes separately: with the scene's Lambert
   shading and flat-shaded (geometry alone).
3. Area coverage: a box seen from straight above, flat-shaded, its edges at several angles:
   each edge pixel's grey level against its exact coverage (polygon clipping), as a share of
   the contrast.

Anchor: issue 9's edge snapping is asked to reach 0.3 px on rendered frames; the renderer's own
edges should sit well inside that.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from app.render import Renderer  # noqa: E402
from app.render.measure import edge_offsets, polygon_coverage, top_down_scene, visible_edges  # noqa: E402
from app.report.markdown import markdown_table  # noqa: E402
from app.scene import default_scene_path, load_scene, scene_from_dict  # noqa: E402

CLIP = 12  # frames (one second) of each still scene


def _decoded(path: str, first: int, n: int) -> list[np.ndarray]:
    import cv2

    cap = cv2.VideoCapture(path)
    out = []
    try:
        cap.set(cv2.CAP_PROP_POS_FRAMES, first)
        for _ in range(n):
            ok, f = cap.read()
            if not ok:
                break
            out.append(cv2.cvtColor(f, cv2.COLOR_BGR2GRAY).astype(float))
    finally:
        cap.release()
    return out


def _through_mp4v(frames: list[np.ndarray]) -> list[np.ndarray]:
    """Frames encoded by OpenCV's mp4v as one clip and decoded."""
    import tempfile

    import cv2

    with tempfile.TemporaryDirectory() as tmp:
        path = str(Path(tmp) / "clip.mp4")
        h, w = frames[0].shape
        writer = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"mp4v"), 12.0, (w, h))
        for f in frames:
            writer.write(np.repeat(f[:, :, None], 3, axis=2))
        writer.release()
        return _decoded(path, 0, len(frames))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--times", type=float, nargs="+", default=[0.0, 16.0, 27.0])
    args = ap.parse_args()
    scene = load_scene(default_scene_path())
    spec = scene.render
    print(f"# mcit renderer — {platform.processor() or platform.machine()}, Python {platform.python_version()}")
    print(
        f"scene {scene.name}: {scene.camera.width}×{scene.camera.height}, aa {spec.aa_samples} samples/edge pixel, "
        f"blur σ {spec.blur_sigma_px} px, noise σ {spec.noise_sigma} grey levels\n"
    )

    rows_t, rows_s = [], []
    offsets: dict[str, list[float]] = {}
    video = scene.video.path if scene.video and scene.video.path.is_file() else None
    for t in args.times:
        r = Renderer(scene)
        k = scene.video.frame_index(t)
        t = scene.video.frame_time(k)
        c0 = time.process_time()
        clean, labels = r.render_float(t)
        c1 = time.process_time()
        frame = r.render(t, k)
        edge_px = int((labels != np.roll(labels, 1, 0)).sum() + (labels != np.roll(labels, 1, 1)).sum())
        rows_t.append([f"{t:.2f}", c1 - c0, edge_px])
        # One second of the still scene: frames k … k + 11, each with its own sensor noise.
        frames = [frame] + [r.render(t, j) for j in range(k + 1, k + CLIP)]
        images = {"noise-free": [clean], "frames (blur + noise)": [f.astype(float) for f in frames]}
        if video is not None:
            images[f"decoded video ({video.suffix})"] = _decoded(str(video), k, CLIP)
        images["frames through mp4v"] = _through_mp4v(frames)
        edges = list(visible_edges(scene, r, t))
        for name, imgs in images.items():
            for img in imgs:
                m = [np.nanmean(edge_offsets(img, uv)) for _, _, uv in edges]
                offsets.setdefault(name, []).extend(np.abs(m))
        flat = Renderer(scene, spec=dataclasses.replace(spec, ambient=1.0))
        flat_img, _ = flat.render_float(t)
        for label, renderer, img in (("Lambert (scene)", r, clean), ("flat-shaded", flat, flat_img)):
            sil = [e for e in visible_edges(scene, renderer, t, kinds=("silhouette",)) if e[0] == "unknown_cylinder"]
            offs = [float(np.mean(edge_offsets(img, uv))) for _, _, uv in sil]
            rows_s.append([f"{t:.2f}", label, ", ".join(f"{o:+.3f}" for o in offs)])

    print("## Time per frame (CPU s, one thread)")
    print(markdown_table(["t (s)", "render (s)", "label changes"], rows_t))
    print(
        "## Edge offsets from the projected true edges (px), all "
        f"edges at t = {', '.join(f'{t:g}' for t in args.times)} s"
    )
    rows_e = [
        [name, len(v), float(np.median(v)), float(np.percentile(v, 95)), float(np.max(v))]
        for name, v in offsets.items()
    ]
    print(f"(each still scene seen in {CLIP} consecutive frames; one row per edge per frame)")
    print(markdown_table(["image", "edge × frame", "median |offset|", "95th percentile", "max |offset|"], rows_e))
    print("## Cylinder silhouettes, noise-free (px, left and right)")
    print(markdown_table(["t (s)", "shading", "offsets"], rows_s))

    rows_c = []
    for yaw in (0.0, 17.0, 41.0, 45.0, 58.3, 80.0):
        s = scene_from_dict(top_down_scene(yaw), ".")
        img, _ = Renderer(s).render_float(0.0)
        T = s.bodies[0].pose_at(0.0)
        cover = polygon_coverage(s.camera.project(s.bodies[0].model.vertices @ T[:3, :3].T + T[:3, 3]), *s.camera.size)
        mixed = (cover > 1e-12) & (cover < 1 - 1e-12)
        e = (img - 200.0 * (0.1 + 0.7 * cover))[mixed] / 140.0 * 100.0
        rows_c.append([yaw, int(mixed.sum()), float(e.mean()), float(np.abs(e).mean()), float(np.abs(e).max())])
    print("## Edge pixels' grey level against their exact area coverage (% of the contrast)")
    print(markdown_table(["edge angle (°)", "edge pixels", "mean error", "mean |error|", "max |error|"], rows_c))
    return 0


if __name__ == "__main__":
    sys.exit(main())
