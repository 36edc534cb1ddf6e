"""SceneRaycaster: first hits against the true meshes, at the bodies' poses of the asked time."""

import numpy as np
import pytest

from app.devices.raycast import SceneRaycaster
from app.scene import Body
from core.brep import BRep
from core.transforms import make_T, rot_z


def test_first_hit_is_the_nearest_face_at_the_analytic_distance(workcell):
    rc = SceneRaycaster(workcell)
    b = workcell.body("unknown_box")
    T = b.pose_at(0.0)
    normals = b.model.face_normals() @ T[:3, :3].T
    centroids = b.model.face_centroids() @ T[:3, :3].T + T[:3, 3]
    k = int(np.argmax(normals[:, 2]))  # the top face, seen from straight above
    origin = centroids[k] + np.array([0.0, 0.0, 0.8])
    dist, body = rc.cast(origin, [0.0, 0.0, -3.0], 0.0)
    assert body == "unknown_box" and dist == pytest.approx(0.8, abs=1e-9)
    depth = float(np.ptp(b.model.vertices[:, 2]))
    inside = centroids[k] - np.array([0.0, 0.0, 0.3 * depth])  # from inside, out through the top
    d_up, b_up = rc.cast(inside, [0.0, 0.0, 1.0], 0.0)
    assert b_up == "unknown_box" and d_up == pytest.approx(0.3 * depth, abs=1e-9)


def test_a_beam_into_the_sky_misses(workcell):
    top = max(float((b.pose_at(0.0) @ np.r_[b.model.bounds()[1], 1.0])[2]) for b in workcell.bodies)
    assert SceneRaycaster(workcell).cast([0.0, 0.0, top + 1.0], [0.0, 0.0, 1.0]) == (np.inf, None)


def test_moving_bodies_are_cast_at_the_asked_time():
    start = make_T(np.eye(3), [0.0, 0.0, 0.0])
    moving = Body("crate", "box", "known", BRep.box(0.2, 0.2, 0.1), start, ((2.0, make_T(rot_z(0.3), [0.5, 0.0, 0.0])),))
    rc = SceneRaycaster([moving])
    origin, down = np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, -1.0])
    assert rc.cast(origin, down, 0.0) == (pytest.approx(0.9, abs=1e-9), "crate")
    assert rc.cast(origin, down, 5.0) == (np.inf, None)  # it has gone from under the beam
    halfway = rc.cast(origin + [0.25, 0.0, 0.0], down, 1.0)  # at t = 1 s its centre is at x = 0.25
    assert halfway == (pytest.approx(0.9, abs=1e-9), "crate")


def test_bad_beams_are_refused(workcell):
    rc = SceneRaycaster(workcell)
    with pytest.raises(ValueError, match="non-zero direction"):
        rc.cast([0, 0, 0], [0, 0, 0])
    with pytest.raises(ValueError, match="no bodies"):
        SceneRaycaster([])
