"""The renderer: deterministic frames, exact area coverage at edges, edges where C projects them."""

import dataclasses

import numpy as np
import pytest

from app.render import Renderer, lattice_offsets, value_noise
from app.render.measure import edge_offsets, polygon_coverage, top_down_scene, visible_edges
from app.render.raycast import SceneCaster
from app.scene import default_scene_path, load_scene, scene_from_dict


@pytest.fixture(scope="module")
def workcell():
    return load_scene(default_scene_path())


@pytest.fixture(scope="module")
def workcell_t16(workcell):
    """The workcell's renderer and its noise-free image and labels at t = 16 s (rendered once)."""
    r = Renderer(workcell)
    clean, labels = r.render_float(16.0)
    return r, clean, labels


def test_lattice_offsets_fill_the_pixel():
    off = lattice_offsets(89)
    assert off.shape == (89, 2) and off.min() >= -0.5 and off.max() < 0.5
    assert len(np.unique(np.floor((off[:, 0] + 0.5) * 89))) == 89  # one sample per column stratum
    assert abs(off[:, 1].mean()) < 0.02
    with pytest.raises(ValueError, match="at least one sample"):
        lattice_offsets(0)


def test_value_noise_is_deterministic_bounded_and_smooth():
    rng = np.random.default_rng(0)
    X = rng.uniform(-1, 1, (2000, 3))
    a, b = value_noise(X, 0.05), value_noise(X, 0.05)
    assert np.array_equal(a, b) and np.all(np.abs(a) <= 1.0) and a.std() > 0.1
    near = value_noise(X + 1e-4, 0.05)
    assert np.abs(near - a).max() < 0.05  # 1e-4 m against a 5 cm feature size
    assert not np.array_equal(value_noise(X, 0.05, salt=1), a)


def test_frames_are_deterministic(tmp_path, small_scene_dict):
    scene = scene_from_dict(small_scene_dict, tmp_path)
    r = Renderer(scene)
    f1 = r.render(0.3, 3)
    f2 = Renderer(scene).render(0.3, 3)  # a new renderer: nothing cached
    assert f1.dtype == np.uint8 and f1.shape == (64, 96)
    assert np.array_equal(f1, f2)
    f3 = r.render(0.3, 4)  # the same scene, another frame's sensor noise
    diff = f3.astype(float) - f1
    assert 1.5 < diff.std() < 4.0  # two independent draws of σ = 2 grey levels: σ√2 ≈ 2.8 before rounding
    bgr = r.render_bgr(0.3, 3)
    assert bgr.shape == (64, 96, 3) and np.array_equal(bgr[:, :, 0], f1) and np.array_equal(bgr[:, :, 2], f1)
    moved = Renderer(scene).render(0.7, 3)  # the box has moved: another image where it was and is, same noise elsewhere
    changed = moved != f1
    assert 100 < changed.sum() < 0.5 * changed.size
    assert np.array_equal(moved[:10], f1[:10])  # the far background is untouched
    with pytest.raises(ValueError, match="non-negative integer"):
        r.render(0.3, -1)


@pytest.mark.parametrize("yaw_deg", [0.0, 17.0, 41.0, 58.3])
def test_edge_pixels_carry_their_exact_area_coverage(yaw_deg):
    scene = scene_from_dict(top_down_scene(yaw_deg, -0.0031), ".")
    img, _ = Renderer(scene).render_float(0.0)
    # Flat shading: the box's image is the convex hull of its projected corners; each pixel's
    # exact coverage is the area of that hull clipped to the pixel's square.
    body = scene.bodies[0]
    T = body.pose_at(0.0)
    uv = scene.camera.project(body.model.vertices @ T[:3, :3].T + T[:3, 3])
    cover = polygon_coverage(uv, *scene.camera.size)
    expected = 200.0 * (0.1 + (0.8 - 0.1) * cover)
    mixed = (cover > 1e-12) & (cover < 1 - 1e-12)
    assert mixed.sum() >= 20
    err = np.abs(img - expected)
    assert err[~mixed].max() < 1e-6
    # 89 lattice samples a pixel resolve the coverage to a few 1/89ths of the contrast (140 grey
    # levels), without bias: each pixel shifts the lattice (measured: max 3.1 %, mean 0.9 %).
    e = (img - expected)[mixed] / 140.0
    assert np.abs(e).max() < 0.035
    assert np.abs(e).mean() < 0.01
    assert abs(e.mean()) < 0.005


def test_measurements_on_a_synthetic_step():
    img = np.zeros((20, 30))
    img[:, 11:] = 100.0
    img[:, 10] = 100.0 * 0.2  # an edge at u = 10.3: pixel 10 is 20 % bright
    np.testing.assert_allclose(edge_offsets(img, [[10.3, 2.0], [10.3, 18.0]]), 0.0, atol=1e-12)
    np.testing.assert_allclose(
        edge_offsets(img, [[10.0, 2.0], [10.0, 18.0]]), -0.3, atol=1e-12
    )  # edge right of p0→p1 down
    cover = polygon_coverage([[10.3, -5.0], [40.0, -5.0], [40.0, 40.0], [10.3, 40.0]], 30, 20)
    np.testing.assert_allclose(cover, img / 100.0, atol=1e-12)
    tri = polygon_coverage([[0.0, 0.0], [4.0, 0.0], [0.0, 4.0]], 6, 6)
    assert abs(tri.sum() - 8.0) < 1e-12  # the area of the triangle


def test_rendered_edges_lie_where_C_projects_the_true_edges(workcell, workcell_t16):
    r, clean, _ = workcell_t16
    frame = r.render(16.0, 192)
    edges = list(visible_edges(workcell, r, 16.0))
    assert len(edges) >= 15
    worst_clean, worst_frame = 0.0, 0.0
    for _name, _k, uv in edges:
        o_clean = edge_offsets(clean, uv)
        o_frame = edge_offsets(frame, uv)
        worst_clean = max(worst_clean, abs(o_clean.mean()))
        worst_frame = max(worst_frame, abs(o_frame.mean()))
    # Noise-free, the edge's image is exact to a few hundredths of a pixel; with the sensor's
    # blur (σ 0.5 px) and noise (σ 2 grey levels) a 9-sample mean stays well within 0.2 px.
    assert worst_clean < 0.06, worst_clean
    assert worst_frame < 0.2, worst_frame


def test_cylinder_silhouettes_lie_where_C_projects_them(workcell):
    # Flat shading isolates geometry: with Lambert shading the lit lateral surface adds its own
    # gradient inside the contour (a real camera sees that too).
    flat = Renderer(workcell, spec=dataclasses.replace(workcell.render, ambient=1.0))
    clean, _ = flat.render_float(0.0)
    sil = [e for e in visible_edges(workcell, flat, 0.0, kinds=("silhouette",)) if e[0] == "unknown_cylinder"]
    assert len(sil) == 2
    for _, _, uv in sil:
        assert abs(edge_offsets(clean, uv).mean()) < 0.03


def test_labels_and_depth_agree_with_the_caster(workcell, workcell_t16):
    r, _, labels = workcell_t16
    uv = np.array([[300.0, 140.0], [20.0, 20.0], [256.0, 250.0]])
    h = SceneCaster.for_scene(workcell, 16.0).cast(workcell.camera.center, r.rays(uv))
    names = [workcell.bodies[b].name for b in h.body]
    assert names[0] == "unknown_cylinder" and names[1] in ("back_wall", "floor")
    for (u, v), b, f in zip(uv.astype(int), h.body, h.face):
        assert labels[v, u] == b * 4096 + f
    X = workcell.camera.center + h.t[:, None] * r.rays(uv)
    np.testing.assert_allclose(workcell.camera.depth(X), h.t, atol=1e-9)  # t is the depth s
    np.testing.assert_allclose(workcell.camera.project(X), uv, atol=1e-9)
