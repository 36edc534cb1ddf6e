"""The demo's measures: box sizes in the paper's order, the cylinder's depth, P3L in click order,
and the simulated sweeps (small instances: exact without noise, plausible with it)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from app.demo.results import box_dims_paper_order, cylinder_depth_m, first_p3l
from app.demo.simulation import box_sweep, cylinder_sweep, operator_order, pose_sweep, sim_setup
from app.scene import default_scene_path, load_scene
from core.brep import BRep, Revolution
from core.geometry import Plane
from core.modeling import model_box, model_cylinder
from core.modeling.simulate import SimWorld, look_at_setup, simulate_box, simulate_revolution
from core.pose.synthetic import paper_problems
from core.transforms import make_T, pose_error, rot_z

TABLE = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
BOX = np.array([0.09, 0.094, 0.14])


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


def test_box_sizes_come_out_in_the_papers_order_whatever_the_models_axes():
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.07]), 1.4)
    T_true = make_T(rot_z(np.radians(40.0)), [0.002, -0.001, 0.0])
    faces = simulate_box(cam, SimWorld(T_wt, boxes=((T_true, tuple(BOX)),)), T_true, BOX, None, step_quantize=False)
    res = model_box(cam, faces, TABLE)
    est, sig, truth = box_dims_paper_order(res, T_true, BOX)
    assert np.allclose(truth, [0.09, 0.14, 0.094])  # width (x), height (z), length (y)
    assert np.allclose(est, truth, atol=1e-6) and np.all(sig > 0)
    # The same true box described in a frame turned 90° (its x and y sizes swapped): the estimate
    # follows, axis by axis.
    T_turned = T_true @ make_T(rot_z(np.pi / 2), [0.0, 0.0, 0.0])
    est2, _, truth2 = box_dims_paper_order(res, T_turned, BOX[[1, 0, 2]])
    assert np.allclose(truth2, [0.094, 0.14, 0.09]) and np.allclose(est2, truth2, atol=1e-6)


def test_cylinder_depth_is_the_radius_for_an_exact_model():
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.083]), 1.2)
    sol = Revolution([0.003, -0.002, 0.0], [0.003, -0.002, 0.166], 0.051, 0.051)
    sil, scans = simulate_revolution(cam, SimWorld(T_wt, solids=(sol,)), sol, None, exact_edges=True)
    res = model_cylinder(cam, "tangential", silhouettes_uv=sil, scans=scans, T_world_turret=T_wt, support=TABLE)
    O = T_wt[:3, 3]
    mid = np.array([0.003, -0.002, 0.083])
    front = np.linalg.norm((mid - O)[:2]) - 0.051
    assert cylinder_depth_m(res, O, front) == pytest.approx(0.051, abs=1e-6)
    assert cylinder_depth_m(res, O, front - 0.01) == pytest.approx(0.061, abs=1e-6)  # a farther front: deeper


def test_first_p3l_skips_unusable_triples_and_finds_the_truth():
    pb = paper_problems(np.random.default_rng(1), 1, 0.0)[0]
    # Three edges through one vertex first (P3L cannot fix the depth from them), then the rest.
    V = [{tuple(p) for p in e} for e in pb.edges_obj]
    tri = next(t for t in itertools.combinations(range(len(V)), 3) if V[t[0]] & V[t[1]] & V[t[2]])
    order = np.array(list(tri) + [k for k in range(len(V)) if k not in tri])
    cands, triple = first_p3l(pb.camera, pb.segs_uv[order], pb.edges_obj[order])
    assert triple != (0, 1, 2)
    assert triple is not None and len(triple) == 3
    assert min(pose_error(T, pb.T_world_obj)[0] for T in cands) < 1e-6
    assert first_p3l(pb.camera, pb.segs_uv[:2], pb.edges_obj[:2]) == ([], None)


def test_operator_order_starts_with_a_non_degenerate_triple():
    E = BRep.box(0.35, 0.231, 0.132).edge_segments()
    order = operator_order(E)
    assert sorted(order.tolist()) == list(range(len(E)))
    d = E[order[:3], 1] - E[order[:3], 0]
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    assert np.all(np.abs(d @ d.T - np.eye(3)) < 0.99)  # pairwise non-parallel
    ends = [{tuple(p) for p in E[k]} for k in order[:3]]
    assert not (ends[0] & ends[1] & ends[2])
    with pytest.raises(ValueError, match="non-parallel"):
        operator_order(E[[0, 2, 4, 6]])  # bottom and top edges of a box: two directions only


def test_sim_setup_copies_the_scene(scene):
    s = sim_setup(scene)
    assert s.elevation_deg == pytest.approx(28.3, abs=1e-6)
    assert s.baseline_m == pytest.approx(0.2, abs=1e-9) and s.f_px == pytest.approx(500.0)
    assert (s.width, s.height) == (512, 256)


def test_sweeps_on_small_instances(scene):
    setup = sim_setup(scene)
    rng = np.random.default_rng(0)
    box = box_sweep(setup, BOX, (1.3, 1.6), 3, rng)
    assert box.errors["planes"].shape == (2, 3, 4) and box.sigmas["fused"].shape == (2, 3, 3)
    assert np.all(box.rms("planes")[:, :3] < 0.01)  # σ 1 px, 5 mm: millimetres, not centimetres
    cyl = cylinder_sweep(setup, 0.051, 0.166, (1.0,), 3, rng)
    assert cyl.values["fused"].shape == (1, 3, 4)
    assert np.all(np.abs(cyl.mean_depth("fused") - 0.051) < 0.005) and np.all(cyl.rms("fused", 1) < 0.005)
    clean = pose_sweep(5, 0.0, rng)
    assert clean.failed == 0 and clean.refine_failed == 0
    assert np.all(clean.noise_free[:, 0] < 1e-5) and np.all(clean.refined[:, 1] < 1e-8)
    noisy = pose_sweep(10, 1.0, rng)
    assert len(noisy.p3l) + noisy.failed == 10 and len(noisy.refined) == len(noisy.candidates_tried)
    assert np.median(noisy.refined[:, 0]) < np.median(noisy.p3l[:, 0])  # refinement beats three edges
