"""Fuzz tests of core.camera: non-finite, huge, tiny and degenerate inputs give a ValueError or a
finite result of the documented shape (issue 14)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.camera import Camera, as_segment, as_uv
from core.pose.synthetic import paper_camera

from .fuzzing import call, finite, mutated, scalar

CAM = paper_camera()
X = np.array([[0.1, 0.45, 0.1], [0.3, 0.5, 0.0], [-0.2, 0.6, 0.2], [0.0, 0.3, 0.05]])
UV = CAM.project(X)
SEG = UV[:2]
FAST = settings(max_examples=100, deadline=None)


def _valid_camera(cam) -> None:
    assert isinstance(cam, Camera)
    assert cam.C.shape == (3, 4) and finite(cam.C)
    assert cam.center.shape == (3,) and finite(cam.center)
    assert isinstance(cam.width, int) and cam.width > 0 and isinstance(cam.height, int) and cam.height > 0
    K, T = cam.decompose()
    assert finite(K) and finite(T)
    assert isinstance(repr(cam), str)


@FAST
@given(
    mutated(CAM.C), st.one_of(scalar, st.just(512)), st.one_of(scalar, st.just(256)), st.one_of(st.none(), mutated(X))
)
def test_camera(C, width, height, in_front):
    cam = call(Camera, C, width, height, in_front=in_front)
    if cam is not None:
        _valid_camera(cam)


@FAST
@given(mutated(CAM.decompose()[0]), mutated(CAM.decompose()[1]))
def test_from_intrinsics(K, T):
    cam = call(Camera.from_intrinsics, K, T, 512, 256)
    if cam is not None:
        _valid_camera(cam)


@FAST
@given(mutated(X))
def test_project_depth(Xm):
    uv = call(CAM.project, Xm)
    if uv is not None:
        assert uv.shape == Xm.shape[:-1] + (2,) and finite(uv)
    s = call(CAM.depth, Xm)
    if s is not None:
        assert np.shape(s) == Xm.shape[:-1] and finite(s)


@FAST
@given(mutated(X), mutated(CAM.decompose()[1]))
def test_project_obj(Xm, T):
    uv = call(CAM.project_obj, T, Xm)
    if uv is not None:
        assert uv.shape == Xm.shape[:-1] + (2,) and finite(uv)


@FAST
@given(mutated(UV), st.one_of(scalar, mutated(np.full(len(UV), 2.0))))
def test_rays_backproject_planes(uvm, depth):
    out = call(CAM.rays, uvm)
    if out is not None:
        o, d = out
        assert o.shape == (3,) and d.shape == (len(uvm), 3) and finite(o) and finite(d)
    Xb = call(CAM.backproject, uvm, depth)
    if Xb is not None:
        assert Xb.shape == (len(uvm), 3) and finite(Xb)
    planes = call(CAM.pixel_planes, uvm)
    if planes is not None:
        assert [p.shape for p in planes] == [(len(uvm), 3), (len(uvm),)] * 2 and finite(planes)
    e = call(CAM.reprojection_errors, X[: len(uvm)] if len(uvm) <= len(X) else X, uvm)
    if e is not None:
        assert e.shape == (len(uvm),) and finite(e)
    m = call(CAM.in_image, uvm)
    if m is not None:
        assert m.dtype == bool


@FAST
@given(mutated(SEG))
def test_segments(seg):
    for f in (as_segment, Camera.image_line):
        out = call(f, seg)
        if out is not None:
            assert finite(out)
    plane = call(CAM.interpretation_plane, seg)
    if plane is not None:
        assert finite(plane.n) and finite(plane.d) and abs(np.linalg.norm(plane.n) - 1.0) < 1e-9


@FAST
@given(mutated(UV))
def test_as_uv(uvm):
    out = call(as_uv, uvm)
    if out is not None:
        assert out.shape == (len(uvm), 2) and finite(out)


def test_the_cases_issue_14_found():
    """Each returned a camera with an all-NaN C, or raised OverflowError."""
    for kwargs in (dict(in_front=[]), dict(in_front=[[np.nan, 0.0, 0.0]])):
        with pytest.raises(ValueError, match="in_front"):
            Camera(CAM.C, 512, 256, **kwargs)
    with pytest.raises(ValueError, match="width must be a positive finite integer.*got inf"):
        Camera(CAM.C, np.inf, 256)
