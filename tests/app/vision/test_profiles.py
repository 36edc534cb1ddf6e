"""app.vision.profiles: sub-pixel edges along normals."""

import numpy as np
import pytest

from app.vision.profiles import bilinear, search_along_normals, smooth, to_gray_f32


def _half_plane(n_dir, offset, size=(80, 100), k=16, lo=40.0, hi=200.0):
    """Grey image, brighter where n·(u, v) > offset, each pixel the area average over k × k sub-pixels."""
    H, W = size
    f = (np.arange(k) + 0.5) / k - 0.5
    u = (np.arange(W)[:, None] + f[None, :]).reshape(-1)
    v = (np.arange(H)[:, None] + f[None, :]).reshape(-1)
    inside = (n_dir[0] * u[None, :] + n_dir[1] * v[:, None]) > offset
    img = np.where(inside, hi, lo).reshape(H, k, W, k).mean(axis=(1, 3))
    return img.astype(np.float32)


@pytest.mark.parametrize("angle_deg", [0.0, 17.0, 45.0, 71.0, 133.0])
def test_finds_a_straight_step_edge_to_a_few_hundredths_of_a_pixel(angle_deg):
    a = np.radians(angle_deg)
    n = np.array([np.cos(a), np.sin(a)])
    centre = np.array([50.0, 40.0])
    offset = n @ centre + 0.37  # the edge passes 0.37 px beyond the centre along n
    img = smooth(_half_plane(n, offset), 1.0)
    t = np.array([-n[1], n[0]])
    P = centre + np.linspace(-15, 15, 31)[:, None] * t + np.random.default_rng(0).uniform(-3, 3, (31, 1)) * n
    hits = search_along_normals(img, P, np.tile(n, (31, 1)), 6.0)
    assert hits.found.all()
    edge = hits.points(P, np.tile(n, (31, 1)))
    dist = edge @ n - offset
    assert np.max(np.abs(dist)) < 0.06
    assert np.all(hits.strength > 0)  # brighter along +n
    # the opposite polarity finds nothing there
    none = search_along_normals(img, P, np.tile(n, (31, 1)), 6.0, polarity=-1)
    assert not none.found.any()


def test_prior_prefers_the_nearer_of_two_edges():
    # a bright stripe: a strong edge at v = 30 (+) and another at v = 36 (−)
    img = np.full((60, 60), 50.0, np.float32)
    img[30:36] = 250.0
    img = smooth(img, 1.0)
    P = np.array([[30.0, 35.0]])
    n = np.array([[0.0, 1.0]])
    near = search_along_normals(img, P, n, 8.0, prior_sigma_px=2.0)
    assert near.found[0] and abs(near.points(P, n)[0, 1] - 35.5) < 0.2  # the falling edge at 35.5
    rising = search_along_normals(img, P, n, 8.0, polarity=1)
    assert rising.found[0] and abs(rising.points(P, n)[0, 1] - 29.5) < 0.2


def test_samples_whose_window_leaves_the_image_are_not_found():
    img = smooth(_half_plane(np.array([1.0, 0.0]), 50.0), 1.0)
    P = np.array([[50.0, 40.0], [50.0, 1.0], [97.0, 40.0]])
    hits = search_along_normals(img, P, np.tile([1.0, 0.0], (3, 1)), 6.0)
    assert hits.found.tolist() == [True, True, False]
    assert np.isnan(hits.offset_px[2]) and hits.strength[2] == 0.0


def test_bilinear_and_gray_conversion():
    img = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert bilinear(img, np.array([1.5]), np.array([0.5]))[0] == pytest.approx(3.5)  # mean of 1, 2, 5, 6
    rgb = np.dstack([np.full((4, 5), 10, np.uint8)] * 3)
    g = to_gray_f32(rgb)
    assert g.shape == (4, 5) and g.dtype == np.float32 and np.allclose(g, 10)
    with pytest.raises(ValueError, match="grey"):
        to_gray_f32(np.zeros((2, 2)))
    with pytest.raises(ValueError, match="same shape"):
        search_along_normals(img, np.zeros((2, 2)), np.zeros((3, 2)), 2.0)
