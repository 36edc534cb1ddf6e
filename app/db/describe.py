"""What ``mcit db list | show | history | show-calibration`` say, as JSON values (``--json``) and, for
calibrations, as text: one document per command, keys fixed and documented in docs/database.md.

Poses are the records of ``app.db.export`` (the fields ``mcit db export-poses`` and the live feed
write: ``T``, ``xyz_m``, ``quat_xyzw``, ``rotvec_rad``, ``sigma``, ``cov``; docs/exchange.md).

* ``objects_doc``: ``{"format": "mcit-objects/1", "database", "objects": [record, …]}``.
* ``object_doc``: the record of one object plus its model, dimensions, creation and history count.
* ``history_doc``: ``{"format": "mcit-history/1", "database", "object", "changes": [change, …]}``,
  oldest first; a change's ``pose`` is the object's pose after it (null for a removal or a calibration).
* ``calibrations_doc``: ``{"format": "mcit-calibrations/1", "database", "calibrations": [calibration, …]}``:
  each camera's, the turret's and the robot base's latest (or the ones asked), with the calibrated
  thing's pose in the world (``pose``), its figures and, for a camera, C and K.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from core.transforms import invert_T

from .export import iso, pose_fields, record_of

__all__ = [
    "OBJECTS_FORMAT",
    "OBJECT_FORMAT",
    "HISTORY_FORMAT",
    "CALIBRATIONS_FORMAT",
    "objects_doc",
    "object_doc",
    "history_doc",
    "calibration_record",
    "calibrations_doc",
    "pick_calibrations",
    "calibration_lines",
]

OBJECTS_FORMAT = "mcit-objects/1"
OBJECT_FORMAT = "mcit-object/1"
HISTORY_FORMAT = "mcit-history/1"
CALIBRATIONS_FORMAT = "mcit-calibrations/1"
CALIBRATION_KINDS = ("camera", "turret", "robot_base")  # as the database names them; "camera:NAME" per other camera


def objects_doc(db) -> dict[str, Any]:
    """Every live object's record (``app.db.export.object_record``, world frame), by id."""
    return {"format": OBJECTS_FORMAT, "database": str(db.path), "objects": [record_of(db, o) for o in db.objects()]}


def object_doc(db, o) -> dict[str, Any]:
    """One object (an ``app.db.ObjectRecord``): its record plus ``model`` (counts of its primitives,
    ``model_id``, ``source``: the file it was imported from or null), ``dims_m`` and ``sigma_dims_m``
    (name → metres; σ null when unknown), ``created``/``created_iso`` and ``changes`` (its history's length)."""
    m = o.model
    doc: dict[str, Any] = {"format": OBJECT_FORMAT, "database": str(db.path)}
    doc.update(record_of(db, o))
    doc["model"] = {
        "model_id": int(o.model_id),
        "vertices": len(m.vertices),
        "edges": len(m.edges),
        "faces": len(m.faces),
        "solids": len(m.solids),
        "circles": len(m.circles),
        "source": o.source,
    }
    doc["dims_m"] = {k: float(v) for k, v in o.dims.items()}
    doc["sigma_dims_m"] = {k: None if o.sigmas.get(k) is None else float(o.sigmas[k]) for k in o.dims}
    doc["created"], doc["created_iso"] = float(o.created_at), iso(o.created_at)
    doc["changes"] = len(db.history(o.id))
    return doc


def _change(c, calibration_kinds: dict[int, str]) -> dict[str, Any]:
    after = c.after or {}
    posed = bool(after) and not after.get("removed") and after.get("T_world_obj") is not None
    cov = after.get("cov") if posed else None
    return {
        "change": int(c.id),
        "time": float(c.time),
        "time_iso": iso(c.time),
        "who": c.client,
        "action": c.action,
        "method": c.method,
        "undoes": c.undoes,
        "note": c.note,
        "seen_at": c.seen_at,  # when the image it was measured on was taken (null: not measured on an image)
        # what the method used and left, as kept (JSON values; null when none): clicks, range measurements, residuals
        "clicks": c.clicks,
        "measurements": c.measurements,
        "residuals": c.residuals,
        "object": c.object_name,
        "object_id": c.object_id,
        "version": c.version,
        "kind": after.get("kind") if c.object_id is not None else None,
        "status": after.get("status") if posed else None,
        "calibration_id": c.calibration_id,
        "calibration_kind": calibration_kinds.get(c.calibration_id) if c.calibration_id else None,
        "pose": pose_fields(np.asarray(after["T_world_obj"], float), None if cov is None else np.asarray(cov))
        if posed
        else None,
    }


def history_doc(db, changes: Iterable, name: str | None = None) -> dict[str, Any]:
    """The changes (``app.db.ChangeRecord``, oldest first) as a document; ``name``: the object asked, or None."""
    changes = list(changes)
    kinds = {cal.id: cal.kind for cal in db.calibrations()} if any(c.calibration_id for c in changes) else {}
    return {
        "format": HISTORY_FORMAT,
        "database": str(db.path),
        "object": name,
        "changes": [_change(c, kinds) for c in changes],
    }


# ---------------------------------------------------------------------------------------------- calibrations
def _camera_name(cal) -> str | None:
    name = cal.data.get("view")
    if name is None and ":" in cal.kind:
        name = cal.kind.split(":", 1)[1]
    return None if name is None else str(name)


def _turret_cov_world(cov: Any, R_world_turret: np.ndarray) -> np.ndarray | None:
    """core.calibration.TurretCalibration's covariance, (rotation vector, translation) in the turret frame
    (``T = T̂ · exp(δ)``), as the database's pose convention: (δt, δr) in the world, R ← exp([δr]×) R,
    t ← t + δt (to first order δr = R ω, δt = R v)."""
    if cov is None:
        return None
    C = np.asarray(cov, float)
    if C.shape != (6, 6):
        return None
    order = [3, 4, 5, 0, 1, 2]  # (ω, v) → (v, ω)
    B = np.zeros((6, 6))
    B[:3, :3] = B[3:, 3:] = R_world_turret
    return B @ C[np.ix_(order, order)] @ B.T


def _count(value: Any) -> int:
    return len(value) if isinstance(value, (list, tuple)) else 0


def calibration_record(cal) -> dict[str, Any]:
    """One calibration (an ``app.db.CalibrationRecord``) as a dict; every key present for every kind
    (null where it does not apply). ``pose`` is the pose in the world of the camera (T_world_cam, from
    C = K [R | t]; null for a mirrored C), the turret (T_world_turret) or the robot's base
    (T_world_base), with σ where the calibration gave a covariance."""
    d, kind = cal.data, cal.kind
    rec: dict[str, Any] = {
        "calibration_id": int(cal.id),
        "kind": kind,
        "camera": None,
        "time": float(cal.time),
        "time_iso": iso(cal.time),
        "who": cal.client,
        "method": cal.method,
        "pose": None,
        "rms_px": None if d.get("rms_px") is None else float(d["rms_px"]),
        "rms_m": None if d.get("rms_m") is None else float(d["rms_m"]),
        "measurements": 0,
        "nominal": None,
        "width": None,
        "height": None,
        "C": None,
        "K": None,
        "resolution_arcsec": None,
        "pan_limits_steps": None,
        "tilt_limits_steps": None,
    }
    if kind == "camera" or kind.startswith("camera:"):
        from core.camera import Camera

        width, height = int(d.get("width", 1)), int(d.get("height", 1))
        C = np.asarray(d["C"], float)
        K, T_cam_world = Camera(C, width, height).decompose()
        rec.update(
            camera=_camera_name(cal),
            width=d.get("width"),
            height=d.get("height"),
            C=[[float(v) for v in row] for row in C],
            K=[[float(v) for v in row] for row in K],
            measurements=_count(d.get("X_world")),
        )
        if K[0, 0] > 0:  # a mirrored C (fx < 0) has no camera frame in the world
            rec["pose"] = pose_fields(invert_T(T_cam_world), None)
    elif kind == "turret":
        T = np.asarray(d["T_world_turret"], float)
        rec["pose"] = pose_fields(T, _turret_cov_world(d.get("cov"), T[:3, :3]))
        rec["measurements"] = _count(d.get("range_m"))
        for key in ("resolution_arcsec", "pan_limits_steps", "tilt_limits_steps"):
            rec[key] = d.get(key)
    elif kind == "robot_base":
        cov = d.get("cov")
        rec["pose"] = pose_fields(np.asarray(d["T_world_base"], float), None if cov is None else np.asarray(cov))
        rec.update(nominal=bool(d.get("nominal", False)), camera=d.get("camera"), measurements=_count(d.get("edges")))
    return rec


def _kind_order(kind: str) -> tuple[int, str]:
    if kind == "camera" or kind.startswith("camera:"):
        return 0, "" if kind == "camera" else kind
    return (1 + CALIBRATION_KINDS.index(kind), "") if kind in CALIBRATION_KINDS else (9, kind)


def pick_calibrations(db, what: str | None = None) -> list:
    """The calibrations ``mcit db show-calibration [WHAT]`` shows: the latest of each kind (every
    camera's, the turret's, the robot base's) for None; "camera" (every camera's latest), "turret",
    "robot-base" (or "robot_base"), a camera's name, or a calibration's number. ValueError (one line:
    what the database has) when there is none such; [] for None on a database without calibrations."""
    from .records import NotFoundError

    every = db.calibrations()
    if what is not None and what.isdigit():
        hit = [c for c in every if c.id == int(what)]
        if not hit:
            raise NotFoundError(f"no calibration #{what} in {db.path} (see mcit db history)")
        return hit
    latest: dict[str, Any] = {}
    for cal in every:  # oldest first: the last one of each kind stays
        latest[cal.kind] = cal
    chosen = [latest[k] for k in sorted(latest, key=_kind_order)]
    if what is None:
        return chosen
    key = what.replace("-", "_")
    if key == "camera":
        chosen = [c for c in chosen if _kind_order(c.kind)[0] == 0]
    elif key in CALIBRATION_KINDS:
        chosen = [c for c in chosen if c.kind == key]
    else:
        chosen = [c for c in chosen if _kind_order(c.kind)[0] == 0 and _camera_name(c) == what]
    if not chosen:
        has = ", ".join(
            f"{c.kind.replace('_', '-')}" + (f" ({_camera_name(c)})" if _camera_name(c) else "")
            for c in latest.values()
        )
        raise ValueError(
            f"{db.path} has no {what} calibration; it has: {has or 'none'} "
            "(give camera, turret, robot-base, a camera's name or a calibration's number)"
        )
    return chosen


def calibrations_doc(db, calibrations: Iterable) -> dict[str, Any]:
    return {
        "format": CALIBRATIONS_FORMAT,
        "database": str(db.path),
        "calibrations": [calibration_record(c) for c in calibrations],
    }


def _pose_line(what: str, pose: dict[str, Any]) -> str:
    from app.scene import pose_to_json

    xyz = ", ".join(f"{v + 0.0:.4f}".replace("-0.0000", "0.0000") for v in pose["xyz_m"])
    rpy = ", ".join(f"{v:.2f}".replace("-0.00", "0.00") for v in pose_to_json(np.asarray(pose["T"]))["rpy_deg"])
    line = f"  {what} in the world: position ({xyz}) m, roll pitch yaw ({rpy})°"
    s = pose["sigma"]
    if s is not None:
        line += (
            f"; σ position ({', '.join(f'{1e3 * v:.1f}' for v in s['xyz_m'])}) mm, "
            f"rotation ({', '.join(f'{np.degrees(v):.2f}' for v in s['rot_rad'])})°"
        )
    return line


def _matrix_lines(name: str, rows: list) -> list[str]:
    return [f"  {name}:"] + ["    " + " ".join(f"{v:12.6g}" for v in row) for row in rows]


def calibration_lines(rec: dict[str, Any], when: str) -> list[str]:
    """``calibration_record``'s text for ``mcit db show-calibration``; ``when``: its time as shown."""
    kind = rec["kind"]
    head = f"#{rec['calibration_id']} "
    if rec["C"] is not None:
        head += "camera" + (f" {rec['camera']!r}" if rec["camera"] else "")
    else:
        head += {"robot_base": "robot base"}.get(kind, kind)
    head += f": {when}, by {rec['who']}, {rec['method']}"
    if rec["nominal"]:
        head += "; nominal (the drawing's pose, not calibrated)"
    fit = []
    if rec["rms_px"] is not None:
        fit.append(f"RMS {rec['rms_px']:.2f} px")
    if rec["rms_m"] is not None:
        fit.append(f"RMS {1e3 * rec['rms_m']:.1f} mm")
    if rec["measurements"]:
        unit = {"turret": "ranges", "robot_base": "edges"}.get(kind, "points")
        fit.append(f"from {rec['measurements']} {unit}")
    lines = [head + (f"; {' '.join(fit)}" if fit else "")]
    if rec["K"] is not None:
        K = rec["K"]
        lines.append(
            f"  image {rec['width']}×{rec['height']} px; K: fx {K[0][0]:.2f} px, fy {K[1][1]:.2f} px, "
            f"centre ({K[0][2]:.2f}, {K[1][2]:.2f}) px, skew {K[0][1]:.3g}"
        )
    what = {"turret": "turret", "robot_base": "base"}.get(kind, "camera")
    if rec["pose"] is not None:
        lines.append(_pose_line(what, rec["pose"]))
    elif rec["C"] is not None:
        lines.append("  camera in the world: none (C is mirrored: a reconstruction in a reflected frame)")
    if rec["resolution_arcsec"] is not None:
        lines.append(
            f"  resolution {rec['resolution_arcsec']}″ a step; pan limits {rec['pan_limits_steps']}, "
            f"tilt limits {rec['tilt_limits_steps']} steps"
        )
    if rec["C"] is not None:
        lines += _matrix_lines("C", rec["C"])
    if rec["pose"] is not None:
        lines += _matrix_lines(
            {"turret": "T_world_turret", "robot_base": "T_world_base"}.get(kind, "T_world_cam"), rec["pose"]["T"]
        )
    return lines
