"""The pose solvers' first use on a new machine, and once prepared (issue 27, item 3).

Each row runs in a process of its own with numba's cache in a folder of its own: *cold* starts from an empty
cache (a fresh clone: every kernel compiles), *warm* from the cache the cold run left (a later start). In each:

1. ``mcit serve``'s warm-up (``app.ui.serve._warm_pose_kernels``: what it runs in the background at start while
   the panel says the solvers are being prepared);
2. then, on the workcell's frame at t = 16 s (the box has moved) through the Update pose workflow as the interface
   drives it: the first one-click search (Find at the box's centre), the first Auto match (four clicked edges), the
   first Refine — each timed from the call, as an operator waits for it after the click.

Run: ``.venv/bin/python bench/first_use.py``. Target: each first answer within 2 s of the click once the warm-up has
run (the interface says how long the warm-up takes while it runs).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child() -> None:
    sys.path.insert(0, str(ROOT))
    t0 = time.perf_counter()
    from app.ui.serve import _warm_pose_kernels

    _warm_pose_kernels()
    warm_s = time.perf_counter() - t0

    from app.db import Database, seed_from_scene
    from app.scene import default_scene_path, load_scene
    from app.workflows import Site
    from app.workflows.update_pose import UpdatePose
    from tests.e2e.harness import site_frame
    from tests.e2e.test_workflows_pose import AUTO_EDGES

    scene = load_scene(default_scene_path())
    t_s = 16.0
    frame = site_frame(scene, None, t_s)
    db = Database.open(Path(tempfile.mkdtemp()) / "site.sqlite")
    seed_from_scene(db, scene)
    site = Site(scene, db, clock=lambda: t_s, frames=lambda t: frame)
    T = scene.body("parallelepiped").pose_at(t_s)
    out = {"warm_up_s": warm_s}

    wf = UpdatePose(site, client="bench", object_name="parallelepiped", snap=False)
    t = time.perf_counter()
    wf.find(site.camera.project_obj(T, wf.obj.model.vertices).mean(axis=0))
    out["search_s"] = time.perf_counter() - t
    wf.cancel()

    wf = UpdatePose(site, client="bench", object_name="parallelepiped", snap=False)
    wf.auto_match()  # no edges clicked yet: switches to automatic assignment (as the button does)
    obj = wf.obj
    segs = obj.model.edge_segments(T)
    for k in AUTO_EDGES:  # the browser test's four edges (not all parallel)
        uv = site.camera.project(segs[k])
        wf.click(uv[0] + 0.25 * (uv[1] - uv[0]))
        wf.click(uv[0] + 0.75 * (uv[1] - uv[0]))
    t = time.perf_counter()
    wf.auto_match()
    out["auto_match_s"] = time.perf_counter() - t
    wf.confirm_match()
    t = time.perf_counter()
    wf.refine()
    out["refine_s"] = time.perf_counter() - t
    print(json.dumps(out))


def main() -> int:
    if sys.argv[1:] == ["--child"]:
        child()
        return 0
    cache = tempfile.mkdtemp(prefix="mcit-numba-")
    rows = []
    for label in ("cold (a new machine)", "warm (a later start)"):
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        res = subprocess.run([sys.executable, __file__, "--child"], env=env, capture_output=True, text=True, cwd=ROOT)
        if res.returncode != 0:
            print(res.stderr[-2000:])
            return 1
        rows.append((label, json.loads(res.stdout.strip().splitlines()[-1])))
    print(f"\nFirst use of the pose solvers, {os.cpu_count()} cores, load {os.getloadavg()[0]:.1f} (seconds)\n")
    print("| start | warm-up at start | then: first one-click search | first Auto match | first Refine |")
    print("|---|---|---|---|---|")
    for label, r in rows:
        print(
            f"| {label} | {r['warm_up_s']:.1f} | {r['search_s']:.2f} | {r['auto_match_s']:.2f} | {r['refine_s']:.2f} |"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
