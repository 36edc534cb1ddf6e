"""The headless workflow layer: what the operator does, as explicit calls.

The viser interface (app/ui) and the headless demo drive the same objects:
``Site`` (shared: scene, camera, database, devices, clock), ``Session`` (one operator: the
selected object and the workflow under way) and one small state machine per workflow.
No viser here.
"""

from .base import Cancelled, Ghost, Marks, Workflow, WorkflowError
from .calibrate_camera import CalibrateCamera
from .calibrate_camera_robot import CalibrateCameraFromRobot
from .calibrate_robot import CalibrateRobot
from .calibrate_turret import CalibrateTurret
from .designate import DesignateTarget, Target
from .history import History
from .model_object import ModelObject
from .model_polyhedron import ModelPolyhedron
from .move_robot import MoveRobot
from .pick_place import PickPlace
from .session import WORKFLOWS, Session, register
from .site import RayHit, Site, SiteObject
from .snapping import ClickSnap
from .track import TrackObject
from .update_pose import UpdatePose

for _cls in (
    CalibrateCamera,
    CalibrateCameraFromRobot,
    CalibrateRobot,
    CalibrateTurret,
    DesignateTarget,
    History,
    UpdatePose,
    ModelObject,
    ModelPolyhedron,
    MoveRobot,
    PickPlace,
    TrackObject,
):
    register(_cls)

__all__ = [
    "Cancelled",
    "Ghost",
    "Marks",
    "Workflow",
    "WorkflowError",
    "CalibrateCamera",
    "CalibrateCameraFromRobot",
    "CalibrateRobot",
    "CalibrateTurret",
    "History",
    "DesignateTarget",
    "ModelObject",
    "ModelPolyhedron",
    "MoveRobot",
    "PickPlace",
    "Target",
    "UpdatePose",
    "TrackObject",
    "ClickSnap",
    "WORKFLOWS",
    "Session",
    "register",
    "RayHit",
    "Site",
    "SiteObject",
]
