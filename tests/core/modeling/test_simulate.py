import numpy as np
import pytest

from core.brep import BRep, Revolution
from core.geometry import Plane
from core.modeling.scans import segment_scan
from core.modeling.simulate import (
    SimWorld,
    look_at_setup,
    ray_box,
    ray_convex,
    ray_plane,
    ray_revolution,
    simulate_revolution,
)
from core.modeling.small import image_line, interp_plane
from core.rangefinder import RangeFinderSpec, RangeScan
from core.transforms import make_T, rot_z

O = np.array([0.0, -2.0, 0.05])
D = np.array([[0.0, 1.0, 0.0], [0.0, 1.0, 0.5], [1.0, 0.0, 0.0]])
D = D / np.linalg.norm(D, axis=1, keepdims=True)


def test_ray_casts():
    T = make_T(rot_z(0.3), [0.0, 0.0, 0.0])
    hit = ray_box(O, D, T, (0.1, 0.1, 0.1))
    assert np.isfinite(hit[0]) and np.isnan(hit[1]) and np.isnan(hit[2])
    Bw = BRep.box(0.1, 0.1, 0.1).transformed(T)
    assert ray_convex(O, D, Bw)[0] == pytest.approx(hit[0], abs=1e-12)
    assert np.isnan(ray_convex(O, D, Bw)[1:]).all()
    cyl = Revolution([0, 0, 0], [0, 0, 0.2], 0.05, 0.05)
    assert ray_revolution(O, D, cyl)[0] == pytest.approx(2.0 - 0.05, abs=1e-12)
    cone = Revolution([0, 0, 0], [0, 0, 0.2], 0.05, 0.0)
    assert ray_revolution(O, D, cone)[0] == pytest.approx(2.0 - 0.05 * (1 - 0.05 / 0.2), abs=1e-12)
    down = np.array([[0.0, 0.0, -1.0]])
    assert ray_plane(O, down, Plane(np.array([0, 0, 1.0]), 0.0))[0] == pytest.approx(0.05)
    assert ray_revolution(np.array([0, 0, 0.5]), down, cyl)[0] == pytest.approx(0.3)  # the top cap


def test_look_at_and_fast_plane_helpers_agree_with_the_camera():
    cam, T_wt = look_at_setup(np.array([0.1, 0.2, 0.05]), 1.5, elevation_deg=30.0)
    assert cam.project(np.array([0.1, 0.2, 0.05])) == pytest.approx([255.5, 127.5], abs=1e-9)
    assert np.linalg.norm(cam.center - [0.1, 0.2, 0.05]) == pytest.approx(1.5)
    assert np.linalg.norm(T_wt[:3, 3] - cam.center) == pytest.approx(0.2)
    seg = np.array([[10.0, 20.0], [200.0, 100.0]])
    assert interp_plane(cam.C, seg) == pytest.approx(cam.interpretation_plane(seg).as_vector())
    assert image_line(*seg) == pytest.approx(cam.image_line(seg))


def test_simulated_scan_is_segmented_with_tangents_between_last_hit_and_first_miss():
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.08]), 1.3)
    sol = Revolution([0, 0, 0], [0, 0, 0.166], 0.051, 0.051)
    world = SimWorld(T_wt, solids=(sol,))
    _, scans = simulate_revolution(cam, world, sol, None)
    seg = segment_scan(scans[0], T_wt, RangeFinderSpec())
    a, b = seg.run
    # The background (the table behind) returned ranges beside the object, not in its run.
    assert np.isfinite(scans[0].range_m[a - 1]) and scans[0].range_m[a - 1] > scans[0].range_m[a] + 0.05
    assert [t.side for t in seg.tangents] == [-1, 1]
    lo = seg.tangents[0]
    assert scans[0].pan_rad[a - 1] < lo.pan_rad < scans[0].pan_rad[a]
    assert lo.sigma_pan_rad == pytest.approx(
        np.hypot(RangeFinderSpec().step_rad / np.sqrt(12), RangeFinderSpec().sigma_angle)
    )
    assert seg.hits_world.shape == (b - a, 3) and seg.covs.shape == (b - a, 3, 3)
    with pytest.raises(ValueError, match="no return"):
        segment_scan(RangeScan([0.0, 0.1], [0.0, 0.0], [np.nan, np.nan]), T_wt, RangeFinderSpec())
