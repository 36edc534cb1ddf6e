"""A new site database from a scene: its known objects, its camera and its turret calibration."""

from __future__ import annotations

from typing import Any

from app.scene import Scene
from core.brep import BRep

from .database import Database

__all__ = ["dimensions_of", "seed_from_scene"]


def dimensions_of(model: BRep, kind: str) -> dict[str, float]:
    """The named dimensions (metres) of a box, cylinder or cone model; {} for other shapes.

    box: size_x, size_y, size_z (its bounds); cylinder: radius, height; cone: radius_bottom,
    radius_top, height (of its one solid of revolution).
    """
    if kind in ("box", "table") and len(model.vertices) and not model.solids:
        lo, hi = model.bounds()
        return {"size_x": float(hi[0] - lo[0]), "size_y": float(hi[1] - lo[1]), "size_z": float(hi[2] - lo[2])}
    if len(model.solids) == 1 and not len(model.vertices):
        s = model.solids[0]
        if kind == "cylinder" and s.is_cylinder:
            return {"radius": s.r0, "height": s.height}
        if kind == "cone":
            return {"radius_bottom": s.r0, "radius_top": s.r1, "height": s.height}
    return {}


def seed_from_scene(db: Database, scene: Scene, *, client: str = "seed") -> dict[str, Any]:
    """Write the scene's "known" bodies (status known, pose at t = 0), its camera C, its turret pose
    (when it has a turret) and, with a robot, its base's nominal pose (``RobotSpec.nominal_base``: the
    drawing's, marked ``nominal`` until the base is calibrated) as the first calibrations, all in one
    transaction.

    Raises ValueError (nothing written) when the database already has objects or calibrations.
    Returns {"objects": [names], "calibrations": [ids]} (camera, then turret and robot base when there are).
    """
    if db.objects() or db.calibrations():
        raise ValueError(
            f"the database {db.path} already holds a site; seed only a new database (or choose another --db)"
        )
    method = f"seed from scene {scene.name!r}"
    names, cal_ids = [], []
    with db.transaction():
        for body in scene.known:
            db.add_object(
                body.name,
                body.kind,
                body.model,
                body.pose_at(0.0),
                dims=dimensions_of(body.model, body.kind),
                status="known",
                source=str(scene.root),
                method=method,
                client=client,
            )
            names.append(body.name)
        cam = scene.camera
        cal_ids.append(
            db.add_calibration(
                "camera", {"C": cam.C, "width": cam.width, "height": cam.height}, None, method=method, client=client
            ).id
        )
        t = scene.turret
        if t is not None:  # a camera-only site has none
            cal_ids.append(
                db.add_calibration(
                    "turret",
                    {
                        "T_world_turret": t.T_world_turret,
                        "resolution_arcsec": t.resolution_arcsec,
                        "pan_limits_steps": t.pan_limits_steps,
                        "tilt_limits_steps": t.tilt_limits_steps,
                    },
                    None,
                    method=method,
                    client=client,
                ).id
            )
        if scene.robot is not None:
            cal_ids.append(
                db.add_calibration(
                    "robot_base",
                    {"T_world_base": scene.robot.nominal_base, "nominal": True},
                    None,
                    method=method,
                    client=client,
                ).id
            )
    return {"objects": names, "calibrations": cal_ids}
