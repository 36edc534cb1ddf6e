"""What ``mcit serve`` loads before its first page: none of scipy's heavy parts (stats, optimize,
linalg, spatial, ndimage: ~0.5 s of imports), nor matplotlib or trimesh — they load when a
calibration, a model or a report needs them (bench/startup.py times the start itself)."""

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
HEAVY = ("scipy.stats", "scipy.optimize", "scipy.linalg", "scipy.spatial", "scipy.ndimage", "matplotlib", "trimesh")


def test_serving_modules_do_not_import_the_heavy_libraries():
    code = (
        "import sys\n"
        "import app.cli, app.ui.serve, app.ui.server, app.workflows, app.db, app.video, app.devices, app.scene\n"
        f"print(' '.join(sorted(m for m in sys.modules if m.startswith({HEAVY!r}))))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True).stdout
    assert out.split() == []


def test_the_lazy_imports_still_load_where_needed():
    """Camera.decompose (scipy.linalg.rq) and calibrate_dlt (scipy.optimize, scipy.stats) work when called."""
    import numpy as np

    from core.calibration import calibrate_dlt
    from core.modeling.simulate import look_at_setup

    cam, _ = look_at_setup(np.array([0.0, 0.0, 0.1]), 1.5)
    K, T = cam.decompose()
    assert np.isclose(K[2, 2], 1.0) and np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3))
    X = np.random.default_rng(0).uniform(-0.3, 0.3, (8, 3))
    fit = calibrate_dlt(X, cam.project(X), cam.width, cam.height)
    assert np.allclose(fit.camera.project(X), cam.project(X), atol=1e-6)
