"""One-click pose search (app.vision.search): the workcell video's moved parallelepiped found from one
click, with and without the table hint; a rendered cylinder on the table; clicks on nothing refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from app.scene import default_scene_path, load_scene
from app.vision.search import Cancelled, NoPoseFits, heading_period, rests_on, search_pose
from app.vision.sequence import iter_frames
from core.brep import BRep
from core.geometry import Plane
from core.transforms import make_T, pose_error, rot_z


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


@pytest.fixture(scope="module")
def table(scene):
    body = scene.body("table")
    T = body.T_world_obj
    top = T[:3, :3] @ np.array([0.0, 0.0, body.model.bounds()[1][2]]) + T[:3, 3]
    return Plane(T[:3, 2], float(-T[:3, 2] @ top))


def frame(scene, t_s: float):
    k = int(round(t_s * scene.video.fps))
    return next(iter_frames(scene.video.path, k, 1))[1], k / scene.video.fps


def centre_pixel(scene, body, T):
    return scene.camera.project_obj(T, body.model.vertices).mean(axis=0)


def test_the_large_move_is_found_from_one_click_on_the_table(scene, table):
    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    T_true, T_old = box.pose_at(t), box.pose_at(0.0)
    assert pose_error(T_true, T_old)[0] > 50.0  # the 55° move: beyond any tracker's reach
    assert rests_on(box.model, T_old, table)
    uv = centre_pixel(scene, box, T_true) + [6.0, -3.0]
    res = search_pose(scene.camera, box.model, T_old, uv, image, table=table, name="parallelepiped")
    assert res.mode == "table"
    best = res.candidates[0]
    deg, m = pose_error(best.T_world_obj, T_true)  # the twin nearest the old pose: the truth itself
    assert deg < 1.0 and m < 0.005, (deg, m)
    assert best.fit_px < 1.0 and best.support_px <= 1.5
    assert np.all(best.std_t_mm < 5.0) and np.all(best.std_r_deg < 1.0)
    fits = [c.fit_px for c in res.candidates]
    assert fits == sorted(fits)


def test_a_small_move_is_found_without_the_table_hint(scene):
    box = scene.body("parallelepiped")
    image, t = frame(scene, 20.0)
    T_true, T_old = box.pose_at(t), box.pose_at(16.5)  # the 6° / 3.6 cm move
    uv = centre_pixel(scene, box, T_true)
    res = search_pose(scene.camera, box.model, T_old, uv, image, table=None, name="parallelepiped")
    assert res.mode == "free"
    deg, m = pose_error(res.candidates[0].T_world_obj, T_true)
    assert deg < 1.0 and m < 0.005, (deg, m)


def test_a_turn_beyond_the_free_searchs_reach_is_refused_saying_its_reach(scene):
    """No table: the 55° move is beyond the free search's 30° reach. The click is on the box: the refusal says the
    reach and what to do instead, not that the click was elsewhere (a new user read that on their cube)."""
    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    uv = centre_pixel(scene, box, box.pose_at(t))
    with pytest.raises(NoPoseFits, match="with no table under it, the search turns it at most 30° .*click its edges"):
        search_pose(scene.camera, box.model, box.pose_at(0.0), uv, image, table=None, name="parallelepiped")


@pytest.mark.parametrize("where", ["table", "unknown_box", "unknown_cylinder"])
def test_a_click_on_nothing_or_on_another_object_finds_no_pose(scene, table, where):
    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    if where == "table":
        uv = scene.camera.project(np.array([[0.3, -0.3, 0.0]]))[0]
    else:
        other = scene.body(where)
        uv = scene.camera.project_obj(other.pose_at(t), np.array([[0.0, 0.0, 0.05]]))[0]
    with pytest.raises(NoPoseFits, match="no pose of the parallelepiped fits the image near your click"):
        search_pose(scene.camera, box.model, box.pose_at(0.0), uv, image, table=table, name="parallelepiped")


@pytest.mark.parametrize("t_s", [16.5, 20.0, 24.0])
def test_another_objects_model_on_the_parallelepiped_finds_no_pose(scene, table, t_s):
    """The operator selected the box but double-clicked the parallelepiped: the box's model fits a corner
    of it (a third of its outline matched); refused (at a mismatch limit of 0.70 it was found in these
    frames)."""
    box, para = scene.body("unknown_box"), scene.body("parallelepiped")
    image, t = frame(scene, t_s)
    uv = centre_pixel(scene, para, para.pose_at(t))
    # what to do, not "click on the box itself", which a click on the object also read (a new operator's on real data)
    with pytest.raises(NoPoseFits, match="no pose of the box fits the image near your click: try another spot on"):
        search_pose(scene.camera, box.model, box.pose_at(0.0), uv, image, table=table, name="box")


def test_bad_input_and_cancel(scene, table):
    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    with pytest.raises(ValueError, match="outside the image"):
        search_pose(scene.camera, box.model, box.pose_at(0.0), [-5.0, 10.0], image, table=table)
    with pytest.raises(ValueError, match="camera is 512×256"):
        search_pose(scene.camera, box.model, box.pose_at(0.0), [100.0, 100.0], image[:100], table=table)
    with pytest.raises(Cancelled):
        search_pose(
            scene.camera,
            box.model,
            box.pose_at(0.0),
            centre_pixel(scene, box, box.pose_at(t)),
            image,
            table=table,
            cancel=lambda: True,
        )


def test_heading_period_follows_the_model_symmetries_about_the_vertical():
    up = np.array([0.0, 0.0, 1.0])
    assert heading_period(BRep.box(0.35, 0.231, 0.132), np.eye(3), up) == pytest.approx(np.pi)
    assert heading_period(BRep.box(0.2, 0.2, 0.1), rot_z(0.3), up) == pytest.approx(np.pi / 2)
    assert heading_period(BRep.cylinder(0.05, 0.16), np.eye(3), up) == 0.0  # the heading is not seen
    wedge = BRep.prism(np.array([[0.0, 0.0], [0.2, 0.0], [0.0, 0.1]]), 0.1)
    assert heading_period(wedge, np.eye(3), up) == pytest.approx(2 * np.pi)


def test_a_rendered_cylinder_moved_on_the_table_is_found(scene, table):
    from app.render.renderer import Renderer

    cyl = scene.body("unknown_cylinder")
    T_old = cyl.pose_at(0.0)
    T_new = make_T(np.eye(3), [0.25, -0.35, 0.0])
    bodies = tuple(
        dataclasses.replace(b, T_world_obj=T_new, motion=()) if b.name == cyl.name else b for b in scene.bodies
    )
    sc = dataclasses.replace(scene, bodies=bodies, render=dataclasses.replace(scene.render, aa_samples=4))
    image = Renderer(sc).render(0.0, 3)
    uv = scene.camera.project_obj(T_new, np.array([[0.01, 0.0, 0.09]]))[0]
    res = search_pose(scene.camera, cyl.model, T_old, uv, image, table=table, name="cylinder")
    T = res.candidates[0].T_world_obj
    axis_deg = np.degrees(np.arccos(np.clip(T[:3, 2] @ [0.0, 0.0, 1.0], -1, 1)))
    assert axis_deg < 1.0 and np.linalg.norm(T[:3, 3] - T_new[:3, 3]) < 0.005, (axis_deg, T[:3, 3])


def test_a_partly_hidden_parallelepiped_is_found_on_the_table_with_a_true_sigma(scene, table):
    """A third of the moved parallelepiped hidden by a grey board (its top face and back edges): the
    refinement on the table's three unknowns finds it within 1° / 5 mm, its σ covers the error, and the
    candidates come ranked by mismatch. Before (the edge tracker settling the pose, and a check that
    counted hidden edges against it) this placement was refused."""
    from app.render.renderer import Renderer

    box = scene.body("parallelepiped")
    T_new = make_T(rot_z(np.radians(40.0)), [0.05, -0.3, 0.0])
    bodies = tuple(
        dataclasses.replace(b, T_world_obj=T_new, motion=()) if b.name == box.name else b for b in scene.bodies
    )
    sc = dataclasses.replace(scene, bodies=bodies, render=dataclasses.replace(scene.render, aa_samples=4))
    image = np.array(Renderer(sc).render(0.0, 5))
    uv = scene.camera.project_obj(T_new, box.model.vertices)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    cut = int(lo[1] + 0.33 * (hi[1] - lo[1]))
    image[: cut + 3, int(lo[0]) - 3 : int(hi[0]) + 3] = 120  # the board: from above the object to a third of it
    click = np.array([0.5 * (lo[0] + hi[0]), 0.5 * (cut + hi[1])])
    res = search_pose(scene.camera, box.model, box.pose_at(0.0), click, image, table=table, name="parallelepiped")
    best = res.candidates[0]
    deg, m = min(
        (pose_error(best.T_world_obj @ S, T_new) for S in (np.eye(4), make_T(rot_z(np.pi), [0, 0, 0]))),
        key=lambda e: e[0],
    )
    assert deg < 1.0 and m < 0.005, (deg, m)
    assert best.confidence < 0.9  # part of it is hidden indeed
    err_mm = 1000.0 * np.abs(
        best.T_world_obj[:3, 3] - T_new[:3, 3]
    )  # the pose is the truth's, not its twin's (deg < 1)
    assert np.all(err_mm[:2] <= 3.0 * np.maximum(best.std_t_mm[:2], 1e-3)), (err_mm, best.std_t_mm)
    mism = [c.mismatch for c in res.candidates]
    assert mism == sorted(mism) and 0.0 <= mism[0] < 0.7


def test_the_camera_calibration_share_of_a_found_pose_matches_a_perturbed_camera(scene, table):
    """The covariance the camera's calibration adds to a found pose (``camera_cov``) is the linearised
    move of the refinement's solution with C: checked against refining again with C moved along one
    direction (rank-one camera_cov), and it enlarges the σ the search reports."""
    from app.vision import search as S
    from app.vision.profiles import smooth, to_gray_f32
    from core.camera import Camera
    from core.pose.uncertainty import Priors

    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    T_true, T_old = box.pose_at(t), box.pose_at(0.0)
    uv = centre_pixel(scene, box, T_true)
    plain = search_pose(scene.camera, box.model, T_old, uv, image, table=table).candidates[0]
    C = scene.camera.C
    d = np.random.default_rng(0).normal(size=12) * 1e-3 * np.abs(C).ravel()
    with_cam = search_pose(
        scene.camera, box.model, T_old, uv, image, table=table, camera_cov=np.outer(d, d)
    ).candidates[0]
    assert np.max(with_cam.std_t_mm) > np.max(plain.std_t_mm)
    # the linearised share against the refinement redone with C + d
    sp = S._TableSpace(S.level_on(box.model, T_old, table), table)
    pts = S._support_points(box.model)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    z0 = -table.d - float((((pts - centre) @ sp.R_old.T) @ sp.up).min())
    space = S._OnTable(sp, z0, centre, 3)
    img_s = smooth(to_gray_f32(image), 1.0)
    T0, _ = S._refine(scene.camera, box.model, plain.T_world_obj, img_s, space, False)
    share = S._prior_share(scene.camera, box.model, T0, img_s, space, False, Priors(np.outer(d, d), 0.0))
    moved = Camera(C + d.reshape(3, 4), scene.camera.width, scene.camera.height)
    T1, _ = S._refine(moved, box.model, T0, img_s, space, False)
    dt = T1[:3, 3] - T0[:3, 3]
    predicted = np.sqrt(np.diag(share)[:3])  # rank one: |the predicted move| per axis
    assert np.linalg.norm(dt) > 2e-4  # the move is real (metres)
    assert np.allclose(np.abs(dt), predicted, rtol=0.3, atol=2e-5), (dt, predicted)


def test_a_camera_share_that_cannot_be_computed_leaves_the_sigma_unknown(scene, table, monkeypatch):
    """Where the camera's share cannot be linearised (too few edges found at the final pose), the pose's σ
    is unknown (the interface then says so), not the image's σ alone as if it held."""
    from app.vision import search as S

    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    monkeypatch.setattr(S, "_prior_share", lambda *a, **k: None)
    c = search_pose(
        scene.camera,
        box.model,
        box.pose_at(0.0),
        centre_pixel(scene, box, box.pose_at(t)),
        image,
        table=table,
        camera_cov=np.eye(12) * 1e-8,
    ).candidates[0]
    assert c.cov is None and np.all(np.isnan(c.std_t_mm)) and np.all(np.isnan(c.std_r_deg))


def test_an_image_edge_is_given_to_the_nearer_of_two_parallel_model_edges():
    """_own_edges: two model edges drawn 2 px apart and parallel both find one image edge: the farther
    one's samples are dropped; samples of one edge, or of edges that meet at an angle, are kept."""
    from app.vision.search import _own_edges

    y = np.arange(0.0, 20.0, 2.0)
    n = len(y)
    near = np.column_stack([np.full(n, 100.0), y])  # edge 0 at x = 100, its image edge at x = 100.1
    far = np.column_stack([np.full(n, 102.0), y + 1.0])  # edge 1 at x = 102: finds the same image edge
    uv = np.vstack([near, far])
    normals = np.tile([1.0, 0.0], (2 * n, 1))
    r = np.concatenate([np.full(n, 0.1), np.full(n, -1.9)])
    groups = np.repeat([0, 1], n)
    keep = _own_edges(uv, normals, r, groups)
    assert keep[:n].all() and not keep[n:].any()
    assert _own_edges(uv, normals, r, np.zeros(2 * n, int)).all()  # one edge: nothing to share
    corner = np.vstack([np.column_stack([y, np.full(n, 50.0)]), np.column_stack([np.full(n, 0.0), 50.0 + y])])
    nc = np.vstack([np.tile([0.0, 1.0], (n, 1)), np.tile([1.0, 0.0], (n, 1))])
    assert _own_edges(corner, nc, np.zeros(2 * n), groups).all()  # edges meeting at a corner keep theirs


def test_a_box_with_a_face_seen_edge_on_and_a_third_hidden_is_found_on_the_table(scene, table):
    """bench/search.py (b), unknown_box #20: the box's left face is seen nearly edge-on (3 px wide) and
    lit as its front face, so the image shows one edge where the model draws two; the right third is
    hidden by a grey board. The edge that both model edges found pulled the heading 2.9° off (σ 0.4°),
    a pose that fitted better than the truth until an image edge was given to one model edge only and
    the best poses' headings were stepped (``_own_edges``, ``_heading_profile``)."""
    from app.render.renderer import Renderer

    box = scene.body("unknown_box")
    T_new = make_T(rot_z(np.radians(102.14)), [-0.1198, -0.496, 0.0])
    bodies = tuple(
        dataclasses.replace(b, T_world_obj=T_new, motion=())
        if b.name == box.name
        else dataclasses.replace(b, T_world_obj=b.pose_at(0.0), motion=())
        for b in scene.bodies
    )
    sc = dataclasses.replace(scene, bodies=bodies, render=dataclasses.replace(scene.render, aa_samples=8, seed=1))
    image = np.array(Renderer(sc).render(0.0, 0))
    image[111:189, 211:232] = 102  # the board over the box's right third (rows and columns from the bench's case)
    res = search_pose(
        scene.camera, box.model, box.pose_at(0.0), np.array([207.6, 121.1]), image, table=table, name="box"
    )
    deg, m = pose_error(res.candidates[0].T_world_obj, T_new)
    assert deg < 1.0 and m < 0.005, (deg, m)


def test_a_long_box_with_one_end_behind_a_board_is_not_found_slid_to_the_board(scene, table):
    """bench/search.py (b) seed 1, parallelepiped #23: its left end hidden by a dark board, whose border
    stands in for the box's end. There the refined starts all lay slid 65-117 mm along its length and
    the pose offered was 85 mm off. The slides (``_slides``) step a found pose along its footprint's axes
    and refine again: from that pose they reach the truth, which fits better."""
    from app.render.renderer import Renderer
    from app.vision import search as S
    from app.vision.evaluate import oriented_edges
    from app.vision.profiles import smooth, to_gray_f32

    box = scene.body("parallelepiped")
    T_new = make_T(rot_z(np.radians(10.126)), [0.086406, 0.240628, 0.0])
    bodies = tuple(
        dataclasses.replace(b, T_world_obj=T_new, motion=())
        if b.name == box.name
        else dataclasses.replace(b, T_world_obj=b.pose_at(0.0), motion=())
        for b in scene.bodies
    )
    sc = dataclasses.replace(
        scene, bodies=bodies, render=dataclasses.replace(scene.render, aa_samples=8, seed=109730574)
    )
    image = np.array(Renderer(sc).render(0.0, 23))  # the bench's frame
    image[18:84, 224:261] = np.clip(60 + np.random.default_rng(0).normal(0, 2.0, (66, 37)), 0, 255).astype(
        np.uint8
    )  # the board

    def err(T):
        return min(
            (pose_error(T @ S_, T_new) for S_ in (np.eye(4), make_T(rot_z(np.pi), [0, 0, 0]))), key=lambda e: e[0]
        )

    c = search_pose(
        scene.camera, box.model, box.pose_at(0.0), np.array([305.8848, 54.0240]), image, table=table
    ).candidates[0]
    deg, m = err(c.T_world_obj)
    assert deg < 1.0 and m < 0.005, (deg, m)
    # the pose the bench offered: slid 85 mm along the box's length, its left end on the board's border
    sp = S._TableSpace(box.pose_at(0.0), table)
    pts = S._support_points(box.model)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    z0 = -table.d - float((((pts - centre) @ sp.R_old.T) @ sp.up).min())
    oe, img_s = oriented_edges(image), smooth(to_gray_f32(image), 1.0)
    slid = T_new.copy()
    slid[:3, 3] += 0.085 * T_new[:3, 0]
    space = S._OnTable(sp, z0, centre, 3)
    T, cov = S._refine(scene.camera, box.model, slid, img_s, space, False)
    wrong = S._check(scene.camera, box.model, T, oe, img_s, False, cov, 1.0)
    assert wrong is not None and err(wrong.T_world_obj)[1] > 0.05  # it fits: the board's border taken for the end
    better = S._slides(scene.camera, box.model, wrong, oe, img_s, sp, z0, centre)
    assert better is not None and better.mismatch < wrong.mismatch
    deg, m = err(better.T_world_obj)
    assert deg < 1.0 and m < 0.005, (deg, m)


def test_refine_from_a_given_pose_is_the_search_last_stage(scene, table):
    """``refine_from``: the bench's anchor (what the image allows a placement). From the truth shifted
    4 mm and turned 1° it returns to the truth, on the table and free; on a blank frame it is refused."""
    from app.vision.search import refine_from

    box = scene.body("parallelepiped")
    image, t = frame(scene, 16.5)
    T_true = box.pose_at(t)
    start = T_true @ make_T(rot_z(np.radians(1.0)), [0.004, 0.0, 0.0])
    for hint in (table, None):
        c = refine_from(scene.camera, box.model, start, image, table=hint)
        assert c is not None
        deg, m = pose_error(c.T_world_obj, T_true)
        assert deg < 0.3 and m < 0.002, (hint, deg, m)
        assert np.all(c.std_t_mm < 5.0) and c.mismatch < 0.5
    assert refine_from(scene.camera, box.model, T_true, np.full_like(image, 90), table=table) is None


def test_a_click_just_beside_the_box_offers_the_box_said_to_be_beside(scene, table):
    """A double click 15 px left of the parallelepiped (a new operator's): the poses under the click lie half
    on it and half on the floor (turned 90°, 84 mm off, mismatch 0.48, and was offered as the only pose); the
    pose beside the click fits far better and is offered first, marked as beside the click."""
    box = scene.body("parallelepiped")
    image, t = frame(scene, 11.0)
    T_true = box.pose_at(t)
    uv = scene.camera.project_obj(T_true, box.model.vertices)
    click = np.array([uv[:, 0].min() - 15.0, 0.5 * (uv[:, 1].min() + uv[:, 1].max())])
    res = search_pose(scene.camera, box.model, box.pose_at(16.0), click, image, table=table)
    best = res.candidates[0]
    deg, m = pose_error(best.T_world_obj, T_true)
    assert best.beside_click and deg < 1.0 and m < 0.005, (deg, m)
    assert all(not c.beside_click for c in res.candidates[1:])
    # a click on the box itself: found under the click, not marked
    res = search_pose(scene.camera, box.model, box.pose_at(16.0), uv.mean(axis=0), image, table=table)
    assert not res.candidates[0].beside_click and pose_error(res.candidates[0].T_world_obj, T_true)[0] < 1.0


@pytest.mark.parametrize("k", [3, 2])
def test_the_refinement_jacobian_on_the_table_is_the_derivative_of_the_projection(scene, table, k):
    """``_normal_jacobian`` (what the refinement on the table uses) against central differences of the
    projected points along their normals, for x, y, heading (k = 3) and x, y with the heading held (k = 2)."""
    from app.vision import search as S

    box = scene.body("parallelepiped")
    T = box.pose_at(0.0)
    sp = S._TableSpace(T, table)
    pts = S._support_points(box.model)
    centre = 0.5 * (pts.min(axis=0) + pts.max(axis=0))
    space = S._OnTable(sp, S._centre_height(pts, centre, sp, table), centre, k, psi=0.3)
    p = space.params(T) + np.array([0.004, -0.003, 0.05])[:k]
    rng = np.random.default_rng(0)
    X = rng.uniform(-1.0, 1.0, (20, 3)) * np.ptp(box.model.vertices, axis=0) / 2 + centre
    a = rng.uniform(0.0, 2.0 * np.pi, 20)
    normals = np.column_stack([np.cos(a), np.sin(a)])
    J = S._normal_jacobian(scene.camera, space.pose(p), X, normals, space.G(space.pose(p)))
    for j in range(k):
        dp = np.zeros(k)
        dp[j] = 1e-6
        moved = scene.camera.project_obj(space.pose(p + dp), X) - scene.camera.project_obj(space.pose(p - dp), X)
        want = np.einsum("ni,ni->n", moved / 2e-6, normals)
        assert np.allclose(J[:, j], want, rtol=1e-5, atol=1e-6 * np.abs(want).max()), (j, J[:, j], want)
    assert np.abs(J).max() > 1.0  # pixels per metre or radian: not all zero


def test_the_real_teabox_is_found_from_one_click_where_the_camera_moved(shared_data):
    """The held-out ViSP tea box, close (0.45 m) and printed: its pose from the four clicks on frame 0, the camera
    moved since (frames 0-24: the pose 0.9-1.1° and 1-16 mm off the tracker's). A click on the box finds it, within
    0.6° and 1 mm of the tracker's pose. Before, every click was refused: the free search's coarse poses lie 100 px and
    more apart on so close an object, and none led to it; the old pose (and it moved onto the click) now start too."""
    from app.models_io import read_cao
    from app.vision.pnp import solve_pnp
    from app.vision.sequence import read_init_points
    from app.vision.track import EdgeTracker
    from core.camera import Camera
    from tests.app.vision.test_track import TEABOX_CLICKS, TEABOX_K

    folder = shared_data("visp-teabox")
    model = read_cao(folder / "teabox.cao")
    cam = Camera.from_intrinsics(TEABOX_K, np.eye(4), 640, 480)
    T0 = solve_pnp(TEABOX_K, read_init_points(folder / "teabox.init"), TEABOX_CLICKS, 640, 480).T_cam_world
    tracker = EdgeTracker(cam, model, T0)
    for i, image in iter_frames(folder / "teabox.mp4", 0, 25):
        T_track, _, lost = tracker.track(image)
        assert not lost
        if i in (0, 12, 24):
            uv = cam.project_obj(T_track, model.vertices).mean(axis=0)
            found = search_pose(cam, model, T0, uv, image, name="teabox").candidates[0]
            deg, m = pose_error(found.T_world_obj, T_track)
            assert deg < 0.6 and m < 0.001, (i, deg, m)
