"""Scene files: a site's camera, turret, range finder, table and objects, with their ground truth.

A scene is a folder ``scenes/<name>/`` holding ``scene.json`` and the files it references (a
video, ``.cao`` models, meshes, an intrinsics file). The format (``"format": "mcit-scene/1"``;
docs/scene-format.md is the full reference)::

    {
      "format": "mcit-scene/1",
      "name": "workcell",
      "description": "free text",
      "camera": {"width": 512, "height": 256,
                 "C": [[...4], [...4], [...4]]}                   # the global model, or
                 "K": [[...3] x3], "T_world_cam": <pose>}          # intrinsics + camera pose, or
                 "intrinsics_file": "cam.xml", "T_world_cam": <pose>}   # ViSP .xml / OpenCV .yml
                 # (a file with lens distortion: Scene.lens; the video is undistorted on arrival and the
                 #  renderer renders through the lens; C holds in the undistorted image, app/undistort.py)
      "turret": {"T_world_turret": <pose>, "resolution_arcsec": 185.1428,      # optional: none on a
                 "pan_limits_steps": [-3090, 3090], "tilt_limits_steps": [-907, 604],   # camera-only site
                 "speed_steps_s": 1000},
      "rangefinder": {"sigma_range_m": 0.005, "min_range_m": 0.6, "max_range_m": 10.0},  # with a turret
      "bodies": [                                                     # optional (default: none)
        {"name": "table", "kind": "table", "status": "known",
         "model": {"box": [1.6, 1.0, 0.05]}, "pose": <pose>},
        {"name": "box1", "kind": "box", "status": "known" | "unknown" | "scenery",
         "model": {"box": [sx, sy, sz]} | {"cylinder": [r, h]} | {"cone": [r_bottom, r_top, h]}
                | {"cao": "file.cao"} | {"mesh": "file.stl"} | {"brep": <BRep.to_dict()>},
         "pose": <pose>,
         "motion": [{"t": 2.0, "pose": <pose>}, ...],            # optional keyframes, seconds
         "appearance": {"albedo": 0.7, "texture": 0.03, "texture_scale_m": 0.04}}   # optional
      ],
      "video": {"file": "video.mp4", "fps": 12, "duration_s": 28},   # optional
      "render": {"light_dir": [-0.4, -0.5, 1], "ambient": 0.35, "noise_sigma": 2.0,
                 "blur_sigma_px": 0.5, "seed": 8, "aa_samples": 89, "sky": 0.2},  # optional
      "robot": {"urdf": "arm.urdf", "T_world_base": <pose>,                   # optional
                "T_world_base_nominal": <pose>,                               # optional
                "home_deg": {"shoulder_pan_joint": 180, ...}, "home_m": {"finger_joint": 0.03},
                "calibration_base_deg": [[-90, -40, 55, -180, -120, -15], ...],  # optional
                "calibration_camera_deg": [[...], ...],                           # optional
                "tool": "tool0", "appearance": {...}}
    }

A ``<pose>`` is either a 4×4 matrix (rows) or ``{"xyz": [x, y, z], "rpy_deg": [roll, pitch, yaw]}``
with ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Between motion keyframes a body moves linearly in
translation and along the geodesic in rotation; before the first keyframe it is at ``pose``
(time 0), after the last it stays there.

Status: "known" bodies start in the database with their true pose at t = 0; "unknown" ones exist
only in the truth (the emulated range finder sees them; the operator must model them);
"scenery" bodies (floor, walls) are seen by the camera and the range finder but never enter the
database.

The robot (``Scene.robot``, a ``RobotSpec``) is not one of the bodies: the prerecorded videos were
rendered without it. Its home joint positions are by joint name, revolute and continuous joints in
degrees (``home_deg``), prismatic ones in metres (``home_m``); ``RobotSpec.home_q(model)`` checks them
against the URDF's joints and limits (``app.robot.urdf.load_scene_robot`` loads both).
``T_world_base`` is where the base truly stands (the emulated site's truth); ``T_world_base_nominal``
is where the drawing says it stands (default: the same), what a new database believes until the base
is calibrated from the video. ``calibration_base_deg`` and ``calibration_camera_deg`` are the joint
configurations the calibration workflows send the robot to (``RobotSpec.calibration_qs``): each one
angle in degrees per actuated joint that is not prismatic, in the URDF's order, the prismatic ones (the
gripper) at their lower limits (closed).

Every block is checked: a missing or malformed field, or a key the format does not know (a
typo), raises ``SceneError`` (a ``ValueError``) naming the file and the field. Keys starting with
``_`` are comments and are ignored.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.names import check_object_name
from core.brep import BRep
from core.camera import Camera
from core.rangefinder import RangeFinderSpec
from core.transforms import check_T, exp_so3, invert_T, log_so3, make_T, rot_x, rot_y, rot_z

__all__ = [
    "SceneError",
    "Appearance",
    "Body",
    "TurretSpec",
    "VideoSpec",
    "RenderSpec",
    "RobotSpec",
    "Scene",
    "SceneView",
    "DEFAULT_VIEW",
    "load_scene",
    "scene_from_dict",
    "parse_pose",
    "pose_to_json",
    "scenes_dir",
    "default_scene_path",
    "STATUSES",
]

FORMAT = "mcit-scene/1"
STATUSES = ("known", "unknown", "scenery")


class SceneError(ValueError):
    """A scene file is malformed; the message names the file and the field."""


def scenes_dir() -> Path:
    """The project's bundled ``scenes/`` folder."""
    return Path(__file__).resolve().parent.parent / "scenes"


def default_scene_path() -> Path:
    """The bundled scene ``mcit`` opens by default."""
    return scenes_dir() / "workcell"


# ---------------------------------------------------------------------- small validators
def _keys(d: Any, allowed: tuple[str, ...], where: str) -> dict:
    """``d`` must be an object whose keys are in ``allowed`` (``_comments`` are ignored)."""
    if not isinstance(d, dict):
        raise SceneError(f"{where}: expected an object {{...}}, got {type(d).__name__}")
    unknown = sorted(k for k in d if k not in allowed and not str(k).startswith("_"))
    if unknown:
        raise SceneError(f"{where}: unknown field(s) {unknown}; the allowed fields are {list(allowed)}")
    return d


def _need(d: dict, key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise SceneError(f"{where}: missing field '{key}'")
    return d[key]


def _number(
    value: Any, where: str, *, lo: float | None = None, lo_open: bool = False, hi: float | None = None
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SceneError(f"{where}: a number expected, got {value!r}")
    v = float(value)
    if not np.isfinite(v):
        raise SceneError(f"{where}: must be finite, got {value!r}")
    if lo is not None and (v <= lo if lo_open else v < lo):
        raise SceneError(f"{where}: must be {'>' if lo_open else '≥'} {lo}, got {v}")
    if hi is not None and v > hi:
        raise SceneError(f"{where}: must be ≤ {hi}, got {v}")
    return v


def _numbers(value: Any, n: int, where: str, *, positive: bool = False) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != n:
        raise SceneError(f"{where}: a list of {n} numbers expected, got {value!r}")
    return [_number(v, f"{where}[{i}]", lo=0.0 if positive else None, lo_open=positive) for i, v in enumerate(value)]


def _int(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise SceneError(f"{where}: an integer expected, got {value!r}")
    return int(value)


def _matrix(value: Any, shape: tuple[int, int], where: str) -> np.ndarray:
    try:
        M = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: expected a {shape[0]}×{shape[1]} matrix of numbers") from None
    if M.shape != shape:
        raise SceneError(f"{where}: expected a {shape[0]}×{shape[1]} matrix, got shape {M.shape}")
    if not np.all(np.isfinite(M)):
        i, j = (int(k) for k in np.argwhere(~np.isfinite(M))[0])
        raise SceneError(f"{where}: entry ({i + 1}, {j + 1}) is {M[i, j]}; every entry must be a finite number")
    return M


# ---------------------------------------------------------------------- poses
def parse_pose(value: Any, where: str) -> np.ndarray:
    """A pose from JSON (4×4 rows, or {"xyz", "rpy_deg"}) → T (4, 4); SceneError on bad input."""
    if isinstance(value, dict):
        unknown = set(value) - {"xyz", "rpy_deg"}
        if unknown:
            raise SceneError(f"{where}: unknown pose keys {sorted(unknown)}; use 'xyz' and 'rpy_deg'")
        xyz = _numbers(value.get("xyz", [0, 0, 0]), 3, f"{where}.xyz")
        roll, pitch, yaw = np.radians(_numbers(value.get("rpy_deg", [0, 0, 0]), 3, f"{where}.rpy_deg"))
        return make_T(rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), xyz)
    try:
        T = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: a pose is a 4×4 matrix or {{'xyz': [...], 'rpy_deg': [...]}}") from None
    try:
        return check_T(T, where)
    except ValueError as exc:
        raise SceneError(str(exc)) from None


def pose_to_json(T: np.ndarray) -> dict[str, list[float]]:
    """Inverse of ``parse_pose`` in the readable form (xyz, rpy_deg)."""
    R = np.asarray(T)[:3, :3]
    pitch = float(np.arcsin(np.clip(-R[2, 0], -1.0, 1.0)))
    if abs(np.cos(pitch)) > 1e-9:
        roll = float(np.arctan2(R[2, 1], R[2, 2]))
        yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    else:  # gimbal lock: put everything in yaw
        roll = 0.0
        yaw = float(np.arctan2(-R[0, 1], R[1, 1]))
    return {
        "xyz": [float(v) for v in np.asarray(T)[:3, 3]],
        "rpy_deg": [float(np.degrees(a)) for a in (roll, pitch, yaw)],
    }


# ---------------------------------------------------------------------- data
@dataclass(frozen=True)
class TurretSpec:
    """The pan/tilt unit: its pose, resolution, limits (steps) and speed (steps/s)."""

    T_world_turret: np.ndarray
    resolution_arcsec: float = 185.1428
    pan_limits_steps: tuple[int, int] = (-3090, 3090)
    tilt_limits_steps: tuple[int, int] = (-907, 604)
    speed_steps_s: float = 1000.0

    @property
    def step_rad(self) -> float:
        """One step in radians."""
        return float(np.radians(self.resolution_arcsec / 3600.0))

    def within_limits(self, pan_rad: float, tilt_rad: float) -> bool:
        """True when the angles (radians) are inside the pan and tilt limits."""
        pan_s, tilt_s = pan_rad / self.step_rad, tilt_rad / self.step_rad
        return bool(
            self.pan_limits_steps[0] <= pan_s <= self.pan_limits_steps[1]
            and self.tilt_limits_steps[0] <= tilt_s <= self.tilt_limits_steps[1]
        )


@dataclass(frozen=True)
class Appearance:
    """How the renderer shades a body (no effect on geometry or sensing).

    albedo : reflectance in [0, 1] (grey). texture : amplitude of a smooth value-noise texture
    fixed to the body (fraction of the albedo). texture_scale_m : the texture's feature size, metres.
    """

    albedo: float = 0.6
    texture: float = 0.0
    texture_scale_m: float = 0.05


@dataclass(frozen=True)
class Body:
    """One object of the site with its ground truth.

    name : unique name. kind : "table", "box", "cylinder", "cone", "polyhedron", ... (free).
    status : "known" (in the initial database), "unknown" (truth only) or "scenery" (floor,
    walls: seen by the sensors, never in the database).
    model : BRep in the object frame. T_world_obj : pose at t = 0.
    motion : tuple of (t_s, T_world_obj) keyframes, sorted by time.
    appearance : shading parameters for the renderer.
    """

    name: str
    kind: str
    status: str
    model: BRep
    T_world_obj: np.ndarray
    motion: tuple = ()
    appearance: Appearance = Appearance()

    def pose_at(self, t_s: float) -> np.ndarray:
        """True pose ``T_world_obj`` (4, 4) at time t_s (seconds from the start of the video)."""
        keys = ((0.0, self.T_world_obj),) + tuple(self.motion)
        if t_s <= keys[0][0]:
            return keys[0][1].copy()
        for (t0, T0), (t1, T1) in zip(keys, keys[1:]):
            if t_s <= t1:
                a = (t_s - t0) / (t1 - t0) if t1 > t0 else 1.0
                R = T0[:3, :3] @ exp_so3(a * log_so3(T0[:3, :3].T @ T1[:3, :3]))
                return make_T(R, (1 - a) * T0[:3, 3] + a * T1[:3, 3])
        return keys[-1][1].copy()

    @property
    def moves(self) -> bool:
        return bool(self.motion)

    def is_static(self, t0_s: float, t1_s: float) -> bool:
        """True when the body does not move during [t0_s, t1_s] (seconds)."""
        keys = ((0.0, self.T_world_obj),) + tuple(self.motion)
        for (ta, Ta), (tb, Tb) in zip(keys, keys[1:]):
            if tb > t0_s and ta < t1_s and not np.allclose(Ta, Tb, atol=1e-12):
                return False
        return True


@dataclass(frozen=True)
class VideoSpec:
    """The scene's prerecorded video: file (absolute path), frame rate and length."""

    path: Path
    fps: float = 12.0
    duration_s: float = 10.0

    @property
    def frame_count(self) -> int:
        """Number of frames: ⌊duration × fps⌋ + 1 (frame k shows the scene at t = k / fps)."""
        return int(np.floor(self.duration_s * self.fps + 1e-9)) + 1

    def frame_time(self, k: int) -> float:
        """Scene time (s) of frame k."""
        return k / self.fps

    def frame_index(self, t_s: float) -> int:
        """The frame showing scene time t_s (nearest, clamped to the video)."""
        return int(np.clip(np.round(t_s * self.fps), 0, self.frame_count - 1))


@dataclass(frozen=True)
class SceneView:
    """One camera of the site (a view): its name, the global model C, its lens (or None) and its
    prerecorded video (or None)."""

    name: str
    camera: Camera
    lens: Any = field(default=None, compare=False)
    video: VideoSpec | None = None
    # The camera came from an intrinsics file (ViSP .xml, OpenCV or ROS .yml) that states no covariance: a pose's
    # σ then holds the file's stated prior (core.pose.uncertainty.intrinsics_prior_cov; issue 27). A camera
    # written in the scene (C, or K and its pose: a simulation's, or one mcit calibrated) holds none.
    from_file: bool = field(default=False, compare=False)


@dataclass(frozen=True)
class RenderSpec:
    """Renderer settings (app.render): light, sensor noise, blur, anti-aliasing.

    light_dir : array, shape (3,), unit vector towards the light, world frame. ambient : share
    of the light that reaches every surface. gain : grey level of a surface of albedo 1 facing
    the light. sky : radiance (albedo-like) of rays that hit nothing. noise_sigma : sensor
    noise, grey levels (Gaussian, seeded by ``seed`` and the frame index). blur_sigma_px : optical
    blur (Gaussian, pixels; 0 for none). aa_samples : samples per pixel where a pixel straddles
    an edge (a golden-ratio lattice shifted per pixel; the rest of the image takes one sample per
    pixel).
    """

    light_dir: tuple[float, float, float] = (-0.4, -0.5, 1.0)
    ambient: float = 0.35
    gain: float = 235.0
    sky: float = 0.2
    noise_sigma: float = 2.0
    blur_sigma_px: float = 0.5
    seed: int = 0
    aa_samples: int = 89

    @property
    def light(self) -> np.ndarray:
        v = np.asarray(self.light_dir, dtype=float)
        return v / np.linalg.norm(v)


@dataclass(frozen=True)
class RobotSpec:
    """The site's robot: its URDF, where its base stands, its home joint positions, its tool and its shading.

    urdf_path : absolute path of the URDF. T_world_base : array, shape (4, 4), the URDF's root link in
    the world (the truth). home : joint name → position (radians for a revolute or continuous joint, metres for a
    prismatic one); joints not named are at 0 (brought within their limits). tool : the tool link (None: "tool0"
    when the URDF has one, else its deepest link that no finger moves).
    appearance : how the renderer shades every link. home_in_metres : the joints the file gave in
    metres (``home_m``), checked against the URDF's joint kinds. T_world_base_nominal : (4, 4) where the
    drawing puts the base (None: at ``T_world_base``). calibration : {"base": ..., "camera": ...}, each a
    tuple of configurations (tuples of degrees, one per actuated joint that is not prismatic).
    """

    urdf_path: Path
    T_world_base: np.ndarray
    home: dict = field(default_factory=dict)
    tool: str | None = None
    appearance: Appearance = Appearance()
    home_in_metres: frozenset = frozenset()
    T_world_base_nominal: np.ndarray | None = None
    calibration: dict = field(default_factory=dict)

    @property
    def nominal_base(self) -> np.ndarray:
        """Where the drawing puts the base (4, 4): what a new database believes until it is calibrated."""
        return self.T_world_base if self.T_world_base_nominal is None else self.T_world_base_nominal

    def calibration_qs(self, model, which: str) -> np.ndarray:
        """The joint configurations (k, n) of ``calibration_<which>_deg`` ("base" or "camera") in ``model``'s
        joint order, the prismatic joints at their lower limits; (0, n) when the scene gives none. SceneError
        naming the field for a configuration of the wrong length or out of the joint limits."""
        field_name = f"robot.calibration_{which}_deg"
        turning = [k for k, name in enumerate(model.joint_names) if model.joint(name).kind != "prismatic"]
        out = []
        for i, angles in enumerate(self.calibration.get(which, ())):
            if len(angles) != len(turning):
                names = [model.joint_names[k] for k in turning]
                raise SceneError(
                    f"{field_name}[{i}]: {len(angles)} angles for the {len(turning)} turning joints {names}"
                )
            q = np.where(np.isfinite(model.lower), model.lower, 0.0).astype(float)
            q[turning] = np.radians(np.asarray(angles, float))
            beyond = model.within_limits(q)
            if beyond is not None:
                raise SceneError(f"{field_name}[{i}] puts {beyond}")
            out.append(q)
        return np.array(out).reshape(-1, model.n)

    def home_q(self, model) -> np.ndarray:
        """The home joint vector (n,) in ``model``'s joint order (a ``core.robot.RobotModel`` of this URDF).

        SceneError naming the field for a joint the URDF does not move, a value in the wrong unit
        (a prismatic joint in ``home_deg``, a revolute one in ``home_m``) or out of the joint's limits.
        """
        q = np.clip(np.zeros(model.n), model.lower, model.upper)
        for name, value in self.home.items():
            field_name = "home_m" if name in self.home_in_metres else "home_deg"
            if name not in model.joint_names:
                raise SceneError(
                    f"robot.{field_name}: {self.urdf_path.name} has no actuated joint {name!r}; "
                    f"its joints: {list(model.joint_names)}"
                )
            prismatic = model.joint(name).kind == "prismatic"
            if prismatic != (name in self.home_in_metres):
                right = "home_m (metres)" if prismatic else "home_deg (degrees)"
                raise SceneError(f"robot.{field_name}.{name}: a {model.joint(name).kind} joint; give it in {right}")
            q[model.joint_names.index(name)] = value
        beyond = model.within_limits(q)
        if beyond is not None:
            raise SceneError(f"robot: the home position puts {beyond}")
        return q


@dataclass(frozen=True)
class Scene:
    """A loaded scene; see the module docstring for the file format."""

    name: str
    root: Path
    camera: Camera
    turret: TurretSpec | None  # None: a camera-only site (no turret, no range finder)
    rangefinder: RangeFinderSpec
    bodies: tuple[Body, ...]
    video_path: Path | None = None
    description: str = ""
    raw: dict = field(default_factory=dict, repr=False, compare=False)
    video: VideoSpec | None = None
    render: RenderSpec = RenderSpec()
    # The camera's lens distortion (app.undistort.LensDistortion) from an intrinsics file, or None: the
    # video is undistorted on arrival (C holds in the undistorted image); the renderer renders through it.
    lens: Any = field(default=None, compare=False)
    # Every camera of the site, the first one's being camera, lens and video above (a scene with one
    # "camera" block has one view, named "main").
    views: tuple[SceneView, ...] = ()
    # The site's robot (not one of the bodies: the prerecorded videos were rendered without it), or None.
    robot: RobotSpec | None = None

    def __post_init__(self) -> None:
        v = self.views[0] if self.views else None
        if v is None or v.camera is not self.camera or v.lens is not self.lens or v.video is not self.video:
            # the first view is camera, lens and video (a scene made or replaced field by field keeps to it)
            first = SceneView(DEFAULT_VIEW if v is None else v.name, self.camera, self.lens, self.video)
            object.__setattr__(self, "views", (first, *self.views[1:]))

    def view(self, name: str | None = None) -> SceneView:
        """The view named ``name`` (the first for None); SceneError naming the views otherwise."""
        if name is None:
            return self.views[0]
        for v in self.views:
            if v.name == name:
                return v
        raise SceneError(f"scene {self.name!r} has no camera named {name!r}; its cameras: {self.view_names}")

    def camera_block(self, view: str | None = None) -> dict:
        """One camera's block as the scene file gives it (the first camera for None), {} when the scene
        was not read from a file."""
        raw = self.raw or {}
        if "cameras" not in raw:
            return dict(raw.get("camera") or {}) if view in (None, self.views[0].name) else {}
        name = self.view(view).name
        return next((dict(c) for c in raw["cameras"] if isinstance(c, dict) and c.get("name") == name), {})

    @property
    def view_names(self) -> tuple[str, ...]:
        return tuple(v.name for v in self.views)

    def body(self, name: str) -> Body:
        for b in self.bodies:
            if b.name == name:
                return b
        raise KeyError(f"scene {self.name!r} has no body named {name!r}; it has {[b.name for b in self.bodies]}")

    @property
    def known(self) -> tuple[Body, ...]:
        return tuple(b for b in self.bodies if b.status == "known")

    @property
    def unknown(self) -> tuple[Body, ...]:
        return tuple(b for b in self.bodies if b.status == "unknown")

    @property
    def scenery(self) -> tuple[Body, ...]:
        return tuple(b for b in self.bodies if b.status == "scenery")

    def truth_meshes(self, t_s: float = 0.0) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """Every body's triangle mesh in the world at time t_s: (name, vertices (V, 3), triangles (T, 3))."""
        out = []
        for b in self.bodies:
            V, T = b.model.triangles()
            T_w = b.pose_at(t_s)
            out.append((b.name, V @ T_w[:3, :3].T + T_w[:3, 3], T))
        return out


# ---------------------------------------------------------------------- blocks
_CAMERA_KEYS = ("width", "height", "C", "K", "T_world_cam", "intrinsics_file", "camera_name")
_TURRET_KEYS = ("T_world_turret", "resolution_arcsec", "pan_limits_steps", "tilt_limits_steps", "speed_steps_s")
_RF_KEYS = ("sigma_range_m", "min_range_m", "max_range_m")
_BODY_KEYS = ("name", "kind", "status", "model", "pose", "motion", "appearance")
_APPEARANCE_KEYS = ("albedo", "texture", "texture_scale_m")
_VIDEO_KEYS = ("file", "fps", "duration_s")
_ROBOT_KEYS = (
    "urdf",
    "T_world_base",
    "T_world_base_nominal",
    "home_deg",
    "home_m",
    "calibration_base_deg",
    "calibration_camera_deg",
    "tool",
    "appearance",
)
_RENDER_KEYS = ("light_dir", "ambient", "gain", "sky", "noise_sigma", "blur_sigma_px", "seed", "aa_samples")
_TOP_KEYS = (
    "format",
    "name",
    "description",
    "camera",
    "cameras",
    "turret",
    "rangefinder",
    "bodies",
    "video",
    "render",
    "robot",
)
VIEW_NAME = re.compile(r"[A-Za-z0-9_-]{1,32}")  # a camera's name: it is typed in --video NAME=SOURCE
DEFAULT_VIEW = "main"  # the name of the one view of a scene with a "camera" block
_MODEL_KINDS = ("box", "cylinder", "cone", "brep", "cao", "mesh")


def _camera(d: Any, root: Path, where: str) -> Camera:
    """The Camera of a scene's camera block (its lens: ``_camera_and_lens``)."""
    return _camera_and_lens(d, root, where)[0]


def _camera_and_lens(d: Any, root: Path, where: str):
    """(Camera, LensDistortion or None) of a scene's camera block."""
    _keys(d, _CAMERA_KEYS, where)
    given = [k for k in ("C", "K", "intrinsics_file") if k in d]
    if len(given) != 1:
        raise SceneError(
            f"{where}: give exactly one of 'C' (3×4), 'K' (3×3, with 'T_world_cam') or 'intrinsics_file' "
            f"(with 'T_world_cam'); got {given or 'none'}"
        )
    width = height = None
    if "width" in d:
        width = _int(d["width"], f"{where}.width")
    if "height" in d:
        height = _int(d["height"], f"{where}.height")
    if "camera_name" in d and given != ["intrinsics_file"]:
        raise SceneError(f"{where}.camera_name: names a camera in 'intrinsics_file'; remove it or give that file")
    if given == ["C"] and "T_world_cam" in d:
        raise SceneError(f"{where}.T_world_cam: C already holds the camera pose; remove one of them")
    try:
        if given == ["C"]:
            C = _matrix(d["C"], (3, 4), f"{where}.C")
            w, h = _size(width, height, where)
            return Camera(C, w, h), None
        lens = None
        if given == ["K"]:
            K = _matrix(d["K"], (3, 3), f"{where}.K")
        else:
            from app.camera_io import read_intrinsics

            file = (root / str(d["intrinsics_file"])).resolve()
            name = d.get("camera_name")
            if name is not None and not isinstance(name, str):
                raise SceneError(
                    f"{where}.camera_name: the name of a camera in the intrinsics file expected, got {name!r}"
                )
            try:
                size = (width, height) if width is not None and height is not None else None
                intr = read_intrinsics(file, camera_name=name, image_size=size)
            except ValueError as exc:
                raise SceneError(f"{where}.intrinsics_file: {exc}") from None
            K = intr.K
            width = intr.width if width is None else width
            height = intr.height if height is None else height
            if intr.has_distortion:
                from app.undistort import lens_of

                if intr.width is not None and (width, height) != (intr.width, intr.height):
                    raise SceneError(
                        f"{where}.intrinsics_file: {file} was calibrated on {intr.width}×{intr.height} "
                        f"images, the camera block says {width}×{height}; give the intrinsics for this size"
                    )
                try:
                    lens = lens_of(intr, width, height)
                except ValueError as exc:
                    raise SceneError(f"{where}.intrinsics_file: {exc}") from None
        T_world_cam = parse_pose(_need(d, "T_world_cam", where), f"{where}.T_world_cam")
        w, h = _size(width, height, where)
        return Camera.from_intrinsics(K, invert_T(T_world_cam), w, h), lens
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None


def _size(width: int | None, height: int | None, where: str) -> tuple[int, int]:
    if width is None or height is None:
        raise SceneError(f"{where}: missing field '{'width' if width is None else 'height'}' (image size in pixels)")
    if width <= 0 or height <= 0:
        raise SceneError(f"{where}.width/height: positive integers expected, got {width} × {height}")
    return width, height


def _turret(t: Any, where: str) -> TurretSpec:
    _keys(t, _TURRET_KEYS, where)
    T = parse_pose(_need(t, "T_world_turret", where), f"{where}.T_world_turret")
    res = _number(t.get("resolution_arcsec", 185.1428), f"{where}.resolution_arcsec", lo=0.0, lo_open=True)
    limits = []
    for key, default in (("pan_limits_steps", [-3090, 3090]), ("tilt_limits_steps", [-907, 604])):
        v = t.get(key, default)
        if not isinstance(v, (list, tuple)) or len(v) != 2:
            raise SceneError(f"{where}.{key}: [min, max] in steps expected, got {v!r}")
        lo, hi = _int(v[0], f"{where}.{key}[0]"), _int(v[1], f"{where}.{key}[1]")
        if not lo < 0 < hi:
            raise SceneError(f"{where}.{key}: [min, max] with min < 0 < max expected, got {[lo, hi]}")
        limits.append((lo, hi))
    speed = _number(t.get("speed_steps_s", 1000.0), f"{where}.speed_steps_s", lo=0.0, lo_open=True)
    return TurretSpec(T, res, limits[0], limits[1], speed)


def _rangefinder(rf: Any, step_rad: float, where: str) -> RangeFinderSpec:
    _keys(rf, _RF_KEYS, where)
    sigma = _number(rf.get("sigma_range_m", 0.005), f"{where}.sigma_range_m", lo=0.0)
    lo = _number(rf.get("min_range_m", 0.6), f"{where}.min_range_m", lo=0.0)
    hi = _number(rf.get("max_range_m", 10.0), f"{where}.max_range_m", lo=0.0, lo_open=True)
    if not lo < hi:
        raise SceneError(f"{where}: min_range_m ({lo}) must be below max_range_m ({hi})")
    return RangeFinderSpec(sigma_range_m=sigma, min_range_m=lo, max_range_m=hi, step_rad=step_rad)


def _model(d: Any, root: Path, where: str) -> BRep:
    if not isinstance(d, dict) or len(d) != 1:
        raise SceneError(f"{where}: a model is one object with one key among {list(_MODEL_KINDS)}, got {d!r}")
    ((kind, value),) = d.items()
    if kind not in _MODEL_KINDS:
        raise SceneError(f"{where}: unknown model kind {kind!r}; use one of {list(_MODEL_KINDS)}")
    w = f"{where}.{kind}"
    try:
        if kind == "box":
            return BRep.box(*_numbers(value, 3, f"{w} [size_x, size_y, size_z] (m)", positive=True))
        if kind == "cylinder":
            return BRep.cylinder(*_numbers(value, 2, f"{w} [radius, height] (m)", positive=True))
        if kind == "cone":
            r0, r1, h = _numbers(value, 3, f"{w} [radius_bottom, radius_top, height] (m)")
            if r0 < 0 or r1 < 0 or r0 + r1 <= 0 or h <= 0:
                raise SceneError(f"{w}: radii ≥ 0 (not both 0) and a positive height expected, got {value}")
            return BRep.cone(r0, r1, h)
        if kind == "brep":
            if not isinstance(value, dict):
                raise SceneError(f"{w}: an object {{vertices, edges, faces, solids}} expected")
            return BRep.from_dict(value)
        # "cao" / "mesh": a file beside scene.json
        if not isinstance(value, str) or not value:
            raise SceneError(f"{w}: a file name (relative to the scene folder) expected, got {value!r}")
        path = (root / value).resolve()
        if not path.is_file():
            raise SceneError(f"{w}: file not found: {path}")
        from app.models_io import MODEL_LOADERS  # the readers (trimesh) load when a scene names a file

        return MODEL_LOADERS[kind](path)
    except SceneError:
        raise
    except (TypeError, ValueError, KeyError) as exc:
        raise SceneError(f"{w}: {exc}") from None


def _appearance(a: Any, where: str) -> Appearance:
    _keys(a, _APPEARANCE_KEYS, where)
    return Appearance(
        _number(a.get("albedo", 0.6), f"{where}.albedo", lo=0.0, hi=1.0),
        _number(a.get("texture", 0.0), f"{where}.texture", lo=0.0, hi=1.0),
        _number(a.get("texture_scale_m", 0.05), f"{where}.texture_scale_m", lo=0.0, lo_open=True),
    )


def _body(b: Any, i: int, root: Path, names: set, where: str) -> Body:
    bw = f"{where}: bodies[{i}]"
    if not isinstance(b, dict):
        raise SceneError(f"{bw}: expected an object {{name, model, pose, ...}}, got {type(b).__name__}")
    name = _need(b, "name", bw)
    try:
        check_object_name(name, "a body's name")
    except ValueError as exc:
        raise SceneError(f"{bw}.name: {exc}") from None
    if name in names:
        raise SceneError(f"{bw}.name: duplicate body name {name!r}; every body needs its own name")
    names.add(name)
    bw = f"{where}: bodies[{i}] ({name})"
    _keys(b, _BODY_KEYS, bw)
    status = b.get("status", "known")
    if status not in STATUSES:
        raise SceneError(f"{bw}.status: one of {list(STATUSES)} expected, got {status!r}")
    kind = b.get("kind", "object")
    if not isinstance(kind, str) or not kind:
        raise SceneError(f"{bw}.kind: a non-empty string expected, got {kind!r}")
    model = _model(_need(b, "model", bw), root, f"{bw}.model")
    T0 = parse_pose(_need(b, "pose", bw), f"{bw}.pose")
    motion = []
    last_t = 0.0
    keys = b.get("motion", [])
    if not isinstance(keys, list):
        raise SceneError(f"{bw}.motion: a list of {{t, pose}} keyframes expected, got {type(keys).__name__}")
    for k, key in enumerate(keys):
        kw = f"{bw}.motion[{k}]"
        _keys(key, ("t", "pose"), kw)
        tk = _number(_need(key, "t", kw), f"{kw}.t")
        if tk <= last_t:
            raise SceneError(f"{kw}.t: keyframe times must increase and be > 0 (seconds), got {tk} after {last_t}")
        last_t = tk
        motion.append((tk, parse_pose(_need(key, "pose", kw), f"{kw}.pose")))
    appearance = _appearance(b.get("appearance", {}), f"{bw}.appearance")
    return Body(name, kind, status, model, T0, tuple(motion), appearance)


def _video(v: Any, root: Path, bodies: list[Body], where: str) -> VideoSpec:
    _keys(v, _VIDEO_KEYS, where)
    file = _need(v, "file", where)
    if not isinstance(file, str) or not file:
        raise SceneError(f"{where}.file: a file name (relative to the scene folder) expected, got {file!r}")
    fps = _number(v.get("fps", 12.0), f"{where}.fps", lo=0.0, lo_open=True)
    last_key = max((b.motion[-1][0] for b in bodies if b.motion), default=0.0)
    duration = _number(v.get("duration_s", max(last_key + 2.0, 5.0)), f"{where}.duration_s", lo=0.0, lo_open=True)
    return VideoSpec((root / file).resolve(), fps, duration)


def _render(r: Any, where: str) -> RenderSpec:
    _keys(r, _RENDER_KEYS, where)
    base = RenderSpec()
    light = tuple(_numbers(r.get("light_dir", list(base.light_dir)), 3, f"{where}.light_dir"))
    if np.linalg.norm(light) <= 0:
        raise SceneError(f"{where}.light_dir: a non-zero vector expected")
    aa = _int(r.get("aa_samples", base.aa_samples), f"{where}.aa_samples")
    if not 1 <= aa <= 1024:
        raise SceneError(f"{where}.aa_samples: 1 … 1024 samples per edge pixel expected, got {aa}")
    return RenderSpec(
        light_dir=light,
        ambient=_number(r.get("ambient", base.ambient), f"{where}.ambient", lo=0.0, hi=1.0),
        gain=_number(r.get("gain", base.gain), f"{where}.gain", lo=0.0, lo_open=True, hi=255.0),
        sky=_number(r.get("sky", base.sky), f"{where}.sky", lo=0.0, hi=1.0),
        noise_sigma=_number(r.get("noise_sigma", base.noise_sigma), f"{where}.noise_sigma", lo=0.0),
        blur_sigma_px=_number(r.get("blur_sigma_px", base.blur_sigma_px), f"{where}.blur_sigma_px", lo=0.0),
        seed=_int(r.get("seed", base.seed), f"{where}.seed"),
        aa_samples=aa,
    )


def _robot(r: Any, root: Path, where: str) -> RobotSpec:
    _keys(r, _ROBOT_KEYS, where)
    file = _need(r, "urdf", where)
    if not isinstance(file, str) or not file:
        raise SceneError(f"{where}.urdf: a URDF file name (relative to the scene folder) expected, got {file!r}")
    path = (root / file).resolve()
    if not path.is_file():
        raise SceneError(f"{where}.urdf: file not found: {path}")
    T = parse_pose(_need(r, "T_world_base", where), f"{where}.T_world_base")
    home: dict[str, float] = {}
    metres = set()
    for key, scale in (("home_deg", np.pi / 180.0), ("home_m", 1.0)):
        values = r.get(key, {})
        if not isinstance(values, dict):
            raise SceneError(f"{where}.{key}: an object {{joint name: value}} expected, got {values!r}")
        for name, value in values.items():
            if name in home:
                raise SceneError(f"{where}.{key}.{name}: the joint is given twice (home_deg and home_m)")
            home[str(name)] = _number(value, f"{where}.{key}.{name}") * scale
            if key == "home_m":
                metres.add(str(name))
    tool = r.get("tool")
    if tool is not None and (not isinstance(tool, str) or not tool):
        raise SceneError(f"{where}.tool: the name of the tool link expected, got {tool!r}")
    appearance = _appearance(r.get("appearance", {}), f"{where}.appearance")
    nominal = None
    if "T_world_base_nominal" in r:
        nominal = parse_pose(r["T_world_base_nominal"], f"{where}.T_world_base_nominal")
    calibration = {which: _configurations(r, f"calibration_{which}_deg", where) for which in ("base", "camera")}
    return RobotSpec(path, T, home, tool, appearance, frozenset(metres), nominal, calibration)


def _configurations(r: dict, key: str, where: str) -> tuple:
    """A list of joint configurations (each a list of angles in degrees) as a tuple of tuples."""
    values = r.get(key, [])
    if not isinstance(values, list):
        raise SceneError(f"{where}.{key}: a list of configurations (lists of angles in degrees) expected")
    out = []
    for i, angles in enumerate(values):
        if not isinstance(angles, list) or not angles:
            raise SceneError(f"{where}.{key}[{i}]: a list of angles in degrees expected, got {angles!r}")
        out.append(tuple(_number(a, f"{where}.{key}[{i}]") for a in angles))
    return tuple(out)


def _views(d: dict, root: Path, bodies: list[Body], where: str) -> tuple[SceneView, ...]:
    """The scene's cameras: a "cameras" list (each a camera block with a "name" and its own "video"), or
    one "camera" block (and the top-level "video") named ``DEFAULT_VIEW``."""
    if "cameras" in d:
        if "camera" in d or "video" in d:
            raise SceneError(
                f"{where}: give either 'cameras' (a list, each camera with its own 'video') or 'camera' and "
                "'video', not both"
            )
        cams = d["cameras"]
        if not isinstance(cams, list) or not cams:
            raise SceneError(f"{where}: cameras: a non-empty list of camera blocks expected")
        views: list[SceneView] = []
        for i, c in enumerate(cams):
            at = f"{where}: cameras[{i}]"
            if not isinstance(c, dict):
                raise SceneError(f"{at}: expected an object {{...}}, got {type(c).__name__}")
            name = _need(c, "name", at)
            if not isinstance(name, str) or not VIEW_NAME.fullmatch(name):
                raise SceneError(f"{at}.name: 1 to 32 letters, digits, '-' or '_' expected, got {name!r}")
            if name in (v.name for v in views):
                raise SceneError(f"{at}.name: {name!r} names two cameras; give each its own name")
            block = {k: v for k, v in c.items() if k not in ("name", "video")}
            camera, lens = _camera_and_lens(block, root, at)
            video = _video(c["video"], root, bodies, f"{at}.video") if "video" in c else None
            views.append(SceneView(name, camera, lens, video, from_file="intrinsics_file" in block))
        return tuple(views)
    block = _need(d, "camera", where)
    camera, lens = _camera_and_lens(block, root, f"{where}: camera")
    video = _video(d["video"], root, bodies, f"{where}: video") if "video" in d else None
    return (SceneView(DEFAULT_VIEW, camera, lens, video, from_file="intrinsics_file" in block),)


def scene_from_dict(d: Any, root: str | Path, where: str = "scene.json") -> Scene:
    """Validate a scene description (the parsed JSON) whose files live in the folder ``root``."""
    root = Path(root)
    if not isinstance(d, dict):
        raise SceneError(f"{where}: a scene is a JSON object, got {type(d).__name__}")
    fmt = d.get("format")
    if fmt != FORMAT:
        raise SceneError(f"{where}: 'format' must be {FORMAT!r}, got {fmt!r}")
    _keys(d, _TOP_KEYS, where)
    # A camera-only site (docs/own-site.md) has no turret, hence no range finder: Scene.turret is None.
    turret = _turret(d["turret"], f"{where}: turret") if "turret" in d else None
    if turret is None and "rangefinder" in d:
        raise SceneError(
            f"{where}: rangefinder: a range finder is carried by the turret; give the scene its 'turret' block too, "
            "or drop 'rangefinder' for a camera-only site"
        )
    step_rad = (turret or TurretSpec(np.eye(4))).step_rad
    spec = _rangefinder(d.get("rangefinder", {}), step_rad, f"{where}: rangefinder")
    raw_bodies = d.get("bodies", [])
    if not isinstance(raw_bodies, list):
        raise SceneError(
            f"{where}: bodies: a list of bodies expected (empty for none), got {type(raw_bodies).__name__}"
        )
    names: set[str] = set()
    bodies = [_body(b, i, root, names, where) for i, b in enumerate(raw_bodies)]
    views = _views(d, root, bodies, where)
    render = _render(d.get("render", {}), f"{where}: render")
    robot = _robot(d["robot"], root, f"{where}: robot") if "robot" in d else None
    for key in ("name", "description"):
        if key in d and not isinstance(d[key], str):
            raise SceneError(f"{where}: '{key}' must be a string, got {d[key]!r}")
    first = views[0]
    return Scene(
        str(d.get("name", root.name)),
        root,
        first.camera,
        turret,
        spec,
        tuple(bodies),
        first.video.path if first.video else None,
        str(d.get("description", "")),
        d,
        first.video,
        render,
        first.lens,
        views,
        robot,
    )


def load_scene(path: str | Path) -> Scene:
    """Load and validate ``scene.json`` (or a folder containing it)."""
    path = Path(path)
    file = path / "scene.json" if path.is_dir() else path
    if not file.is_file():
        raise SceneError(f"{file}: no such scene file (a scene is a folder with scene.json)")
    try:
        d = json.loads(file.read_text())
    except json.JSONDecodeError as exc:
        raise SceneError(f"{file}: not valid JSON: {exc}") from None
    return scene_from_dict(d, file.parent, str(file))
