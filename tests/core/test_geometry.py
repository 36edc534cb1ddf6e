import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from core.geometry import (
    Line,
    Plane,
    angle_between_planes,
    bisecting_planes,
    closest_points_lines,
    distance_lines,
    distance_point_line,
    fit_plane_ols,
    fit_plane_tls,
    intersect_line_plane,
    intersect_planes,
    line_from_points,
    make_plane,
    plane_from_points,
    plane_through_point,
    point_from_planes,
    project_onto_plane,
    signed_distance,
)

finite = st.floats(-5.0, 5.0, allow_nan=False)
vec3 = st.lists(finite, min_size=3, max_size=3).map(np.array)


def test_plane_from_points_contains_them_and_is_unit():
    rng = np.random.default_rng(0)
    A, B, C = rng.normal(size=(3, 3))
    p = plane_from_points(A, B, C)
    assert np.linalg.norm(p.n) == pytest.approx(1.0)
    np.testing.assert_allclose(signed_distance(p, np.array([A, B, C])), 0.0, atol=1e-12)
    n, d = p  # a plane unpacks as (n, d)
    assert np.allclose(n, p.n) and d == p.d


def test_plane_from_collinear_points_raises():
    with pytest.raises(ValueError, match="collinear"):
        plane_from_points([0, 0, 0], [1, 1, 1], [2, 2, 2])


def test_make_plane_normalises_and_rejects_zero_normal():
    p = make_plane([0, 0, 2], -4)
    assert np.allclose(p.n, [0, 0, 1]) and p.d == pytest.approx(-2)
    with pytest.raises(ValueError, match="non-zero normal"):
        make_plane([0, 0, 0], 1)


def test_signed_distance_sign_and_projection():
    p = plane_through_point([0, 0, 1], [0, 0, 1])
    assert signed_distance(p, np.array([3.0, 4.0, 2.5])) == pytest.approx(1.5)
    assert signed_distance(p, np.array([0.0, 0.0, 0.0])) == pytest.approx(-1.0)
    np.testing.assert_allclose(project_onto_plane(p, np.array([[1, 2, 7.0]])), [[1, 2, 1]])


@given(vec3, vec3, vec3, vec3)
@settings(max_examples=60, deadline=None)
def test_intersect_planes_line_lies_on_both(n1, n2, X1, X2):
    if np.linalg.norm(n1) < 1e-3 or np.linalg.norm(n2) < 1e-3:
        return
    p1, p2 = plane_through_point(n1, X1), plane_through_point(n2, X2)
    if np.linalg.norm(np.cross(p1.n, p2.n)) < 1e-3:
        with pytest.raises(ValueError) if np.linalg.norm(np.cross(p1.n, p2.n)) < 1e-9 else _nullcontext():
            intersect_planes(p1, p2)
        return
    line = intersect_planes(p1, p2)
    pts = line.at(np.array([-2.0, 0.0, 3.0]))
    scale = 1.0 + np.abs(pts).max()
    assert np.abs(signed_distance(p1, pts)).max() < 1e-9 * scale
    assert np.abs(signed_distance(p2, pts)).max() < 1e-9 * scale
    assert np.linalg.norm(line.direction) == pytest.approx(1.0)


class _nullcontext:
    def __enter__(self):
        return self

    def __exit__(self, *a):
        return False


def test_parallel_planes_raise():
    with pytest.raises(ValueError, match="parallel"):
        intersect_planes(make_plane([0, 0, 1], 0), make_plane([0, 0, 2], 1))


def test_line_plane_intersection_and_parallel_case():
    line = Line(np.array([0.0, 0, 5]), np.array([0.0, 0, -1]))
    X = intersect_line_plane(line, make_plane([0, 0, 1], -1))
    np.testing.assert_allclose(X, [0, 0, 1])
    with pytest.raises(ValueError, match="parallel"):
        intersect_line_plane(Line(np.zeros(3), np.array([1.0, 0, 0])), make_plane([0, 0, 1], -1))


def test_point_from_planes_exact_and_least_squares():
    rng = np.random.default_rng(3)
    X = rng.normal(size=3)
    planes = [plane_through_point(rng.normal(size=3), X) for _ in range(6)]
    np.testing.assert_allclose(point_from_planes(planes), X, atol=1e-12)
    # Noisy offsets: the covariance predicts the scatter of the solution.
    sigma = 0.01
    normals = np.array([p.n for p in planes])
    sols = []
    for _ in range(2000):
        noisy = [Plane(p.n, p.d + sigma * rng.normal()) for p in planes]
        sols.append(point_from_planes(noisy))
    _, cov = point_from_planes(planes, weights=np.full(6, 1 / sigma**2), return_cov=True)
    emp = np.cov(np.array(sols).T)
    np.testing.assert_allclose(np.diag(emp), np.diag(cov), rtol=0.15)
    assert normals.shape == (6, 3)


def test_point_from_planes_degenerate_raises():
    with pytest.raises(ValueError, match="at least 3"):
        point_from_planes([make_plane([0, 0, 1], 0)] * 2)
    planes = [make_plane([1, 0, 0], 0), make_plane([0, 1, 0], 0), make_plane([1, 1, 0], 0)]
    with pytest.raises(ValueError, match="do not span"):
        point_from_planes(planes)


def test_bisecting_planes_are_equidistant():
    rng = np.random.default_rng(4)
    p1 = plane_through_point(rng.normal(size=3), rng.normal(size=3))
    p2 = plane_through_point(rng.normal(size=3), rng.normal(size=3))
    b1, b2 = bisecting_planes(p1, p2)
    line = intersect_planes(p1, p2)
    for b, sign in ((b1, 1.0), (b2, -1.0)):
        # Points of the bisector are (signed-)equidistant from both planes.
        e = np.cross(b.n, line.direction)
        pts = line.point + np.outer([0.5, -1.3, 2.0], e) + np.outer([0.0, 1.0, -1.0], line.direction)
        np.testing.assert_allclose(signed_distance(b, pts), 0.0, atol=1e-12)
        np.testing.assert_allclose(signed_distance(p1, pts), sign * signed_distance(p2, pts), atol=1e-12)
    assert abs(b1.n @ b2.n) < 1e-12  # the two bisectors are perpendicular
    with pytest.raises(ValueError, match="parallel"):
        bisecting_planes(make_plane([0, 0, 1], 0), make_plane([0, 0, 1], 1))


def test_distances_between_points_and_lines():
    l1 = line_from_points([0, 0, 0], [1, 0, 0])
    l2 = line_from_points([0, 1, 2], [0, 2, 2])
    assert distance_point_line(np.array([3.0, 4.0, 0.0]), l1) == pytest.approx(4.0)
    assert distance_lines(l1, l2) == pytest.approx(2.0)
    A, B = closest_points_lines(l1, l2)
    np.testing.assert_allclose(A, [0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(B, [0, 0, 2], atol=1e-12)
    # Parallel lines: distance between them.
    assert distance_lines(l1, line_from_points([0, 3, 0], [5, 3, 0])) == pytest.approx(3.0)
    with pytest.raises(ValueError, match="coincide"):
        line_from_points([1, 1, 1], [1, 1, 1])
    assert angle_between_planes(make_plane([0, 0, 1], 0), make_plane([0, 1, 1], 0)) == pytest.approx(np.pi / 4)


def _points_on_plane(rng, plane_n, plane_point, n, spread=0.2):
    plane = plane_through_point(plane_n, plane_point)
    e1 = np.cross(plane.n, [1.0, 0.3, 0.1])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(plane.n, e1)
    uv = rng.uniform(-spread, spread, size=(n, 2))
    return plane, plane_point + uv[:, :1] * e1 + uv[:, 1:] * e2


@pytest.mark.parametrize("fit", [fit_plane_ols, fit_plane_tls])
def test_plane_fits_exact_without_noise(fit):
    rng = np.random.default_rng(5)
    plane, X = _points_on_plane(rng, [0.2, -0.1, 1.0], np.array([0.3, 0.1, 1.5]), 12)
    f = fit(X)
    sign = np.sign(f.plane.n @ plane.n)
    np.testing.assert_allclose(sign * f.plane.n, plane.n, atol=1e-12)
    assert sign * f.plane.d == pytest.approx(plane.d, abs=1e-12)
    assert f.rms_m < 1e-12 and f.cov.shape == (4, 4) and f.residuals_m.shape == (12,)


def test_ols_is_the_papers_form():
    rng = np.random.default_rng(6)
    X = rng.uniform(-1, 1, size=(20, 3))
    X[:, 2] = -(0.3 * X[:, 0] - 0.2 * X[:, 1] + 0.5)  # z = -(a x + b y + d)
    f = fit_plane_ols(X)
    np.testing.assert_allclose(f.params, [0.3, -0.2, 0.5], atol=1e-12)
    assert f.method == "ols"


def test_ols_rejects_vertical_face_tls_accepts_it():
    rng = np.random.default_rng(7)
    _, X = _points_on_plane(rng, [1.0, 0.0, 0.0], np.array([2.0, 0.0, 0.0]), 15)
    with pytest.raises(ValueError, match="fit_plane_tls"):
        fit_plane_ols(X)
    assert abs(fit_plane_tls(X).plane.n[0]) == pytest.approx(1.0)


@pytest.mark.parametrize("fit", [fit_plane_ols, fit_plane_tls])
def test_plane_fit_covariance_matches_scatter(fit):
    """Monte Carlo: the predicted covariance of (n, d) matches the observed scatter within 20 %."""
    rng = np.random.default_rng(8)
    plane, X0 = _points_on_plane(rng, [0.1, 0.2, 1.0], np.array([0.0, 0.0, 1.2]), 30)
    sigma = 0.005
    ests, covs = [], []
    for _ in range(600):
        X = X0 + plane.n * sigma * rng.normal(size=(len(X0), 1))
        f = fit(X, sigma_m=sigma)
        v = f.plane.as_vector() * np.sign(f.plane.n @ plane.n)
        ests.append(v)
        covs.append(f.cov)
    emp = np.cov(np.array(ests).T)
    pred = np.mean(covs, axis=0)
    # Compare the variance of the offset and of the normal's in-plane tilt.
    assert emp[3, 3] == pytest.approx(pred[3, 3], rel=0.2)
    assert np.trace(emp[:3, :3]) == pytest.approx(np.trace(pred[:3, :3]), rel=0.2)


def test_plane_fit_estimates_sigma_from_residuals():
    rng = np.random.default_rng(9)
    plane, X0 = _points_on_plane(rng, [0.0, 0.3, 1.0], np.zeros(3), 400)
    X = X0 + plane.n * 0.01 * rng.normal(size=(400, 1))
    assert fit_plane_tls(X).sigma_m == pytest.approx(0.01, rel=0.1)
    assert fit_plane_ols(X).sigma_m == pytest.approx(0.01, rel=0.1)


def test_plane_fit_bad_input():
    with pytest.raises(ValueError, match="at least 3"):
        fit_plane_tls(np.zeros((2, 3)))
    with pytest.raises(ValueError, match="collinear"):
        fit_plane_tls(np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3.0]]))
    with pytest.raises(ValueError, match="NaN"):
        fit_plane_ols(np.array([[0, 0, 0], [1, 0, 0], [0, 1, np.nan]]))
    with pytest.raises(ValueError, match="shape"):
        fit_plane_tls(np.zeros((5, 2)))


# ---------------------------------------------------------------------------- hull_overlap
def _cube(c, s):
    g = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float) - 0.5
    return np.asarray(c, float) + s * g


def test_hull_overlap_of_two_unit_cubes_matches_the_exact_volume():
    from core.geometry import hull_overlap

    A = _cube([0, 0, 0], 1.0)
    for shift, exact in [(0.0, 1.0), (0.25, 0.75), (0.5, 0.5), (0.9, 0.1), (1.5, 0.0)]:
        got = hull_overlap(A, _cube([shift, 0, 0], 1.0))
        assert abs(got - exact) < 0.03, (shift, got)
    # A inside a bigger B: all of it; B's share inside A: (1/2)^3
    assert hull_overlap(A, _cube([0, 0, 0], 2.0)) == 1.0
    assert abs(hull_overlap(_cube([0, 0, 0], 2.0), A) - 0.125) < 0.02


def test_hull_overlap_of_a_rotated_box_and_a_flat_or_apart_hull():
    from core.geometry import hull_overlap
    from core.transforms import rot_z

    R = rot_z(np.radians(45.0))
    A = _cube([0, 0, 0], 1.0) @ R.T  # a cube turned 45° about z inside the cube of side √2
    assert hull_overlap(A, _cube([0, 0, 0], np.sqrt(2.0) + 1e-9)) == 1.0
    # the turned cube's corners stick out of the axis-aligned unit cube: inside share 2(√2-1) ≈ 0.83
    assert abs(hull_overlap(A, _cube([0, 0, 0], 1.0)) - 2 * (np.sqrt(2) - 1)) < 0.03
    flat = _cube([0, 0, 0], 1.0) * np.array([1, 1, 0])
    assert hull_overlap(A, flat) == 0.0 and hull_overlap(flat, A) == 0.0
    with pytest.raises(ValueError):
        hull_overlap(A[:3], A)
