"""app.vision.track: sampling the visible edges, tracking rendered video with known truth and the
real ViSP sequences (skipped cleanly when ../shared/data is absent)."""

import numpy as np
import pytest

from app.vision.evaluate import edge_distance
from app.vision.pnp import solve_pnp
from app.vision.sequence import iter_frames, read_init_points, read_visp_pose
from app.vision.synthetic import render_poses
from app.vision.track import EdgeTracker, sample_visible_edges
from core.brep import BRep, Revolution
from core.camera import Camera
from core.transforms import exp_so3, make_T, pose_error

K = np.array([[420.0, 0.0, 159.5], [0.0, 420.0, 119.5], [0.0, 0.0, 1.0]])
CUBE_K = np.array([[547.7367575, 0, 338.7036994], [0, 542.0744058, 234.5083345], [0, 0, 1]])
TEABOX_K = np.array([[839.21470, 0, 325.66776], [0, 839.44555, 243.69727], [0, 0, 1]])

# The four teabox.init model points, clicked once on frame 0 of teabox.mp4 (by eye, on 10× zooms
# of the frame with a pixel grid): (0, 0, 0) is the top corner at the back of the long side face
# (192, 84.5); (0.165, 0, 0) the top corner where that face meets the small end face showing
# "Infusion des Marmottes" (349.5, 205.5); (0.165, 0, −0.08) the bottom corner below it, where the
# box's outline meets the table (324, 376); (0.165, 0.068, −0.08) the end face's other bottom
# corner (458.5, 351), a faint corner on a white table. The order is teabox.init's and ViSP's
# help image (teabox.png). SQPnP reprojects them within 1.2–4 px: the tracker's first frame
# pulls the model onto the edges from there.
TEABOX_CLICKS = np.array([[192.0, 84.5], [349.5, 205.5], [324.0, 376.0], [458.5, 351.0]])


def _camera():
    return Camera.from_intrinsics(K, np.eye(4), 320, 240)


def test_samples_lie_on_the_projected_visible_edges():
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    T = make_T(exp_so3([2.2, 0.4, 0.3]), [0.0, 0.0, 0.9])
    s = sample_visible_edges(cam, box, T, step_px=4.0)
    assert len(s) > 50
    assert s.uv.shape == (len(s), 2) and s.normals.shape == (len(s), 2)
    assert s.X_obj.shape == (len(s), 3) and s.D_obj.shape == (len(s), 3) and s.feature.shape == (len(s),)
    assert np.allclose(cam.project_obj(T, s.X_obj), s.uv, atol=1e-9)  # perspective-correct
    assert np.allclose(np.linalg.norm(s.normals, axis=1), 1.0)
    # the normal is perpendicular to the projected edge direction
    tip = cam.project_obj(T, s.X_obj + 1e-4 * s.D_obj) - s.uv
    assert np.allclose(np.einsum("ij,ij->i", tip, s.normals), 0.0, atol=1e-9)
    assert cam.in_image(s.uv, 2.0).all()
    wf = box.wireframe(cam.center, T)
    assert set(s.feature.tolist()) <= set(np.flatnonzero(wf.visible).tolist())


def test_faces_seen_edge_on_and_cylinder_rims_are_left_out():
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    # looking almost straight down on the top face: the side faces are seen at ~86°
    T = make_T(exp_so3([np.pi - 0.07, 0.0, 0.0]), [0.0, -0.04, 0.9])  # the −y face seen at 87.5°
    all_edges = set(sample_visible_edges(cam, box, T, max_face_angle_deg=90.0).feature.tolist())
    seen = set(sample_visible_edges(cam, box, T).feature.tolist())
    top = {k for k in range(len(box.edges)) if np.all(box.vertices[box.edges[k], 2] > 0.07)}
    assert seen == top and len(all_edges) > len(seen)
    cyl = BRep(np.zeros((0, 3)), np.zeros((0, 2), np.int64), (), (Revolution([0, 0, 0], [0, 0, 0.2], 0.04, 0.04),))
    Tc = make_T(exp_so3([-1.2, 0.0, 0.0]), [0.0, 0.05, 0.8])
    sil = sample_visible_edges(cam, cyl, Tc)
    with_rims = sample_visible_edges(cam, cyl, Tc, rims=True)
    assert set(sil.feature.tolist()) == {0, 1}  # the two silhouettes only
    assert len(with_rims) > len(sil) and set(with_rims.feature.tolist()) > {0, 1}


def _moving_box(n=6):
    poses = []
    R0 = exp_so3([2.2, 0.4, 0.3])
    for k in range(n):
        R = exp_so3(np.radians(1.0) * k * np.array([0.6, 0.8, 0.0])) @ R0
        poses.append(make_T(R, [0.004 * k, -0.002 * k, 0.9 + 0.003 * k]))
    return poses


def test_tracks_a_rendered_moving_box_to_its_true_pose():
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    truth = _moving_box()
    frames = render_poses(cam, box, truth, noise_sigma=2.0)
    tracker = EdgeTracker(cam, box, truth[0] @ make_T(exp_so3([0.01, -0.01, 0.0]), [0.002, 0.0, 0.0]))
    for img, T_true in zip(frames, truth):
        T, conf, lost = tracker.track(img)
        assert not lost and conf > 0.8
        rot_deg, trans_m = pose_error(T, T_true)
        assert rot_deg < 0.5 and trans_m < 2e-3
        d = tracker.diagnostics
        assert (
            d.n_samples == len(d.samples)
            and d.matched_uv.shape == (d.n_samples, 2)
            and d.weights.shape == (d.n_samples,)
        )
        assert d.rms_px < 0.5 and d.reason == ""
    assert np.allclose(tracker.T_world_obj, T)


def test_lost_on_a_frame_without_the_object_and_stays_lost_until_reset():
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    truth = _moving_box(2)
    frames = render_poses(cam, box, truth, noise_sigma=2.0)
    tracker = EdgeTracker(cam, box, truth[0])
    T0, _, lost = tracker.track(frames[0])
    assert not lost
    blank = np.full((240, 320), 40, np.uint8)
    T1, conf, lost = tracker.track(blank)
    assert lost and conf < 0.3 and np.allclose(T1, T0)
    assert tracker.lost and tracker.diagnostics.reason
    # sticky: even the right frame does not resume tracking
    assert tracker.track(frames[1]).lost
    tracker.reset(truth[1])
    T2, conf, lost = tracker.track(frames[1])
    assert not lost and pose_error(T2, truth[1])[0] < 0.5


def test_a_wrongly_converged_pose_is_flagged_lost_and_a_right_one_is_not():
    """Two wrong convergences on a rendered frame that the former rule (lost below confidence 0.3)
    reported as tracked: started 20° off about the box's x axis, it settles 13.8° off with 43 % of
    the samples on an edge; started 2 cm along the box's long side, it stays 2 cm off (the long
    edges slide along themselves) with 67 %. Both are lost now (confidence below 0.5, or the model's
    edges more than 1.5 px from the image's on average); from a start 1° / 3 mm off it is right and kept."""
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    truth = _moving_box(1)[0]
    img = render_poses(cam, box, [truth], noise_sigma=2.0)[0]
    turned = truth @ make_T(exp_so3(np.radians(20.0) * np.array([1.0, 0.0, 0.0])), [0.0, 0.0, 0.0])
    slid = truth @ make_T(np.eye(3), [-0.02, 0.0, 0.0])
    for T_start, low_conf in ((turned, True), (slid, False)):
        old = EdgeTracker(cam, box, T_start, lost_confidence=0.3, max_edge_distance_px=np.inf)
        T, conf, lost = old.track(img)
        deg, m = pose_error(T, truth)
        assert (deg > 5.0 or m > 0.01) and conf >= 0.3 and not lost  # what the issue saw
        assert (conf < 0.5) == low_conf

        tracker = EdgeTracker(cam, box, T_start, motion_model=False, start_search=(0.0, 0.0, 0))
        T, conf, lost = tracker.track(img)
        assert lost and tracker.lost and np.allclose(T, T_start)  # the wrong pose is not reported
        assert "not supported by the image" in tracker.diagnostics.reason
        if not low_conf:  # the support check caught it
            assert (
                tracker.diagnostics.edge_distance_px > 1.5 and "px from the image's edges" in tracker.diagnostics.reason
            )

    # With the motion model's coarse passes (their robust scale at least an eighth of the band), the
    # start slid 2 cm (9 px) is pulled onto the truth instead; the turned one is still lost.
    T, conf, lost = EdgeTracker(cam, box, slid).track(img)
    assert not lost and pose_error(T, truth)[0] < 0.5 and pose_error(T, truth)[1] < 0.002
    # So is it by the pose search near a given pose (start_search, on by default) without them.
    T, conf, lost = EdgeTracker(cam, box, slid, motion_model=False).track(img)
    assert not lost and pose_error(T, truth)[0] < 0.5 and pose_error(T, truth)[1] < 0.002
    assert EdgeTracker(cam, box, turned, motion_model=False).track(img).lost
    assert EdgeTracker(cam, box, turned).track(img).lost

    right = EdgeTracker(
        cam, box, truth @ make_T(exp_so3(np.radians(1.0) * np.array([1.0, 0.0, 0.0])), [0.003, 0.0, 0.0])
    )
    T, conf, lost = right.track(img)
    assert not lost and conf > 0.9 and pose_error(T, truth)[0] < 0.5
    assert right.diagnostics.edge_distance_px < 0.5


def test_bad_input():
    cam = _camera()
    box = BRep.box(0.2, 0.13, 0.08)
    T = _moving_box(1)[0]
    tracker = EdgeTracker(cam, box, T)
    with pytest.raises(ValueError, match="camera is 320×240"):
        tracker.track(np.zeros((100, 100), np.uint8))
    with pytest.raises(ValueError, match="Camera"):
        EdgeTracker(K, box, T)
    with pytest.raises(ValueError, match="BRep"):
        EdgeTracker(cam, "box", T)
    with pytest.raises(ValueError, match="T_world_obj"):
        EdgeTracker(cam, box, np.eye(3))
    with pytest.raises(ValueError, match="lost_confidence"):
        EdgeTracker(cam, box, T, lost_confidence=1.5)
    with pytest.raises(ValueError, match="max_edge_distance_px"):
        EdgeTracker(cam, box, T, max_edge_distance_px=0.0)


def test_real_visp_cube_first_frames_stay_on_the_edges(shared_data):
    from app.models_io import read_cao

    folder = shared_data("visp-cube")
    model = read_cao(folder / "cube_and_cylinder.cao")
    cam = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
    T0 = read_visp_pose(folder / "cube.0.pos")
    tracker = EdgeTracker(cam, model, T0)
    for i, frame in iter_frames(folder / "frames", 0, 16):
        T, conf, lost = tracker.track(frame)
        assert not lost, tracker.diagnostics.reason
        assert conf > 0.5
        if i % 5 == 0:
            assert edge_distance(frame, cam, model, T).mean_px < 1.5
    # 16 frames of a slowly moving hand-held camera: the pose has moved by little
    rot_deg, trans_m = pose_error(tracker.T_world_obj, T0)
    assert rot_deg < 5.0 and trans_m < 0.02


def test_real_teabox_initialised_from_four_clicks(shared_data):
    from app.models_io import read_cao

    folder = shared_data("visp-teabox")
    model = read_cao(folder / "teabox.cao")
    cam = Camera.from_intrinsics(TEABOX_K, np.eye(4), 640, 480)
    X = read_init_points(folder / "teabox.init")
    T0 = solve_pnp(TEABOX_K, X, TEABOX_CLICKS, 640, 480).T_cam_world  # the camera frame is the world
    assert np.max(np.linalg.norm(cam.project_obj(T0, X) - TEABOX_CLICKS, axis=1)) < 5.0
    tracker = EdgeTracker(cam, model, T0)
    dists = []
    for i, frame in iter_frames(folder / "teabox.mp4", 0, 8):
        T, conf, lost = tracker.track(frame)
        assert not lost, tracker.diagnostics.reason
        dists.append(edge_distance(frame, cam, model, T).mean_px)
        if i == 0:
            first = edge_distance(frame, cam, model, T0).mean_px
            assert dists[0] < first  # the first frame pulled the clicked pose onto the edges
    assert max(dists) < 1.5


def test_the_frame_is_smoothed_only_around_the_samples_as_the_whole_frame_would_be():
    from app.vision.profiles import smooth, to_gray_f32
    from app.vision.track import BandSmoothed

    rng = np.random.default_rng(0)
    for shape in [(240, 320), (100, 77, 3)]:
        frame = rng.integers(0, 255, shape).astype(np.uint8)
        whole = smooth(to_gray_f32(frame), 1.0)
        band = BandSmoothed(frame, 1.0)
        H, W = shape[:2]
        P = np.array([[-3.0, 5.0], [W / 2, H / 2], [W - 1.0, H - 1.0]])
        img = band.around(P, 10.0)
        near = np.zeros((H, W), bool)
        vv, uu = np.mgrid[:H, :W]
        for u, v in P:
            near |= (np.abs(uu - u) <= 10) & (np.abs(vv - v) <= 10)
        assert np.allclose(img[near], whole[near], atol=1e-3)
        if shape == (240, 320):
            assert band.done.mean() < 0.5  # the rest of the frame is left alone


def test_real_visp_cube_every_third_frame_is_followed_coarse_to_fine(shared_data):
    """Fast motion: every 3rd frame of the real cube. Frame 63 moves beyond the ±8 px band (the
    usual passes leave the model 1.7 px off the image's edges, lost); tried again coarse to fine
    from ±32 px, it is followed to the end, on the edges."""
    from app.models_io import read_cao

    folder = shared_data("visp-cube")
    model = read_cao(folder / "cube_and_cylinder.cao")
    cam = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
    T0 = read_visp_pose(folder / "cube.0.pos")
    frames = [f for i, f in iter_frames(folder / "frames") if i % 3 == 0]
    without = EdgeTracker(cam, model, T0, capture_px=0.0, motion_model=False)  # issue 16's, without its retry
    lost_at = next((k for k, f in enumerate(frames) if without.track(f).lost), None)
    assert lost_at == 21 and "px from the image's edges" in without.diagnostics.reason
    tracker = EdgeTracker(cam, model, T0)
    for k, frame in enumerate(frames):
        T, conf, lost = tracker.track(frame)
        assert not lost, (k, tracker.diagnostics.reason)
        if k % 6 == 3 or k in (21, 22):
            assert edge_distance(frame, cam, model, T).mean_px < 1.5


@pytest.fixture(scope="module")
def visp_cube_ref():
    """visp-cube's model, camera, first 141 frames (grey) and the tracker's own poses from ViSP's pose."""
    from app.models_io import read_cao
    from tests.conftest import shared_data_path

    folder = shared_data_path("visp-cube")
    model = read_cao(folder / "cube_and_cylinder.cao")
    cam = Camera.from_intrinsics(CUBE_K, np.eye(4), 640, 480)
    frames = [f for i, f in iter_frames(folder / "frames") if i <= 150]
    tracker = EdgeTracker(cam, model, read_visp_pose(folder / "cube.0.pos"))
    ref = [tracker.track(f).T_world_obj for f in frames]
    return cam, model, frames, ref


def _off(T, axis, direction):
    """T turned 5° about an object axis and moved 1 cm along a world direction (bench/tracking.py's starts)."""
    out = T @ make_T(exp_so3(np.radians(5.0) * np.asarray(axis, float)), [0.0, 0.0, 0.0])
    out[:3, 3] += 0.01 * np.asarray(direction, float)
    return out


def test_a_given_pose_5_degrees_and_1_cm_off_is_captured_coarse_to_fine_on_its_first_frame(visp_cube_ref):
    """The real cube at frame 5 from a start 5° / 1 cm off: the ±8 px band loses it on the first
    frame; tried again coarse to fine from ±24 and ±16 px (both answers agree), it is tracked, on the
    reference, and followed. Auto match's settling step (lost_confidence 0) does not capture."""
    cam, model, frames, ref = visp_cube_ref
    T0 = _off(ref[5], [1, 0, 0], [0, 1, 0])
    without = EdgeTracker(cam, model, T0, start_capture_px=())
    assert without.track(frames[5]).lost
    tracker = EdgeTracker(cam, model, T0)
    for k in range(5, 16):
        T, conf, lost = tracker.track(frames[k])
        assert not lost, (k, tracker.diagnostics.reason)
        deg, m = pose_error(T, ref[k])
        assert deg < 1.0 and m < 0.003, (k, deg, m)
    assert tracker.diagnostics.edge_distance_px < 1.5
    settle = EdgeTracker(cam, model, T0, lost_confidence=0.0).track(frames[5]).T_world_obj
    plain = EdgeTracker(cam, model, T0, lost_confidence=0.0, start_capture_px=()).track(frames[5]).T_world_obj
    assert np.array_equal(settle, plain) and pose_error(settle, ref[5])[0] > 1.0
    # after a reset the next frame is a first frame again
    tracker.reset(_off(ref[15], [1, 0, 0], [0, 1, 0]))
    assert not tracker.track(frames[15]).lost


def test_a_first_frame_the_image_fits_two_ways_is_lost_not_guessed(visp_cube_ref):
    """Frame 140 of the real cube: from this start 5° / 1 cm off, the two coarse-to-fine captures
    end on two poses both supported by the image (edges within 1.5 px of it), 2.6 px apart: the
    other one is 4° and 18 mm from the reference. Neither is reported; the given pose is kept."""
    cam, model, frames, ref = visp_cube_ref
    T0 = _off(ref[140], [1, 0, 0], [-1, 0, 0])
    tracker = EdgeTracker(cam, model, T0)
    T, conf, lost = tracker.track(frames[140])
    assert lost and np.array_equal(T, T0)
    assert "fits two poses" in tracker.diagnostics.reason
    one = EdgeTracker(cam, model, T0, start_capture_px=(24.0,))  # one hypothesis alone would guess
    T1, _, lost1 = one.track(frames[140])
    assert not lost1 and one.diagnostics.edge_distance_px < 1.5


def test_a_first_frame_that_passes_off_the_object_is_replaced_by_the_pose_search_near_it(visp_cube_ref):
    """Frame 118 of the real cube from a start 5° / 1 cm off: the ±8 px band settles 5° and 14 mm off the
    reference with the edges 1 px or so from the image's, and it passes the lost tests. The pose search
    near the given pose (``start_search``), run on every first frame (``start_check``), finds the
    reference fitting clearly better (by more than ``start_ambiguity_px``), and that is reported."""
    cam, model, frames, ref = visp_cube_ref
    T0 = _off(ref[118], [0, 1, 0], [0, 1, 0])
    unchecked = EdgeTracker(cam, model, T0, start_check=False)
    T, _, lost = unchecked.track(frames[118])
    deg, m = pose_error(T, ref[118])
    assert not lost and (deg > 4.0 and m > 0.01), (deg, m)  # reported tracked, wrong
    tracker = EdgeTracker(cam, model, T0)
    T, _, lost = tracker.track(frames[118])
    deg, m = pose_error(T, ref[118])
    assert not lost and deg < 0.3 and m < 0.001, (deg, m)
    assert tracker.diagnostics.edge_distance_px < unchecked.diagnostics.edge_distance_px - 0.3


def test_a_first_frame_that_passes_where_the_image_fits_two_poses_is_lost_not_reported(visp_cube_ref):
    """Frame 144 of the real cube, where the image fits two poses 4° / 16 mm apart (bench/tracking.py's two
    references): from this start 5° / 1 cm off, the ±8 px band settles 6° and 28 mm off the reference and
    passes the lost tests, its edges nearer the image's than the reference's by less than
    ``start_ambiguity_px``. Judged with the pose search's answers, which lie apart from it, the frame is
    lost and the given pose kept: the image does not show which is right."""
    cam, model, frames, ref = visp_cube_ref
    T0 = _off(ref[144], [0, 1, 0], [0, 1, 0])
    band = EdgeTracker(cam, model, T0, start_check=False)
    T, _, lost = band.track(frames[144])
    deg, m = pose_error(T, ref[144])
    assert not lost and deg > 5.0 and m > 0.02, (deg, m)  # what the band alone reports: tracked, wrong
    at_ref = EdgeTracker(cam, model, ref[144], start_check=False)
    assert not at_ref.track(frames[144]).lost
    fit_gap = band.diagnostics.edge_distance_px - at_ref.diagnostics.edge_distance_px
    assert 0.0 < fit_gap < 0.3, fit_gap  # the reference fits better, but within start_ambiguity_px
    tracker = EdgeTracker(cam, model, T0)
    T, _, lost = tracker.track(frames[144])
    assert lost and np.array_equal(T, T0), pose_error(T, ref[144])
    assert "fits two poses" in tracker.diagnostics.reason


def test_a_first_frame_that_passes_short_of_the_pose_it_heads_for_is_not_a_second_pose(visp_cube_ref):
    """Frame 118 of the real cube from a start 5° / 1 cm off: the ±8 px band stops about 1° short of the
    reference, its edges a pixel or two from the search's answers yet fitting about as well. Taken as it
    is, it would make the frame "fit two poses" and be lost; given one more round of passes it reaches the
    reference, and the frame is tracked there."""
    cam, model, frames, ref = visp_cube_ref
    T0 = _off(ref[118], [1, 0, 0], [0, -1, 0])
    short = EdgeTracker(cam, model, T0, start_check=False)
    T, _, lost = short.track(frames[118])
    assert not lost and pose_error(T, ref[118])[0] > 0.5, pose_error(T, ref[118])
    tracker = EdgeTracker(cam, model, T0)
    T, _, lost = tracker.track(frames[118])
    assert not lost, tracker.diagnostics.reason
    deg, m = pose_error(T, ref[118])
    assert deg < 0.3 and m < 0.001, (deg, m)


def _circle(speed_px: float, n: int = 24):
    """A box on a circle at speed_px image pixels a frame (0.9 m, f = 600 px, 640×480), turning 1.5° a
    frame, from rest: frame 1 already moves at full speed (bench/tracking.py's circle_sequence)."""
    f, omega = 600.0, 0.3
    cam = Camera.from_intrinsics(np.array([[f, 0, 319.5], [0, f, 239.5], [0, 0, 1]]), np.eye(4), 640, 480)
    a = speed_px / omega * 0.9 / f
    R0 = exp_so3([2.2, 0.4, 0.3])
    truth = [
        make_T(
            exp_so3(np.radians(1.5) * k * np.array([0.3, 0.8, 0.5])) @ R0,
            [a * np.sin(omega * k), a * (np.cos(omega * k) - 1.0), 0.9 + 0.01 * np.sin(k / 5.0)],
        )
        for k in range(n)
    ]
    return cam, truth


def test_follows_30_px_a_frame_on_default_settings_and_the_tracker_of_before_did_not():
    """30 px of image motion a frame: the first moving frame is caught by the coarse-to-fine retry, the
    others by the constant-velocity prediction; every frame on the truth. Without the motion model
    (issue 16's defaults) the object is lost on the first moving frame."""
    cam, truth = _circle(30.0)
    box = BRep.box(0.2, 0.13, 0.08)
    frames = render_poses(cam, box, truth, noise_sigma=2.0, blur_sigma_px=0.5, seed=1)
    motion = [
        np.median(np.linalg.norm(cam.project_obj(a, box.vertices) - cam.project_obj(b, box.vertices), axis=1))
        for a, b in zip(truth, truth[1:])
    ]
    assert min(motion) > 27.0  # the motion the issue asks for, on every frame
    tracker = EdgeTracker(cam, box, truth[0])
    for k, (img, T_true) in enumerate(zip(frames, truth)):
        T, conf, lost = tracker.track(img)
        assert not lost, (k, tracker.diagnostics.reason)
        deg, m = pose_error(T, T_true)
        assert deg < 0.5 and m < 0.005, (k, deg, m)
    before = EdgeTracker(cam, box, truth[0], motion_model=False)
    assert not before.track(frames[0]).lost
    assert before.track(frames[1]).lost


def test_a_jump_beyond_the_capture_band_is_lost_not_reported_wrong():
    """Followed at 30 px a frame, then the object jumps 60 px against its motion (a dropped run of
    frames): no band reaches it, and the frame is flagged lost with the last good pose kept."""
    cam, truth = _circle(30.0, n=8)
    box = BRep.box(0.2, 0.13, 0.08)
    jump = truth[5].copy()
    jump[:3, 3] += [-0.09, 0.0, 0.0]  # 60 px left of frame 5, where the motion predicts it 30 px right
    frames = render_poses(cam, box, truth[:6] + [jump], noise_sigma=2.0, blur_sigma_px=0.5, seed=2)
    tracker = EdgeTracker(cam, box, truth[0])
    for img in frames[:6]:
        assert not tracker.track(img).lost
    T, conf, lost = tracker.track(frames[6])
    assert lost and np.array_equal(T, tracker.T_world_obj)
    assert pose_error(T, truth[5])[1] < 0.005 and tracker.diagnostics.reason


def test_the_prediction_is_a_rotation_and_resets_forget_the_motion():
    cam, truth = _circle(10.0, n=4)
    box = BRep.box(0.2, 0.13, 0.08)
    frames = render_poses(cam, box, truth, noise_sigma=2.0, seed=3)
    tracker = EdgeTracker(cam, box, truth[0])
    for img in frames[:3]:
        assert not tracker.track(img).lost
    Tp = tracker._prediction()
    assert np.allclose(Tp[:3, :3].T @ Tp[:3, :3], np.eye(3), atol=1e-12)
    assert pose_error(Tp, truth[3])[1] < pose_error(tracker.T_world_obj, truth[3])[1]  # the prediction is nearer
    tracker.reset(truth[3])
    assert np.array_equal(tracker._prediction(), truth[3]) and tracker._schedule() == (8.0, 3.0)
