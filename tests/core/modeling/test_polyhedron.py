import numpy as np
import pytest

from core.brep import BRep
from core.modeling import model_polyhedron
from core.modeling.simulate import SimWorld, look_at_setup, simulate_polyhedron
from core.transforms import make_T, rot_z

from .conftest import TABLE

SHAPES = {
    "box_parallel": (BRep.box(0.09, 0.094, 0.14), dict(parallel_faces=[(0, 1), (2, 4), (3, 5)])),
    "box_vertical": (BRep.box(0.09, 0.094, 0.14), dict(vertical_faces=[2, 3, 4, 5])),
    "prism": (BRep.prism(np.array([[0, 0], [0.12, 0.0], [0.03, 0.10]]), 0.08), dict(vertical_faces=[2, 3, 4])),
    "pyramid": (
        BRep.pyramid(np.array([[-0.08, -0.08], [0.08, -0.08], [0.08, 0.08], [-0.08, 0.08]]), np.array([0, 0, 0.06])),
        {},
    ),
}


def _setup(brep, yaw=0.6):
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.05]), 1.2, elevation_deg=35.0)
    Bw = brep.transformed(make_T(rot_z(yaw), [0.01, 0.02, 0.0]))
    return cam, T_wt, Bw, SimWorld(T_wt, polyhedra=(Bw,))


@pytest.mark.parametrize("name", list(SHAPES))
def test_polyhedron_noise_free_exact(name):
    brep, hints = SHAPES[name]
    cam, T_wt, Bw, world = _setup(brep)
    fp, fc, es = simulate_polyhedron(cam, world, Bw, None)
    res = model_polyhedron(
        cam, brep.faces, face_points=fp, face_point_covs=fc, edge_segments=es, support=TABLE, support_faces=[0], **hints
    )
    assert np.abs(res.vertices_world - Bw.vertices).max() < 1e-6
    assert np.abs(res.model_world().vertices - Bw.vertices).max() < 1e-6
    for a, b in brep.edges:
        key = f"edge_{min(a, b)}_{max(a, b)}"
        assert res.dimensions[key] == pytest.approx(np.linalg.norm(Bw.vertices[a] - Bw.vertices[b]), abs=1e-6)
        assert res.sigmas[key] > 0
    assert res.dimensions["height"] == pytest.approx(Bw.vertices[:, 2].max(), abs=1e-6)
    assert res.cov.shape == (3 * len(Bw.vertices),) * 2
    assert res.T_world_obj[2, 2] == pytest.approx(1.0)
    assert abs(res.residuals["clicks_px"]).max() < 1e-6


def test_hidden_vertices_need_a_hint_and_the_hint_completes_them():
    brep, hints = SHAPES["prism"]
    cam, T_wt, Bw, world = _setup(brep)
    fp, fc, es = simulate_polyhedron(cam, world, Bw, None)
    top = 1
    loop = brep.faces[top]
    top_edges = {(min(a, b), max(a, b)) for a, b in zip(loop, loop[1:] + loop[:1])}
    kw = dict(
        face_points={top: fp[top]},
        face_point_covs={top: fc[top]},
        edge_segments={e: es[e] for e in top_edges},
        support=TABLE,
        support_faces=[0],
    )
    # The top face and its outline fix the top; nothing says where the bottom corners are.
    with pytest.raises(ValueError, match="not fixed"):
        model_polyhedron(cam, brep.faces, **kw)
    # "A right prism standing on the table": its sides are vertical.
    res = model_polyhedron(cam, brep.faces, vertical_faces=[2, 3, 4], **kw)
    assert np.abs(res.vertices_world - Bw.vertices).max() < 1e-6
    assert sorted(res.details["completed_vertices"]) == [0, 1, 2]


def test_polyhedron_sigmas_match_scatter():
    brep, hints = SHAPES["box_parallel"]
    cam, T_wt, Bw, world = _setup(brep)
    rng = np.random.default_rng(3)
    errs, sig = [], []
    for _ in range(200):
        fp, fc, es = simulate_polyhedron(cam, world, Bw, rng)
        res = model_polyhedron(
            cam,
            brep.faces,
            face_points=fp,
            face_point_covs=fc,
            edge_segments=es,
            support=TABLE,
            support_faces=[0],
            support_sigma_m=1e-6,
            **hints,
        )
        errs.append(res.vertices_world - Bw.vertices)
        sig.append(np.sqrt(np.diag(res.cov)).reshape(-1, 3))
    # The scatter about the mean matches σ; the intersections of planes seen at grazing angles
    # are also biased (second order, up to ~0.8 σ on the far corners here): bounded below σ.
    std = np.std(errs, axis=0)
    bias = np.abs(np.mean(errs, axis=0))
    pred = np.sqrt(np.mean(np.square(sig), axis=0))
    big = pred > 1e-4  # coordinates pinned by the support have ~0 spread
    assert np.all(np.abs(std[big] / pred[big] - 1) < 0.2), (std, pred)
    assert np.all(bias[big] < pred[big]), (bias, pred)
    assert len(res.details["completed_vertices"]) == 1  # the hidden corner's σ is checked too


def test_polyhedron_error_paths():
    brep, hints = SHAPES["prism"]
    cam, T_wt, Bw, world = _setup(brep)
    fp, fc, es = simulate_polyhedron(cam, world, Bw, None)
    with pytest.raises(ValueError, match="not an edge"):
        model_polyhedron(cam, brep.faces, face_points=fp, edge_segments={(0, 4): es[next(iter(es))]})
    with pytest.raises(ValueError, match="without the support"):
        model_polyhedron(cam, brep.faces, face_points=fp, edge_segments=es, support_faces=[0])
    with pytest.raises(ValueError, match="out of range"):
        model_polyhedron(cam, brep.faces, face_points={99: fp[next(iter(fp))]}, edge_segments=es)
    with pytest.raises(ValueError, match="at least 3"):
        model_polyhedron(cam, brep.faces, face_points={1: fp[1][:2]}, edge_segments=es)
    with pytest.raises(ValueError, match="no vertex is fixed"):
        model_polyhedron(cam, brep.faces, face_points={}, edge_segments={})
