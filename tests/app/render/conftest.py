"""A small scene (96 × 64 px: a table, a moving box, a can) for quick renderer and video tests."""

import copy

import pytest

SMALL = {
    "format": "mcit-scene/1",
    "name": "small",
    "camera": {
        "width": 96,
        "height": 64,
        "K": [[80, 0, 47.5], [0, 80, 31.5], [0, 0, 1]],
        "T_world_cam": {"xyz": [0, -1.2, 0.5], "rpy_deg": [-110, 0, 0]},
    },
    "turret": {"T_world_turret": {"xyz": [0.2, -1.2, 0.5], "rpy_deg": [0, 0, 90]}},
    "bodies": [
        {
            "name": "table",
            "model": {"box": [1.0, 1.0, 0.04]},
            "pose": {"xyz": [0, 0, -0.04]},
            "appearance": {"albedo": 0.3},
        },
        {
            "name": "box",
            "model": {"box": [0.2, 0.1, 0.1]},
            "pose": {"xyz": [0, 0, 0]},
            "appearance": {"albedo": 0.8, "texture": 0.05},
            "motion": [{"t": 0.5, "pose": {"xyz": [0.1, 0.05, 0], "rpy_deg": [0, 0, 30]}}],
        },
        {
            "name": "can",
            "model": {"cylinder": [0.04, 0.12]},
            "pose": {"xyz": [-0.25, -0.1, 0]},
            "appearance": {"albedo": 0.7},
        },
    ],
    "video": {"file": "clip.avi", "fps": 10, "duration_s": 0.7},
}


@pytest.fixture
def small_scene_dict() -> dict:
    """A fresh copy of the small scene's description (tests may edit it)."""
    return copy.deepcopy(SMALL)
