"""Fuzz tests of core.calibration: non-finite, huge, tiny and degenerate inputs give a ValueError
or a finite result of the documented shape (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.calibration import (
    calibrate_dlt,
    calibrate_turret,
    calibrate_turret_planes,
    check_covariance,
    dlt,
    kabsch,
    perturbed_camera,
    perturbed_turret,
    principal_steps,
)
from core.pose.synthetic import paper_camera
from core.rangefinder import aim
from core.transforms import make_T, rot_z

from .fuzzing import call, finite, mutated, nasty, scalar

CAM = paper_camera()
_rng = np.random.default_rng(3)
UV = np.column_stack([_rng.uniform(20, 490, 10), _rng.uniform(20, 230, 10)])
X = CAM.backproject(UV, _rng.uniform(1.5, 2.5, 10))
T_TURRET = make_T(rot_z(0.3), [0.2, -0.5, 0.4])
PAN, TILT, RHO = aim(T_TURRET, X)
# Points on three walls (normals x, y, z) for the plane calibration.
N = np.repeat(np.eye(3), 3, axis=0)
P = _rng.uniform(0.2, 1.0, (9, 3))
P[np.arange(9), np.repeat(np.arange(3), 3)] = 1.5
D = -np.full(9, 1.5)
PAN_P, TILT_P, RHO_P = aim(T_TURRET, P)
FAST = settings(max_examples=100, deadline=None)


@FAST
@given(mutated(X), mutated(UV), st.one_of(st.none(), mutated(np.ones(10))), st.booleans())
def test_calibrate_dlt(Xm, uvm, sigma, refine):
    r = call(calibrate_dlt, Xm, uvm, 512, 256, refine=refine, sigma_px=sigma)
    if r is not None:
        cam, rms = r
        assert finite(cam.C) and finite(cam.center) and finite(rms) and finite(r.linear_rms_px)
        assert r.residuals_px.shape == (len(Xm), 2) and finite(r.residuals_px)
        if refine:
            assert r.cov.shape == (12, 12) and finite(r.cov) and finite(r.variance_factor)


@FAST
@given(scalar, scalar)
def test_calibrate_dlt_image_size(width, height):
    r = call(calibrate_dlt, X, UV, width, height, refine=False)
    if r is not None:
        assert r.camera.size == (width, height)


@FAST
@given(mutated(X), mutated(UV))
def test_dlt(Xm, uvm):
    C = call(dlt, Xm, uvm)
    if C is not None:
        assert C.shape == (3, 4) and finite(C)


@FAST
@given(mutated(X), mutated(X @ rot_z(0.4)[:3, :3].T + 1.0), st.one_of(st.none(), mutated(np.ones(10))))
def test_kabsch(Xb, Xa, w):
    T = call(kabsch, Xb, Xa, w)
    if T is not None:
        assert T.shape == (4, 4) and finite(T)


@FAST
@given(mutated(PAN), mutated(TILT), mutated(RHO), mutated(X))
def test_calibrate_turret(pan, tilt, rho, Xm):
    cal = call(calibrate_turret, pan, tilt, rho, Xm)
    if cal is not None:
        assert cal.T_world_turret.shape == (4, 4) and finite(cal.T_world_turret)
        assert cal.cov.shape == (6, 6) and finite(cal.cov) and finite(cal.rms_m) and finite(cal.residuals_m)


@FAST
@given(mutated(PAN_P), mutated(TILT_P), mutated(RHO_P), mutated(N), mutated(D), mutated(T_TURRET))
def test_calibrate_turret_planes(pan, tilt, rho, n, d, T0):
    cal = call(calibrate_turret_planes, pan, tilt, rho, n, d, T0)
    if cal is not None:
        assert cal.T_world_turret.shape == (4, 4) and finite(cal.T_world_turret)
        assert cal.cov.shape == (6, 6) and finite(cal.cov) and finite(cal.rms_m) and finite(cal.residuals_m)


@FAST
@given(mutated(np.diag([1e-4, 2e-4, 1e-3, 1e-6])), st.one_of(st.just(1e-9), nasty))
def test_covariance_steps(cov, floor):
    c = call(check_covariance, cov, 4, "cov")
    if c is not None:
        assert c.shape == (4, 4) and finite(c)
    steps = call(principal_steps, cov, floor)
    if steps is not None:
        assert steps.ndim == 2 and steps.shape[1] == len(cov) and finite(steps)


@FAST
@given(mutated(np.full(12, 1e-4)))
def test_perturbed_camera(delta):
    cam = call(perturbed_camera, CAM, delta)
    if cam is not None:
        assert finite(cam.C) and finite(cam.center)


@FAST
@given(mutated(T_TURRET), mutated(np.full(6, 1e-3)))
def test_perturbed_turret(T, delta):
    Tp = call(perturbed_turret, T, delta)
    if Tp is not None:
        assert Tp.shape == (4, 4) and finite(Tp)


def test_the_case_issue_14_found():
    """Near-collinear points at 1e12 m returned rms_px = nan."""
    Xc = np.outer(np.linspace(1.0, 2.0, 10), [1e12, 1e12, 1e12]) + np.random.default_rng(0).normal(size=(10, 3))
    with pytest.raises(ValueError, match=r"X_world must lie within ±1e\+06 m"):
        calibrate_dlt(Xc, UV, 512, 256)
