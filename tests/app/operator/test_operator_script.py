"""The recorded operator script: format validation, and the workcell's clicks against the truth."""

import copy
import json

import numpy as np
import pytest

from app.operator.generate import ScriptOptions, generate_script, still_windows
from app.operator.script import ScriptError, load_script, save_script, script_from_dict
from app.render.raycast import SceneCaster
from app.scene import default_scene_path, load_scene
from core.rangefinder import beam_point
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
    assert kinds[:4] == [("calibrate_camera", None), ("calibrate_turret", None),
                         ("model_object", "unknown_box"), ("model_object", "unknown_cylinder")]
    assert kinds[4:] == [("update_pose", "parallelepiped")] * 4
    for r in runs:
        assert r.actions[0].action == "start" and r.actions[-1].action == "accept"
    methods = [a.args["method"] for a in script.actions if a.workflow == "update_pose" and a.action == "solve"]
    assert methods == ["large", "small", "small", "small"]
    steps = script.steps()
    assert all("truth" not in s for s in steps) and steps[0] == {"t": 0.3, "workflow": "calibrate_camera", "action": "start"}


def _line_distance(uv, A_uv, B_uv):
    t = (B_uv - A_uv) / np.linalg.norm(B_uv - A_uv)
    n = np.array([-t[1], t[0]])
    return float((uv - A_uv) @ n), float((uv - A_uv) @ t) / np.linalg.norm(B_uv - A_uv)


def test_edge_clicks_lie_on_the_true_projected_edges_within_the_noise(scene, script):
    cam = scene.camera
    across, along_px = [], []
    for a in script.actions:
        tr = a.truth or {}
        if a.action != "click" or "edge" not in tr and "silhouette" not in tr:
            continue
        body = scene.body(tr["body"])
        T = body.pose_at(a.t)
        if "edge" in tr:
            A, B = body.model.edge_segments(T)[tr["edge"]]
        else:
            c_obj = transform_points(np.linalg.inv(T), cam.center[None])[0]
            A, B = transform_points(T, body.model.solids[0].silhouette(c_obj)[tr["silhouette"]])
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
        if a.action in ("click", "aim") and "uv_true" in tr:
            np.testing.assert_allclose(scene.camera.project(np.array(tr["X_world"])), tr["uv_true"], atol=1e-3)
            err.append(np.subtract(a.args["uv"], tr["uv_true"]))
    err = np.array(err)
    assert len(err) >= 100
    assert 0.85 * SIGMA < err.std(axis=0).mean() < 1.15 * SIGMA
    assert np.all(np.abs(err.mean(axis=0)) < 3 * SIGMA / np.sqrt(len(err)))


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


def test_turret_jogs_put_the_beam_near_the_known_points(scene, script):
    T_wt = scene.turret.T_world_turret
    step = scene.turret.step_rad
    moves = [a for a in script.actions if a.action == "move_turret"]
    assert len(moves) >= 3
    for a in moves:
        pan, tilt = a.args["pan_steps"] * step, a.args["tilt_steps"] * step
        assert scene.turret.within_limits(pan, tilt)
        assert abs(a.args["pan_steps"] - a.truth["pan_steps_exact"]) < 4.5  # ± 1 step of operator error (σ), rounded
        X = np.array(a.truth["X_world"])
        rho = np.linalg.norm(X - T_wt[:3, 3])
        miss = np.linalg.norm(beam_point(T_wt, pan, tilt, rho) - X)
        assert miss < rho * 5 * step
    P = np.array([a.truth["X_world"] for a in moves])
    assert np.linalg.matrix_rank(P - P.mean(axis=0), tol=0.05) >= 2


def test_range_aims_land_inside_their_face(scene, script):
    box = scene.body("unknown_box")
    T = box.pose_at(0.0)
    normals = box.model.face_normals()
    per_face = {}
    for a in script.actions:
        if a.action != "aim":
            continue
        X_obj = transform_points(np.linalg.inv(T), np.array([a.truth["X_world"]]))[0]
        f = a.truth["face"]
        loop = box.model.vertices[list(box.model.faces[f])]
        assert abs((X_obj - loop[0]) @ normals[f]) < 1e-6  # on the face's plane (truth rounded to µm)
        lo, hi = loop.min(axis=0), loop.max(axis=0)
        margin = 0.2 * (hi - lo)
        inside = (X_obj >= lo + margin - 1e-12) | (normals[f] != 0)
        assert np.all(inside & ((X_obj <= hi - margin + 1e-12) | (normals[f] != 0)))
        per_face[f] = per_face.get(f, 0) + 1
    assert len(per_face) == 3 and min(per_face.values()) >= 3  # the top and the two visible sides


def test_updates_happen_while_the_box_is_still_after_each_motion(scene, script):
    box = scene.body("parallelepiped")
    windows = still_windows(box, scene.video.duration_s)
    runs = [r for r in script.runs() if r.workflow == "update_pose"]
    assert len(runs) == len(windows) - 1
    for r, w in zip(runs, windows[1:]):
        assert w[0] <= r.t_start and r.t_end <= w[1]
        assert box.is_static(r.t_start, r.t_end)
        np.testing.assert_allclose(r.actions[-1].truth["T_world_obj"], box.pose_at(r.t_end), atol=1e-8)
        edges = [a.args["index"] for a in r.actions if a.action == "assign_edge"]
        assert len(edges) == 6 and len(set(edges)) == 6
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
            {"t": 0.2, "workflow": "update_pose", "action": "assign_edge", "index": 3, "truth": {"edge": 3}},
            {"t": 0.3, "workflow": "update_pose", "action": "solve", "method": "small"},
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
        (lambda d: d["actions"][2].update(index=3.5), r"actions\[2\]\.index: an integer"),
        (lambda d: d["actions"][3].update(method="medium"), r"actions\[3\]\.method"),
        (lambda d: d["actions"][1].update(workflow="calibrate_everything"), r"actions\[1\]\.workflow: unknown workflow"),
        (lambda d: d["actions"][1].update(action="teleport"), r"actions\[1\]\.action: update_pose has no action 'teleport'"),
        (lambda d: d["actions"][1].pop("t"), r"actions\[1\]: missing field 't'"),
        (lambda d: d["actions"].pop(0), r"actions\[0\]: a script begins with a workflow's 'start'"),
        (lambda d: d["actions"].__setitem__(2, {"t": 0.2, "workflow": "calibrate_camera", "action": "click", "uv": [1, 2]}),
         "without a 'start'"),
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
