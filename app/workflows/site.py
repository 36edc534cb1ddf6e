"""The site one mcit server (or one headless demo) works on: the scene, the current calibrations,
the database, the devices and the scene clock, shared by every operator.

Workflows read the site through snapshots (``objects()``, ``camera``) and write only through
``Site``'s methods, each one database transaction; every write bumps ``revision`` so that
every client's overlay redraws. ``poll()`` also notices changes made by another process (the
``mcit db`` command, a second server on the same file).
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from app.scene import Scene
from core.brep import BRep
from core.camera import Camera

__all__ = ["SiteObject", "RayHit", "Site"]


@dataclass(frozen=True)
class SiteObject:
    """One database object as the interface sees it (a read-only snapshot).

    T_world_obj : (4, 4). cov : (6, 6) or None. status : "known", "modelled" or "stale".
    version : the database version, passed back on update (conflict detection).
    """

    id: Any
    name: str
    kind: str
    status: str
    model: BRep
    T_world_obj: np.ndarray
    version: int
    cov: np.ndarray | None = None
    dimensions: dict = field(default_factory=dict)
    sigmas: dict = field(default_factory=dict)

    def vertices_world(self) -> np.ndarray:
        """Model vertices in the world, (V, 3)."""
        V = self.model.vertices
        return V @ self.T_world_obj[:3, :3].T + self.T_world_obj[:3, 3] if len(V) else np.zeros((0, 3))


@dataclass(frozen=True)
class RayHit:
    """Where a ray meets the database's surfaces: ``X_world`` (3,), the object's name, the
    distance along the ray (metres) and the surface normal (3,) in the world."""

    X_world: np.ndarray
    name: str
    distance_m: float
    normal: np.ndarray


def _record_to_object(rec: Any) -> SiteObject:
    """An ``app.db.ObjectRecord`` → SiteObject."""
    return SiteObject(
        id=rec.id,
        name=rec.name,
        kind=rec.kind,
        status=rec.status,
        model=rec.model,
        T_world_obj=np.asarray(rec.T_world_obj, dtype=float),
        version=int(rec.version),
        cov=None if rec.cov is None else np.asarray(rec.cov, dtype=float),
        dimensions=dict(rec.dims),
        sigmas=dict(rec.sigmas),
    )


class Site:
    """Shared world of one server.

    Parameters
    ----------
    scene : Scene
        The site's description (camera and turret at start-up, truth for the emulators).
    db : app.db.Database
        The site's database (objects, history, calibrations); its latest camera and turret
        calibrations are used (the scene's when it has none).
    devices : object with ``.rangefinder`` and ``.turret``, optional
        Opened devices (real or emulated); None when running without them.
    clock : callable returning the scene time in seconds, optional
        The video's time (a prerecorded video's position); default: time since start.
    frames : "scene", None or a callable ``frames(t_s) -> image | None``
        Where the frame the operator clicked on comes from (edge and corner snapping, automatic
        matching, tracking; ``app.workflows.frames``): "scene" (default) reads the scene's
        prerecorded video at the scene time, if it has one; None: no frames (clicks are used as
        clicked); the interface installs its video grabber (``set_frames``).
    """

    def __init__(self, scene: Scene, db: Any, devices: Any = None, clock: Callable[[], float] | None = None,
                 frames: Any = "scene"):
        self.scene = scene
        self.db = db
        self.devices = devices
        self._t0 = time.monotonic()
        self.clock = clock or (lambda: time.monotonic() - self._t0)
        self.lock = threading.RLock()
        self.revision = 0
        self._objects: tuple[SiteObject, ...] | None = None
        self._objects_key: Any = None
        self._meshes: dict[str, Any] = {}
        self._cal_ids: dict[str, Any] = {}
        self._camera = scene.camera
        # The calibrations' covariances (None for the scene's nominal values, until calibrated here).
        self._camera_cov: np.ndarray | None = None
        self._turret_cov: np.ndarray | None = None
        self._T_world_turret = np.asarray(scene.turret.T_world_turret, float).copy()
        self.beam_X_world: np.ndarray | None = None  # the range finder's last measured point (shown)
        self._load_calibrations()
        self._frames: Callable[[float], Any] | None = None
        if isinstance(frames, str):
            if frames != "scene":
                raise ValueError(f"frames must be 'scene', None or a callable frames(t_s) -> image, got {frames!r}")
            video = getattr(scene, "video", None)
            if video is not None and Path(video.path).is_file():
                from .frames import SceneVideoFrames

                self._frames = SceneVideoFrames(video)
        elif frames is not None:
            if not callable(frames):
                raise ValueError(f"frames must be 'scene', None or a callable frames(t_s) -> image, got {type(frames).__name__}")
            self._frames = frames

    # ------------------------------------------------------------------ video frames
    def set_frames(self, frames: Callable[[float], Any] | None) -> None:
        """Use another frame provider (the interface's grabber), or None for none."""
        if frames is not None and not callable(frames):
            raise ValueError(f"frames must be a callable frames(t_s) -> image, or None; got {type(frames).__name__}")
        with self.lock:
            self._frames = frames

    @property
    def has_frames(self) -> bool:
        """True when the site can show workflows the frame the operator clicked on."""
        return self._frames is not None

    def frame_at(self, t_s: float | None = None) -> np.ndarray | None:
        """The video frame showing scene time ``t_s`` (default: now, ``time_s()``) — RGB or grey
        uint8, (H, W, 3) or (H, W) — or None when the site has no frames or the source has none."""
        frames = self._frames
        if frames is None:
            return None
        image = frames(self.time_s() if t_s is None else float(t_s))
        return None if image is None else np.asarray(image)

    # ------------------------------------------------------------------ reading
    @property
    def camera(self) -> Camera:
        """The current camera calibration (the global model C)."""
        with self.lock:
            return self._camera

    @property
    def T_world_turret(self) -> np.ndarray:
        """The current turret calibration, (4, 4)."""
        with self.lock:
            return self._T_world_turret.copy()

    @property
    def calibration_covs(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(camera_cov (12, 12), turret_cov (6, 6)) of the current calibrations; None for one that is
        the scene's nominal value (not calibrated in this database) or was stored without one."""
        with self.lock:
            return self._camera_cov, self._turret_cov

    def time_s(self) -> float:
        """The scene time, seconds (the video's position)."""
        return float(self.clock())

    def objects(self) -> tuple[SiteObject, ...]:
        """Every object in the database (snapshot, cached until the database changes)."""
        with self.lock:
            if self._objects is None:
                self._objects = tuple(_record_to_object(r) for r in self.db.objects())
                self._objects_key = self._key(self._objects)
            return self._objects

    def object(self, name: str) -> SiteObject:
        """One object by name; WorkflowError-style ValueError naming the known ones if absent."""
        for o in self.objects():
            if o.name == name:
                return o
        raise KeyError(f"no object named {name!r} in the database; it has {[o.name for o in self.objects()]}")

    @staticmethod
    def _key(objects: tuple[SiteObject, ...]) -> tuple:
        return tuple((o.id, o.version, o.status) for o in objects)

    def poll(self) -> bool:
        """Re-read the database (objects and the latest calibrations); True, and ``revision``
        bumped, when something changed since (e.g. ``mcit db undo`` from another process)."""
        fresh = tuple(_record_to_object(r) for r in self.db.objects())
        key = self._key(fresh)
        with self.lock:
            changed = self._load_calibrations()
            if key != self._objects_key:
                self._objects, self._objects_key = fresh, key
                changed = True
            if changed:
                self.revision += 1
            return changed

    def _changed(self) -> None:
        with self.lock:
            self._objects = None
            self.revision += 1

    # ------------------------------------------------------------------ calibrations
    def _load_calibrations(self) -> bool:
        """Adopt the database's latest camera and turret calibrations; True if either changed."""
        changed = False
        cam = self.db.latest_calibration("camera")
        if cam is not None and self._cal_ids.get("camera") != cam.id:
            d = cam.data
            self._camera = Camera(np.asarray(d["C"], float), int(d.get("width", self.scene.camera.width)),
                                  int(d.get("height", self.scene.camera.height)))
            self._camera_cov = None if d.get("cov") is None else np.asarray(d["cov"], float)
            self._cal_ids["camera"] = cam.id
            changed = True
        tur = self.db.latest_calibration("turret")
        if tur is not None and self._cal_ids.get("turret") != tur.id:
            self._T_world_turret = np.asarray(tur.data["T_world_turret"], float).copy()
            self._turret_cov = None if tur.data.get("cov") is None else np.asarray(tur.data["cov"], float)
            self._cal_ids["turret"] = tur.id
            changed = True
        return changed

    def set_camera(self, camera: Camera, *, rms_px: float, residuals_px: np.ndarray, points: dict, client: str,
                   method: str = "dlt", cov: np.ndarray | None = None) -> None:
        """Store a new camera calibration (one transaction) and use it from now on.
        cov : (12, 12) covariance of ``camera.C.ravel()`` (``calibrate_dlt(...).cov``), or None."""
        data = {"C": camera.C, "width": camera.width, "height": camera.height, "rms_px": float(rms_px), **points}
        if cov is not None:
            data["cov"] = np.asarray(cov, float)
        rec = self.db.add_calibration("camera", data, np.asarray(residuals_px, float), method=method, client=client)
        with self.lock:
            self._camera = camera
            self._camera_cov = None if cov is None else np.asarray(cov, float).copy()
            self._cal_ids["camera"] = rec.id
            self.revision += 1

    def set_turret(self, T_world_turret: np.ndarray, *, rms_m: float, residuals_m: np.ndarray, cov: np.ndarray,
                   measurements: dict, client: str, method: str = "turret calibration") -> None:
        """Store a new turret calibration (one transaction) and use it from now on."""
        data = {"T_world_turret": np.asarray(T_world_turret, float), "rms_m": float(rms_m),
                "cov": np.asarray(cov, float), **measurements}
        rec = self.db.add_calibration("turret", data, np.asarray(residuals_m, float), method=method, client=client)
        with self.lock:
            self._T_world_turret = np.asarray(T_world_turret, float).copy()
            self._turret_cov = np.asarray(cov, float).copy()
            self._cal_ids["turret"] = rec.id
            self.revision += 1

    # ------------------------------------------------------------------ writing objects
    def write(self, fn: Callable[[Any], Any]) -> Any:
        """Run one database write ``fn(db)`` (one transaction: the Database's own methods are) and
        redraw every client. Exceptions pass through; nothing is written when one is raised."""
        result = fn(self.db)
        self._changed()
        return result

    def set_beam(self, X_world: np.ndarray | None) -> None:
        """Show the range finder's last measured point (None hides it)."""
        with self.lock:
            self.beam_X_world = None if X_world is None else np.asarray(X_world, float).copy()

    # ------------------------------------------------------------------ ray casting
    def surfaces(self):
        """All objects as one triangle mesh (trimesh, its ray index built once) and each
        triangle's object name; cached until the database changes."""
        import trimesh

        objects = self.objects()
        key = self._key(objects)
        with self.lock:
            if self._meshes.get("key") == key:
                return self._meshes["mesh"], self._meshes["owner"]
        Vs, Fs, owner, offset = [], [], [], 0
        for obj in objects:
            V, F = obj.model.triangles()
            Vs.append(V @ obj.T_world_obj[:3, :3].T + obj.T_world_obj[:3, 3])
            Fs.append(F + offset)
            owner += [obj.name] * len(F)
            offset += len(V)
        mesh = trimesh.Trimesh(np.vstack(Vs), np.vstack(Fs), process=False) if Vs else None
        with self.lock:
            self._meshes = {"key": key, "mesh": mesh, "owner": np.array(owner)}
        return mesh, np.array(owner)

    def raycast(self, origin: np.ndarray, direction: np.ndarray) -> RayHit | None:
        """The first database surface a ray (origin (3,), direction (3,), world) meets, or None."""
        mesh, owner = self.surfaces()
        if mesh is None:
            return None
        o = np.asarray(origin, float).reshape(1, 3)
        d = np.asarray(direction, float).reshape(1, 3)
        d = d / np.linalg.norm(d)
        locs, _, tri = mesh.ray.intersects_location(o, d, multiple_hits=True)
        if len(locs) == 0:
            return None
        dist = (locs - o) @ d[0]
        ahead = dist > 0
        if not np.any(ahead):
            return None
        i = int(np.flatnonzero(ahead)[np.argmin(dist[ahead])])
        return RayHit(locs[i].copy(), str(owner[tri[i]]), float(dist[i]), mesh.face_normals[tri[i]].copy())
