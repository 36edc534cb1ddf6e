"""app.vision.matching: clicked image edges assigned to model edges without being told which."""

import numpy as np
import pytest

from app.vision.matching import edge_symmetries, match_edges, p3l_all_triples, same_drawing
from app.vision.synthetic import render_poses
from core.brep import BRep
from core.camera import Camera
from core.transforms import exp_so3, make_T, pose_error

K = np.array([[500.0, 0.0, 255.5], [0.0, 500.0, 127.5], [0.0, 0.0, 1.0]])
BOX = (0.35, 0.231, 0.132)


def _camera():
    return Camera.from_intrinsics(K, np.eye(4), 512, 256)


def _clicks(cam, box, T, edges, rng=None, sigma=0.0):
    out = []
    for k in edges:
        a, b = cam.project(box.edge_segments(T)[k])
        seg = np.array([a + 0.2 * (b - a), a + 0.8 * (b - a)])
        if rng is not None:
            seg = seg + rng.normal(0.0, sigma, (2, 2))
        out.append(seg)
    return np.array(out)


def _right(box, edges, truth):
    return any(np.array_equal(p[truth], edges) for p in edge_symmetries(box))


T_TRUE = make_T(exp_so3([2.0, 0.6, -0.5]), [0.03, -0.02, 2.0])


def test_box_symmetries():
    assert len(edge_symmetries(BRep.box(*BOX))) == 4  # identity and three half-turns
    assert len(edge_symmetries(BRep.box(0.1, 0.1, 0.1))) == 24  # the cube's rotation group
    p = edge_symmetries(BRep.box(*BOX))
    assert np.array_equal(p[0], np.arange(12)) and all(sorted(q.tolist()) == list(range(12)) for q in p)


def test_batched_p3l_contains_the_true_pose():
    cam = _camera()
    box = BRep.box(*BOX)
    wf = box.wireframe(cam.center, T_TRUE)
    vis = [k for k in range(12) if wf.visible[k]]
    pick = [vis[0], vis[2], vis[4]]
    segs = _clicks(cam, box, T_TRUE, pick)
    out = p3l_all_triples(cam, segs, box.vertices[box.edges])
    assert out.n_triples > 1000 and out.R.shape == (len(out.t), 3, 3) and out.edges.shape == (len(out.t), 3)
    mine = np.flatnonzero(np.all(out.edges == pick, axis=1))
    errs = [pose_error(make_T(out.R[i], out.t[i]), T_TRUE) for i in mine]
    assert min(e[0] for e in errs) < 1e-5 and min(e[1] for e in errs) < 1e-7
    # one triple per family of symmetric triples: a quarter for a box, the truth still drawn
    sym = p3l_all_triples(cam, segs, box.vertices[box.edges], edge_symmetries(box))
    assert sym.n_triples == out.n_triples // 4
    assert any(same_drawing(cam, box, make_T(R, t), T_TRUE, 1e-6) for R, t in zip(sym.R, sym.t))
    with pytest.raises(ValueError, match=r"\(3, 2, 2\)"):
        p3l_all_triples(cam, segs[:2], box.vertices[box.edges])


def test_finds_the_assignment_from_four_exact_clicks():
    cam = _camera()
    box = BRep.box(*BOX)
    wf = box.wireframe(cam.center, T_TRUE)
    vis = [k for k in range(12) if wf.visible[k] and np.linalg.norm(np.subtract(*cam.project(wf.segments[k]))) > 30]
    pick = np.array(vis[:4])
    res = match_edges(cam, box, _clicks(cam, box, T_TRUE, pick), sigma_px=0.3)
    assert res.candidates, "no candidate"
    best = res.candidates[0]
    assert _right(box, best.edges, pick)
    assert same_drawing(cam, box, best.T_world_obj, T_TRUE, 0.05)
    assert best.rms_px < 1e-3 and np.isnan(best.image_px) and best.score_px == best.rms_px
    assert best.T_world_obj.shape == (4, 4) and best.edges.shape == (4,)
    assert [c.score_px for c in res.candidates] == sorted(c.score_px for c in res.candidates)
    assert res.n_triples > 0 and res.n_poses > 0 and len(res.bases) >= 1 and res.total_s >= res.p3l_s


def test_the_image_picks_the_right_one_of_noisy_clicks():
    rng = np.random.default_rng(4)
    cam = _camera()
    box = BRep.box(*BOX)
    wf = box.wireframe(cam.center, T_TRUE)
    vis = [k for k in range(12) if wf.visible[k] and np.linalg.norm(np.subtract(*cam.project(wf.segments[k]))) > 30]
    pick = np.array(vis[:4])
    segs = _clicks(cam, box, T_TRUE, pick, rng, 1.0)
    img = render_poses(cam, box, [T_TRUE], noise_sigma=2.0)[0]
    res = match_edges(cam, box, segs, image=img, sigma_px=1.0)
    best = res.candidates[0]
    assert _right(box, best.edges, pick)
    # settled on the image's edges: the pose is as precise as the image allows
    assert same_drawing(cam, box, best.T_world_obj, T_TRUE, 1.0)
    assert best.image_px < 0.6 and best.score_px == pytest.approx(best.rms_px + best.image_px)


def test_bad_input():
    cam = _camera()
    box = BRep.box(*BOX)
    segs = _clicks(cam, box, T_TRUE, [0, 1, 2, 3])
    with pytest.raises(ValueError, match="S ≥ 3"):
        match_edges(cam, box, segs[:2])
    with pytest.raises(ValueError, match="coincide"):
        match_edges(cam, box, np.concatenate([segs, np.zeros((1, 2, 2))]))
    with pytest.raises(ValueError, match="Camera"):
        match_edges(K, box, segs)
    with pytest.raises(ValueError, match="meet in one point"):
        # three segments through one pixel
        star = np.array(
            [[[100.0, 100.0], [150.0, 100.0]], [[100.0, 100.0], [100.0, 150.0]], [[100.0, 100.0], [150.0, 150.0]]]
        )
        match_edges(cam, box, star)


def test_image_distances_of_many_poses_are_edge_distances():
    """The batched first measure of the candidates (all poses at once) is ``edge_distance`` per pose."""
    from app.vision import matching
    from app.vision.evaluate import edge_distance, oriented_edges

    rng = np.random.default_rng(7)
    cam = _camera()
    box = BRep.box(*BOX)
    oe = oriented_edges(render_poses(cam, box, [T_TRUE], noise_sigma=2.0)[0])
    Ts = [T_TRUE] + [
        make_T(
            exp_so3(rng.normal(0.0, 1.5, 3)), [rng.uniform(-0.15, 0.15), rng.uniform(-0.1, 0.1), rng.uniform(1.5, 2.5)]
        )
        for _ in range(12)
    ]
    Ts.append(make_T(np.eye(3), [0.0, 0.0, -2.0]))  # behind the camera: nothing measured
    Ts = np.array(Ts)
    for step in (2.0, 4.0):
        got = matching._image_distances(oe, cam, box, matching._Faces.of(box), Ts, step)
        want = np.array([edge_distance(oe, cam, box, T, step_px=step).mean_px for T in Ts])
        assert np.array_equal(np.isnan(got), np.isnan(want)) and np.isnan(got[-1])
        np.testing.assert_allclose(got[~np.isnan(got)], want[~np.isnan(want)], rtol=0, atol=1e-9)
    cyl = BRep.cylinder(0.05, 0.2)  # a solid of revolution: measured one pose at a time, the same way
    got = matching._image_distances(oe, cam, cyl, matching._Faces.of(cyl), Ts[:3], 4.0)
    want = [edge_distance(oe, cam, cyl, T, step_px=4.0).mean_px for T in Ts[:3]]
    np.testing.assert_allclose(got, want, rtol=0, atol=0)


def test_only_the_best_candidates_settle_on_the_image(monkeypatch):
    """With the frame, at most ``settle`` candidates take a tracker step; the others are ranked by
    their clicks' RMS plus their image distance where they are; the best is the one settling all finds."""
    from app.vision import matching
    from app.vision.evaluate import edge_distance

    cam = _camera()
    box = BRep.box(*BOX)
    pick = np.array([2, 3, 9, 10])  # four visible edges whose noisy clicks several assignments fit
    assert box.wireframe(cam.center, T_TRUE).visible[pick].all()
    segs = _clicks(cam, box, T_TRUE, pick, np.random.default_rng(0), 1.0)
    img = render_poses(cam, box, [T_TRUE], noise_sigma=2.0)[0]
    calls = []
    real = matching._settle
    monkeypatch.setattr(matching, "_settle", lambda *a, **k: calls.append(1) or real(*a, **k))
    every = match_edges(cam, box, segs, image=img, sigma_px=1.0, settle=None)
    n_every = len(calls)
    calls.clear()
    some = match_edges(cam, box, segs, image=img, sigma_px=1.0)
    assert (
        len(calls) <= 4 and len(calls) < n_every and n_every >= len(every.candidates) >= 5 and len(some.candidates) >= 5
    )
    assert np.array_equal(some.candidates[0].edges, every.candidates[0].edges) and _right(
        box, some.candidates[0].edges, pick
    )
    np.testing.assert_allclose(some.candidates[0].T_world_obj, every.candidates[0].T_world_obj, atol=1e-12)
    calls.clear()
    match_edges(cam, box, segs, image=img, sigma_px=1.0, settle=0)
    assert not calls
    # those not settled are measured where the clicks put them (every 4 px), the settled every 2 px
    at4 = [
        abs(c.image_px - edge_distance(img, cam, box, c.T_world_obj, step_px=4.0).mean_px) < 1e-9
        for c in some.candidates
    ]
    at2 = [abs(c.image_px - edge_distance(img, cam, box, c.T_world_obj).mean_px) < 1e-9 for c in some.candidates]
    assert sum(at4) >= len(some.candidates) - 4 and all(a or b for a, b in zip(at4, at2))
    assert all(c.score_px == pytest.approx(c.rms_px + c.image_px) for c in some.candidates)
