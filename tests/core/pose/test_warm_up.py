"""``core.pose.warm_up`` prepares every compiled kernel version the public solvers use: after it, P3L, the batched
P3L, the refinement (plain and robust, lines and points) and ``estimate_pose`` add no kernel version, which numba
would otherwise compile at an operator's first click (9-20 s on a fresh machine). Run in a process of its own, so
that what other tests called directly does not hide a version missing from the warm-up."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

SCRIPT = r"""
import numpy as np
import core.pose._kernels as K
from core.pose import estimate_pose, p3l, p3l_batch, refine, warm_up
from core.pose.synthetic import random_lines_problem

warm_up()
def versions():
    return {n: set(map(str, getattr(K, n).signatures)) for n in dir(K) if hasattr(getattr(K, n), "signatures")}
before = versions()
rng = np.random.default_rng(3)
pb = random_lines_problem(rng, 4, sigma_px=0.5)
cam, segs, edges = pb.camera, pb.segs_uv, pb.edges_obj
p3l(cam, segs[:3], edges[:3])
p3l_batch(cam, segs[:3], np.stack([edges[:3], edges[1:]]))
X = edges[:, 0]
uv = cam.project_obj(pb.T_world_obj, X)
for loss in ("l2", "huber"):
    refine(cam, pb.T_world_obj, segs_uv=segs, edges_obj=edges, loss=loss)
    refine(cam, pb.T_world_obj, segs_uv=segs, edges_obj=edges, points_uv=uv[:1], points_obj=X[:1], loss=loss)
estimate_pose(cam, segs, edges)
after = versions()
print(sorted(n for n in after if after[n] - before[n]))
"""


def test_no_kernel_version_is_compiled_after_the_warm_up():
    done = subprocess.run([sys.executable, "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert done.stdout.strip() == "[]", f"kernels given argument types warm_up did not prepare: {done.stdout}"
