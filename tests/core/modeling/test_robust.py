import numpy as np
import pytest

from core.modeling.robust import object_runs, ransac_plane


def test_ransac_finds_the_plane_among_outliers():
    rng = np.random.default_rng(0)
    X = np.column_stack([rng.uniform(-1, 1, 40), rng.uniform(-1, 1, 40), rng.normal(0, 0.001, 40)])
    out = rng.uniform(-1, 1, (10, 3)) + [0, 0, 0.5]
    mask = ransac_plane(np.vstack([X, out]), 0.005)
    assert mask[:40].all()
    assert not mask[40:].any()


def test_ransac_small_sets_use_every_triple_and_bad_threshold_raises():
    X = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.0], [0.5, 0.5, 0.3]])
    mask = ransac_plane(X, 0.01)
    assert mask.tolist() == [True, True, True, True, False]
    with pytest.raises(ValueError, match="threshold"):
        ransac_plane(X, 0.0)


def test_object_runs_split_on_misses_and_jumps():
    rho = np.array([np.nan, 1.0, 1.01, 1.02, 1.5, 1.51, np.nan, 2.0])
    assert object_runs(rho, 0.05) == [(1, 4), (4, 6), (7, 8)]
    with pytest.raises(ValueError):
        object_runs(rho, -1.0)
