"""The database's poses out, for the robot's software: JSON, CSV and ViSP ``.pos`` (``mcit db export-poses``).

One record per object, the same fields as the live feed's ``pose`` lines (``app.feed``, docs/exchange.md):

* ``object``, ``object_id``, ``kind``, ``status`` ("known", "modelled", "stale"), ``version``;
* the pose as a 4×4 (``T``: object → frame, metres), as ``xyz_m`` + ``quat_xyzw`` (unit quaternion
  x, y, z, w with w ≥ 0, ROS's order) and as ``rotvec_rad`` (axis × angle, ViSP's θu);
* ``sigma``: {"xyz_m": 3, "rot_rad": 3} from the pose's covariance (None when the method gave none),
  ``cov`` the 6×6 itself (order δt, δr: ``R ← exp([δr]×) R``, ``t ← t + δt``, docs/pose.md);
* ``who`` and ``method`` of the object's last change, ``time`` (unix seconds) and ``time_iso`` (UTC).

``frame``: "world" (the database's T_world_obj) or "camera" (T_cam_obj = T_cam_world · T_world_obj
with the database's latest camera calibration C = K [R | t]; the covariance is rotated with it). A
ViSP ``.pos`` is the object's pose in the camera (``cMo``: tx ty tz θux θuy θuz, one number a line,
what ``vpMbTracker::initFromPose`` reads), so it is written in the camera frame unless asked otherwise.
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import secrets
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from core.transforms import log_so3

__all__ = [
    "POSES_FORMAT",
    "pose_fields",
    "object_record",
    "record_of",
    "camera_T",
    "export_poses",
    "format_of",
    "write_atomically",
]

POSES_FORMAT = "mcit-poses/1"
FORMATS = ("json", "csv", "pos")
CSV_COLUMNS = (
    "object",
    "object_id",
    "kind",
    "status",
    "version",
    "frame",
    "x_m",
    "y_m",
    "z_m",
    "qx",
    "qy",
    "qz",
    "qw",
    "rx_rad",
    "ry_rad",
    "rz_rad",
    "sigma_x_m",
    "sigma_y_m",
    "sigma_z_m",
    "sigma_rx_rad",
    "sigma_ry_rad",
    "sigma_rz_rad",
    "who",
    "method",
    "time",
    "time_iso",
)


def quat_xyzw(R: np.ndarray) -> list[float]:
    """Unit quaternion (x, y, z, w), w ≥ 0, of a rotation matrix (3, 3)."""
    from scipy.spatial.transform import Rotation

    q = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    if q[3] < 0 or (q[3] == 0 and q[np.flatnonzero(q)[0]] < 0):
        q = -q
    return [float(v) for v in q]


def iso(t: float | None) -> str | None:
    """UTC ISO 8601 with milliseconds ("2026-12-01T18:41:31.123Z")."""
    if t is None:
        return None
    ms = int(round((t - math.floor(t)) * 1000))
    s = math.floor(t) + (1 if ms == 1000 else 0)
    return time.strftime("%Y-%m-%dT%H:%M:%S", time.gmtime(s)) + f".{ms % 1000:03d}Z"


def pose_fields(T: np.ndarray, cov: np.ndarray | None, R_frame: np.ndarray | None = None) -> dict[str, Any]:
    """The pose's fields: ``T`` (4×4 rows), ``xyz_m``, ``quat_xyzw``, ``rotvec_rad``, ``sigma``, ``cov``.

    cov : (6, 6) of (δt, δr) in the database's world frame, or None. R_frame : (3, 3), the rotation
    from the world to the frame T is given in (the covariance is turned with it), None for the world.
    """
    T = np.asarray(T, float)
    out: dict[str, Any] = {
        "T": [[float(v) for v in row] for row in T],
        "xyz_m": [float(v) for v in T[:3, 3]],
        "quat_xyzw": quat_xyzw(T[:3, :3]),
        "rotvec_rad": [float(v) for v in log_so3(T[:3, :3])],
        "sigma": None,
        "cov": None,
    }
    if cov is not None:
        C = np.asarray(cov, float)
        if R_frame is not None:
            B = np.zeros((6, 6))
            B[:3, :3] = B[3:, 3:] = np.asarray(R_frame, float)
            C = B @ C @ B.T
        s = np.sqrt(np.clip(np.diag(C), 0.0, None))
        out["sigma"] = {"xyz_m": [float(v) for v in s[:3]], "rot_rad": [float(v) for v in s[3:]]}
        out["cov"] = [[float(v) for v in row] for row in C]
    return out


def object_record(
    name: str,
    object_id: Any,
    kind: str,
    status: str,
    version: int,
    T_world_obj: np.ndarray,
    cov: np.ndarray | None,
    *,
    who: str | None,
    method: str | None,
    when: float | None,
    T_frame_world: np.ndarray | None = None,
    frame: str = "world",
) -> dict[str, Any]:
    """One object's record (see the module docstring); T_frame_world (4, 4) moves it to another frame."""
    T = np.asarray(T_world_obj, float)
    R = None
    if T_frame_world is not None:
        T = np.asarray(T_frame_world, float) @ T
        R = np.asarray(T_frame_world, float)[:3, :3]
    rec = {
        "object": name,
        "object_id": object_id,
        "kind": kind,
        "status": status,
        "version": int(version),
        "frame": frame,
    }
    rec.update(pose_fields(T, cov, R))
    rec.update({"who": who, "method": method, "time": None if when is None else float(when), "time_iso": iso(when)})
    return rec


def camera_T(db) -> tuple[np.ndarray, int]:
    """(T_cam_world (4, 4), the calibration's id) from the database's latest camera calibration."""
    from core.camera import Camera

    cal = db.latest_calibration("camera")
    if cal is None:
        raise ValueError(
            f"{db.path}: the database has no camera calibration, so poses cannot be given in the "
            "camera frame; calibrate the camera or export with --frame world"
        )
    d = cal.data
    cam = Camera(np.asarray(d["C"], float), int(d.get("width", 1)), int(d.get("height", 1)))
    K, T_cam_world = cam.decompose()
    if K[0, 0] < 0:
        raise ValueError(
            f"{db.path}: the camera calibration #{cal.id} is mirrored (its image is flipped), so it has "
            "no camera frame; export with --frame world"
        )
    return T_cam_world, int(cal.id)


def format_of(path: str | Path, fmt: str | None) -> str:
    """The export format: ``fmt`` or the file's suffix (.json, .csv, .pos)."""
    if fmt is not None:
        if fmt not in FORMATS:
            raise ValueError(f"unknown pose format {fmt!r}; use json, csv or pos")
        return fmt
    suffix = Path(str(path).replace("{name}", "x")).suffix.lower().lstrip(".")
    if suffix not in FORMATS:
        raise ValueError(
            f"{path}: cannot tell the format from the suffix {('.' + suffix) if suffix else '(none)'}; "
            "name it .json, .csv or .pos, or give --format"
        )
    return suffix


def _records(db, names: Iterable[str] | None, frame: str) -> tuple[list[dict], dict]:
    objs = db.objects()
    if names:
        by_name = {o.name: o for o in objs}
        missing = [
            n for n in names if n not in by_name and not (str(n).isdigit() and any(o.id == int(n) for o in objs))
        ]
        if missing:
            raise ValueError(
                f"no object named {', '.join(map(repr, missing))} in the database; it has "
                f"{', '.join(o.name for o in objs) or 'none'}"
            )
        wanted = [by_name.get(n) or next(o for o in objs if o.id == int(n)) for n in names]
    else:
        wanted = list(objs)
    if not wanted:
        raise ValueError(f"{db.path}: the database has no objects: nothing to export")
    meta: dict[str, Any] = {"frame": frame}
    T_fw = None
    if frame == "camera":
        T_fw, cal_id = camera_T(db)
        meta["camera_calibration"] = cal_id
        meta["T_cam_world"] = [[float(v) for v in row] for row in T_fw]
    elif frame != "world":
        raise ValueError(f"unknown frame {frame!r}; use world or camera")
    return [record_of(db, o, T_fw, frame) for o in wanted], meta


def record_of(db, o, T_frame_world: np.ndarray | None = None, frame: str = "world") -> dict[str, Any]:
    """``object_record`` of an ``app.db.ObjectRecord`` as it stands, with the client and method of its
    last change (from the history); T_frame_world (4, 4) moves it to ``frame``."""
    last = db.history(o.id, limit=1)
    who, method = (last[0].client, last[0].method) if last else (None, None)
    return object_record(
        o.name,
        o.id,
        o.kind,
        o.status,
        o.version,
        o.T_world_obj,
        o.cov,
        who=who,
        method=method,
        when=o.updated_at,
        T_frame_world=T_frame_world,
        frame=frame,
    )


def _csv_text(records: list[dict]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(CSV_COLUMNS)
    for r in records:
        s = r["sigma"] or {"xyz_m": [None] * 3, "rot_rad": [None] * 3}
        num = lambda v: "" if v is None else repr(float(v))  # noqa: E731 - full precision, empty when unknown
        w.writerow(
            [r["object"], r["object_id"], r["kind"], r["status"], r["version"], r["frame"]]
            + [num(v) for v in r["xyz_m"] + r["quat_xyzw"] + r["rotvec_rad"] + s["xyz_m"] + s["rot_rad"]]
            + [r["who"] or "", r["method"] or "", num(r["time"]), r["time_iso"] or ""]
        )
    return buf.getvalue()


def pos_text(T: np.ndarray) -> str:
    """A ViSP ``.pos``: tx ty tz (m) θux θuy θuz (rad), one number a line."""
    T = np.asarray(T, float)
    return "".join(f"{v:.12g}\n" for v in np.r_[T[:3, 3], log_so3(T[:3, :3])])


def write_atomically(files: Mapping[Path, Callable[[Path], None]]) -> None:
    """Write files all or none: ``write(temporary)`` for each, then each temporary replaces its file.

    files : {path: write}; ``write`` writes the whole file at the path it is given: a temporary in
    the path's folder, with the path's suffix (a writer that picks the format by suffix picks the
    same). A reader never sees half a file. On any failure (a full disk, Ctrl-C) every temporary is
    removed and every file is as it was; the error names the file, not its temporary.
    """
    staged: list[tuple[Path, Path]] = []
    try:
        for path, write in files.items():
            path = Path(path)
            tmp = path.with_name(f".{path.name}.{secrets.token_hex(4)}.tmp{path.suffix}")
            staged.append((tmp, path))
            try:
                write(tmp)
                with open(tmp, "rb") as fh:
                    os.fsync(fh.fileno())  # a full disk may only show here; and the file is whole before it is named
            except OSError as exc:
                raise OSError(exc.errno, exc.strerror or str(exc), str(path)) from None
            except ValueError as exc:
                if str(tmp) not in str(exc):
                    raise
                raise ValueError(str(exc).replace(str(tmp), str(path))) from None
        for tmp, path in staged:
            os.replace(tmp, path)
    except BaseException:
        for tmp, _ in staged:
            with contextlib.suppress(OSError):
                tmp.unlink(missing_ok=True)
        raise


def export_poses(
    db, out: str | Path, *, fmt: str | None = None, names: Iterable[str] | None = None, frame: str | None = None
) -> list[Path]:
    """Write the poses of the database's objects (all, or ``names``) to ``out``; returns the files written.

    fmt : "json", "csv" or "pos" (default: from the suffix). frame : "world" or "camera" (default:
    world, camera for .pos). A ``.pos`` holds one object: give one name, or put ``{name}`` in ``out``
    (one file per object). ValueError, nothing written, on bad input; OSError (naming the file),
    nothing written either, when a file cannot be written (``write_atomically``).
    """
    fmt = format_of(out, fmt)
    frame = frame or ("camera" if fmt == "pos" else "world")
    names = list(names or [])
    records, meta = _records(db, names, frame)
    files: dict[Path, str] = {}
    if fmt == "pos":
        if "{name}" in str(out):
            bad = [r["object"] for r in records if any(c in r["object"] for c in "/\\\0") or r["object"] in (".", "..")]
            if bad:
                raise ValueError(f"the object name {bad[0]!r} cannot be a file name; export it alone with its name")
            for r in records:
                files[Path(str(out).replace("{name}", r["object"]))] = pos_text(np.array(r["T"]))
        elif len(records) == 1:
            files[Path(out)] = pos_text(np.array(records[0]["T"]))
        else:
            raise ValueError(
                f"{out}: a ViSP .pos holds one pose; name one object, or put {{name}} in the path "
                f"(e.g. poses/{{name}}.pos) for one file per object ({len(records)} objects)"
            )
    elif fmt == "json":
        doc = {"format": POSES_FORMAT, **meta, "database": str(db.path), "exported_at": time.time(), "objects": records}
        doc["exported_at_iso"] = iso(doc["exported_at"])
        files[Path(out)] = json.dumps(doc, indent=1) + "\n"
    else:
        files[Path(out)] = _csv_text(records)
    for path in files:
        path.parent.mkdir(parents=True, exist_ok=True)
    write_atomically({path: (lambda tmp, text=text: tmp.write_text(text)) for path, text in files.items()})
    return list(files)
