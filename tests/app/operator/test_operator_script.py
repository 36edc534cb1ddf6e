"""The recorded operator script: format validation, and the workcell's clicks against the truth."""

import copy
import json

import numpy as np
import pytest

from app.operator.generate import ScriptOptions, generate_script, still_windows
from app.operator.script import ScriptError, load_script, save_script, script_from_dict
from app.render.raycast import SceneCaster
from app.scene import default_scene_path, load_scene
from core.transforms import transform_points

SIGMA = 1.0


@pytest.fixture(scope="module")
def scene():
    return load_scene(default_scene_path())


@pytest.fixture(scope="module")
def script(scene):
    return load_script(scene.root / "operator.json")


def test_committed_script_is_what_the_generator_writes(scene, script, tmp_path):
    fresh = generate_script(scene)
    assert fresh.to_dict() == script.to_dict()  # re-generate with `mcit script` after editing the scene
    save_script(fresh, tmp_path / "again.json")
    assert (tmp_path / "again.json").read_text() == (scene.root / "operator.json").read_text()


def test_script_covers_the_session(script):
    runs = script.runs()
    kinds = [(r.workflow, r.object_name) for r in runs]
    assert kinds[:4] == [
        ("calibrate_camera", None),
        ("calibrate_turret", None),
        ("model_object", "unknown_box"),
        ("model_object", "unknown_cylinder"),
    ]
    assert kinds[4:] == [("update_pose", "parallelepiped")] * 4
    for r in runs:
        assert r.actions[0].action == "start" and r.actions[-1].action == "accept"
    ends = [
        [a.action for a in r.actions if a.action in ("solve", "refine")] for r in runs if r.workflow == "update_pose"
    ]
    assert ends == [["solve", "refine"], ["refine"], ["refine"], ["refine"]]  # P3L after the large motion only
    assert [r.actions[0].truth["motion"] for r in runs[4:]] == ["large", "small", "small", "small"]
    box = [a.action for a in runs[2].actions if a.action not in ("click",)]
    assert box == ["start", "measure", "next_face", "measure", "next_face", "measure", "solve", "accept"]
    cyl = [a.action for a in runs[3].actions]
    assert cyl == ["start"] + ["click"] * 4 + ["scan", "solve", "accept"]
    steps = script.steps()
    assert all("truth" not in s for s in steps) and steps[0] == {
        "t": 0.3,
        "workflow": "calibrate_camera",
        "action": "start",
    }


def _line_distance(uv, A_uv, B_uv):
    t = (B_uv - A_uv) / np.linalg.norm(B_uv - A_uv)
    n = np.array([-t[1], t[0]])
    return float((uv - A_uv) @ n), float((uv - A_uv) @ t) / np.linalg.norm(B_uv - A_uv)


def test_edge_clicks_lie_on_the_true_projected_edges_within_the_noise(scene, script):
    cam = scene.camera
    across, along_px = [], []
    for a in script.actions:
        tr = a.truth or {}
        if a.action != "click" or "edge" not in tr:
            continue
        body = scene.body(tr["body"])
        T = body.pose_at(a.t)
        A, B = body.model.edge_segments(T)[tr["edge"]]
        A_uv, B_uv = cam.project(np.array([A, B]))
        d, s = _line_distance(np.array(a.args["uv"]), A_uv, B_uv)
        across.append(d)
        _, s_true = _line_distance(np.array(tr["uv_true"]), A_uv, B_uv)
        assert 0.0 < s_true < 1.0
        # never at a vertex: ≥ 10 % of the visible run from its ends
        length = np.linalg.norm(B_uv - A_uv)
        along_px.append(min(s_true, 1 - s_true) * length)
        np.testing.assert_allclose(cam.project(np.array(tr["X_world"])), tr["uv_true"], atol=1e-3)
        assert abs(_line_distance(np.array(tr["uv_true"]), A_uv, B_uv)[0]) < 1e-3
    across = np.array(across)
    assert len(across) >= 70
    rms = float(np.sqrt(np.mean(across**2)))
    assert 0.8 * SIGMA < rms < 1.2 * SIGMA, rms  # the click noise across the edge is the stated σ
    assert np.abs(across).max() < 4.5 * SIGMA
    assert abs(across.mean()) < 3 * SIGMA / np.sqrt(len(across))
    assert min(along_px) > 1.0


def test_point_clicks_scatter_around_the_true_pixels(scene, script):
    err = []
    for a in script.actions:
        tr = a.truth or {}
        if a.action == "click" and "uv_true" in tr:
            np.testing.assert_allclose(scene.camera.project(np.array(tr["X_world"])), tr["uv_true"], atol=1e-3)
            err.append(np.subtract(a.args["uv"], tr["uv_true"]))
    err = np.array(err)
    assert len(err) >= 100
    assert 0.85 * SIGMA < err.std(axis=0).mean() < 1.15 * SIGMA
    assert np.all(np.abs(err.mean(axis=0)) < 3 * SIGMA / np.sqrt(len(err)))


def test_cylinder_silhouettes_are_clicked_at_their_ends_bottom_first(scene, script):
    cyl = scene.body("unknown_cylinder")
    s = cyl.model.solids[0]
    T = cyl.pose_at(0.0)
    c_obj = transform_points(np.linalg.inv(T), scene.camera.center[None])[0]
    sil = transform_points(T, s.silhouette(c_obj).reshape(-1, 3)).reshape(2, 2, 3)
    clicks = [a for a in script.actions if a.action == "click" and "silhouette" in (a.truth or {})]
    assert len(clicks) == 4
    for first, second in (clicks[:2], clicks[2:]):
        assert first.truth["silhouette"] == second.truth["silhouette"]
        ends = sil[first.truth["silhouette"]]
        assert {tuple(np.round(first.truth["X_world"], 5)), tuple(np.round(second.truth["X_world"], 5))} == {
            tuple(np.round(e, 5)) for e in ends
        }
        assert first.truth["uv_true"][1] > second.truth["uv_true"][1]  # the bottom end (lower in the image) first
    us = [np.mean([c.truth["uv_true"][0] for c in pair]) for pair in (clicks[:2], clicks[2:])]
    assert us[0] < us[1]  # left silhouette, then right


def test_calibration_points_are_visible_known_vertices(scene, script):
    caster = SceneCaster.for_scene(scene, 0.0)
    pairs = [(a, b) for a, b in zip(script.actions, script.actions[1:]) if a.action == "choose_vertex"]
    assert len(pairs) >= 10
    names = set()
    for choose, click in pairs:
        assert click.action == "click" and choose.workflow == click.workflow == "calibrate_camera"
        body = scene.body(choose.args["name"])
        assert body.status == "known"
        X = transform_points(body.pose_at(choose.t), body.model.vertices[[choose.args["index"]]])[0]
        np.testing.assert_allclose(X, click.truth["X_world"], atol=1e-6)
        i = [b.name for b in scene.bodies].index(body.name)
        assert not caster.occluded(scene.camera.center, X[None], body=i, tol_m=1e-4)[0]
        names.add(body.name)
    X = np.array([c.truth["X_world"] for _, c in pairs])
    assert names == {"table", "parallelepiped"}
    assert np.linalg.svd(X - X.mean(axis=0), compute_uv=False)[2] > 0.01  # not coplanar: the DLT can use them


def test_turret_targets_are_known_surfaces_the_turret_sees(scene, script):
    T_wt = scene.turret.T_world_turret
    caster = SceneCaster.for_scene(scene, 0.0)
    names = [b.name for b in scene.bodies]
    picks = [a for a in script.actions if a.workflow == "calibrate_turret" and a.action == "choose_point"]
    assert len(picks) >= 6  # the workflow asks for 6 points on faces of 3 orientations
    normals = set()
    for a in picks:
        X = np.array(a.args["X_world"])
        n = np.array(a.truth["normal_world"])
        body = scene.body(a.args["label"].split(" face ")[0])
        assert body.status == "known"
        # the beam from the turret meets that body first, at the point; its face is within 75° of the beam
        h = caster.cast(T_wt[:3, 3], (X - T_wt[:3, 3])[None])
        assert h.body[0] == names.index(body.name) and abs(h.t[0] - 1.0) < 1e-6
        v = T_wt[:3, 3] - X
        assert n @ v / np.linalg.norm(v) > np.cos(np.radians(75.0))
        step = scene.turret.step_rad
        assert scene.turret.within_limits(a.truth["pan_steps_exact"] * step, a.truth["tilt_steps_exact"] * step)
        normals.add(tuple(np.round(n, 3)))
    assert len(normals) >= 3
    after = [b.action for a, b in zip(script.actions, script.actions[1:]) if a in picks]
    assert set(after) == {"measure"}


def test_box_faces_are_clicked_side_by_side_then_measured(scene, script):
    box = scene.body("unknown_box")
    run = [r for r in script.runs() if r.object_name == "unknown_box"][0]
    faces, current = [], []
    for a in run.actions[1:]:
        if a.action == "click":
            current.append(a)
        elif a.action == "measure":
            faces.append((a.truth["face"], current))
            current = []
    assert len(faces) == 3
    T = box.pose_at(0.0)
    normals = box.model.face_normals() @ T[:3, :3].T
    assert normals[faces[0][0]][2] > 0.99  # the top first
    E = box.model.edges
    for f, clicks in faces:
        assert len(clicks) == 8  # two clicks on each of the face's four sides
        assert {c.truth["face"] for c in clicks} == {f}
        loop = box.model.faces[f]
        sides = {
            int(np.flatnonzero(((E == [a, b]) | (E == [b, a])).all(axis=1))[0])
            for a, b in zip(loop, loop[1:] + loop[:1])
        }
        assert {c.truth["edge"] for c in clicks} == sides


def test_updates_happen_while_the_box_is_still_after_each_motion(scene, script):
    box = scene.body("parallelepiped")
    windows = still_windows(box, scene.video.duration_s)
    runs = [r for r in script.runs() if r.workflow == "update_pose"]
    assert len(runs) == len(windows) - 1
    for r, w in zip(runs, windows[1:]):
        assert w[0] <= r.t_start and r.t_end <= w[1]
        assert box.is_static(r.t_start, r.t_end)
        np.testing.assert_allclose(r.actions[-1].truth["T_world_obj"], box.pose_at(r.t_end), atol=1e-8)
        edges = [a.args["edge"] for a in r.actions if a.action == "assign_edge"]
        assert len(edges) >= 6 and len(set(edges)) == len(edges)
        E = box.model.edges[edges[:3]]
        D = box.model.vertices[E[:, 1]] - box.model.vertices[E[:, 0]]
        D /= np.linalg.norm(D, axis=1, keepdims=True)
        assert abs(D[0] @ D[1]) < 0.95 and abs(D[0] @ D[2]) < 0.95 and abs(D[1] @ D[2]) < 0.95  # P3L: not parallel
        assert not (set(E[0]) & set(E[1]) & set(E[2]))  # nor meeting in one vertex
    first_motion = windows[0][1]
    before = [a for a in script.actions if a.workflow != "update_pose"]
    assert before[-1].t < first_motion


def test_other_seeds_and_noise_levels(scene):
    quiet = generate_script(scene, ScriptOptions(click_sigma_px=0.0))
    for a in quiet.actions:
        if a.truth and "uv_true" in a.truth and "uv" in a.args:
            np.testing.assert_allclose(a.args["uv"], a.truth["uv_true"], atol=1e-3)
    other = generate_script(scene, ScriptOptions(seed=9))
    assert other.to_dict() != generate_script(scene).to_dict()


def test_shortened_script(script):
    runs = script.runs()
    short = script.with_runs([runs[0], runs[4]])
    assert [r.workflow for r in short.runs()] == ["calibrate_camera", "update_pose"]
    assert short.generator["shortened"] is True
    script_from_dict(json.loads(json.dumps(short.to_dict())))  # still a valid script


# ---------------------------------------------------------------------- validation
def _base() -> dict:
    return {
        "format": "mcit-operator-script/1",
        "scene": "workcell",
        "actions": [
            {"t": 0.0, "workflow": "update_pose", "action": "start", "object_name": "box"},
            {"t": 0.1, "workflow": "update_pose", "action": "click", "uv": [10.0, 20.5]},
            {"t": 0.2, "workflow": "update_pose", "action": "assign_edge", "edge": 3, "truth": {"edge": 3}},
            {"t": 0.3, "workflow": "update_pose", "action": "add_segment", "seg_uv": [[1, 2], [3, 4.5]], "edge": 4},
            {"t": 0.4, "workflow": "update_pose", "action": "refine"},
        ],
    }


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d["actions"][1].update(uv=[10.0]), r"actions\[1\]\.uv: a list of 2 numbers"),
        (lambda d: d["actions"][1].update(uv=[10.0, float("nan")]), r"actions\[1\]\.uv: finite numbers"),
        (lambda d: d["actions"][1].pop("uv"), r"actions\[1\] \(update_pose\.click\): missing argument 'uv'"),
        (lambda d: d["actions"][1].update(pixel=[1, 2]), r"unknown argument 'pixel'"),
        (lambda d: d["actions"][2].update(t=0.05), r"actions\[2\]\.t: times must not decrease"),
        (lambda d: d["actions"][2].update(edge=3.5), r"actions\[2\]\.edge: an integer"),
        (lambda d: d["actions"][3].update(seg_uv=[[1, 2]]), r"actions\[3\]\.seg_uv: two pixels"),
        (lambda d: d["actions"][3].update(seg_uv=[[1, 2], [3]]), r"actions\[3\]\.seg_uv\[1\]: a list of 2 numbers"),
        (lambda d: d["actions"][3].update(edge=True), r"actions\[3\]\.edge: an integer"),
        (
            lambda d: d["actions"][1].update(workflow="calibrate_everything"),
            r"actions\[1\]\.workflow: unknown workflow",
        ),
        (
            lambda d: d["actions"][1].update(action="teleport"),
            r"actions\[1\]\.action: update_pose has no action 'teleport'",
        ),
        (lambda d: d["actions"][1].pop("t"), r"actions\[1\]: missing field 't'"),
        (lambda d: d["actions"].pop(0), r"actions\[0\]: a script begins with a workflow's 'start'"),
        (
            lambda d: d["actions"].__setitem__(
                2, {"t": 0.2, "workflow": "calibrate_camera", "action": "click", "uv": [1, 2]}
            ),
            "without a 'start'",
        ),
        (lambda d: d.update(format="v0"), "'format' must be"),
        (lambda d: d.update(actions=[]), "non-empty list"),
        (lambda d: d.update(extra=1), "unknown top-level field"),
    ],
)
def test_bad_scripts_name_the_action_and_field(mutate, match):
    d = _base()
    script_from_dict(copy.deepcopy(d))
    mutate(d)
    with pytest.raises(ScriptError, match=match):
        script_from_dict(d)


def test_load_errors_name_the_file(tmp_path):
    f = tmp_path / "op.json"
    f.write_text("{")
    with pytest.raises(ScriptError, match="op.json: not valid JSON"):
        load_script(f)
    d = _base()
    d["actions"][1]["uv"] = "here"
    f.write_text(json.dumps(d))
    with pytest.raises(ScriptError, match=r"op.json: actions\[1\]\.uv"):
        load_script(f)
