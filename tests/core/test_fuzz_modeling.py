"""Fuzz tests of core.modeling: non-finite, huge, tiny and degenerate inputs give a ValueError or
a finite result of the documented shape (issue 14)."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from core.brep import BRep, Revolution
from core.geometry import Plane
from core.modeling import BoxFace, fit_face_plane, interpretation_plane_obs, model_box, model_cylinder, model_polyhedron
from core.modeling.simulate import (
    SimWorld,
    look_at_setup,
    simulate_box,
    simulate_box_scans,
    simulate_polyhedron,
    simulate_revolution,
)
from core.rangefinder import RangeScan
from core.transforms import make_T, rot_z

from .fuzzing import call, finite, mutated, nasty, scalar

TABLE_N = np.array([0.0, 0.0, 1.0])
# The paper's box on the table (tests/core/modeling/conftest.py's box_scene).
CAM, T_WT = look_at_setup(np.array([0.0, 0.0, 0.07]), 1.4)
T_BOX = make_T(rot_z(np.radians(35.0)), [0.0, 0.0, 0.0])
FACES = simulate_box(
    CAM,
    SimWorld(T_WT, boxes=((T_BOX, (0.09, 0.094, 0.14)),)),
    T_BOX,
    np.array([0.09, 0.094, 0.14]),
    np.random.default_rng(0),
    step_quantize=False,
)
BOX_SCANS = simulate_box_scans(
    SimWorld(T_WT, boxes=((T_BOX, (0.09, 0.094, 0.14)),)), T_BOX, (0.09, 0.094, 0.14), np.random.default_rng(4)
)
# A cylinder (conftest.cylinder_scene).
CAM_C, T_WT_C = look_at_setup(np.array([0.0, 0.0, 0.083]), 1.3)
SOL = Revolution(np.zeros(3), np.array([0.0, 0.0, 0.166]), 0.051, 0.051)
SIL, SCANS = simulate_revolution(CAM_C, SimWorld(T_WT_C, solids=(SOL,)), SOL, np.random.default_rng(1))
# A prism (tests/core/modeling/test_polyhedron.py).
PRISM = BRep.prism(np.array([[0, 0], [0.12, 0.0], [0.03, 0.10]]), 0.08)
CAM_P, T_WT_P = look_at_setup(np.array([0.0, 0.0, 0.05]), 1.2, elevation_deg=35.0)
PRISM_W = PRISM.transformed(make_T(rot_z(0.6), [0.01, 0.02, 0.0]))
FP, FC, ES = simulate_polyhedron(CAM_P, SimWorld(T_WT_P, polyhedra=(PRISM_W,)), PRISM_W, np.random.default_rng(2))
FAST = settings(max_examples=60, deadline=None)
support = st.one_of(st.none(), st.builds(lambda n, d: Plane(n, d), mutated(TABLE_N), st.one_of(st.just(0.0), nasty)))


def _result(res) -> None:
    assert finite(res.T_world_obj) and res.T_world_obj.shape == (4, 4)
    assert all(np.isfinite(v) for v in res.dimensions.values())
    assert all(np.isfinite(v) for v in res.sigmas.values())
    assert finite(res.vertices_world) and finite(res.cov)


@FAST
@given(
    st.integers(0, len(FACES) - 1),
    mutated(FACES[0].points_world),
    mutated(FACES[0].edges_uv),
    support,
    st.one_of(st.just(1.0), scalar),
    st.sampled_from(["planes", "fused"]),
)
def test_model_box(k, points, edges, sup, sigma_px, method):
    faces = list(FACES)
    faces[k] = BoxFace(points, edges, None)
    res = call(model_box, CAM, faces, sup, sigma_px=sigma_px, method=method)
    if res is not None:
        _result(res)


@FAST
@given(
    st.integers(0, len(BOX_SCANS) - 1),
    mutated(BOX_SCANS[0].range_m),
    mutated(BOX_SCANS[0].pan_rad),
    mutated(T_WT),
    st.booleans(),
)
def test_model_box_with_scans(k, rho, pan, T_wt, with_support):
    scans = list(BOX_SCANS)
    n = min(len(rho), len(pan))
    scans[k] = call(RangeScan, pan[:n], BOX_SCANS[k].tilt_rad[:n], rho[:n])
    if scans[k] is None:
        return
    sup = Plane(TABLE_N, 0.0) if with_support else None
    res = call(model_box, CAM, FACES, sup, method="fused", scans=scans, T_world_turret=T_wt)
    if res is not None:
        _result(res)


@FAST
@given(
    mutated(SIL),
    st.integers(0, len(SCANS) - 1),
    mutated(SCANS[0].range_m),
    support,
    st.one_of(st.none(), mutated(TABLE_N)),
    st.one_of(st.just(1.0), scalar),
    st.sampled_from(["tangential", "bisecting", "rf_tangential", "fused"]),
    mutated(T_WT_C),
)
def test_model_cylinder(sil, k, rho, sup, axis, sigma_px, method, T_wt):
    scans = list(SCANS)
    scans[k] = call(RangeScan, scans[k].pan_rad[: len(rho)], scans[k].tilt_rad[: len(rho)], rho)
    if scans[k] is None:
        return
    res = call(
        model_cylinder,
        CAM_C,
        method,
        silhouettes_uv=sil,
        scans=scans,
        T_world_turret=T_wt,
        support=sup,
        axis_dir=axis,
        sigma_px=sigma_px,
    )
    if res is not None:
        _result(res)


@FAST
@given(st.sampled_from(sorted(FP)), st.sampled_from(sorted(ES)), support, st.one_of(st.just(1.0), scalar), st.data())
def test_model_polyhedron(face, edge, sup, sigma_px, data):
    fp = dict(FP)
    fp[face] = data.draw(mutated(FP[face]))
    es = dict(ES)
    es[edge] = data.draw(mutated(ES[edge]))
    fc = {f: c for f, c in FC.items() if f != face}
    res = call(
        model_polyhedron,
        CAM_P,
        PRISM.faces,
        face_points=fp,
        face_point_covs=fc,
        edge_segments=es,
        support=sup,
        support_faces=[0] if sup is not None else (),
        vertical_faces=[2, 3, 4],
        sigma_px=sigma_px,
    )
    if res is not None:
        _result(res)


@FAST
@given(
    mutated(FACES[0].points_world),
    st.one_of(st.none(), scalar),
    st.sampled_from(["tls", "ols"]),
    st.booleans(),
    st.one_of(st.none(), scalar),
)
def test_fit_face_plane(points, sigma_m, method, robust, threshold_m):
    fit = call(fit_face_plane, points, sigma_m=sigma_m, method=method, robust=robust, threshold_m=threshold_m)
    if fit is not None:
        assert (
            finite(fit.obs.plane.n) and finite(fit.obs.plane.d) and finite(fit.obs.cov) and fit.obs.cov.shape == (4, 4)
        )


@FAST
@given(mutated(FACES[0].edges_uv[0]), scalar)
def test_interpretation_plane_obs(seg, sigma_px):
    obs = call(interpretation_plane_obs, CAM, seg, sigma_px)
    if obs is not None:
        assert finite(obs.plane.n) and finite(obs.plane.d) and finite(obs.cov) and obs.cov.shape == (4, 4)
