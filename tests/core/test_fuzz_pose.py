"""Fuzz tests of core.pose: non-finite, huge, tiny and degenerate inputs give a ValueError or a
finite result of the documented shape (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.brep import BRep
from core.pose import (
    edge_symmetries,
    estimate_pose,
    nearest_twin,
    p3l,
    p3l_batch,
    plausibility,
    refine,
    symmetry_transforms,
)
from core.pose.synthetic import PAPER_BOX_M, paper_problems

from .fuzzing import call, finite, mutated, nasty, scalar

PB = paper_problems(np.random.default_rng(5), 1, sigma_px=0.5)[0]
CAM, T_TRUE, EDGES, SEGS = PB.camera, PB.T_world_obj, PB.edges_obj, PB.segs_uv
T_START = T_TRUE.copy()
T_START[:3, 3] += 0.01
BOX = BRep.box(*PAPER_BOX_M)
PTS_OBJ = BOX.vertices[:2]
PTS_UV = CAM.project_obj(T_TRUE, PTS_OBJ)
FAST = settings(max_examples=100, deadline=None)
sigma = st.one_of(scalar, st.just(0.5), mutated(np.full(len(SEGS), 0.5)))


def _pose(T) -> None:
    assert T.shape == (4, 4) and finite(T)
    assert np.allclose(T[:3, :3].T @ T[:3, :3], np.eye(3), atol=1e-6)


@FAST
@given(mutated(SEGS[:3]), mutated(EDGES[:3]), st.booleans(), mutated(PTS_UV), mutated(PTS_OBJ))
def test_p3l(segs, edges, with_points, puv, pobj):
    sols = call(p3l, CAM, segs, edges, *((puv, pobj) if with_points else ()))
    if sols is not None:
        assert isinstance(sols, list)
        for T in sols:
            _pose(T)


@FAST
@given(mutated(SEGS[:3]), mutated(np.stack([EDGES[:3], EDGES[1:4]])))
def test_p3l_batch(segs, edges):
    out = call(p3l_batch, CAM, segs, edges)
    if out is not None:
        T, valid = out
        assert T.shape[:1] + T.shape[2:] == (len(edges), 4, 4) and valid.shape == T.shape[:2]
        assert finite(T[valid])


@FAST
@given(
    mutated(SEGS),
    mutated(EDGES),
    mutated(T_START),
    sigma,
    st.one_of(st.just(3.0), scalar),
    st.sampled_from(["l2", "huber"]),
)
def test_refine(segs, edges, T0, sigma_px, huber_px, loss):
    r = call(refine, CAM, T0, segs_uv=segs, edges_obj=edges, sigma_px=sigma_px, huber_px=huber_px, loss=loss)
    if r is not None:
        _pose(r.T_world_obj)
        assert r.cov.shape == (6, 6) and finite(r.cov) and finite(r.rms_px)


@FAST
@given(
    mutated(SEGS[:5]),
    mutated(EDGES[:5]),
    st.one_of(st.none(), mutated(T_START)),
    sigma,
    st.one_of(st.none(), scalar),
    st.one_of(st.just(50), scalar),
)
def test_estimate_pose(segs, edges, prior, sigma_px, fit_rms_px, max_triples):
    if np.ndim(sigma_px) == 1:
        sigma_px = sigma_px[:5]
    est = call(
        estimate_pose,
        CAM,
        segs,
        edges,
        T_prior=prior,
        sigma_px=sigma_px,
        fit_rms_px=fit_rms_px,
        max_triples=max_triples,
    )
    if est is not None:
        _pose(est.T_world_obj if hasattr(est, "T_world_obj") else est.best.T_world_obj)
        assert finite(est.result.cov) and finite(est.result.rms_px)
        for c in est.candidates:
            _pose(c.T_start)


@FAST
@given(mutated(T_TRUE), st.one_of(st.none(), scalar), st.one_of(st.just(np.inf), scalar))
def test_plausibility(T, rms_px, max_rms_px):
    why = call(plausibility, CAM, BOX, T, rms_px, max_rms_px)
    if why is not None:
        assert isinstance(why, str)


@FAST
@given(st.tuples(*[st.one_of(st.floats(1e-6, 1e6), nasty)] * 3), st.one_of(st.just(1e-6), scalar))
def test_symmetries(size, rel_tol):
    model = call(BRep.box, *size)
    if model is None:
        return
    perms = call(edge_symmetries, model, rel_tol)
    if perms is not None:
        assert all(p.shape == (len(model.edges),) for p in perms)
    st_ = call(symmetry_transforms, model)
    if st_ is not None:
        for _, S in st_:
            assert S.shape == (4, 4) and finite(S)


@FAST
@given(
    mutated(T_TRUE),
    mutated(np.array([0.0, 3.0, 5.0])),
    mutated(T_START),
    st.one_of(st.none(), st.dictionaries(st.integers(-2, 4), st.integers(-2, 20), max_size=2)),
)
def test_nearest_twin(T, edges, T_ref, hand):
    out = call(nearest_twin, BOX, T, edges, T_ref, hand)
    if out is not None:
        T2, e2 = out
        _pose(T2)
        assert e2.shape == np.shape(edges)


def test_the_cases_issue_14_found():
    """A coordinate of 1e200 raised OverflowError; sigma_px=1e-200 gave an all-NaN covariance."""
    huge = EDGES.copy()
    huge[0, 0, 0] = 1e200
    with pytest.raises(ValueError, match=r"edges_obj must lie within .*1e\+200"):
        p3l(CAM, SEGS[:3], huge[:3])
    with pytest.raises(ValueError, match=r"edges_obj must lie within .*1e\+200"):
        refine(CAM, T_START, segs_uv=SEGS, edges_obj=huge)
    with pytest.raises(ValueError, match=r"edges_obj must lie within .*1e\+200"):
        estimate_pose(CAM, SEGS, huge)
    with pytest.raises(ValueError, match="sigma_px .* got 1e-200"):
        refine(CAM, T_START, segs_uv=SEGS, edges_obj=EDGES, sigma_px=1e-200)
