"""Free circular edges of a B-Rep (``Circle``): construction, drawing, pose baking, serialisation."""

import numpy as np
import pytest

from core.brep import BRep, Circle
from core.transforms import make_T, random_rotation


def test_circle_polyline_lies_on_the_circle():
    c = Circle([0.1, -0.2, 0.3], [0, 0, 2.0], 0.05)
    assert np.allclose(c.normal, [0, 0, 1])
    P = c.polyline(32)
    assert P.shape == (33, 3)
    assert np.allclose(np.linalg.norm(P - c.centre, axis=1), 0.05)
    assert np.allclose((P - c.centre) @ c.normal, 0.0)
    assert np.allclose(P[0], P[-1])


@pytest.mark.parametrize(
    "bad", [dict(normal=[0, 0, 0], radius=1.0), dict(normal=[0, 0, 1], radius=0.0), dict(normal=[0, 0, 1], radius=-1.0)]
)
def test_circle_rejects_bad_input(bad):
    with pytest.raises(ValueError):
        Circle([0, 0, 0], **bad)


def test_model_of_circles_alone_draws_them_and_round_trips():
    rng = np.random.default_rng(0)
    m = BRep(np.zeros((0, 3)), np.zeros((0, 2)), circles=(Circle([0, 0, 0.1], [0, 1, 0], 0.04),))
    T = make_T(random_rotation(rng), rng.normal(size=3))
    wf = m.wireframe(np.array([0.0, -3.0, 0.0]), T, n_circle=24)
    assert wf.segments.shape == (24, 2, 3) and wf.visible.all() and set(wf.kind) == {"circle"}
    world = m.transformed(T)
    cw = world.circles[0]
    assert np.allclose(cw.centre, T[:3, :3] @ [0, 0, 0.1] + T[:3, 3]) and np.allclose(cw.normal, T[:3, 1])
    assert np.allclose(np.linalg.norm(wf.segments.reshape(-1, 3) - cw.centre, axis=1), 0.04)
    assert np.allclose((wf.segments.reshape(-1, 3) - cw.centre) @ cw.normal, 0.0)
    assert BRep.from_dict(m.to_dict()) == m
    assert "circles" not in BRep.box(1, 1, 1).to_dict()
    assert m != BRep(np.zeros((0, 3)), np.zeros((0, 2)), circles=(Circle([0, 0, 0.1], [0, 1, 0], 0.05),))
    b = m.bounds()
    assert np.allclose(b[:, 1], [0, 0]) and np.isclose(b[1, 0], 0.04, atol=1e-3)
