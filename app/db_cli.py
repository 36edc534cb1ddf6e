"""``mcit db …``: the site's database from the command line (parsers here, work in app.db).

    mcit db init --scene scenes/workcell        a new database from a scene's known objects
    mcit db import model.cao [--name N] [--xyz X Y Z] [--rpy-deg R P Y] [--status known] [--max-faces N]
    mcit db import model.cao --pose FILE [--pose-frame camera|world] [--init-clicks U,V ...] [--site DIR]
    mcit db list | show NAME | history [NAME] [--json]      --json: one JSON document (docs/database.md)
    mcit db show-calibration [camera|turret|robot-base|CAMERA|N] [--json]
    mcit db undo CHANGE [--restore]
    mcit db export NAME out.{cao,obj,stl,ply,gltf,glb} [--world]
    mcit db export-poses out.{json,csv,pos} [--object NAME ...] [--frame world|camera]
    mcit db feed --socket PATH | --file PATH     the pose changes as JSON lines (app.poses_cli)

Every sub-command takes ``--db PATH`` (default ``~/.local/share/mcit/mcit.sqlite``) or ``--site DIR`` (a
site folder's database, ``mcit site new``) and ``--wait-s S`` (how long a change waits for another writer to
finish, default 5 s). list, show, history, show-calibration and export only read: they work on a read-only file,
folder or mount and never create the file. Every failure is one line on stderr (app.cli) and exit status 1, with
nothing written. Heavy modules are imported inside the commands so that ``mcit --help`` stays fast.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from app.argtypes import angle_deg, coordinate_m, number, pixel_uv
from app.oserrors import os_error_advice
from app.terminal import safe_output

__all__ = ["add_db_parser"]


def _when(t: float) -> str:
    return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(t))


def _open(args, readonly: bool = False):
    from app.db import Database
    from app.site_folder import database_of

    path = database_of(args.db, getattr(args, "site", None))
    return Database.open(path, client="cli", busy_timeout_s=args.wait_s, readonly=readonly)


def _cmd_init(args) -> int:
    from app.db import seed_from_scene
    from app.scene import default_scene_path, load_scene

    scene = load_scene(args.scene or default_scene_path())
    with _open(args) as db:
        out = seed_from_scene(db, scene, client="cli")
        print(
            f"{db.path}: seeded from scene {scene.name!r}: objects {', '.join(out['objects']) or '(none)'}; "
            f"calibrations {', '.join(f'#{i}' for i in out['calibrations'])} (mcit db show-calibration)"
        )
    return 0


FAR_TIMES_SIZE = 1000  # a pose this many times the model's size from the camera: a file in millimetres


def _check_distance(pose_path, name: str, model, T_cam_obj, T_world_obj, camera) -> None:
    """ValueError when the pose puts the object more than FAR_TIMES_SIZE times its size from the camera (a pose in
    millimetres read as metres: 0.5 m becomes 500 m, and the object a dot). The distance from the pose in the camera
    frame, else from the camera's centre when the site has a camera, else from the world's origin (a database with
    no camera: the site's world is the size of a work cell)."""
    import numpy as np

    where = "the camera"
    if T_cam_obj is not None:
        far = float(np.linalg.norm(np.asarray(T_cam_obj)[:3, 3]))
    elif camera is not None:
        far = float(np.linalg.norm(np.asarray(T_world_obj)[:3, 3] - camera.center))
    else:
        far, where = float(np.linalg.norm(np.asarray(T_world_obj)[:3, 3])), "the world's origin"
    lo, hi = model.bounds()
    size = float(np.max(hi - lo))
    if size > 0 and far > FAR_TIMES_SIZE * size:
        raise ValueError(
            f"{pose_path}: the pose puts {name!r} {far:.4g} m from {where}, {far / size:,.0f} times its size "
            f"({1000 * size:.4g} mm): is the pose in millimetres? mcit reads metres; write it in metres"
        )


def _cmd_import(args) -> int:
    import numpy as np

    from app.models_io import MAX_MESH_FACES, load_model
    from app.names import check_object_name
    from core.transforms import make_T, rot_x, rot_y, rot_z

    path = Path(args.file)
    name = args.name or path.stem
    try:  # before the file is read: the name is checked again when it is written
        check_object_name(name, "--name" if args.name else f"the object's name, {path.name}'s stem,")
    except ValueError as exc:
        raise ValueError(f"{exc}" + ("" if args.name else "; give the object a name with --name NAME")) from None
    max_faces = args.max_faces or MAX_MESH_FACES
    model = load_model(path, angle_deg=args.angle_deg, max_faces=max_faces)  # raises before the database is touched
    options = None
    if path.suffix.lower() == ".cao":  # ViSP's name= and LOD options, kept in the history for export
        from app.models_io import read_cao_options

        options = read_cao_options(path)[1]
    measurements = {"cao_options": options.to_json()} if options else {}
    cov, said, residuals = None, "", None
    if args.pose is not None:  # read before the database is written: a bad file writes nothing
        from app.pose_files import read_pose_file
        from app.site_folder import current_camera

        if args.xyz is not None or args.rpy_deg is not None:
            raise ValueError("give the pose once: --pose FILE, or --xyz and --rpy-deg")
        camera, lens, cal_id = _import_camera(args, current_camera)
        clicks = None if args.init_clicks is None else np.array(args.init_clicks, dtype=float)
        pose = read_pose_file(args.pose, frame=args.pose_frame, camera=camera, clicks=clicks, lens=lens)
        T, cov = pose.in_world(camera)
        _check_distance(args.pose, name, model, pose.T if pose.frame == "camera" else None, T, camera)
        through = "" if pose.frame == "world" else f" → T_world_obj through the camera's {_cal_text(cal_id)}"
        said = f"; pose from {pose.describe()}{through}"
        residuals = pose.details.get("residuals_px")
        details = {k: v for k, v in pose.details.items() if k != "residuals_px"}
        measurements["pose"] = {
            "file": str(Path(args.pose).resolve()),
            "form": pose.form,
            "frame": pose.frame,
            "frame_from": pose.frame_from,
            "T_file": pose.T,
            "camera_calibration": cal_id,
            **details,
        }
    else:
        if args.init_clicks is not None or args.pose_frame is not None:
            raise ValueError("--init-clicks and --pose-frame go with --pose FILE")
        roll, pitch, yaw = np.radians(args.rpy_deg or (0.0, 0.0, 0.0))
        T = make_T(rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), np.asarray(args.xyz or (0.0, 0.0, 0.0), float))
    with _open(args) as db:
        try:
            rec = db.add_object(
                name,
                args.kind,
                model,
                T,
                cov=cov,
                status=args.status,
                sigmas=None if args.model_sigma_mm is None else {"model": args.model_sigma_mm / 1000.0},
                source=str(path.resolve()),
                method=f"import {path.suffix.lower().lstrip('.')}",
                client="cli",
                measurements=measurements or None,
                residuals=residuals,
            )
        except ValueError as exc:
            if "already exists" not in str(exc):
                raise
            raise ValueError(
                f"an object named {name!r} already exists: give the import another name with --name NAME (a new "
                f"pose of {name!r} itself: Update pose in mcit serve)"
            ) from None
        x, y, z = rec.T_world_obj[:3, 3]
        print(
            f"{db.path}: added #{rec.id} {rec.name!r} ({rec.kind}, {rec.status}): {len(model.vertices)} vertices, "
            f"{len(model.edges)} edges, {len(model.faces)} faces, "
            f"{len(model.solids)} solids, {len(model.circles)} circles; at x y z {x:.4f} {y:.4f} {z:.4f} m{said}"
        )
    return 0


def _print_json(doc: dict) -> None:
    """One JSON document on stdout, indented, in ASCII (any other character as a \\u escape: a name's
    terminal controls never reach the terminal, and ``safe_output`` has nothing to change)."""
    print(json.dumps(doc, indent=1))


def _cal_text(cal_id) -> str:
    return "scene pose (not yet calibrated)" if cal_id is None else f"calibration #{cal_id}"


def _import_camera(args, current_camera):
    """(camera, lens, calibration id) a --pose file is seen through: the database's latest camera calibration
    (the site's scene's camera and lens with --site); (None, None, None) for a database not yet made."""
    from app.db import Database, default_db_path
    from app.site_folder import database_of, open_site

    scene = None
    if getattr(args, "site", None) is not None:
        from app.scene import load_scene

        scene = load_scene(open_site(args.site).scene_path)
    path = database_of(args.db, getattr(args, "site", None)) or default_db_path()
    if not Path(path).exists():
        return current_camera(None, scene) if scene is not None else (None, None, None)
    with Database.open(path, client="cli", busy_timeout_s=args.wait_s, readonly=True) as db:
        return current_camera(db, scene)


def _cmd_list(args) -> int:
    with _open(args, readonly=True) as db:
        if args.json:
            from app.db.describe import objects_doc

            _print_json(objects_doc(db))
            return 0
        objs = db.objects()
        if not objs:
            print(f"{db.path}: no objects")
            return 0
        print(f"{'id':>4}  {'name':<20} {'kind':<12} {'status':<9} {'ver':>4}  {'x':>8} {'y':>8} {'z':>8}  updated")
        for o in objs:
            x, y, z = o.T_world_obj[:3, 3]
            print(
                f"{o.id:>4}  {o.name:<20} {o.kind:<12} {o.status:<9} {o.version:>4}"
                f"  {x:8.4f} {y:8.4f} {z:8.4f}  {_when(o.updated_at)}"
            )
    return 0


def _cmd_show(args) -> int:
    import numpy as np

    from app.scene import pose_to_json

    with _open(args, readonly=True) as db:
        o = db.get(int(args.name) if args.name.isdigit() else args.name)
        if args.json:
            from app.db.describe import object_doc

            _print_json(object_doc(db, o))
            return 0
        m = o.model
        rpy = pose_to_json(o.T_world_obj)["rpy_deg"]
        print(f"#{o.id} {o.name!r}  kind {o.kind}  status {o.status}  version {o.version}")
        print(
            f"  model: {len(m.vertices)} vertices, {len(m.edges)} edges, {len(m.faces)} faces, {len(m.solids)} solids, "
            f"{len(m.circles)} circles (model row {o.model_id}){'  from ' + o.source if o.source else ''}"
        )
        for k, v in o.dims.items():
            s = o.sigmas.get(k)
            print(f"  {k} = {v:.4f} m" + (f" ± {s:.4f} m" if s is not None else ""))
        print(
            f"  position (m): {np.array2string(o.T_world_obj[:3, 3], precision=4)}   rpy (deg): "
            f"{np.array2string(np.array(rpy), precision=2)}"
        )
        print("  T_world_obj:")
        for row in o.T_world_obj:
            print("    " + " ".join(f"{v:10.6f}" for v in row))
        if o.cov is not None:
            sd = np.sqrt(np.clip(np.diag(o.cov), 0.0, None))
            print(
                f"  pose σ: x y z {' '.join(f'{1000 * v:.2f}' for v in sd[:3])} mm, "
                f"rotation about x y z {' '.join(f'{np.degrees(v):.3f}' for v in sd[3:])}°"
            )
        print(
            f"  created {_when(o.created_at)}, updated {_when(o.updated_at)}, "
            f"{len(db.history(o.id))} change{'' if len(db.history(o.id)) == 1 else 's'} in the history"
        )
    return 0


def _cmd_export(args) -> int:
    from app.db.export import write_atomically
    from app.models_io import MODEL_SUFFIXES, save_model

    out = Path(args.out)
    if out.is_dir() or (out.exists() and not out.is_file()):
        raise ValueError(f"{out} is not a file: give the file to write, ending in one of {', '.join(MODEL_SUFFIXES)}")
    if out.suffix.lower() not in MODEL_SUFFIXES:
        raise ValueError(
            f"{out}: unknown model type {out.suffix!r}; end the file's name in one of {', '.join(MODEL_SUFFIXES)}"
        )
    with _open(args, readonly=True) as db:
        o = db.get(int(args.name) if args.name.isdigit() else args.name)
        model = o.model.transformed(o.T_world_obj) if args.world else o.model
        frame = "world" if args.world else "object"
        comment = f"mcit object {o.name!r} (version {o.version}), {frame} frame, metres"
        if out.suffix.lower() == ".cao":
            from app.models_io import write_cao

            options = _imported_cao_options(db, o)

            def write(tmp):
                write_cao(model, tmp, comment, options=options)
        else:

            def write(tmp):
                save_model(model, tmp, comment=comment)

        try:
            write_atomically({out: write})  # a full disk leaves OUT as it was, and no temporary beside it
        except OSError as exc:
            raise ValueError(f"{out}: {exc.strerror or exc} (nothing was written); {os_error_advice(exc)}") from None
        print(f"wrote {args.out}: {o.name!r} in the {frame} frame")
    return 0


def _imported_cao_options(db, o):
    """The ViSP options (name=, LOD) of the .cao file the object's current model was imported from,
    from the import's history record; None when the model is not that file's (modelled, changed)."""
    from app.models_io import CaoOptions

    for change in db.history(o.id):
        m = change.measurements
        if (
            change.action == "add"
            and isinstance(m, dict)
            and "cao_options" in m
            and (change.after or {}).get("model_id") == o.model_id
        ):
            try:
                return CaoOptions.from_json(m["cao_options"])
            except ValueError:
                return None
    return None


def _cmd_history(args) -> int:
    with _open(args, readonly=True) as db:
        name = None if args.name is None else (int(args.name) if args.name.isdigit() else args.name)
        changes = db.history(name, limit=args.limit)
        if args.json:
            from app.db.describe import history_doc

            _print_json(history_doc(db, changes, args.name))
            return 0
        if not changes:
            print(f"{db.path}: the history is empty")
            return 0
        print(f"{'#':>5}  {'when':<19}  {'client':<10} {'action':<14} {'object':<20} {'ver':>4}  method")
        for c in changes:
            what = c.object_name or (f"calibration #{c.calibration_id}" if c.calibration_id else "")
            extra = f" (of #{c.undoes})" if c.undoes else ""
            print(
                f"{c.id:>5}  {_when(c.time)}  {c.client:<10} {c.action + extra:<14} {what:<20}"
                f" {c.version or '':>4}  {c.method}"
            )
    return 0


def _cmd_show_calibration(args) -> int:
    from app.db.describe import calibration_lines, calibration_record, calibrations_doc, pick_calibrations

    with _open(args, readonly=True) as db:
        chosen = pick_calibrations(db, args.what)
        if args.json:
            _print_json(calibrations_doc(db, chosen))
            return 0
        if not chosen:
            print(f"{db.path}: no calibrations (mcit db init seeds a scene's; mcit serve calibrates)")
            return 0
        for cal in chosen:
            print("\n".join(calibration_lines(calibration_record(cal), _when(cal.time))))
    return 0


def _cmd_undo(args) -> int:
    with _open(args) as db:
        if not args.restore and not args.yes:
            _refuse_discarding(db, args.change)
        c = db.restore(args.change) if args.restore else db.undo(args.change)
        what = c.object_name or f"calibration #{c.calibration_id}"
        state = "after" if args.restore else "before"
        print(f"change #{c.id}: {what} is back to its state {state} change #{args.change}")
    return 0


def _refuse_discarding(db, change_id: int) -> None:
    """A ValueError when undoing ``change_id`` would also discard later changes of its object (what the
    interface's History asks before doing); nothing is written."""
    from app.db import NotFoundError

    try:
        later = db.later_changes(change_id)
    except NotFoundError:
        return  # the undo says there is no such change
    if not later or (later[-1].method == "undo" and later[-1].undoes == change_id):
        return  # nothing later, or undone already (the database says so)
    last, n = later[-1], len(later)
    raise ValueError(
        f"undoing change #{change_id} brings {last.object_name} back to before it, so it also discards the {n} later "
        f"change{'s' if n > 1 else ''} of it (the last #{last.id}, by {last.client} at {_when(last.time)}); "
        "nothing was changed: add --yes to undo it all the same, or see them with mcit db history"
    )


def _run(func):
    def wrapped(args) -> int:
        with safe_output():  # the database's text may hold terminal escapes: shown as codes
            return func(args)  # a failure: its one line and exit status from app.cli

    return wrapped


_wait_s = number(float, lambda v: 0.0 <= v <= 3600.0, kind="seconds (a number)", expected="0 to 3600 seconds")
_limit = number(int, lambda v: 1 <= v <= 10**9, kind="a whole number of changes", expected="1 to 10⁹ changes")
_max_faces = number(int, lambda v: v >= 1, kind="a whole number of triangles", expected="at least 1 triangle")


def add_db_parser(subparsers) -> argparse.ArgumentParser:
    """Add ``db`` and its sub-commands to the ``mcit`` parser's sub-parsers."""
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument(
        "--db", metavar="PATH", default=None, help="database file (default: ~/.local/share/mcit/mcit.sqlite)"
    )
    common.add_argument(
        "--site", metavar="DIR", type=Path, default=None, help="a site folder (mcit site new): its database"
    )
    common.add_argument(
        "--wait-s",
        type=_wait_s,
        default=5.0,
        metavar="S",
        help="how long a change waits for another program writing the database (default 5 s)",
    )
    db = subparsers.add_parser(
        "db",
        help="the site's database: import, list, show, show-calibration, export, history, undo",
        description="The site's 3D geometric database (SQLite).",
    )
    sub = db.add_subparsers(dest="db_command", metavar="DB_COMMAND", required=True)

    p = sub.add_parser("init", parents=[common], help="create a database from a scene's known objects and calibrations")
    p.add_argument("--scene", metavar="DIR", default=None, help="scene folder (default: the bundled workcell)")
    p.set_defaults(func=_run(_cmd_init))

    p = sub.add_parser("import", parents=[common], help="add an object from a .cao or mesh file (OBJ, STL, PLY, glTF)")
    p.add_argument("file", help="model file: .cao, .obj, .stl, .ply, .gltf or .glb")
    p.add_argument("--name", help="object name (default: the file's stem)")
    p.add_argument("--kind", default="polyhedron", help="box, cylinder, polyhedron, ... (default polyhedron)")
    p.add_argument("--status", default="known", choices=("known", "modelled", "stale"))
    p.add_argument(
        "--xyz",
        nargs=3,
        type=coordinate_m,
        default=None,
        metavar=("X", "Y", "Z"),
        help="position in the world, metres (default 0 0 0)",
    )
    p.add_argument(
        "--rpy-deg",
        nargs=3,
        type=angle_deg,
        default=None,
        metavar=("R", "P", "Y"),
        help="orientation in the world R = Rz(yaw) Ry(pitch) Rx(roll), degrees (default 0 0 0)",
    )
    p.add_argument(
        "--pose",
        metavar="FILE",
        help="the pose from a file instead: ViSP .pos (cMo), a 4×4 matrix (.txt, .dat; cMo unless it says), JSON "
        "(T_world_obj unless it says) or a ViSP .init with its points' pixels (docs/own-site.md)",
    )
    p.add_argument(
        "--pose-frame",
        choices=("camera", "world"),
        help="the frame of a --pose file that does not say: camera (T_cam_obj, ViSP's cMo: taken to the world "
        "through the database's camera calibration) or world (T_world_obj)",
    )
    p.add_argument(
        "--init-clicks",
        nargs="+",
        type=pixel_uv,
        metavar="U,V",
        help="with --pose FILE.init: its points' pixels, in its order (pixels of the video as recorded)",
    )
    p.add_argument(
        "--model-sigma-mm",
        type=number(float, lambda v: 0.0 <= v <= 1000.0, kind="millimetres (a number)", expected="0 to 1000 mm"),
        default=None,
        help="how well the model follows the object: σ of each model edge's position (mm; default 0.3), and √2 of "
        "it for each of the model's extents (a length is read between two edges: one flag, as one measurement "
        "gives both), part of every pose's σ (docs/pose.md, 'What σ covers')",
    )
    p.add_argument("--angle-deg", type=float, default=30.0, help="meshes: dihedral angle from which an edge is drawn")
    p.add_argument(
        "--max-faces",
        type=_max_faces,
        default=None,
        metavar="N",
        help="meshes: the most triangles the file may hold (default 200,000, app.models_io.MAX_MESH_FACES); "
        "it also allows 3 vertices a triangle and 64 MB per 200,000 triangles",
    )
    p.set_defaults(func=_run(_cmd_import))

    as_json = argparse.ArgumentParser(add_help=False)
    as_json.add_argument(
        "--json", action="store_true", help="one JSON document instead of the table (keys: docs/database.md)"
    )
    p = sub.add_parser("list", parents=[common, as_json], help="every object with its status, version and position")
    p.set_defaults(func=_run(_cmd_list))

    p = sub.add_parser("show", parents=[common, as_json], help="one object: model, dimensions ± σ, pose, covariance")
    p.add_argument("name", help="object name or id")
    p.set_defaults(func=_run(_cmd_show))

    p = sub.add_parser(
        "show-calibration",
        parents=[common, as_json],
        help="the cameras', the turret's and the robot base's calibrations: pose in the world, C and K, RMS, σ",
        description="Show the latest calibration of every camera, of the turret and of the robot's base (or "
        "the ones asked): who made it, when and how, the calibrated thing's pose in the world with its σ, "
        "a camera's C and K, the fit's RMS.",
    )
    p.add_argument(
        "what",
        nargs="?",
        help="camera (every camera's), turret, robot-base, a camera's name, or a calibration's number "
        "(mcit db history); default: the latest of each",
    )
    p.set_defaults(func=_run(_cmd_show_calibration))

    p = sub.add_parser("export", parents=[common], help="write an object's model as .cao, OBJ, STL, PLY, glTF or GLB")
    p.add_argument("name", help="object name or id")
    p.add_argument("out", help="output file; its suffix chooses the format")
    p.add_argument("--world", action="store_true", help="bake the pose: write the model in the world frame")
    p.set_defaults(func=_run(_cmd_export))

    p = sub.add_parser("history", parents=[common, as_json], help="every change (of one object): when, who, how")
    p.add_argument("name", nargs="?", help="object name or id (default: all)")
    p.add_argument("--limit", type=_limit, default=None, help="only the last N changes")
    p.set_defaults(func=_run(_cmd_history))

    p = sub.add_parser(
        "undo", parents=[common], help="bring an object back to its state before a change (itself recorded)"
    )
    p.add_argument("change", type=int, help="the change's number (see `mcit db history`)")
    p.add_argument("--restore", action="store_true", help="go back to the state just after the change instead")
    p.add_argument(
        "--yes", action="store_true", help="undo even when later changes of the object are discarded with it"
    )
    p.set_defaults(func=_run(_cmd_undo))

    from app.poses_cli import add_pose_parsers  # export-poses, feed: the poses out (argparse only)

    add_pose_parsers(sub, common, _run)
    return db
