"""A site of one's own: a folder ``mcit serve --site DIR`` serves, made by ``mcit site new`` (docs/own-site.md).

    DIR/scene.json      the scene: the camera (K from the camera file, the image size, its pose in the
                        world), no turret, no bodies — a camera-only site; the database holds the objects
    DIR/camera.<ext>    a copy of the camera file (ViSP .xml, OpenCV or ROS .yml/.yaml/.json), which the
                        scene names (a file with lens distortion: the video is undistorted on arrival); or of a
                        3×4 projection matrix (.P, as Oxford VGG's multi-view data give each view): the scene
                        holds it as C, the camera whole, its pose included (no --camera-pose)
    DIR/site.json       how it is served: {"format": "mcit-site/1", "video": SOURCE, "fps": N or null}
    DIR/site.sqlite     its database, holding the camera's calibration (``app.db.seed_from_scene``)

The camera's pose: a camera brought by a user is seldom measured in any world, so by default the world
frame is the camera's (``T_world_cam`` = I: x right, y down, z along the optical axis, metres from the
optical centre) — an object's pose in the camera (ViSP's cMo) is then its pose in the world. Calibrate
camera in the interface (4 clicked known points, PnP: the lens is known) later moves the camera into a
world of the user's choosing; ``--camera-pose FILE`` gives ``T_world_cam`` at once when it is known.

``SOURCE`` is what ``mcit serve --video`` takes: a video file, an image folder (its images in name
order, frame i at t = i / fps), an image, a camera index or a stream URL. A file, folder or image is
stored as an absolute path (a relative one in site.json is taken from the folder) and opened now to
check it and read the image size; a camera or a stream is not opened until ``mcit serve``.

Nothing is written on a failure: the folder is made beside DIR under another name and renamed to DIR
once complete (``os.rename``: atomic, onto a missing or empty DIR).
"""

from __future__ import annotations

import json
import os
import re
import secrets
import shutil
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "SITE_FORMAT",
    "SITE_FILE",
    "DB_FILE",
    "SiteFolder",
    "open_site",
    "create_site",
    "serve_site_args",
    "current_camera",
    "database_of",
]

SITE_FORMAT = "mcit-site/1"
SITE_FILE = "site.json"
DB_FILE = "site.sqlite"
_SCHEME = re.compile(r"[A-Za-z][A-Za-z0-9+.-]*:")  # rtsp://…, http://…, ros2:TOPIC: a source opened by serve
_SITE_KEYS = ("format", "video", "fps")


@dataclass(frozen=True)
class SiteFolder:
    """A site folder: ``root``; ``video``, the source ``mcit serve`` plays (as ``--video`` takes it);
    ``fps``, the frame rate of an image folder or still (None: the source's own, 10 for a folder)."""

    root: Path
    video: str
    fps: float | None = None

    @property
    def scene_path(self) -> Path:
        return self.root / "scene.json"

    @property
    def db_path(self) -> Path:
        return self.root / DB_FILE


def _is_live(source: str) -> bool:
    """A camera index or a stream (a scheme): opened by ``mcit serve``, not by ``mcit site new``."""
    return source.strip().isdigit() or bool(_SCHEME.match(source) and not Path(source).exists())


def _check_fps(value: Any, where: str) -> float | None:
    from app.argtypes import MAX_FPS

    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value <= MAX_FPS:
        raise ValueError(f"{where}: fps is a frame rate above 0 and at most {MAX_FPS:g}, or null; got {value!r}")
    return float(value)


def open_site(path: str | Path) -> SiteFolder:
    """The site folder at ``path``; ValueError naming the file for a folder that is not one."""
    root = Path(path).expanduser().resolve()
    file = root / SITE_FILE
    if not root.is_dir():
        raise ValueError(
            f"{root}: no such site folder; make one with mcit site new {path} --camera FILE --video SOURCE"
        )
    if not file.is_file():
        raise ValueError(
            f"{root}: not a site folder (no {SITE_FILE}); make one with mcit site new, or serve a scene folder "
            "with --scene"
        )
    try:
        d = json.loads(file.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{file}: cannot be read as JSON ({exc}); make the site again with mcit site new") from None
    if not isinstance(d, dict) or d.get("format") != SITE_FORMAT:
        raise ValueError(f"{file}: 'format' must be {SITE_FORMAT!r}; make the site again with mcit site new")
    unknown = sorted(k for k in d if k not in _SITE_KEYS and not str(k).startswith("_"))
    if unknown:
        raise ValueError(f"{file}: unknown field(s) {unknown}; the allowed fields are {list(_SITE_KEYS)}")
    video = d.get("video")
    if not isinstance(video, str) or not video.strip():
        raise ValueError(f"{file}: 'video' must be the video source (a file, a folder, a camera index or a URL)")
    if not _is_live(video) and not Path(video).expanduser().is_absolute():
        video = str(root / video)  # a path relative to the site folder
    return SiteFolder(root, video, _check_fps(d.get("fps"), str(file)))


def serve_site_args(args) -> None:
    """``mcit serve --site DIR``: its scene and database (refused beside --scene or --db), its video and
    frame rate unless --video or --fps give others."""
    from app.exit_status import UsageError

    site = open_site(args.site)
    for flag, value in (("--scene", args.scene), ("--db", args.db)):
        if value is not None:
            raise UsageError(f"--site {args.site} gives the scene and the database: drop {flag}")
    args.scene, args.db = site.root, site.db_path
    if not args.video:
        args.video = [site.video]
    if args.fps is None:
        args.fps = site.fps


def database_of(db: str | Path | None, site: str | Path | None) -> Path | None:
    """The database a command opens: ``--db``, or the site folder's (``--site``; refused beside --db)."""
    if site is None:
        return None if db is None else Path(db)
    if db is not None:
        raise ValueError(f"--site {site} names its database: drop --db")
    return open_site(site).db_path


def current_camera(db, scene=None):
    """(camera, lens, calibration id) the site sees by now: the database's latest camera calibration (C, the
    first camera's), else the scene's camera (id None), else (None, None, None); the lens is the scene's."""
    from core.camera import Camera

    lens = None if scene is None else scene.lens
    cal = None if db is None else db.latest_calibration("camera")
    if cal is not None:
        d = cal.data
        fallback = scene.camera if scene is not None else None
        width = int(d.get("width", fallback.width if fallback else 1))
        height = int(d.get("height", fallback.height if fallback else 1))
        return Camera(np.asarray(d["C"], float), width, height), lens, int(cal.id)
    return (None, None, None) if scene is None else (scene.camera, lens, None)


# ---------------------------------------------------------------------- mcit site new
def _check_target(root: Path) -> None:
    if root.exists() and not root.is_dir():
        raise ValueError(f"{root}: exists and is not a folder; give the new site's folder")
    if root.is_dir() and any(root.iterdir()):
        raise ValueError(f"{root}: the folder exists and is not empty; give a new folder (or empty this one)")


def _probe(source: str, fps: float | None) -> tuple[str, tuple[int, int]]:
    """(the source as stored: an absolute path, its frames' size) of a file, a folder or an image."""
    from app.video import open_video

    path = Path(source).expanduser()
    if not path.exists():
        raise ValueError(
            f"--video {source}: no such file or folder; give a video file, an image folder, an image, a camera "
            "index (0) or a stream URL (rtsp://...)"
        )
    with open_video(str(path), fps) as video:
        frame = video.read()
    height, width = frame.image.shape[:2]
    return os.path.abspath(path), (width, height)  # symbolic links kept: the path the user knows


def _image_size(intr, probed, size, camera_file: Path, video: str) -> tuple[int, int]:
    """The site's image size: the camera file's, the video's and --size, which must agree."""
    known = {}
    if intr is not None and intr.width is not None:
        known[f"the camera file {camera_file.name}"] = (intr.width, intr.height)
    if probed is not None:
        known[f"the video {video}"] = probed
    if size is not None:
        known["--size"] = tuple(size)
    if not known:
        raise ValueError(
            f"{camera_file}: the image size is not in the camera file and the video ({video}) is not opened now; "
            "give it with --size WIDTH HEIGHT"
        )
    sizes = set(known.values())
    if len(sizes) > 1:
        said = "; ".join(f"{who} {w}×{h}" for who, (w, h) in known.items())
        raise ValueError(f"the image sizes disagree ({said}); give the camera file for this video's size")
    return next(iter(sizes))


def create_site(
    root: str | Path,
    camera_file: str | Path,
    video: str,
    *,
    camera_pose: str | Path | None = None,
    camera_name: str | None = None,
    size: tuple[int, int] | None = None,
    fps: float | None = None,
    name: str | None = None,
) -> dict[str, Any]:
    """Make the site folder ``root`` (see the module docstring); returns what was made, for the summary:
    {"site": SiteFolder, "size": (w, h), "K": (3, 3), "T_world_cam": (4, 4), "lens": text or None,
    "probed": bool, "matrix": bool (a projection matrix)}. ValueError naming the file or the flag, and nothing
    written, on bad input."""
    from app.camera_io import P_SUFFIXES, read_intrinsics, read_projection_matrix
    from app.scene import load_scene, pose_to_json
    from core.camera import Camera
    from core.transforms import invert_T

    root = Path(root).expanduser().absolute()
    _check_target(root)
    camera_file = Path(camera_file).expanduser()
    fps = _check_fps(fps, "--fps")
    live = _is_live(video)
    stored, probed = (video.strip(), None) if live else _probe(video, fps)
    if camera_file.suffix.lower() in P_SUFFIXES:  # the global model itself: its pose in it, no size, no lens
        C = read_projection_matrix(camera_file)
        if camera_pose is not None or camera_name is not None:
            flag = "--camera-pose" if camera_pose is not None else "--camera-name"
            raise ValueError(f"{camera_file}: a projection matrix is the whole camera, its pose included; drop {flag}")
        width, height = _image_size(None, probed, size, camera_file, video)
        K, T_cam_world = Camera(C, width, height).decompose()
        T_world_cam = invert_T(T_cam_world)
        camera = {"width": width, "height": height, "C": [[v + 0.0 for v in row] for row in C.tolist()]}
    else:
        try:
            intr = read_intrinsics(camera_file, camera_name=camera_name, image_size=probed or size)
        except ValueError as exc:
            if "unknown intrinsics format" not in str(exc):
                raise
            raise ValueError(f"{exc}, or a 3×4 projection matrix (.P)") from None
        width, height = _image_size(intr, probed, size, camera_file, video)
        K, T_world_cam = intr.K, np.eye(4)
        if camera_pose is not None:
            from app.pose_files import read_camera_pose

            T_world_cam = read_camera_pose(camera_pose)
        camera = {
            "width": width,
            "height": height,
            "intrinsics_file": "camera" + camera_file.suffix.lower(),
            "T_world_cam": {k: [v + 0.0 for v in vs] for k, vs in pose_to_json(T_world_cam).items()},  # no -0.0
        }
        if camera_name is not None:
            camera["camera_name"] = camera_name
    scene = {
        "format": "mcit-scene/1",
        "name": name or root.name,
        "description": "made by mcit site new: one camera, no turret or range finder (docs/own-site.md)",
        "_camera": (
            f"C: the projection matrix of {camera_file.name}"
            if "C" in camera
            else "T_world_cam: "
            + ("the camera's pose given to mcit site new" if camera_pose else "the world frame is the camera's")
        )
        + " until Calibrate camera moves it",
        "camera": camera,
        "bodies": [],
    }
    site = {"format": SITE_FORMAT, "video": stored, "fps": fps, "_video": "what mcit serve --site plays"}
    made = _make_folders(root.parent)
    tmp = root.parent / f".{root.name}.new-{secrets.token_hex(4)}"
    try:
        tmp.mkdir()
        shutil.copyfile(camera_file, tmp / ("camera.P" if "C" in camera else camera["intrinsics_file"]))
        (tmp / "scene.json").write_text(_json_text(scene))
        (tmp / SITE_FILE).write_text(_json_text(site))
        loaded = load_scene(tmp)  # the scene is checked as mcit serve will read it (the lens too)
        _seed(tmp / DB_FILE, loaded)
        os.rename(tmp, root)  # onto a missing or empty folder: the site appears whole or not at all
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        for folder in reversed(made):
            try:
                folder.rmdir()
            except OSError:
                pass
        raise
    lens = None if loaded.lens is None else loaded.lens.describe()
    folder = SiteFolder(root, stored, fps)
    return {
        "site": folder,
        "size": (width, height),
        "K": K,
        "T_world_cam": T_world_cam,
        "lens": lens,
        "probed": not live,
        "matrix": "C" in camera,
    }


def _json_text(d: dict) -> str:
    """JSON as a person reads it: indented, each list of numbers on one line."""
    text = json.dumps(d, indent=2)
    return re.sub(r"\[\s+([^\[\]{}\"]*?)\s+\]", lambda m: "[" + " ".join(m.group(1).split()) + "]", text) + "\n"


def _make_folders(folder: Path) -> list[Path]:
    """Make ``folder`` and its missing parents; the ones made, outermost first (removed on a failure)."""
    missing = []
    while not folder.exists():
        missing.append(folder)
        folder = folder.parent
    for f in reversed(missing):
        f.mkdir()
    return list(reversed(missing))


def _seed(path: Path, scene) -> None:
    """A new database at ``path`` holding the scene's camera calibration."""
    from app.db import Database, seed_from_scene

    db = Database.open(path, client="cli")
    try:
        seed_from_scene(db, scene, client="cli")
    finally:
        db.close()
