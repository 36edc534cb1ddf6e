"""Shared set-ups for the modelling tests: the paper's sensors (DESIGN.md §Simulation)."""

import numpy as np
import pytest

from core.brep import Revolution
from core.geometry import Plane
from core.modeling.simulate import SimWorld, look_at_setup
from core.transforms import make_T, rot_z

TABLE = Plane(np.array([0.0, 0.0, 1.0]), 0.0)
BOX_SIZE = np.array([0.09, 0.094, 0.14])  # the paper's box, w × l × h


@pytest.fixture
def box_scene():
    """Camera 1.4 m from the paper's box (yaw 35°) on the table, turret 20 cm to its right."""
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, 0.07]), 1.4)
    T_obj = make_T(rot_z(np.radians(35.0)), [0.0, 0.0, 0.0])
    return cam, T_wt, T_obj, SimWorld(T_wt, boxes=((T_obj, tuple(BOX_SIZE)),))


def cylinder_scene(distance_m=1.3, r0=0.051, r1=0.051, h=0.166, offset=(0.0, 0.0), tilt_axis=None):
    """Camera and turret looking at a solid of revolution standing at ``offset`` on the table."""
    cam, T_wt = look_at_setup(np.array([0.0, 0.0, h / 2]), distance_m)
    p0 = np.array([offset[0], offset[1], 0.0])
    a = (
        np.array([0.0, 0.0, 1.0])
        if tilt_axis is None
        else np.asarray(tilt_axis, dtype=float) / np.linalg.norm(tilt_axis)
    )
    sol = Revolution(p0, p0 + h * a, r0, r1)
    return cam, T_wt, sol, SimWorld(T_wt, solids=(sol,))
