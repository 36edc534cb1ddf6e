import numpy as np
import pytest

from core.geometry import make_plane
from core.modeling.observations import PlaneObs
from core.modeling.vertices import solve_vertices


def _obs(n, d, s=0.001):
    p = make_plane(n, d)
    cov = np.zeros((4, 4))
    cov[3, 3] = s**2
    return PlaneObs(p, cov, "p")


def test_vertices_exact_and_shared_planes_correlate():
    planes = [_obs([1, 0, 0], -1), _obs([0, 1, 0], -2), _obs([0, 0, 1], -3), _obs([1, 1, 0], -3.5)]
    X, cov, res, J = solve_vertices(planes, [[0, 1, 2], [1, 2, 3]], return_jacobian=True)
    assert np.allclose(X[0], [1, 2, 3], atol=1e-12)
    assert np.allclose(X[1], [1.5, 2, 3], atol=1e-12)
    assert J.shape == (6, 16)
    assert abs(cov[1, 4]) > 0  # both lie on plane 1 (y = 2): correlated y
    assert cov[1, 1] == pytest.approx(1e-6)


def test_vertex_errors():
    planes = [_obs([1, 0, 0], 0), _obs([0, 1, 0], 0), _obs([1, 1, 0], 0)]
    with pytest.raises(ValueError, match="only 2"):
        solve_vertices(planes, [[0, 1]])
    with pytest.raises(ValueError, match="nearly parallel to one line"):
        solve_vertices(planes, [[0, 1, 2]], names=["A"])
