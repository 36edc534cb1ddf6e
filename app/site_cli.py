"""``mcit site new``: a site of one's own from a camera file and a video (docs/own-site.md).

mcit site new DIR --camera cam.xml --video teabox.mp4         the site folder (work in app.site_folder)
mcit db import teabox.cao --pose teabox.init --site DIR ...   an object into its database (app.db_cli)
mcit serve --site DIR                                         the interface on it (app.ui.serve)
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

__all__ = ["add_site_parser"]


def _cmd_new(args) -> int:
    from app.site_folder import create_site

    out = create_site(
        args.dir,
        args.camera,
        args.video,
        camera_pose=args.camera_pose,
        camera_name=args.camera_name,
        size=args.size,
        fps=args.fps,
        name=args.name,
    )
    site, (w, h), K = out["site"], out["size"], out["K"]
    world = (
        "its pose the projection matrix's"
        if out["matrix"]
        else "the pose --camera-pose gives"
        if args.camera_pose
        else "the world frame is the camera's"
    )
    lines = [
        f"made site {site.root}: one camera, {w}×{h}, px {K[0, 0]:.2f} py {K[1, 1]:.2f} u0 {K[0, 2]:.2f} "
        f"v0 {K[1, 2]:.2f}, {out['lens'] or 'no lens distortion'}; no turret or range finder",
        f"  scene.json   the camera (its file copied beside it); {world} until Calibrate camera",
        f"  site.json    the video: {site.video}" + ("" if out["probed"] else " (opened by mcit serve)"),
        "  site.sqlite  the database, with the camera's calibration",
        f"next: mcit db import MODEL --pose FILE --site {args.dir}   then   mcit serve --site {args.dir}",
    ]
    print("\n".join(lines))
    return 0


def _run(args) -> int:
    """``_cmd_new``, its refusals one line on stderr (status 1)."""
    try:
        return _cmd_new(args)
    except ValueError as exc:
        print(f"mcit site new: error: {exc}", file=sys.stderr)
        return 1
    except OSError as exc:  # a file or folder that cannot be read or written: which and why
        from app.oserrors import os_error_advice

        where = f"{exc.filename}: " if exc.filename else ""
        print(
            f"mcit site new: error: {where}{exc.strerror or exc}; {os_error_advice(exc)} (nothing was written)",
            file=sys.stderr,
        )
        return 1


def _size(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number of pixels, got {text!r}") from None
    if not 1 <= value <= 100_000:
        raise argparse.ArgumentTypeError(f"expected 1 to 100000 pixels, got {text!r}")
    return value


def add_site_parser(sub) -> argparse.ArgumentParser:
    """Add ``site`` (and ``site new``) to the ``mcit`` parser's sub-parsers."""
    from app.argtypes import frame_rate

    site = sub.add_parser(
        "site",
        help="a site of your own: a camera file and a video made into a folder mcit serves",
        description="A site of your own, in three commands: mcit site new DIR --camera FILE --video SOURCE; "
        "mcit db import MODEL --pose FILE --site DIR; mcit serve --site DIR (docs/own-site.md).",
    )
    cmds = site.add_subparsers(dest="site_command", metavar="SITE_COMMAND", required=True)
    p = cmds.add_parser(
        "new",
        help="make a site folder (scene, camera file, video source, database) from a camera file and a video",
        description="Make the folder DIR that mcit serve --site DIR serves: a camera-only scene (no turret or "
        "range finder) whose camera is the camera file's K at the video's image size, the video source, and a "
        "database holding the camera's calibration. The world frame is the camera's until Calibrate camera "
        "(or --camera-pose) places it; a projection matrix (.P) gives the camera whole, its pose included. Nothing "
        "is written on a failure.",
    )
    p.add_argument("dir", type=Path, help="the site's folder, to be made (a missing or empty folder)")
    p.add_argument(
        "--camera",
        required=True,
        type=Path,
        metavar="FILE",
        help="the camera's intrinsics: ViSP .xml, OpenCV or ROS camera_info .yml/.yaml/.json; or the whole camera as "
        "a 3×4 projection matrix .P (its pose included) (copied into DIR)",
    )
    p.add_argument(
        "--video",
        required=True,
        metavar="SOURCE",
        help="what mcit serve plays: a video file, an image folder (name order), an image, a camera index (0) or "
        "a stream URL",
    )
    p.add_argument(
        "--camera-name", help="the camera to read in a file that holds several (ViSP <name>, a YAML camera key)"
    )
    p.add_argument(
        "--camera-pose",
        type=Path,
        metavar="FILE",
        help="the camera's pose in the world, T_world_cam: a 4×4 matrix (.txt, .dat) or a JSON pose "
        "(default: the world frame is the camera's)",
    )
    p.add_argument(
        "--size",
        nargs=2,
        type=_size,
        metavar=("WIDTH", "HEIGHT"),
        help="the image size in pixels, when neither the camera file nor the video says it (a camera or stream)",
    )
    p.add_argument("--fps", type=frame_rate, default=None, help="frame rate of an image folder or still (default: 10)")
    p.add_argument("--name", help="the site's name (default: the folder's)")
    p.set_defaults(func=_run)
    return site
