import numpy as np
import pytest

from core.geometry import Line, distance_point_line
from core.modeling import METHODS, model_cylinder
from core.modeling.simulate import simulate_revolution
from core.rangefinder import RangeScan

from .conftest import TABLE, cylinder_scene

HINTS = {"support": dict(support=TABLE), "vertical": dict(axis_dir=[0, 0, 1]), "free": dict()}


def _axis_error(res, sol):
    mid = res.axis.point + 0.5 * res.axis.direction * (res.dimensions["height"])
    return distance_point_line(mid, Line(sol.p0, sol.axis))


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("hint", list(HINTS))
def test_cylinder_noise_free_exact(method, hint):
    cam, T_wt, sol, world = cylinder_scene(1.3, offset=(0.01, -0.02))
    sil, scans = simulate_revolution(cam, world, sol, None, exact_edges=True)
    res = model_cylinder(cam, method, silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, **HINTS[hint])
    assert res.kind == "cylinder" and res.method == method
    assert res.dimensions["radius"] == pytest.approx(0.051, abs=1e-6)
    assert res.dimensions["height"] == pytest.approx(0.166, abs=1e-6)
    assert _axis_error(res, sol) < 1e-6
    assert np.allclose(res.axis.point, sol.p0, atol=1e-6)
    assert abs(abs(res.axis.direction @ sol.axis) - 1) < 1e-9
    assert res.T_world_obj.shape == (4, 4) and np.allclose(res.T_world_obj[:3, 3], sol.p0, atol=1e-6)
    assert set(res.sigmas) == {"radius", "height", "axis_position"}
    assert all(np.isfinite(v) and v > 0 for v in res.sigmas.values())
    assert res.cov.shape == (8, 8) and len(res.cov_names) == 8
    assert res.vertices_world.shape == (2, 3)
    assert np.abs(res.residuals["silhouettes_px"]).max() < 1e-4


@pytest.mark.parametrize("method", METHODS)
def test_cone_noise_free_exact(method):
    cam, T_wt, sol, world = cylinder_scene(1.3, r0=0.06, r1=0.03, offset=(-0.01, 0.01))
    sil, scans = simulate_revolution(cam, world, sol, None, exact_edges=True)
    res = model_cylinder(cam, method, silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE, cone=True)
    assert res.kind == "cone"
    assert res.dimensions["radius_bottom"] == pytest.approx(0.06, abs=1e-6)
    assert res.dimensions["radius_top"] == pytest.approx(0.03, abs=1e-6)
    assert res.dimensions["height"] == pytest.approx(0.166, abs=1e-6)
    assert _axis_error(res, sol) < 1e-6
    assert res.model.solids[0].r0 == pytest.approx(0.06, abs=1e-6)


@pytest.mark.parametrize("method", ["tangential", "bisecting", "rf_tangential", "fused"])
def test_oblique_cylinder_without_hint_exact(method):
    cam, T_wt, sol, world = cylinder_scene(1.3, tilt_axis=[0.15, -0.1, 1.0])
    sil, scans = simulate_revolution(cam, world, sol, None, exact_edges=True)
    res = model_cylinder(cam, method, silhouettes_uv=sil, scans=scans, T_world_turret=T_wt)
    assert res.dimensions["radius"] == pytest.approx(0.051, abs=1e-6)
    assert res.dimensions["height"] == pytest.approx(0.166, abs=1e-6)
    assert abs(res.axis.direction @ sol.axis - 1) < 1e-9
    assert _axis_error(res, sol) < 1e-6


def test_cylinder_sigmas_match_scatter_over_200_trials():
    """Predicted σ (radius, height, axis position) within 20 % of the RMS error over 200 trials (4 standard errors),
    for the fused fit and the paper's tangential method, on the same simulated measurements."""
    rng = np.random.default_rng(11)
    methods = ("fused", "tangential")
    out = {m: [] for m in methods}
    for _ in range(200):
        off = rng.uniform(-0.005, 0.005, 2)  # a random phase of the turret's step grid
        cam, T_wt, sol, world = cylinder_scene(1.3, offset=off)
        sil, scans = simulate_revolution(cam, world, sol, rng, step_multiple=4)
        true_mid = sol.p0 + 0.5 * sol.height * sol.axis
        for m in methods:
            res = model_cylinder(cam, m, silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE)
            mid = res.axis.point + 0.5 * res.dimensions["height"] * res.axis.direction
            e = mid - true_mid
            e -= (e @ res.axis.direction) * res.axis.direction
            s = res.sigmas
            out[m].append(
                [
                    res.dimensions["radius"] - 0.051,
                    res.dimensions["height"] - 0.166,
                    e @ e,
                    s["radius"] ** 2,
                    s["height"] ** 2,
                    s["axis_position"] ** 2,
                ]
            )
    for m in methods:
        v = np.array(out[m])
        rms = np.sqrt([np.mean(v[:, 0] ** 2), np.mean(v[:, 1] ** 2), np.mean(v[:, 2])])
        pred = np.sqrt(v[:, 3:].mean(axis=0))
        assert np.all(np.abs(rms / pred - 1) < 0.2), (m, rms, pred)


def test_fused_beats_two_mm_and_ignores_background_and_stray_returns():
    cam, T_wt, sol, world = cylinder_scene(1.5, offset=(0.003, -0.002))
    rng = np.random.default_rng(5)
    sil, scans = simulate_revolution(cam, world, sol, rng)
    # A stray return in the middle of the object's run (a 4 cm short range: dust, a reflection).
    s0 = scans[0]
    hits = np.flatnonzero(np.isfinite(s0.range_m))
    rho = s0.range_m.copy()
    mid_hit = hits[np.argmin(rho[hits])]
    rho[mid_hit + 3] -= 0.04
    scans[0] = RangeScan(s0.pan_rad, s0.tilt_rad, rho)
    res = model_cylinder(cam, "fused", silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE)
    assert abs(res.dimensions["radius"] - 0.051) < 0.002
    assert _axis_error(res, sol) < 0.002
    assert res.details["outliers"] >= 1
    # The table behind the object returned ranges beside it: they were not taken as the object.
    assert any(np.isfinite(s.range_m[: s_.run[0]]).any() for s, s_ in zip(scans, res.details["segments"]))


def test_cylinder_error_paths():
    cam, T_wt, sol, world = cylinder_scene(1.3)
    sil, scans = simulate_revolution(cam, world, sol, None)
    kw = dict(silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE)
    with pytest.raises(ValueError, match="method must be one of"):
        model_cylinder(cam, "least_squares", **kw)
    with pytest.raises(ValueError, match="same image line"):
        model_cylinder(cam, "tangential", **{**kw, "silhouettes_uv": np.array([sil[0], sil[0]])})
    with pytest.raises(ValueError, match="needs the two silhouettes"):
        model_cylinder(cam, "bisecting", **{**kw, "silhouettes_uv": None})
    with pytest.raises(ValueError, match="shape"):
        model_cylinder(cam, "tangential", **{**kw, "silhouettes_uv": sil[0]})
    with pytest.raises(ValueError, match="at least one range scan"):
        model_cylinder(cam, "tangential", **{**kw, "scans": []})
    with pytest.raises(ValueError, match="T_world_turret"):
        model_cylinder(cam, "tangential", **{**kw, "T_world_turret": None})
    with pytest.raises(ValueError, match="axis direction"):
        model_cylinder(cam, "tangential", silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, cone=True)
    # A scan that stops on the object: no miss beyond one edge, no lateral plane there.
    s = scans[0]
    hits = np.flatnonzero(np.isfinite(s.range_m) & (s.range_m < np.nanmin(s.range_m) + 0.1))
    cut = RangeScan(s.pan_rad[: hits[-1] - 3], s.tilt_rad[: hits[-1] - 3], s.range_m[: hits[-1] - 3])
    with pytest.raises(ValueError, match="both sides"):
        model_cylinder(cam, "rf_tangential", **{**kw, "scans": [cut]})
    # Too few returns on the object.
    few = RangeScan(s.pan_rad[hits[:2]], s.tilt_rad[hits[:2]], s.range_m[hits[:2]])
    with pytest.raises(ValueError, match="only 2 return"):
        model_cylinder(cam, "tangential", **{**kw, "scans": [few]})
    # Silhouettes that do not bound the scanned object: both clicked 80 px (two widths) left of it.
    left = sil + [-80.0, 0.0]
    with pytest.raises(ValueError, match="do not bound|not between"):
        model_cylinder(cam, "tangential", **{**kw, "silhouettes_uv": left})
