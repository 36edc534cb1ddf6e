"""The fused box fit with profile scans: returns as face points, edge transitions as tangent planes."""

import numpy as np
import pytest

from core.modeling import model_box
from core.modeling.box_scans import (
    assign_returns,
    associate_tangents,
    box_entry,
    distance_to_box,
    reduce_box_scans,
    tangent_distances,
)
from core.modeling.robust import object_runs
from core.modeling.simulate import SimWorld, look_at_setup, simulate_box, simulate_box_scans
from core.rangefinder import RangeFinderSpec, RangeScan, aim
from core.transforms import make_T, rot_x, rot_y, rot_z

from .conftest import BOX_SIZE, TABLE

STEP = RangeFinderSpec().step_rad


def _true_corners(T_obj):
    s = np.array([[1 if v & 1 else -1, 1 if v & 2 else -1, 1 if v & 4 else -1] for v in range(8)])
    off = np.column_stack([s[:, 0] * BOX_SIZE[0] / 2, s[:, 1] * BOX_SIZE[1] / 2, (s[:, 2] + 1) / 2 * BOX_SIZE[2]])
    return T_obj[:3, 3] + off @ T_obj[:3, :3].T


def _sizes_in_true_axes(res, T_obj):
    perm = np.argmax(np.abs(res.T_world_obj[:3, :3].T @ T_obj[:3, :3]), axis=1)
    est = np.array([res.dimensions[k] for k in ("size_x", "size_y", "size_z")])
    sig = np.array([res.sigmas[k] for k in ("size_x", "size_y", "size_z")])
    return est, BOX_SIZE[perm], sig


@pytest.mark.parametrize("distance_m", [1.3, 1.6])
@pytest.mark.parametrize("yaw_deg", [20.0, 35.0, 60.0])
@pytest.mark.parametrize("with_support", [True, False])
def test_box_with_scans_noise_free_exact(distance_m, yaw_deg, with_support):
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.07]), distance_m)
    T_obj = make_T(rot_z(np.radians(yaw_deg)), [0.01, -0.02, 0.0])
    world = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)),))
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, None, step_quantize=False)
    scans = simulate_box_scans(world, T_obj, BOX_SIZE, None, exact_edges=True)
    res = model_box(cam, faces, TABLE if with_support else None, method="fused", scans=scans, T_world_turret=T_wt)
    est, true, sig = _sizes_in_true_axes(res, T_obj)
    assert np.abs(est - true).max() < 1e-6
    d = np.linalg.norm(res.vertices_world[:, None] - _true_corners(T_obj)[None], axis=2).min(axis=1)
    assert d.max() < 1e-6
    assert res.method == "fused" and res.cov.shape == (9, 9) and np.all(sig > 0)
    info = res.details["scans"]
    assert len(info["tangents"]) == 4  # two scans, both sides
    # Each transition went to a vertical edge (corner indices differ in z only) of extreme azimuth.
    assert all(t["edge"][0].replace("-z", "+z") == t["edge"][1] for t in info["tangents"])
    assert np.abs(res.residuals["scan_edges_m"]).max() < 1e-6
    n_used = int(info["points_used"].sum())
    assert 100 < n_used < len(info["points_used"])  # returns near a face's border are left out
    assert res.residuals["scan_points_m"].shape == (n_used,)
    assert np.abs(res.residuals["scan_points_m"]).max() < 1e-6


def test_scans_add_what_the_clicks_miss(box_scene):
    """One noisy set of measurements: the tangent planes pin the far edges the clicks place poorly."""
    cam, T_wt, T_obj, world = box_scene
    rng = np.random.default_rng(3)
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, rng)
    scans = simulate_box_scans(world, T_obj, BOX_SIZE, rng)
    plain = model_box(cam, faces, TABLE, support_sigma_m=1e-6, method="fused")
    fused = model_box(cam, faces, TABLE, support_sigma_m=1e-6, method="fused", scans=scans, T_world_turret=T_wt)
    s_plain = _sizes_in_true_axes(plain, T_obj)[2]
    s_scans = _sizes_in_true_axes(fused, T_obj)[2]
    assert np.all(s_scans[:2] < 0.5 * s_plain[:2])  # the horizontal sizes: σ more than halved
    assert s_scans[2] == pytest.approx(s_plain[2], rel=0.1)  # the height still comes from the clicks
    # The residuals are those of a fit at the sensors' noise (in σ: RMS about 1).
    assert 0.7 < np.sqrt(np.mean(fused.details["fused_residuals_sigma"] ** 2)) < 1.3


def test_box_scans_sigmas_match_scatter_over_200_trials(box_scene):
    """200 trials at 1.4 m, the box moved U(±5 mm) each time (a random phase of the step grid):
    the predicted σ of the three sizes within 20 % of the RMS error; every size under 3 mm RMS."""
    cam, T_wt, T_obj0, _ = box_scene
    rng = np.random.default_rng(11)
    errs, sigs = [], []
    for _ in range(200):
        T_obj = make_T(T_obj0[:3, :3], [*rng.uniform(-0.005, 0.005, 2), 0.0])
        world = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)),))
        faces = simulate_box(cam, world, T_obj, BOX_SIZE, rng)
        scans = simulate_box_scans(world, T_obj, BOX_SIZE, rng)
        res = model_box(cam, faces, TABLE, support_sigma_m=1e-6, method="fused", scans=scans, T_world_turret=T_wt)
        est, true, sig = _sizes_in_true_axes(res, T_obj)
        errs.append(est - true)
        sigs.append(sig)
    rms = np.sqrt(np.mean(np.square(errs), axis=0))
    pred = np.sqrt(np.mean(np.square(sigs), axis=0))
    assert np.all(np.abs(rms / pred - 1) < 0.2), (rms, pred)
    assert rms.max() < 3e-3, rms


def test_box_scans_find_the_box_beside_another_object(box_scene):
    """A wide sweep that also crosses a second box: the run kept is the one on the modelled box."""
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, None, step_quantize=False)
    other = make_T(rot_z(0.3), [0.16, 0.05, 0.0])
    crowded = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)), (other, tuple(BOX_SIZE))))
    scans = simulate_box_scans(crowded, T_obj, BOX_SIZE, None, margin_m=0.3, exact_edges=True)
    res = model_box(cam, faces, TABLE, method="fused", scans=scans, T_world_turret=T_wt)
    est, true, _ = _sizes_in_true_axes(res, T_obj)
    assert np.abs(est - true).max() < 1e-6
    # The kept run is not the longest: the table beside the boxes returns more beams.
    runs = object_runs(scans[0].range_m, 0.05)
    assert res.details["scans"]["segments"][0].run != max(runs, key=lambda r: r[1] - r[0])


def test_tangents_go_to_the_silhouette_edges_within_half_a_step(box_scene):
    cam, T_wt, T_obj, world = box_scene
    scans = simulate_box_scans(world, T_obj, BOX_SIZE, None)  # commanded whole steps, exact beams
    R, t = T_obj[:3, :3], T_obj[:3, 3]
    data = reduce_box_scans(scans, T_wt, RangeFinderSpec(), R, t, BOX_SIZE)
    corners = _true_corners(T_obj)
    assoc = associate_tangents(data, T_wt, corners, R)
    pans = aim(T_wt, corners[:4])[0]  # the bottom corners: one per vertical edge
    low, high = int(np.argmin(pans)), int(np.argmax(pans))
    assert [a.edge for a in assoc] == [(low, low + 4), (high, high + 4)] * 2
    dist = tangent_distances(assoc, corners, T_wt[:3, 3])
    rho_h = np.array([np.linalg.norm((corners[a.edge[0]] - T_wt[:3, 3])[:2]) for a in assoc])  # turret z = world z
    assert np.all(np.abs(dist) <= 0.5 * STEP * rho_h + 1e-9)
    # σ: a uniform position within the step and the pointing noise, both step/√12, at the edge's distance.
    assert np.array([a.sigma_m for a in assoc]) == pytest.approx(rho_h * STEP / np.sqrt(6), rel=1e-3)
    # With the box moved 2 cm sideways, the same transitions still go to the same edges.
    moved = associate_tangents(data, T_wt, corners + [0.02, 0.0, 0.0], R)
    assert [a.edge for a in moved] == [a.edge for a in assoc]


def test_box_entry_and_return_assignment():
    R, t, dims = rot_z(0.4), np.array([0.1, 0.2, 0.0]), np.array([0.09, 0.094, 0.14])
    O = np.array([0.1, -1.0, 0.07])
    target = t + R @ np.array([0.0, -dims[1] / 2, 0.07])  # the centre of the −y face
    D = np.array([target - O, target + R @ [0.5 * dims[0] - 0.002, 0.0, 0.0] - O, [0.0, -1.0, 0.0]])
    D /= np.linalg.norm(D, axis=1, keepdims=True)
    s, axis, side, border = box_entry(O, D, R, t, dims)
    assert s[0] == pytest.approx(np.linalg.norm(target - O)) and (axis[0], side[0]) == (1, -1)
    assert border[0] == pytest.approx(min(dims[0] / 2, 0.07))
    assert border[1] == pytest.approx(0.002, abs=1e-9)  # 2 mm from the face's side edge
    assert np.isnan(s[2])  # pointing away
    X = np.array([target, target - 0.03 * (R @ [0.0, 1.0, 0.0]), t + [0.0, 0.0, 0.05]])
    assert distance_to_box(X, R, t, dims) == pytest.approx([0.0, 0.03, 0.0])

    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.07]), 1.4)
    T_obj = make_T(rot_z(np.radians(35.0)), [0.0, 0.0, 0.0])
    world = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)),))
    data = reduce_box_scans(
        simulate_box_scans(world, T_obj, BOX_SIZE, None), T_wt, RangeFinderSpec(), T_obj[:3, :3], T_obj[:3, 3], BOX_SIZE
    )
    used, axis, side = assign_returns(data, T_obj[:3, :3], T_obj[:3, 3], BOX_SIZE, edge_margin_m=0.005)
    # Every return used lies on the face it was given to; the ones left out are near a border.
    n = side[used, None] * T_obj[:3, :3][:, axis[used]].T
    face_pt = (
        T_obj[:3, 3]
        + T_obj[:3, :3] @ [0.0, 0.0, 0.07]
        + n * np.where(axis[used] < 2, BOX_SIZE[axis[used]] / 2, 0.07)[:, None]
    )
    assert np.abs(np.einsum("ij,ij->i", data.points_world[used] - face_pt, n)).max() < 1e-9
    assert 0 < (~used).sum() < 0.2 * len(used)
    assert set(zip(axis[used], side[used])) <= {(0, -1), (0, 1), (1, -1), (1, 1)}  # side faces only


def test_box_scans_error_paths(box_scene):
    cam, T_wt, T_obj, world = box_scene
    faces = simulate_box(cam, world, T_obj, BOX_SIZE, None, step_quantize=False)
    scans = simulate_box_scans(world, T_obj, BOX_SIZE, None)
    s = scans[0]

    def fit(sc, **kw):
        return model_box(cam, faces, TABLE, **{"method": "fused", "scans": sc, "T_world_turret": T_wt, **kw})

    with pytest.raises(ValueError, match="method='fused' only"):
        fit(scans, method="planes")
    with pytest.raises(ValueError, match="need T_world_turret"):
        fit(scans, T_world_turret=None)
    with pytest.raises(ValueError, match="must be a core.rangefinder.RangeScan"):
        fit([np.zeros((3, 10))])
    half = len(s) // 2  # stops in the middle of the box
    with pytest.raises(ValueError, match="does not pass the box on both sides"):
        fit([RangeScan(s.pan_rad[:half], s.tilt_rad[:half], s.range_m[:half])])
    tilt = s.tilt_rad + np.arange(len(s)) * 1e-5  # a slanted sweep
    with pytest.raises(ValueError, match="not a pan sweep at a fixed tilt"):
        fit([RangeScan(s.pan_rad, tilt, world.measure(s.pan_rad, tilt, None))])
    with pytest.raises(ValueError, match="above the box"):
        fit(simulate_box_scans(world, T_obj, BOX_SIZE, None, scan_fractions=(0.97,)))
    far = make_T(rot_z(0.3), [0.3, 0.1, 0.0])  # a scan across another box
    two = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)), (far, tuple(BOX_SIZE))))
    with pytest.raises(ValueError, match="not across this box"):
        fit(simulate_box_scans(two, far, BOX_SIZE, None))
    with pytest.raises(ValueError, match="only 2 return"):
        fit([RangeScan(s.pan_rad[:5], s.tilt_rad[:5], [np.nan, 1.3, 1.3, np.nan, np.nan])])
    # A thin post 20 cm in front of the low-pan silhouette edge, covering it by 4 mm.
    bottom = _true_corners(T_obj)[:4]
    E = bottom[int(np.argmin(aim(T_wt, bottom)[0]))]
    u = (E - T_wt[:3, 3])[:2] / np.linalg.norm((E - T_wt[:3, 3])[:2])
    post = make_T(np.eye(3), E - 0.2 * np.r_[u, 0.0] + 0.004 * np.r_[u[1], -u[0], 0.0])
    hidden = SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)), (post, (0.01, 0.01, 0.3))))
    with pytest.raises(ValueError, match="hides the box's edge"):
        fit(simulate_box_scans(hidden, T_obj, BOX_SIZE, None))
    # No box edge near the pan axis (a box standing on a corner): the transitions bracket no edge.
    data = reduce_box_scans(scans, T_wt, RangeFinderSpec(), T_obj[:3, :3], T_obj[:3, 3], BOX_SIZE)
    R_corner = rot_x(np.radians(45.0)) @ rot_y(np.radians(35.26))
    with pytest.raises(ValueError, match="pan axis"):
        associate_tangents(data, T_wt, _true_corners(make_T(R_corner, T_obj[:3, 3])), R_corner)
    # Without scans the API and results are those of the plain fused fit.
    plain = model_box(cam, faces, TABLE, method="fused", scans=[])
    assert "scans" not in plain.details and "scan_points_m" not in plain.residuals
