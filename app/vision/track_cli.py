"""``mcit track``: follow a known object through a recorded video and write the overlay video.

    mcit track FRAMES_OR_VIDEO --model M.cao --intrinsics cam.xml --pose obj.pos --out overlay.mp4
    mcit track teabox.mp4 --model teabox.cao --intrinsics teabox.xml \\
        --init-points teabox.init --init-clicks 192,84.5 349.5,205.5 324,376 458.5,351
    mcit track --scene scenes/workcell --body box1 --out overlay.mp4

The camera is either intrinsics (a ViSP ``.xml`` or OpenCV ``.yml``; the world frame is then the
camera's, as for a hand-held camera) or a scene's calibrated C (``--scene``). The initial pose
is a file read by ``app.pose_files`` (ViSP ``.pos``: tx ty tz θux θuy θuz; a 4×4 matrix; JSON: a 4×4
matrix or {"xyz", "rpy_deg"}; a ViSP ``.init`` with its points' pixels), the pose of ``--body`` in the
scene, or computed from clicked model points (``--init-points``, a ViSP ``.init`` file, and
``--init-clicks``, the pixels in the same order). ``--pos-out`` writes the
tracked poses as ViSP ``.pos`` files: the object's pose in the camera (ViSP's cMo), the form ``--pose``
reads back.

Tracking stops at the first frame where the tracker is lost (exit status 3), and says where to
restart with a new pose; a file that cannot be used is exit status 1, options that do not go
together 2 (app/exit_status.py). Progress goes to stderr on a terminal (``--quiet``: none).
Parsers here; the work is in app.vision.sequence.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from app import exit_status
from app.exit_status import UsageError

__all__ = ["add_track_parser"]


def add_track_parser(sub) -> None:
    from app.argtypes import frame_index, frame_rate, frame_total, number, pixel_uv

    sigma_mm = number(float, lambda v: 0.0 <= v <= 1000.0, kind="millimetres (a number)", expected="0 to 1000 mm")
    lens_sigma = number(float, lambda v: 0.0 <= v <= 100.0, kind="a number", expected="0 to 100 (percent, pixels)")

    p = sub.add_parser(
        "track",
        help="track a known object through a recorded video (model-based edge tracking) and write the overlay video",
        description="Follow a known object through a recorded video (model-based edge tracking from an initial "
        "pose) and write the overlay video.",
        epilog="examples:\n" + "\n".join(line for line in __doc__.split("\n\n")[1].splitlines()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "source", nargs="?", help="a video file or a folder of frames (default: the scene's video with --scene)"
    )
    p.add_argument("--model", help="the object's model (.cao or a mesh); default: the body's model with --scene")
    cam = p.add_mutually_exclusive_group()
    cam.add_argument(
        "--intrinsics", help="camera intrinsics (ViSP .xml or OpenCV .yml); the world frame is the camera's"
    )
    cam.add_argument(
        "--scene", help="a scene folder: its calibrated camera C (and, with --body, model, pose and video)"
    )
    p.add_argument(
        "--camera-name",
        help="with --intrinsics: the camera to read in a file that holds several (ViSP <name>, "
        "or a YAML file's camera key or camera_name)",
    )
    p.add_argument("--body", help="with --scene: the body to track")
    p.add_argument(
        "--pose",
        help="initial pose file: ViSP .pos (tx ty tz θux θuy θuz), a 4×4 matrix (.txt, .dat), JSON (4×4 or "
        "{xyz, rpy_deg}) or a ViSP .init with its points' pixels (app.pose_files; docs/own-site.md)",
    )
    p.add_argument(
        "--pose-frame",
        choices=("camera", "world"),
        help="the frame of a --pose file that does not say: camera (T_cam_obj, ViSP's cMo; the default for .pos "
        "and matrices) or world (T_world_obj; the default for JSON)",
    )
    p.add_argument(
        "--init-points", help="model points clicked to initialise (a ViSP .init file; the same as --pose FILE.init)"
    )
    p.add_argument(
        "--init-clicks",
        nargs="+",
        type=pixel_uv,
        metavar="U,V",
        help="the clicked pixels of --init-points, in order "
        "(pixels of the video's frames as recorded; with lens distortion they are undistorted first)",
    )
    p.add_argument("--out", default="tracked.mp4", help="overlay video to write (.mp4 or .avi; default tracked.mp4)")
    p.add_argument("--csv", help="also write the per-frame poses and figures to this CSV file")
    p.add_argument(
        "--pos-out",
        metavar="PATH",
        help="write poses as ViSP .pos (tx ty tz θux θuy θuz, as --pose reads them): PATH with %%d (e.g. "
        "poses/obj.%%04d.pos) gets one file per tracked frame, any other PATH the last tracked frame's pose",
    )
    p.add_argument(
        "--start",
        type=frame_index,
        help="first frame to track, from 0 (the initial pose is this frame's); default 0, or with --scene SITE "
        "--body NAME the frame its database pose was found on, where its history says",
    )
    p.add_argument("--frames", type=frame_total, help="number of frames to track (default: to the end)")
    p.add_argument(
        "--fps",
        type=frame_rate,
        help="frame rate of the overlay video (above 0, at most 240; default: the source video's, 10 for an image "
        "folder as mcit serve reads it, or a site folder's rate)",
    )
    p.add_argument(
        "--search-px",
        type=float,
        default=8.0,
        help="search ±this many pixels along the edges' normals around the predicted pose (the band widens "
        "by itself, up to ±24 px, where the motion is less steady)",
    )
    p.add_argument("--step-px", type=float, default=5.0, help="spacing of the edge samples (pixels)")
    p.add_argument(
        "--model-sigma-mm",
        type=sigma_mm,
        default=None,
        help="the model's stated uncertainty: σ of each model edge's position (mm, default 0.3), and √2 of it for "
        "each of the model's extents (a length is read between two edges: one flag, as one measurement gives "
        "both), part of each frame's σ in --csv (docs/pose.md, 'What σ covers')",
    )
    p.add_argument(
        "--camera-sigma",
        nargs=2,
        type=lens_sigma,
        metavar=("F_PCT", "C_PX"),
        default=(0.3, 1.0),
        help="the stated uncertainty of a camera file without a calibration's covariance: σ of fx, fy in percent "
        "and of u0, v0 in pixels (default 0.3 %% and 1 px, a checkerboard calibration's; 0 0.5 for a renderer's "
        "camera file, its focal length exact but its pixel convention unsaid; 0 0 only for a camera known exactly, "
        "convention included: docs/pose.md, 'What σ covers')",
    )
    p.add_argument("--keep-going", action="store_true", help="do not stop at a lost frame (draw the last good pose)")
    p.add_argument("--quiet", action="store_true", help="no progress bar (there is none when stderr is not a terminal)")
    p.set_defaults(func=_cmd_track)


def _setup(args):
    """(source, camera, model, T_world_obj, lens or None) from the arguments; ValueError on bad input. Sets
    ``args.camera_cov``: the covariance of C's entries where the site calibrated the camera, else None.
    With lens distortion (the intrinsics file's or the scene's) the frames are undistorted as they are
    read and C holds in the undistorted frames (app/undistort.py)."""
    import numpy as np

    from app.models_io import load_model
    from app.vision.sequence import iter_frames
    from core.camera import Camera

    model = load_model(args.model) if args.model else None
    T = None
    args.start_said = ""
    lens = None
    source = args.source
    args.camera_cov = None
    args.body_model_sigma_m = None  # a site object's stored model prior (mcit db import --model-sigma-mm)
    if args.camera_name and not args.intrinsics:
        raise UsageError("--camera-name chooses a camera in the --intrinsics file; give --intrinsics FILE")
    if args.body and not args.scene:
        raise UsageError("--body names a body of the --scene; give --scene DIR")
    if args.scene:
        from app.scene import load_scene

        scene = load_scene(args.scene)
        camera = scene.camera
        lens = scene.lens
        site = _site_folder(args.scene)
        if site is not None and site.db_path.is_file():  # a site's camera as calibrated there by now
            from app.db import Database
            from app.site_folder import current_camera

            with Database.open(site.db_path, readonly=True) as db:
                camera, lens, cal_id = current_camera(db, scene)
                cal = db.latest_calibration("camera") if cal_id is not None else None
                if cal is not None and cal.data.get("cov") is not None:
                    args.camera_cov = np.asarray(cal.data["cov"], float)
        from_db = False
        if args.body:
            try:
                body_model, T, args.body_model_sigma_m, from_db = _body(scene, site, args.body)
            except KeyError as exc:  # an operator's typo: one line, not an internal error
                raise ValueError(f"--body: {exc.args[0]}") from None
            model = model or body_model
        if source is None and site is not None:
            source = site.video  # a site folder's video (mcit site new)
        if site is not None and args.fps is None and site.fps:
            args.fps = site.fps  # the overlay video at the rate the site is served at
        if args.start is None and args.body and from_db and not args.pose:
            # the database's pose is that frame's (a new user's pose from frame 217 was tracked from frame 0: lost)
            found = _pose_frame(site, args.body, source)
            if found is not None:
                args.start, args.start_said = found
        if source is None:
            if scene.video_path is None:
                raise ValueError(f"scene {scene.name!r} has no video: give a video file or frame folder")
            source = str(scene.video_path)
    if args.start is None:
        args.start = 0
    if not args.scene:
        if source is None:
            raise UsageError("give a video file or a folder of frames (or --scene with a video)")
        if not args.intrinsics:
            raise UsageError("give the camera: --intrinsics FILE (ViSP .xml / OpenCV .yml) or --scene DIR")
        from app.camera_io import read_intrinsics

        at = next(iter_frames(source, args.start, 1), None)
        if at is None:
            raise ValueError(_no_frame(source, args.start))
        h, w = at[1].shape[:2]
        intr = read_intrinsics(args.intrinsics, camera_name=args.camera_name, image_size=(w, h))
        if intr.width is not None and (intr.width, intr.height) != (w, h):
            raise ValueError(
                f"{args.intrinsics}: the camera was calibrated on {intr.width}×{intr.height} images but the "
                f"video's frames are {w}×{h}; give the intrinsics for this size"
            )
        camera = Camera.from_intrinsics(intr.K, np.eye(4), w, h)
        from app.undistort import lens_of

        lens = lens_of(intr, w, h)
    if model is None:
        raise UsageError("give the object's model: --model FILE (or --scene with --body)")
    pose_file = _pose_file(args)
    if pose_file is not None:  # the one reader of pose files (mcit db import --pose reads them too)
        from app.pose_files import read_pose_file

        clicks = None if args.init_clicks is None else np.array(args.init_clicks, dtype=float)
        frame = getattr(args, "pose_frame", None)
        pose = read_pose_file(pose_file, frame=frame, camera=camera, clicks=clicks, lens=lens)
        T = pose.in_world(camera)[0]
    if T is None:
        raise UsageError("give the initial pose: --pose FILE, --init-points/--init-clicks, or --scene with --body")
    return source, camera, model, T, lens


def _no_frame(source, start: int) -> str:
    """What to say when ``source`` has no frame ``start``."""
    from app.vision.sequence import frame_count

    n = frame_count(source)
    if not n:
        return f"{source}: no frame to track (it gives none): check the video or the folder"
    return f"{source} has {n} frames (0–{n - 1}), none at --start {start}: give --start from 0 to {n - 1}"


def _site_folder(path):
    """The site folder (``mcit site new``) at ``path``, None for a scene folder."""
    from app.site_folder import SITE_FILE, open_site

    return open_site(path) if (Path(path) / SITE_FILE).is_file() else None


def _pose_frame(site, name: str, source) -> tuple[int, str] | None:
    """(the frame index, how it is known) of the frame the site database's pose of ``name`` was found on, from its
    last change: the frame the clicks were made on, or a track's last good frame (its time at the site's frame
    rate); None when the history does not say."""
    from app.db import Database
    from app.video import FOLDER_FPS
    from app.vision.sequence import source_fps

    with Database.open(site.db_path, readonly=True) as db:
        changes = db.history(name, limit=1)
    if not changes:
        return None
    ch = changes[-1]
    frame = (ch.clicks or {}).get("frame") if isinstance(ch.clicks, dict) else None
    if isinstance(frame, dict) and int(frame.get("index", -1)) >= 0:
        return int(frame["index"]), f"frame {int(frame['index'])}, where change {ch.id} found the pose"
    t = (ch.measurements or {}).get("t_last_s") if isinstance(ch.measurements, dict) else None
    if t is None:
        return None
    fps = site.fps or source_fps(source) or FOLDER_FPS
    k = int(round(float(t) * fps))
    return k, f"frame {k}, the last tracked by change {ch.id} (t = {float(t):.2f} s at {fps:g} frames/s)"


def _body(scene, site, name: str):
    """(model, T_world_obj, the model's stated σ in metres or None for the default, whether from the database) of
    ``name``: the scene's body, else the site folder's database object; KeyError saying where it looked."""
    try:
        body = scene.body(name)
        return body.model, body.T_world_obj, None, False
    except KeyError:
        pass
    if site is not None and site.db_path.is_file():
        from app.db import Database, NotFoundError

        with Database.open(site.db_path, readonly=True) as db:
            try:
                rec = db.get(name)
            except NotFoundError:
                rec = None
            if rec is not None:
                return rec.model, rec.T_world_obj, rec.model_sigma_m, True
            names = [o.name for o in db.objects()]
        raise KeyError(
            f"site {site.root.name} has no object named {name!r} (its database's: {', '.join(names) or 'none'}); "
            "import it first (mcit db import MODEL --pose FILE --site DIR)"
        )
    names = [b.name for b in scene.bodies]
    raise KeyError(
        f"scene {scene.name!r} has no body named {name!r} (its bodies: {', '.join(names) or 'none'}); or give "
        "--model FILE and --pose FILE"
    )


def _pos_names(pattern: str, indices) -> list[str]:
    """The --pos-out file names of the frames ``indices`` (``pattern % index``); UsageError when malformed."""
    try:
        return [pattern % i for i in indices]
    except (TypeError, ValueError):
        raise UsageError(f"--pos-out {pattern!r}: one %d (e.g. %04d) for the frame number expected") from None


def _pose_file(args) -> Path | None:
    """The initial pose's file: --pose, or --init-points (an .init whose pixels --init-clicks gives)."""
    if args.pose and args.init_points:
        raise UsageError("give the initial pose once: --pose FILE, or --init-points FILE.init with --init-clicks")
    if args.init_points and Path(args.init_points).suffix.lower() != ".init":
        raise UsageError(f"--init-points {args.init_points}: a ViSP .init file expected (the model points clicked)")
    if args.init_clicks and not (args.init_points or str(args.pose or "").lower().endswith(".init")):
        raise UsageError("--init-clicks are the pixels of an .init file's points: give --init-points FILE.init")
    if getattr(args, "pose_frame", None) and not args.pose:
        raise UsageError("--pose-frame says the frame of a --pose file; give --pose FILE")
    path = args.pose or args.init_points
    return None if path is None else Path(path)


def _write_pos(pattern: str, frames, camera) -> str:
    """Write the tracked frames' poses as ViSP .pos files (see --pos-out): each the object's pose in the
    camera (cMo = T_cam_world · T_world_obj, what --pose reads a .pos as); what was written, for the summary."""
    from app.db.export import pos_text

    K, T_cam_world = camera.decompose()
    if K[0, 0] < 0:
        raise ValueError(f"--pos-out {pattern}: the camera is mirrored, so it has no camera frame to give cMo in")

    good = [f for f in frames if not f.lost]
    if not good:
        raise ValueError(f"{pattern}: no frame was tracked, so there is no pose to write")
    if "%" in pattern:
        names = _pos_names(pattern, [f.index for f in good])
        for name, f in zip(names, good):
            Path(name).parent.mkdir(parents=True, exist_ok=True)
            Path(name).write_text(pos_text(T_cam_world @ f.T_world_obj))
        return f"; {len(good)} .pos files: {names[0]} … {names[-1]}" if len(good) > 1 else f"; pose: {names[0]}"
    path = Path(pattern)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(pos_text(T_cam_world @ good[-1].T_world_obj))
    return f"; pose of frame {good[-1].index}: {path}"


def _cmd_track(args) -> int:
    """Track; a failure raises (app.cli says it: status 1, or 2 for a UsageError), a lost object is status 3."""
    import numpy as np

    from app.progress import progress_bar
    from app.vision.sequence import track_sequence
    from core.pose.uncertainty import Priors, intrinsics_prior_cov

    source, camera, model, T, lens = _setup(args)
    # each frame's σ: the camera's calibration (or its file's stated prior) and the model's prior (issue 27)
    f_pct, c_px = args.camera_sigma
    prior = intrinsics_prior_cov(camera, f_pct / 100.0, c_px) if f_pct > 0 or c_px > 0 else None
    camera_cov = prior if args.camera_cov is None else args.camera_cov
    model_sigma_m = args.body_model_sigma_m if args.model_sigma_mm is None else args.model_sigma_mm / 1000.0
    priors = Priors(camera_cov) if model_sigma_m is None else Priors(camera_cov, model_sigma_m)
    if args.pos_out and "%" in args.pos_out:
        _pos_names(args.pos_out, [0])  # a malformed pattern is said before the video is read
    with progress_bar("frames", quiet=args.quiet) as progress:
        frames = track_sequence(
            source,
            camera,
            model,
            T,
            start=args.start,
            count=args.frames,
            video_out=args.out,
            csv_out=args.csv,
            fps_out=args.fps,
            stop_when_lost=not args.keep_going,
            search_px=args.search_px,
            sample_step_px=args.step_px,
            lens=lens,
            progress=progress,
            priors=priors,
        )
    if not frames:
        raise ValueError(_no_frame(source, args.start))
    pos_written = _write_pos(args.pos_out, frames, camera) if args.pos_out else ""
    conf = np.array([f.confidence for f in frames if not f.lost] or [0.0])
    ms = np.array([f.track_ms for f in frames])
    lost = [f for f in frames if f.lost]
    print(
        f"tracked {len(frames) - len(lost)} frames ({frames[0].index}–{frames[-1].index}) of {source}; "
        f"confidence min {conf.min():.2f}, mean {conf.mean():.2f}; tracking {np.mean(ms):.1f} ms a frame "
        f"({1e3 / np.mean(ms):.0f} frames/s)"
    )
    print(f"overlay video: {args.out}" + (f"; poses: {args.csv}" if args.csv else "") + pos_written)
    if args.start_said:
        print(f"started from {args.start_said} (--start chooses another)")
    if lost:
        f = lost[0]
        print(
            f"mcit track: LOST at frame {f.index}: {f.reason}. Give the pose of frame {f.index} again and restart "
            f"with --start {f.index} --pose <file>.",
            file=sys.stderr,
        )
        return exit_status.LOST
    return exit_status.OK
