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
        star = np.array([[[100.0, 100.0], [150.0, 100.0]], [[100.0, 100.0], [100.0, 150.0]], [[100.0, 100.0], [150.0, 150.0]]])
        match_edges(cam, box, star)
