"""The modelling code's derivatives: the one finite-difference helper, and the analytic Jacobians
that replaced difference loops (each checked against central differences of the map itself)."""

import numpy as np
import pytest

from core.modeling.box import _so3_right_jacobian
from core.modeling.lm import numeric_jacobian
from core.modeling.observations import interpretation_plane_obs
from core.modeling.profile import ProfileFit, axis_basis, front_plane, front_plane_jacobian
from core.modeling.simulate import look_at_setup
from core.modeling.small import interp_plane
from core.transforms import exp_so3, log_so3


def _central(f, x, h=1e-6):
    x = np.asarray(x, float)
    return np.column_stack([(f(x + h * e) - f(x - h * e)) / (2 * h) for e in np.eye(len(x))])


def test_numeric_jacobian_forward_central_and_skipped_columns():
    def f(x):
        return np.array([x[0] ** 2 * x[1], np.sin(x[2]), x[0] + 3 * x[2]])

    x = np.array([1.5, -2.0, 0.3])
    exact = np.array([[2 * x[0] * x[1], x[0] ** 2, 0.0], [0.0, 0.0, np.cos(x[2])], [1.0, 0.0, 3.0]])
    assert np.allclose(numeric_jacobian(f, x, 1e-7), exact, atol=1e-5)
    assert np.allclose(numeric_jacobian(f, x, 1e-5, central=True), exact, atol=1e-8)
    calls = []

    def counted(x):
        calls.append(x.copy())
        return f(x)

    J = numeric_jacobian(counted, x, np.array([1e-7, 0.0, 1e-7]), f0=f(x))
    assert len(calls) == 2  # f0 reused, the zero-step column not evaluated
    assert np.all(J[:, 1] == 0) and np.allclose(J[:, [0, 2]], exact[:, [0, 2]], atol=1e-5)
    assert numeric_jacobian(f, x, 0.0).shape == (3, 3)


@pytest.mark.parametrize("cone", [False, True])
def test_front_plane_jacobian_matches_differences(cone):
    rng = np.random.default_rng(3)
    a = rng.normal(size=3)
    a /= np.linalg.norm(a)
    e1, e2 = axis_basis(a)
    p = np.array([0.01, -0.02, 0.05, 0.2]) if cone else np.array([0.01, -0.02, 0.05])
    fit = ProfileFit(a, rng.normal(size=3), e1, e2, p, np.eye(len(p)), np.zeros(0), np.zeros(0, bool), cone)
    origin = 2.0 * rng.normal(size=3)
    J = front_plane_jacobian(fit, origin, 0.04)
    Jn = _central(lambda q: front_plane(fit, origin, 0.04, q).as_vector(), p)
    assert np.allclose(J, Jn, atol=1e-7)
    assert np.abs(J).max() > 0.1  # not a trivially zero comparison


def test_interpretation_plane_covariance_is_the_derivative_of_the_plane():
    cam, _ = look_at_setup(np.array([0.0, 0.0, 0.08]), 1.3)
    seg = np.array([[100.0, 50.0], [300.0, 200.0]])
    obs = interpretation_plane_obs(cam, seg, 1.5)
    v0 = obs.plane.as_vector()

    def plane(x):
        v = interp_plane(cam.C, x.reshape(2, 2))
        return v if v @ v0 > 0 else -v

    J = _central(plane, seg.reshape(-1), 1e-3)
    assert np.allclose(obs.cov, 1.5**2 * J @ J.T, rtol=1e-6, atol=1e-14)


@pytest.mark.parametrize("w", [np.array([0.3, -0.2, 0.5]), np.array([1e-8, 2e-8, 0.0]), np.zeros(3)])
def test_so3_right_jacobian(w):
    R = exp_so3(w)
    Jn = _central(lambda x: log_so3(R.T @ exp_so3(x)), w, 1e-7)
    assert np.allclose(_so3_right_jacobian(w), Jn, atol=1e-7)


@pytest.mark.parametrize(
    "case", ["cylinder on the support", "cone on the support", "tilted cylinder, axis given", "cone, axis given"]
)
def test_paper_construction_jacobian_matches_differences(case):
    """The paper's three constructions differentiated analytically (known axis direction) give the
    central differences of the construction itself, every input (clicks, tangent beams' angles,
    the front plane), every output (radii, height, mid-point, axis)."""
    import core.modeling.cylinder as cyl
    from core.brep import Revolution
    from core.geometry import Plane
    from core.modeling.simulate import SimWorld, simulate_revolution
    from core.rangefinder import RangeFinderSpec

    table = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
    cone = "cone" in case
    tilt = (
        np.array([0.2, 0.1, 1.0]) / np.linalg.norm([0.2, 0.1, 1.0]) if "tilted" in case else np.array([0.0, 0.0, 1.0])
    )
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.083]), 1.3)
    sol = Revolution(np.zeros(3), 0.166 * tilt, 0.06 if cone else 0.051, 0.04 if cone else 0.051)
    sil, scans = simulate_revolution(cam, SimWorld(T_wt, solids=(sol,)), sol, np.random.default_rng(5), sigma_px=1.0)
    support = table if "support" in case else None
    data = cyl.reduce_cylinder_data(
        cam,
        silhouettes_uv=sil,
        scans=scans,
        T_world_turret=T_wt,
        spec=RangeFinderSpec(),
        support=support,
        axis_dir=None if support else tilt,
        cone=cone,
        jump_m=0.05,
    )
    for method in ("tangential", "bisecting", "rf_tangential"):
        ctx = cyl._stage_one(data, method)
        parts = [sil.reshape(-1)] + [[tb.pan_rad, tb.tilt_rad] for tb in data.tangents]
        if ctx.profile is not None:
            parts.append(cyl.front_plane(ctx.profile, data.rf_origin, float(np.mean(ctx.t_sections))).as_vector())
        z = np.concatenate([np.asarray(p, float).reshape(-1) for p in parts])
        J = cyl._paper_jacobian(z, ctx, cyl._solve_paper(z, ctx))
        Jn = numeric_jacobian(lambda x: cyl._solid_vector(cyl._solve_paper(x, ctx), cone), z, 1e-7, central=True)
        assert J.shape == Jn.shape
        assert np.abs(J - Jn).max() < 1e-6 * np.abs(Jn).max(), method


def _rel_err(J, Jn):
    return float(np.abs(J - Jn).max() / np.abs(Jn).max())


def test_silhouette_ends_and_their_jacobian_at_random_solids():
    from core.brep import Revolution
    from core.modeling.fused import silhouette_ends

    rng = np.random.default_rng(16)
    checked = 0
    for _ in range(30):
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        p0 = rng.normal(scale=0.2, size=3)
        r0, r1, h = rng.uniform(0.02, 0.1), rng.uniform(0.0, 0.1), rng.uniform(0.05, 0.4)
        c = p0 + rng.normal(size=3) * 1.5
        ends, J = silhouette_ends(p0, a, r0, r1, h, c)
        ref = Revolution(p0, p0 + h * a, r0, r1).silhouette(c)
        if ends is None:
            assert len(ref) == 0
            continue
        assert np.allclose(ends, ref, atol=1e-12)
        x = np.concatenate([p0, a, [r0, r1, h]])
        Jn = numeric_jacobian(
            lambda x: silhouette_ends(x[:3], x[3:6], x[6], x[7], x[8], c)[0].reshape(-1), x, 1e-6, central=True
        )
        assert _rel_err(J.reshape(12, 9), Jn) <= 1e-6
        checked += 1
    assert checked >= 20


@pytest.mark.parametrize("k", [0.0, -0.15])
def test_beam_gap_direction_jacobian_matches_differences(k):
    from core.modeling.returns import beam_gap, beam_gap_direction_jacobian

    rng = np.random.default_rng(5)
    p0, a, r0 = np.array([0.01, -0.02, 0.0]), np.array([0.05, 0.02, 1.0]), 0.05
    a /= np.linalg.norm(a)
    O = np.array([1.2, 0.3, 0.08])
    for _ in range(10):
        target = p0 + a * rng.uniform(0.02, 0.15) + rng.normal(scale=0.08, size=3)
        D = (target - O) / np.linalg.norm(target - O)
        J = beam_gap_direction_jacobian(O, D[None], p0, a, r0, k)[0]
        Jn = numeric_jacobian(lambda d: beam_gap(O, d[None], p0, a, r0, k)[0], D, 1e-7, central=True)[0]
        assert np.abs(J - Jn).max() <= 1e-6 * np.abs(Jn).max()


@pytest.mark.parametrize("case", ["cylinder on the support", "cone on the support", "tilted cylinder, free axis"])
def test_fused_fit_jacobian_matches_differences_of_its_residuals(case, monkeypatch):
    """The fused fit's Jacobian against central differences of its own residuals, at its start and
    at random points around it: the tangent beams' and the clicked ends' rows, to 1e-6. (The scan
    returns' rows hold each return's σ — its slope term — fixed by design, ``range_residuals``:
    they are not the residuals' full derivative and are left out here.)"""
    import core.modeling.fused as fused
    from core.modeling import model_cylinder
    from core.modeling.simulate import simulate_revolution

    from .conftest import TABLE, cylinder_scene

    if case == "cone on the support":
        cam, T_wt, sol, world = cylinder_scene(1.3, r0=0.06, r1=0.03, offset=(-0.01, 0.01))
        kw = dict(support=TABLE, cone=True)
    elif case == "cylinder on the support":
        cam, T_wt, sol, world = cylinder_scene(1.3, offset=(0.01, -0.02))
        kw = dict(support=TABLE)
    else:
        cam, T_wt, sol, world = cylinder_scene(1.3, tilt_axis=[0.15, -0.1, 1.0])
        kw = {}
    sil, scans = simulate_revolution(cam, world, sol, np.random.default_rng(2), step_multiple=4)
    seen = []
    real_lm = fused.levenberg_marquardt

    def spy(fun, jac, x0, **k):
        seen.append((fun, jac, np.array(x0, float)))
        return real_lm(fun, jac, x0, **k)

    monkeypatch.setattr(fused, "levenberg_marquardt", spy)
    n_beams = []
    real_dg = fused.beam_gap_direction_jacobian

    def spy_dg(O, D, *args):
        n_beams.append(len(D))
        return real_dg(O, D, *args)

    monkeypatch.setattr(fused, "beam_gap_direction_jacobian", spy_dg)
    model_cylinder(cam, "fused", silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, **kw)
    assert seen
    rng = np.random.default_rng(7)
    fun, jac, th0 = seen[0]
    for i in range(6):
        th = th0 + (0 if i == 0 else rng.normal(scale=2e-3, size=th0.shape))
        J = jac(th)
        Jn = numeric_jacobian(fun, th, 1e-6, central=True)
        assert J.shape == Jn.shape and np.abs(Jn[-8:]).max() > 1.0  # the clicked ends are in it
        m = n_beams[0] + 8  # the tangent beams' rows, then the clicked ends'
        assert n_beams[0] >= 2
        assert _rel_err(J[-m:], Jn[-m:]) <= 1e-6, (i, _rel_err(J[-m:], Jn[-m:]))


@pytest.mark.parametrize("case", ["on the support, with scans", "free, with scans", "on the support, no scans"])
def test_fused_box_jacobian_matches_differences_of_its_residuals(case, box_scene, monkeypatch):
    """The fused box fit's Jacobian (range points with their σ along the normals, scan tangents,
    clicked ends; all analytic) against central differences of its residuals, at each pass's
    start and at random points around it."""
    import core.modeling.box as box
    from core.modeling import model_box
    from core.modeling.simulate import simulate_box, simulate_box_scans

    from .conftest import BOX_SIZE, TABLE

    cam, T_wt, T_obj, world = box_scene
    rng = np.random.default_rng(4)
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, rng)
    kw = {} if "no scans" in case else dict(scans=simulate_box_scans(world, T_obj, BOX_SIZE, rng), T_world_turret=T_wt)
    seen = []
    real_lm = box.levenberg_marquardt

    def spy(fun, jac, x0, **k):
        seen.append((fun, jac, np.array(x0, float)))
        return real_lm(fun, jac, x0, **k)

    monkeypatch.setattr(box, "levenberg_marquardt", spy)
    model_box(cam, faces, TABLE if "support" in case else None, method="fused", **kw)
    assert seen
    fun, jac, th0 = seen[-1]  # the residuals are the last pass's (its points and tangents)
    for i in range(6):
        th = th0 + (0 if i == 0 else rng.normal(scale=2e-3, size=th0.shape))
        J = jac(th)
        Jn = numeric_jacobian(fun, th, 1e-6, central=True)
        assert J.shape == Jn.shape and np.abs(Jn).max() > 1.0
        assert _rel_err(J, Jn) <= 1e-6, (i, _rel_err(J, Jn))
