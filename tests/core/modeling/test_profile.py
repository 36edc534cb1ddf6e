import numpy as np
import pytest

from core.brep import Revolution
from core.modeling.profile import fit_profile, front_plane
from core.modeling.returns import concat_returns
from core.modeling.scans import segment_scan
from core.modeling.simulate import SimWorld, look_at_setup, simulate_revolution
from core.rangefinder import RangeFinderSpec


@pytest.mark.parametrize("cone", [False, True])
def test_profile_fit_exact_and_front_plane_tangent(cone):
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.08]), 1.3)
    sol = Revolution([0.01, -0.01, 0], [0.01, -0.01, 0.166], 0.05, 0.03 if cone else 0.05)
    _, scans = simulate_revolution(cam, SimWorld(T_wt, solids=(sol,)), sol, None)
    segs = [segment_scan(s, T_wt, RangeFinderSpec(), scan_index=k) for k, s in enumerate(scans)]
    ret = concat_returns([s.returns for s in segs])
    groups = np.concatenate([np.full(len(s.hits_world), k) for k, s in enumerate(segs)])
    fit = fit_profile(ret, np.array([0, 0, 1.0]), cone=cone, groups=groups)
    # The axis point and radius at the base height (t measured from X0 along z).
    t_base = -fit.X0[2]
    assert np.allclose(fit.centre(t_base)[:2], sol.p0[:2], atol=1e-7)
    assert fit.radius(t_base) == pytest.approx(0.05, abs=1e-7)
    if cone:
        assert fit.radius(t_base + 0.166) == pytest.approx(0.03, abs=1e-7)
    assert fit.cov.shape == ((4, 4) if cone else (3, 3)) and np.all(np.diag(fit.cov) > 0)
    P3 = front_plane(fit, T_wt[:3, 3], 0.0)
    # P3 touches the surface along the generator facing the range finder, the axis inside.
    w = fit.centre(0.0) - T_wt[:3, 3]
    u = w - w[2] * np.array([0, 0, 1.0])
    u /= np.linalg.norm(u)
    for t in (t_base, t_base + 0.1):
        X = fit.centre(t) - fit.radius(t) * u
        assert abs(P3.n @ X + P3.d) < 1e-9
    assert P3.n @ fit.centre(0.0) + P3.d > 0


def test_profile_errors():
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.08]), 1.3)
    sol = Revolution([0, 0, 0], [0, 0, 0.166], 0.05, 0.05)
    _, scans = simulate_revolution(cam, SimWorld(T_wt, solids=(sol,)), sol, None, scan_fractions=(0.5,))
    seg = segment_scan(scans[0], T_wt, RangeFinderSpec())
    with pytest.raises(ValueError, match="two different heights"):
        fit_profile(seg.returns, np.array([0, 0, 1.0]), cone=True)
    with pytest.raises(ValueError, match="at least 4"):
        fit_profile(seg.returns.subset(np.arange(len(seg.returns)) < 3), np.array([0, 0, 1.0]))
