"""Scene files: a site's camera, turret, range finder, table and objects, with their ground truth.

A scene is a folder ``scenes/<name>/`` holding ``scene.json`` and the files it references (a
video, ``.cao`` models, meshes). The format (``"format": "mcit-scene/1"``)::

    {
      "format": "mcit-scene/1",
      "name": "workcell",
      "description": "free text",
      "camera": {"width": 512, "height": 256,
                 "C": [[...4], [...4], [...4]]}                   # the global model, or
                 "K": [[...3] x3], "T_world_cam": <pose>}          # intrinsics + camera pose
      "turret": {"T_world_turret": <pose>, "resolution_arcsec": 185.1428,
                 "pan_limits_steps": [-3090, 3090], "tilt_limits_steps": [-907, 604],
                 "speed_steps_s": 1000},
      "rangefinder": {"sigma_range_m": 0.005, "min_range_m": 0.6, "max_range_m": 10.0},
      "bodies": [
        {"name": "table", "kind": "table", "status": "known",
         "model": {"box": [1.6, 1.0, 0.05]}, "pose": <pose>},
        {"name": "box1", "kind": "box", "status": "known" | "unknown",
         "model": {"box": [sx, sy, sz]} | {"cylinder": [r, h]} | {"cone": [r_bottom, r_top, h]}
                | {"cao": "file.cao"} | {"mesh": "file.stl"} | {"brep": <BRep.to_dict()>},
         "pose": <pose>,
         "motion": [{"t": 2.0, "pose": <pose>}, ...]}            # optional keyframes, seconds
      ],
      "video": {"file": "video.mp4"}                              # optional, relative to the folder
    }

A ``<pose>`` is either a 4×4 matrix (rows) or ``{"xyz": [x, y, z], "rpy_deg": [roll, pitch, yaw]}``
with ``R = Rz(yaw) Ry(pitch) Rx(roll)``. Between motion keyframes a body moves linearly in
translation and along the geodesic in rotation; before the first keyframe it is at ``pose``
(time 0), after the last it stays there.

"known" bodies start in the database with their true pose at t = 0; "unknown" ones exist only in
the truth (the emulated range finder sees them; the operator must model them).

Errors: ``SceneError`` (a ``ValueError``) naming the file and the field that is wrong.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from core.brep import BRep
from core.camera import Camera
from core.rangefinder import RangeFinderSpec
from core.transforms import check_T, exp_so3, log_so3, make_T, rot_x, rot_y, rot_z

__all__ = [
    "SceneError",
    "Body",
    "TurretSpec",
    "Scene",
    "load_scene",
    "parse_pose",
    "pose_to_json",
    "scenes_dir",
    "default_scene_path",
    "MODEL_LOADERS",
]

FORMAT = "mcit-scene/1"

# Readers for file-based models ("cao", "mesh"): name → fn(path: Path) -> BRep. The model-import
# module registers itself here so this module does not depend on it.
MODEL_LOADERS: dict[str, Callable[[Path], BRep]] = {}


class SceneError(ValueError):
    """A scene file is malformed; the message names the file and the field."""


def scenes_dir() -> Path:
    """The project's bundled ``scenes/`` folder."""
    return Path(__file__).resolve().parent.parent / "scenes"


def default_scene_path() -> Path:
    """The bundled scene ``mcit`` opens by default."""
    return scenes_dir() / "workcell"


def parse_pose(value: Any, where: str) -> np.ndarray:
    """A pose from JSON (4×4 rows, or {"xyz", "rpy_deg"}) → T (4, 4); SceneError on bad input."""
    if isinstance(value, dict):
        unknown = set(value) - {"xyz", "rpy_deg"}
        if unknown:
            raise SceneError(f"{where}: unknown pose keys {sorted(unknown)}; use 'xyz' and 'rpy_deg'")
        try:
            xyz = np.asarray(value.get("xyz", [0, 0, 0]), dtype=float).reshape(3)
            roll, pitch, yaw = np.radians(np.asarray(value.get("rpy_deg", [0, 0, 0]), dtype=float).reshape(3))
        except (TypeError, ValueError) as exc:
            raise SceneError(f"{where}: 'xyz' and 'rpy_deg' must be lists of 3 numbers ({exc})") from None
        if not (np.all(np.isfinite(xyz)) and np.all(np.isfinite([roll, pitch, yaw]))):
            raise SceneError(f"{where}: pose values must be finite")
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
    return {"xyz": [float(v) for v in np.asarray(T)[:3, 3]], "rpy_deg": [float(np.degrees(a)) for a in (roll, pitch, yaw)]}


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


@dataclass(frozen=True)
class Body:
    """One object of the site with its ground truth.

    name : unique name. kind : "table", "box", "cylinder", "cone", "polyhedron", ... (free).
    status : "known" (in the initial database) or "unknown" (truth only).
    model : BRep in the object frame. T_world_obj : pose at t = 0.
    motion : tuple of (t_s, T_world_obj) keyframes, sorted by time.
    """

    name: str
    kind: str
    status: str
    model: BRep
    T_world_obj: np.ndarray
    motion: tuple = ()

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


@dataclass(frozen=True)
class Scene:
    """A loaded scene; see the module docstring for the file format."""

    name: str
    root: Path
    camera: Camera
    turret: TurretSpec
    rangefinder: RangeFinderSpec
    bodies: tuple[Body, ...]
    video_path: Path | None = None
    description: str = ""
    raw: dict = field(default_factory=dict, repr=False, compare=False)

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

    def truth_meshes(self, t_s: float = 0.0) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """Every body's triangle mesh in the world at time t_s: (name, vertices (V, 3), triangles (T, 3))."""
        out = []
        for b in self.bodies:
            V, T = b.model.triangles()
            T_w = b.pose_at(t_s)
            out.append((b.name, V @ T_w[:3, :3].T + T_w[:3, 3], T))
        return out


def _need(d: dict, key: str, where: str) -> Any:
    if not isinstance(d, dict) or key not in d:
        raise SceneError(f"{where}: missing field '{key}'")
    return d[key]


def _matrix(value: Any, shape: tuple[int, int], where: str) -> np.ndarray:
    try:
        M = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise SceneError(f"{where}: expected a {shape[0]}×{shape[1]} matrix of numbers") from None
    if M.shape != shape or not np.all(np.isfinite(M)):
        raise SceneError(f"{where}: expected a finite {shape[0]}×{shape[1]} matrix, got shape {M.shape}")
    return M


def _camera(d: dict, where: str) -> Camera:
    w, h = _need(d, "width", where), _need(d, "height", where)
    if not (isinstance(w, int) and isinstance(h, int) and w > 0 and h > 0):
        raise SceneError(f"{where}.width/height: positive integers expected, got {w!r} × {h!r}")
    try:
        if "C" in d:
            return Camera(_matrix(d["C"], (3, 4), f"{where}.C"), w, h)
        K = _matrix(_need(d, "K", where), (3, 3), f"{where}.K")
        T_world_cam = parse_pose(_need(d, "T_world_cam", where), f"{where}.T_world_cam")
        from core.transforms import invert_T

        return Camera.from_intrinsics(K, invert_T(T_world_cam), w, h)
    except SceneError:
        raise
    except ValueError as exc:
        raise SceneError(f"{where}: {exc}") from None


def _model(d: Any, root: Path, where: str) -> BRep:
    if not isinstance(d, dict) or len(d) != 1:
        raise SceneError(f"{where}: a model is one of {{'box'|'cylinder'|'cone'|'cao'|'mesh'|'brep': ...}}")
    (kind, value), = d.items()
    try:
        if kind == "box":
            return BRep.box(*[float(v) for v in value])
        if kind == "cylinder":
            r, h = (float(v) for v in value)
            return BRep.cylinder(r, h)
        if kind == "cone":
            r0, r1, h = (float(v) for v in value)
            return BRep.cone(r0, r1, h)
        if kind == "brep":
            return BRep.from_dict(value)
        if kind in ("cao", "mesh"):
            path = (root / str(value)).resolve()
            if not path.is_file():
                raise SceneError(f"{where}.{kind}: file not found: {path}")
            if kind not in MODEL_LOADERS:
                import app.models_io  # noqa: F401  (registers the readers)
            return MODEL_LOADERS[kind](path)
    except SceneError:
        raise
    except (TypeError, ValueError) as exc:
        raise SceneError(f"{where}.{kind}: {exc}") from None
    raise SceneError(f"{where}: unknown model kind {kind!r}; use box, cylinder, cone, cao, mesh or brep")


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
    root = file.parent
    where = file.name
    fmt = d.get("format") if isinstance(d, dict) else None
    if fmt != FORMAT:
        raise SceneError(f"{file}: 'format' must be {FORMAT!r}, got {fmt!r}")
    camera = _camera(_need(d, "camera", where), f"{file}: camera")
    t = _need(d, "turret", where)
    try:
        turret = TurretSpec(
            parse_pose(_need(t, "T_world_turret", f"{file}: turret"), f"{file}: turret.T_world_turret"),
            float(t.get("resolution_arcsec", 185.1428)),
            tuple(int(v) for v in t.get("pan_limits_steps", (-3090, 3090))),
            tuple(int(v) for v in t.get("tilt_limits_steps", (-907, 604))),
            float(t.get("speed_steps_s", 1000.0)),
        )
    except (TypeError, ValueError) as exc:
        if isinstance(exc, SceneError):
            raise
        raise SceneError(f"{file}: turret: {exc}") from None
    rf = d.get("rangefinder", {})
    try:
        spec = RangeFinderSpec(
            sigma_range_m=float(rf.get("sigma_range_m", 0.005)),
            min_range_m=float(rf.get("min_range_m", 0.6)),
            max_range_m=float(rf.get("max_range_m", 10.0)),
            step_rad=turret.step_rad,
        )
    except (TypeError, ValueError, AttributeError) as exc:
        raise SceneError(f"{file}: rangefinder: {exc}") from None
    bodies = []
    names = set()
    for i, b in enumerate(_need(d, "bodies", where)):
        bw = f"{file}: bodies[{i}]"
        name = _need(b, "name", bw)
        if not isinstance(name, str) or not name:
            raise SceneError(f"{bw}.name: a non-empty string expected")
        if name in names:
            raise SceneError(f"{bw}.name: duplicate body name {name!r}")
        names.add(name)
        bw = f"{file}: bodies[{i}] ({name})"
        status = b.get("status", "known")
        if status not in ("known", "unknown"):
            raise SceneError(f"{bw}.status: 'known' or 'unknown' expected, got {status!r}")
        model = _model(_need(b, "model", bw), root, f"{bw}.model")
        T0 = parse_pose(_need(b, "pose", bw), f"{bw}.pose")
        motion = []
        last_t = 0.0
        for k, key in enumerate(b.get("motion", [])):
            kw = f"{bw}.motion[{k}]"
            try:
                tk = float(_need(key, "t", kw))
            except (TypeError, ValueError):
                raise SceneError(f"{kw}.t: a number of seconds expected") from None
            if tk <= last_t:
                raise SceneError(f"{kw}.t: keyframe times must increase and be > 0, got {tk} after {last_t}")
            last_t = tk
            motion.append((tk, parse_pose(_need(key, "pose", kw), f"{kw}.pose")))
        bodies.append(Body(name, str(b.get("kind", "object")), status, model, T0, tuple(motion)))
    video = None
    if "video" in d:
        vf = _need(d["video"], "file", f"{where}: video")
        video = (root / vf).resolve()
    return Scene(str(d.get("name", root.name)), root, camera, turret, spec, tuple(bodies), video, str(d.get("description", "")), d)
