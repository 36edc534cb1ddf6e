"""The site one mcit server (or one headless demo) works on: the scene, the current calibrations,
the database, the devices and the scene clock, shared by every operator.

Workflows read the site through snapshots (``objects()``, ``camera``) and write only through
``Site``'s named methods (``update_pose``, ``add_object``, ``set_status``, ``undo``, ``restore``,
``set_camera``, ``set_turret``, ``set_robot_base``), each one database transaction; every write bumps ``revision`` so
that every client's overlay redraws. ``poll()`` also notices changes made by another process (the
``mcit db`` command, a second server on the same file).

Every change — through this Site by any client, or by another process once ``poll()`` sees it —
joins the change feed: ``changes_since(seq)`` lists them as ``Change`` (who, what in one sentence,
which object, when), for the panel to tell each operator what the others did.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from app.scene import Scene
from core.brep import BRep
from core.camera import Camera

__all__ = ["SiteObject", "RayHit", "Change", "Site"]

FEED_LENGTH = 500  # the changes the feed keeps (a client further behind gets the last ones)


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

    @property
    def model_sigma_m(self) -> float:
        """σ of each model edge's position (metres), part of every pose's σ (``ObjectRecord.model_sigma_m``)."""
        from core.pose.uncertainty import model_sigma_of

        return model_sigma_of(self.sigmas)

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


@dataclass(frozen=True)
class Change:
    """One change of the database, as announced to the operators.

    seq : the history's change number (``mcit db history``, the History workflow), increasing.
    who : the client that made it. what : one plain sentence ("moved box_1", "added box_2",
    "marked table stale", "calibrated the camera", "undid change #12"). object_name : the object
    it concerns, None for a calibration. when : wall time, seconds since the epoch.
    """

    seq: int
    who: str
    what: str
    object_name: str | None
    when: float


# The history's method tags in the operator's words (the tag itself stays in the database and `mcit db`).
METHOD_WORDS = {
    "search": "found from one click",
    "search+refine": "one click, then edges refined",
    "p3l+refine": "solved from clicked edges, then refined",
    "match+refine": "edges matched automatically, then refined",
    "refine": "refined from clicked edges",
    "tracking": "tracked in the video",
    "operator": "by hand",
    "dlt": "camera matrix from clicked points",
    "pnp": "camera pose from clicked points (lens known)",
    "robot edges": "robot's base from its clicked edges",
    "robot dlt": "camera matrix from the robot's tool tip",
    "robot pnp": "camera pose from the robot's tool tip (lens known)",
    "undo": "undo",
    "restore": "brought back",
}


def method_words(method: str | None) -> str:
    """A change's method tag as the operator reads it ("p3l+refine" → "solved from clicked edges, then
    refined"); a tag without words (a script's, "model box (fused)") as it is."""
    if not method:
        return ""
    return METHOD_WORDS.get(method, method)


def _is_undo(rec: Any) -> bool:
    return rec.action == "undo" or (rec.action == "calibration" and rec.method == "undo" and rec.undoes is not None)


def is_redo(rec: Any, undone: Any) -> bool:
    """``rec`` undoes ``undone`` (the record it names), itself an undo: a redo of the change first undone."""
    return (
        rec.undoes is not None
        and undone is not None
        and int(undone.id) == int(rec.undoes)
        and _is_undo(rec)
        and _is_undo(undone)
        and undone.undoes is not None
    )


def _change_sentence(rec: Any, undone: Any = None, first_camera: str | None = None) -> str:
    """What an ``app.db.ChangeRecord`` did, in one plain sentence (without who). ``undone``: the
    record an undo undid, when known: the undo of an undo is said as a redo of the change first
    undone ("redid change #7 (undid undo #9)"; a new operator read "undid change #9" as a second undo).
    ``first_camera``: the name of the site's first camera (stored as plain "camera") when it has others."""
    name = rec.object_name or "an object"
    redo = is_redo(rec, undone)
    if rec.action == "calibration":
        kind = (rec.after or {}).get("kind", "")
        if kind == "camera" and first_camera:
            kind = f"camera:{first_camera}"  # beside "camera side", the front camera's is named too
        kind = kind.replace("camera:", "camera ").replace("_", " ")  # "camera side"
        if redo:
            return f"redid change #{undone.undoes} ({kind} calibration; undid undo #{rec.undoes})"
        if rec.undoes is not None:
            return f"{'undid' if rec.method == 'undo' else 'went back to'} change #{rec.undoes} ({kind} calibration)"
        if kind == "robot base" and str(rec.method).startswith("seed"):  # the drawing's pose, not a calibration
            return "set the robot base where the drawing puts it (not calibrated)"
        return f"calibrated the {kind}" if kind else "stored a calibration"
    if rec.action == "add":
        return f"added {name}"
    if rec.action == "remove":
        return f"removed {name}"
    if redo:
        return f"redid change #{undone.undoes}" + (
            f" ({name}; undid undo #{rec.undoes})" if rec.object_name else f" (undid undo #{rec.undoes})"
        )
    if rec.action == "undo" and undone is not None and int(undone.id) == int(rec.undoes) and undone.action == "add":
        return f"removed {name} (undid change #{rec.undoes}, its addition)"
    if rec.action == "undo":
        return f"undid change #{rec.undoes}" + (f" ({name})" if rec.object_name else "")
    if rec.action == "restore":
        return f"brought {name} back to change #{rec.undoes}"
    before, after = rec.before or {}, rec.after or {}

    def differs(k: str) -> bool:
        return k in after and not np.array_equal(
            np.asarray(before.get(k), dtype=object), np.asarray(after.get(k), dtype=object)
        )

    if differs("T_world_obj"):
        return f"moved {name}"
    if differs("model_id") or differs("kind") or differs("dims"):
        return f"remodelled {name}"
    if differs("status"):
        return f"marked {name} {after['status']}"
    return f"updated {name}"


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
    robot : app.robot.cell.RobotCell or None
        The site's robot (its model, controller and calibrated base), None for a site with none. Its base
        is the database's latest "robot_base" calibration (``robot_base_nominal`` while that is the scene's
        nominal pose, or while there is none), adopted here and whenever it changes.
    """

    def __init__(
        self,
        scene: Scene,
        db: Any,
        devices: Any = None,
        clock: Callable[[], float] | None = None,
        frames: Any = "scene",
        robot: Any = None,
    ):
        self.scene = scene
        self.db = db
        self.devices = devices
        self.robot = robot  # an app.robot.cell.RobotCell, or None for a site with no robot
        self._t0 = time.monotonic()
        self.clock = clock or (lambda: time.monotonic() - self._t0)
        self.lock = threading.RLock()
        self.revision = 0
        self._objects: tuple[SiteObject, ...] | None = None
        self._objects_key: Any = None
        self._by_id: dict[Any, SiteObject] = {}  # snapshots kept across reads, keyed by id (version, status checked)
        self._polled_change: int | None = None  # the history's last change id when poll() last read the database
        self._triangles: dict[Any, tuple[tuple, np.ndarray, np.ndarray]] = {}  # id → (key, V_world, F) for surfaces()
        self._meshes: dict[str, Any] = {}
        self._cal_ids: dict[str, Any] = {}
        # Each view's camera, the scene's until calibrated here, and its calibration's covariance (None
        # for the scene's nominal values); the first view's is ``camera``.
        self._views = tuple(v.name for v in scene.views) or ("main",)
        self._cameras: dict[str, Camera] = {v.name: v.camera for v in scene.views} or {"main": scene.camera}
        self._camera_covs: dict[str, np.ndarray | None] = dict.fromkeys(self._views)
        self._turret_cov: np.ndarray | None = None
        # A camera-only site has no turret (scene.turret None): the identity stands in, unused (no devices).
        turret = np.eye(4) if scene.turret is None else scene.turret.T_world_turret
        self._T_world_turret = np.array(turret, dtype=float)  # a copy: the scene's stays as it was
        self._robot_base_nominal = True  # the robot's base is the drawing's until a calibration says otherwise
        self._robot_base_cov: np.ndarray | None = None
        self.beam_X_world: np.ndarray | None = None  # the range finder's last measured point (shown)
        # The change feed: changes from the history after the one that was last when the site opened.
        self._feed: deque[Change] = deque(maxlen=FEED_LENGTH)
        self._feed_seq = int(db.last_change_id())
        self._feed_lock = threading.Lock()  # one reader of the history at a time (no change read twice)
        self.feed: Any = None  # an app.feed.FeedPublisher the changes and targets go out on (attach_feed)
        self._load_calibrations()
        self._frames: dict[str, Callable[[float], Any]] = {}  # each view's frame provider
        if isinstance(frames, str):
            if frames != "scene":
                raise ValueError(f"frames must be 'scene', None or a callable frames(t_s) -> image, got {frames!r}")
            for view in scene.views:
                if view.video is not None and Path(view.video.path).is_file():
                    from .frames import SceneVideoFrames

                    self._frames[view.name] = SceneVideoFrames(view.video, lens=view.lens)
        elif frames is not None:
            if not callable(frames):
                raise ValueError(
                    f"frames must be 'scene', None or a callable frames(t_s) -> image, got {type(frames).__name__}"
                )
            self._frames[self._views[0]] = frames

    # ------------------------------------------------------------------ video frames
    def set_frames(self, frames: Callable[[float], Any] | None, view: str | None = None) -> None:
        """Use another frame provider for one view (the first for None; the interface's grabber), or
        None for none."""
        if frames is not None and not callable(frames):
            raise ValueError(f"frames must be a callable frames(t_s) -> image, or None; got {type(frames).__name__}")
        name = self.view_name(view)
        with self.lock:
            if frames is None:
                self._frames.pop(name, None)
            else:
                self._frames[name] = frames

    def has_frames_of(self, view: str | None = None) -> bool:
        """True when the site can show workflows the frame the operator clicked on in this view."""
        return self.view_name(view) in self._frames

    @property
    def has_frames(self) -> bool:
        """True when the site can show workflows the frame the operator clicked on (first view)."""
        return self.has_frames_of(None)

    def frame_at(self, t_s: float | None = None, view: str | None = None) -> np.ndarray | None:
        """One view's video frame (the first view's for None) showing scene time ``t_s`` (default: now,
        ``time_s()``) — RGB or grey uint8, (H, W, 3) or (H, W) — or None when the site has no frames
        of that view or the source has none."""
        frames = self._frames.get(self.view_name(view))
        if frames is None:
            return None
        image = frames(self.time_s() if t_s is None else float(t_s))
        return None if image is None else np.asarray(image)

    def latest_frame(self, view: str | None = None) -> Any:
        """The newest ``app.video.Frame`` of one view's live video (with its capture ``stamp``), None when the
        view's frames are not a live video's (a recording read by time, or none)."""
        latest = getattr(self._frames.get(self.view_name(view)), "latest", None)
        return None if latest is None else latest()

    # ------------------------------------------------------------------ reading
    @property
    def views(self) -> tuple[str, ...]:
        """The names of the site's cameras (views), the first one's being ``camera``."""
        return self._views

    def change_sentence(self, rec: Any, undone: Any = None) -> str:
        """What change ``rec`` did, in one sentence (``_change_sentence``), the first camera named when there are
        others; ``undone``: the record an undo undid (default: read from the database)."""
        first = self._views[0] if len(self._views) > 1 else None
        return _change_sentence(rec, self.undone(rec) if undone is None else undone, first)

    def view_name(self, view: str | None) -> str:
        """``view``, or the first view's name for None; ValueError for a camera the site does not have."""
        if view is None:
            return self._views[0]
        if view not in self._cameras:
            raise ValueError(f"the site has no camera named {view!r}; its cameras: {', '.join(self._views)}")
        return view

    def camera_of(self, view: str | None = None) -> Camera:
        """The current calibration (the global model C) of one view's camera (the first for None)."""
        name = self.view_name(view)
        with self.lock:
            return self._cameras[name]

    @property
    def camera(self) -> Camera:
        """The current calibration (the global model C) of the first view's camera."""
        with self.lock:
            return self._cameras[self._views[0]]

    @property
    def T_world_turret(self) -> np.ndarray:
        """The current turret calibration, (4, 4) (the identity on a site without a turret: ``has_turret``)."""
        with self.lock:
            return self._T_world_turret.copy()

    @property
    def has_turret(self) -> bool:
        """False for a camera-only site: its scene has no turret (hence no range finder)."""
        return self.scene.turret is not None

    def no_devices(self, what: str, sentence: bool = False) -> str:
        """What a workflow says when it needs the range finder and the site has none now: a camera-only site
        never will, another was started without them. ``what`` it cannot do ("measure"); ``sentence``: with a
        capital and a full stop (a step's text), else as an error's ("no range finder ...")."""
        if not self.has_turret:
            text = f"this site is camera-only: it has no range finder and turret, so it cannot {what}"
        else:
            text = f"no range finder and turret are connected: restart mcit serve with devices to {what}"
        return text[:1].upper() + text[1:] + "." if sentence else text

    @property
    def calibration_covs(self) -> tuple[np.ndarray | None, np.ndarray | None]:
        """(camera_cov (12, 12) of the first view, turret_cov (6, 6)) of the current calibrations; None
        for one that is the scene's nominal value (not calibrated in this database) or was stored
        without one (``camera_cov`` for another view)."""
        with self.lock:
            return self._camera_covs[self._views[0]], self._turret_cov

    def camera_cov(self, view: str | None = None) -> np.ndarray | None:
        """The (12, 12) covariance of one view's calibration, None as ``calibration_covs`` says."""
        name = self.view_name(view)
        with self.lock:
            return self._camera_covs[name]

    def pose_priors(self, views, obj: SiteObject) -> dict:
        """``core.pose.pipeline.refine_starts``' priors for a pose of ``obj`` fitted in ``views`` (issue 27): each
        view's camera covariance (``pose_camera_cov``) and the object's model prior."""
        return dict(camera_covs=[self.pose_camera_cov(v) for v in views], model_sigma_m=obj.model_sigma_m)

    def pose_camera_cov(self, view: str | None = None) -> np.ndarray | None:
        """The camera's share of a pose's σ (issue 27): its calibration's covariance (``camera_cov``), else for a
        camera read from an intrinsics file (``SceneView.from_file``: an own site's ViSP, OpenCV or ROS file) the
        file's stated prior (``core.pose.uncertainty.intrinsics_prior_cov``), else None (a camera the scene
        writes itself, as the simulated workcell's)."""
        from core.pose.uncertainty import intrinsics_prior_cov

        cov = self.camera_cov(view)
        if cov is not None:
            return cov
        name = self.view_name(view)
        spec = next((v for v in self.scene.views if v.name == name), None)
        return intrinsics_prior_cov(self.camera_of(view)) if spec is not None and spec.from_file else None

    @property
    def robot_base_nominal(self) -> bool:
        """True while the robot's base is the scene's nominal pose (the drawing's), not calibrated from the video."""
        with self.lock:
            return self._robot_base_nominal

    @property
    def robot_base_cov(self) -> np.ndarray | None:
        """The (6, 6) covariance of the robot base's calibration ((δt, δr), world frame), None while nominal."""
        with self.lock:
            return None if self._robot_base_cov is None else self._robot_base_cov.copy()

    def robot_base_warning(self) -> str:
        """One line for the operator while the robot's base is nominal ("" when calibrated, or no robot)."""
        if self.robot is None or not self.robot_base_nominal:
            return ""
        how = (
            "Calibrate robot first"
            if self.scene.robot.calibration.get("base")
            else "give the scene's robot block calibration poses (calibration_base_deg, docs/robot-calibration.md) "
            "to calibrate it"
        )
        return (
            "The robot's base is not calibrated: its pose is the drawing's, maybe centimetres off, so the robot may "
            f"miss its target and the clearance checks may be wrong. {how}"
        )

    def time_s(self) -> float:
        """The scene time, seconds (the video's position)."""
        return float(self.clock())

    def objects(self) -> tuple[SiteObject, ...]:
        """Every object in the database (snapshot, cached until the database changes; an object
        whose version and status did not move keeps its snapshot)."""
        with self.lock:
            if self._objects is None:
                self._read_objects()
            return self._objects

    def _read_objects(self) -> bool:
        """Re-read the objects (under ``lock``), rebuilding only the snapshots whose version or
        status moved; True if any did (or one came or went)."""
        fresh = []
        for rec in self.db.objects():  # the database re-parses only the rows whose version moved
            old = self._by_id.get(rec.id)
            if old is None or old.version != rec.version or old.status != rec.status:
                old = _record_to_object(rec)
            fresh.append(old)
        key = self._key(fresh)
        changed = key != self._objects_key
        self._objects, self._objects_key = tuple(fresh), key
        self._by_id = {o.id: o for o in fresh}
        return changed

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
        bumped, when something changed since (e.g. ``mcit db undo`` from another process).
        Another process's changes join the change feed here."""
        self._read_feed()
        last = self.db.last_change_id()  # every change (objects, calibrations) is a history row
        with self.lock:
            if last == self._polled_change and self._objects is not None:
                return False  # nothing written since the last look: no object read at all
            changed = self._load_calibrations()
            changed = self._read_objects() or changed
            self._polled_change = last
            if changed:
                self.revision += 1
            return changed

    def _changed(self) -> None:
        with self.lock:
            self._objects = None
            self.revision += 1

    # ------------------------------------------------------------------ calibrations
    def calibration_kind(self, view: str | None = None) -> str:
        """The database's calibration kind of one view's camera: "camera" for the first view (as
        databases of one camera have it), "camera:NAME" for the others (each undone on its own)."""
        name = self.view_name(view)
        return "camera" if name == self._views[0] else f"camera:{name}"

    def _load_calibrations(self) -> bool:
        """Adopt the database's latest calibrations of every view's camera and of the turret; True if
        one changed."""
        changed = False
        for name in self._views:
            kind = self.calibration_kind(name)
            cam = self.db.latest_calibration(kind)
            if cam is not None and self._cal_ids.get(kind) != cam.id:
                d, nominal = cam.data, self.scene.view(name).camera if self.scene.views else self.scene.camera
                self._cameras[name] = Camera(
                    np.asarray(d["C"], float),
                    int(d.get("width", nominal.width)),
                    int(d.get("height", nominal.height)),
                )
                self._camera_covs[name] = None if d.get("cov") is None else np.asarray(d["cov"], float)
                self._cal_ids[kind] = cam.id
                changed = True
        tur = self.db.latest_calibration("turret")
        if tur is not None and self._cal_ids.get("turret") != tur.id:
            self._T_world_turret = np.asarray(tur.data["T_world_turret"], float).copy()
            self._turret_cov = None if tur.data.get("cov") is None else np.asarray(tur.data["cov"], float)
            self._cal_ids["turret"] = tur.id
            changed = True
        base = self.db.latest_calibration("robot_base") if self.robot is not None else None
        if base is not None and self._cal_ids.get("robot_base") != base.id:
            d = base.data
            self.robot.set_base(np.asarray(d["T_world_base"], float))
            self._robot_base_nominal = bool(d.get("nominal", False))
            self._robot_base_cov = None if d.get("cov") is None else np.asarray(d["cov"], float)
            self._cal_ids["robot_base"] = base.id
            changed = True
        return changed

    def set_camera(
        self,
        camera: Camera,
        *,
        rms_px: float,
        residuals_px: np.ndarray,
        points: dict,
        client: str,
        method: str = "dlt",
        cov: np.ndarray | None = None,
        view: str | None = None,
    ) -> None:
        """Store a new calibration of one view's camera (the first for None; one transaction) and use it
        from now on. cov : (12, 12) covariance of ``camera.C.ravel()`` (``calibrate_dlt(...).cov``), or None."""
        name, kind = self.view_name(view), self.calibration_kind(view)
        data = {"C": camera.C, "width": camera.width, "height": camera.height, "rms_px": float(rms_px), **points}
        data["view"] = name
        if cov is not None:
            data["cov"] = np.asarray(cov, float)
        rec = self.db.add_calibration(kind, data, np.asarray(residuals_px, float), method=method, client=client)
        with self.lock:
            self._cameras[name] = camera
            self._camera_covs[name] = None if cov is None else np.asarray(cov, float).copy()
            self._cal_ids[kind] = rec.id
            self.revision += 1
        self._feed_after_write()

    def set_turret(
        self,
        T_world_turret: np.ndarray,
        *,
        rms_m: float,
        residuals_m: np.ndarray,
        cov: np.ndarray,
        measurements: dict,
        client: str,
        method: str = "turret calibration",
    ) -> None:
        """Store a new turret calibration (one transaction) and use it from now on."""
        data = {
            "T_world_turret": np.asarray(T_world_turret, float),
            "rms_m": float(rms_m),
            "cov": np.asarray(cov, float),
            **measurements,
        }
        rec = self.db.add_calibration("turret", data, np.asarray(residuals_m, float), method=method, client=client)
        with self.lock:
            self._T_world_turret = np.asarray(T_world_turret, float).copy()
            self._turret_cov = np.asarray(cov, float).copy()
            self._cal_ids["turret"] = rec.id
            self.revision += 1
        self._feed_after_write()

    def set_robot_base(
        self,
        T_world_base: np.ndarray,
        *,
        cov: np.ndarray,
        rms_px: float,
        residuals_px: np.ndarray,
        measurements: dict,
        client: str,
        method: str = "robot edges",
    ) -> None:
        """Store a calibration of the robot's base (one transaction) and use it from now on: plans, the overlay
        and the feed's tool poses go through it. cov : (6, 6) of (δt, δr) in the world frame about the base."""
        if self.robot is None:
            raise ValueError("this site has no robot: there is no base to calibrate")
        T = np.asarray(T_world_base, float)
        data = {"T_world_base": T, "nominal": False, "cov": np.asarray(cov, float), "rms_px": float(rms_px)}
        data.update(measurements)
        rec = self.db.add_calibration("robot_base", data, np.asarray(residuals_px, float), method=method, client=client)
        with self.lock:
            self.robot.set_base(T)
            self._robot_base_nominal = False
            self._robot_base_cov = np.asarray(cov, float).copy()
            self._cal_ids["robot_base"] = rec.id
            self.revision += 1
        self._feed_after_write()

    # ------------------------------------------------------------------ writing objects
    # Each is one database transaction (the Database's own methods are), redraws every client and
    # joins the change feed. Errors pass through (app.db.ConflictError when the object moved since
    # it was read, NotFoundError, ValueError for refused values, DatabaseUnavailable when the disk or
    # another program refuses the write); nothing is written then.
    def _wrote(self) -> None:
        self._changed()
        self._feed_after_write()

    def _feed_after_write(self) -> None:
        """Read the change just committed into the feed. A failed read does not undo the write (a
        second Accept would write it twice): the change joins the feed at the next ``poll()``."""
        from app.db import DatabaseUnavailable

        try:
            self._read_feed()
        except DatabaseUnavailable as exc:
            import logging

            logging.getLogger("mcit.site").warning("the change feed will catch up at the next poll: %s", exc)

    def update_pose(
        self,
        obj: SiteObject,
        T_world_obj: np.ndarray,
        cov: np.ndarray | None,
        *,
        method: str,
        client: str,
        clicks: Any = None,
        measurements: Any = None,
        residuals: Any = None,
        status: str = "known",
        seen_at: float | None = None,
    ) -> Any:
        """Write a new pose of ``obj`` (the snapshot the workflow started from: its ``version`` is
        checked) with its covariance; its status becomes ``status``. T_world_obj : (4, 4). cov :
        (6, 6) or None. clicks, measurements, residuals : what the estimate used, kept in the
        history. seen_at : when the image it was measured on was taken (unix seconds). Returns the new
        ``app.db.ObjectRecord``."""
        rec = self.db.update_pose(
            obj.id,
            T_world_obj,
            cov,
            expected_version=obj.version,
            method=method,
            client=client,
            clicks=clicks,
            measurements=measurements,
            residuals=residuals,
            status=status,
            seen_at=seen_at,
        )
        self._wrote()
        return rec

    def add_object(
        self,
        name: str,
        kind: str,
        model: BRep,
        T_world_obj: np.ndarray,
        *,
        method: str,
        client: str,
        cov: np.ndarray | None = None,
        dims: dict | None = None,
        sigmas: dict | None = None,
        status: str = "modelled",
        clicks: Any = None,
        measurements: Any = None,
        residuals: Any = None,
        note: str | None = None,
        seen_at: float | None = None,
    ) -> Any:
        """Add a new object (``app.db.Database.add_object``; ValueError if the name is taken).
        T_world_obj : (4, 4), object → world. dims, sigmas : name → metres. seen_at : when the image it was
        measured on was taken (unix seconds). Returns its record."""
        rec = self.db.add_object(
            name,
            kind,
            model,
            T_world_obj,
            cov=cov,
            dims=dims,
            sigmas=sigmas,
            status=status,
            method=method,
            client=client,
            clicks=clicks,
            measurements=measurements,
            residuals=residuals,
            note=note,
            seen_at=seen_at,
        )
        self._wrote()
        return rec

    def set_status(self, name: str, status: str, *, client: str, method: str = "operator") -> Any:
        """Mark the object ``name`` "known", "modelled" or "stale". Returns its new record."""
        rec = self.db.set_status(name, status, method=method, client=client)
        self._wrote()
        return rec

    def undo(self, change_id: int, *, client: str, expected_version: int | None = None) -> Any:
        """Undo change ``change_id`` (the object, or the calibration, as just before it); the undo is
        itself a change. ``expected_version``: the object's version the operator saw (ConflictError,
        nothing written, when it changed since). Returns its ``app.db.ChangeRecord``."""
        rec = self.db.undo(int(change_id), client=client, expected_version=expected_version)
        self._load_calibration_after_revert(rec)
        self._wrote()
        return rec

    def restore(self, change_id: int, *, client: str) -> Any:
        """Bring the object (or calibration) back to its state just after change ``change_id``."""
        rec = self.db.restore(int(change_id), client=client)
        self._load_calibration_after_revert(rec)
        self._wrote()
        return rec

    def _load_calibration_after_revert(self, rec: Any) -> None:
        if rec.calibration_id is not None:  # a calibration undone: use the one now latest
            with self.lock:
                self._load_calibrations()

    # ------------------------------------------------------------------ change feed
    @property
    def change_seq(self) -> int:
        """The number of the latest change in the feed (start a client's ``changes_since`` here)."""
        with self._feed_lock:
            return self._feed_seq

    def changes_since(self, seq: int) -> list[Change]:
        """The changes after ``seq`` (a ``Change.seq`` or ``change_seq``), oldest first: those made
        through this site, and those of other processes once ``poll()`` has seen them."""
        with self._feed_lock:
            return [c for c in self._feed if c.seq > seq]

    def undone(self, rec: Any) -> Any:
        """The history record that ``rec`` (an undo) undid, or None (not an undo, or not found)."""
        if not _is_undo(rec):
            return None
        from app.db import NotFoundError

        try:
            return self.db.change(int(rec.undoes))
        except NotFoundError:  # the sentence then says "undid", as before
            return None

    def _read_feed(self) -> None:
        """Add the history's new changes to the feed (a cheap query when there are none), and send
        each object's change out on the attached live feed (``attach_feed``)."""
        with self._feed_lock:
            for rec in self.db.history_since(self._feed_seq):
                self._feed.append(
                    Change(
                        int(rec.id),
                        str(rec.client),
                        self.change_sentence(rec),
                        rec.object_name,
                        float(rec.time),
                    )
                )
                self._feed_seq = int(rec.id)
                if self.feed is not None:
                    self._publish_change(rec)

    def _publish_change(self, rec: Any) -> None:
        """One history change out on the live feed; a failure is logged, never the writer's error
        (the change is in the database already)."""
        from app.feed import change_event

        try:
            self.feed.publish(change_event(rec))
        except Exception:  # noqa: BLE001 - the feed must not fail a write that happened
            import logging

            logging.getLogger("mcit.feed").exception("change #%s could not be sent on the live feed", rec.id)

    def attach_feed(self, feed: Any) -> None:
        """Send every accepted change of an object (through this site, or another process's once
        ``poll()`` sees it) and every designated target out on ``feed`` (``app.feed.FeedPublisher``,
        its snapshot the objects as they stand: ``feed_snapshot``); several may be attached (the feed socket
        or file, the ROS 2 bridge: ``app.feed.FeedFanout``); None detaches them all."""
        from app.feed import FeedFanout

        if feed is None or self.feed is None:
            self.feed = feed
        elif isinstance(self.feed, FeedFanout):
            self.feed.sinks.append(feed)
        else:
            self.feed = FeedFanout(self.feed, feed)

    def feed_snapshot(self) -> list[dict]:
        """The live feed's lines for every object as it stands (``action`` "current")."""
        from app.feed import object_event

        return [object_event(rec) for rec in self.db.objects()]

    def publish(self, event: dict | None) -> None:
        """Send one line out on the live feed, if one is attached (a designated target)."""
        feed = self.feed
        if feed is not None:
            feed.publish(event)

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
        Vs, Fs, names, counts, offset = [], [], [], [], 0
        cache = {}
        for obj in objects:  # each object's world triangles are kept until its version moves
            okey = (obj.version, obj.status)
            hit = self._triangles.get(obj.id)
            if hit is None or hit[0] != okey:
                V, F = obj.model.triangles()
                hit = (okey, V @ obj.T_world_obj[:3, :3].T + obj.T_world_obj[:3, 3], F)
            cache[obj.id] = hit
            _, V, F = hit
            Vs.append(V)
            Fs.append(F + offset)
            names.append(obj.name)
            counts.append(len(F))
            offset += len(V)
        self._triangles = cache
        mesh = trimesh.Trimesh(np.vstack(Vs), np.vstack(Fs), process=False) if Vs else None
        # each triangle's object name (the name objects repeated in C: a list of one name per triangle
        # turned into a string array held the interpreter 110-200 ms with 40 meshes among 2,000 objects)
        owner = np.repeat(np.array(names, dtype=object), counts) if names else np.array([])
        with self.lock:
            self._meshes = {"key": key, "mesh": mesh, "owner": owner}
        return mesh, owner

    def raycast(self, origin: np.ndarray, direction: np.ndarray) -> RayHit | None:
        """The first database surface a ray (origin (3,), direction (3,), world) meets, or None.

        Cast exactly by mcit's one ray caster (app.render.raycast: planes, quadrics, triangles);
        each object's caster is kept until its version moves. ValueError for a non-finite origin
        or a zero direction."""
        from app.render.raycast import BodyCaster, SceneCaster

        o = np.asarray(origin, float).reshape(3)
        d = np.asarray(direction, float).reshape(3)
        norm = float(np.linalg.norm(d))
        if not (np.all(np.isfinite(o)) and np.isfinite(norm) and norm > 0):
            raise ValueError(f"a ray needs a finite origin and a non-zero direction, got {o}, {d}")
        d = d / norm
        objects = self.objects()
        if not objects:
            return None
        with self.lock:
            cached = getattr(self, "_ray_casters", {})
            casters = {}
            for obj in objects:
                hit = cached.get(obj.id)
                casters[obj.id] = (
                    hit if hit is not None and hit[0] == obj.version else (obj.version, BodyCaster(obj.model))
                )
            self._ray_casters = casters
        h = SceneCaster(objects, [obj.T_world_obj for obj in objects], [casters[obj.id][1] for obj in objects]).cast(
            o, d[None]
        )
        k = int(h.body[0])
        if k < 0:
            return None
        t = float(h.t[0])
        return RayHit(o + t * d, objects[k].name, t, h.normal[0].copy())
