"""Designate a target: the clicked pixel's ray meets the database's surfaces."""

from __future__ import annotations

import numpy as np
import pytest

from app.workflows import DesignateTarget, WorkflowError


def test_click_on_the_box_top_gives_the_point_on_its_face(site):
    box = site.object("parallelepiped")
    X_true = box.T_world_obj[:3, :3] @ np.array([0.05, -0.03, 0.132]) + box.T_world_obj[:3, 3]
    wf = DesignateTarget(site)
    t = wf.click(site.camera.project(X_true))
    assert t.object == "parallelepiped"
    assert np.allclose(t.X_world, X_true, atol=1e-6)
    assert np.allclose(t.normal, box.T_world_obj[:3, 2], atol=1e-9)  # the top face's normal
    assert t.range_m == pytest.approx(np.linalg.norm(X_true - site.camera.center))
    assert t.text() == " ".join(f"{v:.4f}" for v in X_true)
    assert wf.marks().targets.shape == (1, 2)


def test_table_then_nothing(site):
    wf = DesignateTarget(site)
    table = site.object("table")
    lo, hi = table.model.bounds()
    X = (
        table.T_world_obj[:3, :3] @ np.array([0.8 * lo[0], 0.8 * hi[1], hi[2]]) + table.T_world_obj[:3, 3]
    )  # a far corner
    assert wf.click(site.camera.project(X)).object == "table"
    assert np.allclose(wf.targets[-1].X_world, X, atol=1e-6)
    with pytest.raises(WorkflowError, match="sees no object"):
        wf.click([256.0, 0.0])  # above the table's far edge
    assert len(wf.targets) == 1
    wf.accept()
    assert wf.finished


# ---------------------------------------------------------------------- checked by the range finder
def _true_distance(scene, name, X):
    """Distance of a world point to a scene body's true surface."""
    import trimesh

    b = scene.body(name)
    V, F = b.model.triangles()
    T = b.pose_at(0.0)
    mesh = trimesh.Trimesh(V @ T[:3, :3].T + T[:3, 3], F, process=False)
    return float(trimesh.proximity.closest_point(mesh, np.asarray(X, float).reshape(1, 3))[1][0])


def _on_body(scene, cam, name):
    """The pixel of a body's centre: the camera sees the body there (it is in front of its centre)."""
    b = scene.body(name)
    T = b.pose_at(0.0)
    lo, hi = b.model.bounds()
    return cam.project(T[:3, :3] @ ((lo + hi) / 2) + T[:3, 3])


def test_without_devices_the_target_is_not_checked(site):
    box = site.object("parallelepiped")
    X = box.T_world_obj[:3, :3] @ np.array([0.0, 0.0, 0.132]) + box.T_world_obj[:3, 3]
    wf = DesignateTarget(site)
    t = wf.click(site.camera.project(X))
    assert t.rangefinder_X is None and t.warning == "" and "not checked by the range finder" in t.check
    assert wf.summary()["targets"][0]["check"] == "not checked by the range finder"
    assert "not checked by the range finder" in wf.message.lower()


def test_a_known_object_agrees_with_the_range_finder(device_site):
    site = device_site
    box = site.object("parallelepiped")
    X = box.T_world_obj[:3, :3] @ np.array([0.03, -0.02, 0.132]) + box.T_world_obj[:3, 3]  # its top face
    wf = DesignateTarget(site)
    t = wf.click(site.camera.project(X))
    assert t.object == "parallelepiped" and np.allclose(t.X_world, X, atol=1e-6)
    assert t.warning == "" and "agrees" in t.check, t.check
    assert t.rangefinder_X is not None and abs(t.disagreement_m) <= 3 * t.sigma_m
    assert 0.004 < t.sigma_m < 0.01  # about σ_ρ = 5 mm along a line of sight near the beam's
    assert np.linalg.norm(site.beam_X_world - t.rangefinder_X) < 1e-9  # the spot shows the range finder's point
    assert wf.progress is None and len(wf.marks().points) == 0  # nothing to flag


@pytest.mark.parametrize("name", ["unknown_box", "unknown_cylinder"])
def test_an_object_not_in_the_database_is_flagged(device_site, fast_scene, name):
    """The bundled scene's unknown box and cylinder stand on the table but are not in the seeded
    database: the database target is on what lies behind them, the range finder meets them."""
    site = device_site
    assert name not in [o.name for o in site.objects()]
    wf = DesignateTarget(site)
    t = wf.click(_on_body(fast_scene, site.camera, name))
    assert t.object == "table"  # the database sees the table behind it
    assert t.warning and "something not in the database is in the way" in t.warning
    assert t.disagreement_m < -3 * t.sigma_m
    # the range finder's point lies on the body (within a few σ of its true surface)
    assert _true_distance(fast_scene, name, t.rangefinder_X) < 3 * t.sigma_m
    assert "Warning" in wf.message and "Warning" in wf.next_step
    m = wf.marks()
    assert len(m.targets) == 1 and len(m.points) == 1  # the database target and the range finder's point
    assert any("R1" == text for _, text in m.labels)
    row = wf.summary()["targets"][0]
    assert row["check"] == "range finder disagrees" and row["disagreement_mm"] < 0
    # what the operator copies for the robot is where the range finder found the surface, not the
    # database's point behind the unmodelled object
    assert wf.copy_text() == row["x y z (m)"] == " ".join(f"{v:.4f}" for v in t.rangefinder_X)


def test_no_database_surface_but_the_range_finder_hits(device_site, fast_scene):
    site = device_site
    wall = fast_scene.body("back_wall")
    T = wall.pose_at(0.0)
    lo, hi = wall.model.bounds()
    X = T[:3, :3] @ np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.8 * hi[2] + 0.2 * lo[2]]) + T[:3, 3]
    uv = site.camera.project(X)
    o, d = site.camera.rays(uv.reshape(1, 2))
    assert site.raycast(o, d[0]) is None  # above the table: no database surface
    wf = DesignateTarget(site)
    t = wf.click(uv)
    assert t.object == "not in the database" and t.warning and "something the database does not have" in t.warning
    assert np.array_equal(t.X_world, t.rangefinder_X)
    assert min(_true_distance(fast_scene, b.name, t.X_world) for b in fast_scene.bodies) < 3 * t.sigma_m
    # the table says the same as the message (it said "range finder disagrees": with nothing to disagree with)
    assert wf.summary()["targets"][0]["check"] == "not in the database: the range finder's point"


def test_a_device_fault_keeps_nothing(device_site, devices):
    site = device_site
    box = site.object("parallelepiped")
    X = box.T_world_obj[:3, :3] @ np.array([0.0, 0.0, 0.132]) + box.T_world_obj[:3, 3]
    wf = DesignateTarget(site)
    devices.site.rangefinder.unplug(np.inf)
    with pytest.raises(WorkflowError, match="device fault"):
        wf.click(site.camera.project(X))
    assert wf.targets == [] and wf.progress is None


def test_a_database_object_that_is_not_there_is_flagged(device_site, db):
    """An object in the database where the workcell has none: the range finder sees past it."""
    site = device_site
    box = site.object("parallelepiped")
    T = box.T_world_obj.copy()
    T[:3, 3] += [-0.35, 0.0, 0.0]  # on a bare part of the table
    db.add_object("ghost", "box", box.model, T, status="known", method="test")
    site.poll()
    X = T[:3, :3] @ np.array([0.0, 0.0, 0.132]) + T[:3, 3]
    wf = DesignateTarget(site)
    t = wf.click(site.camera.project(X))
    assert t.object == "ghost" and t.disagreement_m > 3 * t.sigma_m
    assert "ghost is not where the database has it" in t.warning


def test_the_turret_calibrations_share_of_sigma(device_site):
    """σ along the ray includes the turret calibration's covariance once there is one; its share
    matches a Monte Carlo draw of the turret pose."""
    from app.workflows.designate import along_ray_sigma
    from core.calibration import perturbed_turret

    site = device_site
    uv = _box_top(site)
    wf = DesignateTarget(site)
    plain = wf.click(uv)
    assert plain.details["sigma_turret_m"] == 0.0
    cov = np.diag([np.radians(0.3)] * 3 + [0.003] * 3) ** 2
    site.set_turret(
        site.T_world_turret, rms_m=0.001, residuals_m=np.zeros((1, 3)), cov=cov, measurements={}, client="test"
    )
    t = wf.click(uv)
    assert t.sigma_m > plain.sigma_m and t.details["sigma_turret_m"] > 0.003
    assert t.sigma_m == pytest.approx(np.hypot(t.details["sigma_rangefinder_m"], t.details["sigma_turret_m"]))
    T = site.T_world_turret
    _, d = site.camera.rays(uv.reshape(1, 2))
    x_t = np.linalg.solve(T, np.append(t.rangefinder_X, 1.0))
    rng = np.random.default_rng(0)
    draws = rng.multivariate_normal(np.zeros(6), cov, 4000)
    along = [float(d[0] @ (perturbed_turret(T, s) @ x_t)[:3]) for s in draws]
    _, _, s_T = along_ray_sigma(np.zeros((3, 3)), t.rangefinder_X, d[0], T, cov)
    assert s_T == pytest.approx(np.std(along), rel=0.1)


def _box_top(site) -> np.ndarray:
    """The pixel of the middle of the parallelepiped's top face."""
    box = site.object("parallelepiped")
    return site.camera.project(box.T_world_obj[:3, :3] @ np.array([0.0, 0.0, 0.132]) + box.T_world_obj[:3, 3])


def test_the_measurement_runs_outside_the_workflows_lock(device_site, devices):
    """The redraw loop calls marks(), which takes the lock: it must be free while the devices run."""
    import threading

    site = device_site
    uv = _box_top(site)
    wf = DesignateTarget(site)
    free = []
    measure = devices.rangefinder.measure

    def watched(*args, **kwargs):
        def probe():
            got = wf.lock.acquire(blocking=False)
            free.append(got)
            if got:
                wf.marks()
                wf.lock.release()

        th = threading.Thread(target=probe)
        th.start()
        th.join()
        return measure(*args, **kwargs)

    devices.rangefinder.measure = watched
    wf.click(uv)
    assert free and all(free)


def test_a_measurement_stopped_half_way_leaves_no_beam_spot(device_site, devices):
    """Stopped while the turret aims (the operator's Cancel/Esc): no target, the workflow stays open,
    and the beam spot of the half-done aim is taken away (a new operator saw it left on the video)."""
    from app.workflows import Cancelled

    site = device_site
    uv = _box_top(site)
    wf = DesignateTarget(site)
    seen = []
    shot = devices.rangefinder.measure

    def stop_while_aiming(*args, **kwargs):  # an aiming shot
        seen.append((wf.current_step().name, wf.current_step().prompt))
        site.set_beam(np.array([0.1, 0.2, 0.3]))  # where the aim had got to
        wf.cancel_event.set()
        return shot(*args, **kwargs)

    devices.rangefinder.measure = stop_while_aiming
    with pytest.raises(Cancelled):
        wf.click(uv)
    assert seen and seen[0][0] == "checking" and "Checking the target with the range finder: " in seen[0][1]
    assert wf.targets == [] and wf.progress is None and not wf.finished
    assert site.beam_X_world is None


def test_a_disagreement_found_from_an_old_frozen_frame_says_when_the_frame_was(device_site, fast_scene):
    """The range finder measures the site now: a disagreement found from a frame frozen 2.5 s before says
    so and the frame's time (a new operator read a true disagreement as false: the frozen frame showed the
    box where the database had it); from a frame 0.5 s old nothing is added."""
    from app.workflows.base import FrameRef

    site = device_site
    image = np.zeros((site.camera.height, site.camera.width, 3), np.uint8)
    uv = _on_body(fast_scene, site.camera, "unknown_box")
    for t_s, said in ((-2.5, True), (-0.5, False)):
        wf = DesignateTarget(site)
        wf.use_frame(FrameRef(image, t_s))
        t = wf.click(uv)
        assert "something not in the database is in the way" in t.warning
        assert (
            "(the range finder measures the site as it is now, at t = 0.0 s; your click was on the frame of "
            "t = -2.5 s)" in t.warning
        ) == said
        assert ("measures the site as it is now" in wf.message) == said


class _LiveVideo:
    """A site's live video of one image whose newest frame was taken at ``stamp`` (unix seconds)."""

    def __init__(self, image, stamp: float):
        self.image, self.stamp = image, stamp

    def __call__(self, _t_s):
        return self.image

    def latest(self):
        from app.video import Frame

        return Frame(self.image, 100, 0.0, self.stamp)


@pytest.mark.parametrize("age_s", [30.0, 3.0])
def test_a_target_on_an_old_frozen_frame_says_its_age_and_claims_no_agreement_with_it(device_site, age_s):
    """On a frame frozen 30 s before the newest, the database and the range finder agree on the site as it is
    now, but not with what the frame shows: the target says the frame's age (a new operator was told "on
    table, range finder agrees" for a point drawn on a box); 3 s old (under STALE_FRAME_S): nothing added."""
    from app.workflows.base import STALE_FRAME_S, FrameRef

    site = device_site
    image = np.full((site.camera.height, site.camera.width, 3), 90, np.uint8)
    site.set_frames(_LiveVideo(image, stamp=1000.0 + age_s))
    table = site.object("table")
    T = table.T_world_obj
    X = T[:3, :3] @ np.array([0.25, -0.3, float(table.model.vertices[:, 2].max())]) + T[:3, 3]
    wf = DesignateTarget(site)
    wf.use_frame(FrameRef(image, 0.0, stamp=1000.0))
    t = wf.click(site.camera.project(X))
    assert t.object == "table" and "agrees" in t.check
    stale = age_s > STALE_FRAME_S
    assert (f"this frame is {age_s:.0f} s old; the scene may have changed since" in t.warning) == stale
    assert ("this frame is" in wf.message) == stale and ("range finder agrees" in wf.message) != stale
    assert (wf.summary()["targets"][0]["check"] == "frame 30 s old: the site now") == stale
    assert np.isfinite(t.frame_age_s) == stale


def test_a_target_on_something_the_database_lacks_on_an_old_frame_reads_as_a_sentence(device_site, fast_scene):
    """On a frame frozen 30 s before the newest, a point the range finder met where the database has nothing: a new
    operator read "Target 3: … m on not in the database", and the warning said "put it now, on not in the
    database"."""
    from app.workflows.base import FrameRef

    site = device_site
    wall = fast_scene.body("back_wall")
    lo, hi = wall.model.bounds()
    T = wall.pose_at(0.0)
    X = T[:3, :3] @ np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.8 * hi[2] + 0.2 * lo[2]]) + T[:3, 3]
    image = np.full((site.camera.height, site.camera.width, 3), 90, np.uint8)
    site.set_frames(_LiveVideo(image, stamp=1030.0))
    wf = DesignateTarget(site)
    wf.use_frame(FrameRef(image, 0.0, stamp=1000.0))
    t = wf.click(site.camera.project(X))
    assert t.object == "not in the database" and np.isfinite(t.frame_age_s)
    for text in (t.warning, wf.next_step):
        assert "on not in the database" not in text and "on something not in the database" in text, text
