"""``mcit db export-poses`` and ``mcit db feed``: the database's poses out, for the robot's software.

    mcit db export-poses poses.json                       every object's pose (world frame), JSON
    mcit db export-poses poses.csv --object box1 table    some objects, CSV
    mcit db export-poses box1.pos --object box1           ViSP .pos: the pose in the camera (cMo)
    mcit db export-poses 'poses/{name}.pos'               one .pos per object
    mcit db feed --socket /tmp/mcit-feed.sock             publish every change as JSON lines until stopped
    mcit db feed --file feed.jsonl

Formats and the feed's schema: docs/exchange.md (work in app.db.export and app.feed). The parsers
are added to ``mcit db`` by ``app.db_cli``.
"""

from __future__ import annotations

import argparse
import signal
import threading

__all__ = ["add_pose_parsers"]


def _open(args):
    from app.db import Database
    from app.site_folder import database_of

    kwargs = {"client": "cli", "readonly": True}  # both commands only read: they work on a read-only file or mount
    if getattr(args, "wait_s", None) is not None:
        kwargs["busy_timeout_s"] = args.wait_s
    return Database.open(database_of(args.db, getattr(args, "site", None)), **kwargs)


def _cmd_export_poses(args) -> int:
    from app.db.export import export_poses

    with _open(args) as db:
        files = export_poses(db, args.out, fmt=args.format, names=args.object, frame=args.frame)
    shown = ", ".join(map(str, files[:3])) + (f" and {len(files) - 3} more" if len(files) > 3 else "")
    print(f"wrote {shown}")
    return 0


def _cmd_feed(args) -> int:
    """Publish the database's changes until SIGTERM/SIGINT (another process writes them: the
    interface, ``mcit db`` commands)."""
    from app.db.export import iso
    from app.feed import FeedPublisher, change_event, object_event

    if not args.interval_s > 0:
        from app.exit_status import UsageError

        raise UsageError(f"--interval-s must be positive, got {args.interval_s}")
    stop = threading.Event()
    with _open(args) as db:
        last = db.last_change_id()
        feed = FeedPublisher(
            file=args.file, socket_path=args.socket, snapshot=lambda: [object_event(r) for r in db.objects()]
        )
        try:
            where = " and ".join(f"{k} {v}" for k, v in (("socket", args.socket), ("file", args.file)) if v)
            import time

            print(
                f"mcit db feed: publishing the changes of {db.path} on {where} from change #{last} "
                f"({iso(time.time())}); Ctrl-C stops",
                flush=True,
            )
            for sig in (signal.SIGTERM, signal.SIGINT):
                signal.signal(sig, lambda *_: stop.set())
            while not stop.wait(args.interval_s):
                for rec in db.history_since(last):
                    feed.publish(change_event(rec))
                    last = int(rec.id)
        finally:
            feed.close()
    return 0


def add_pose_parsers(sub, common: argparse.ArgumentParser, run) -> None:
    """Add ``export-poses`` and ``feed`` to ``mcit db``'s sub-parsers (``run`` wraps a command's errors)."""
    p = sub.add_parser(
        "export-poses",
        parents=[common],
        help="write the objects' poses (4×4, xyz + quaternion, σ, version) as JSON, CSV or ViSP .pos",
        description="Write the objects' poses for another program: JSON, CSV, or ViSP .pos (the pose "
        "in the camera, cMo). Schema: docs/exchange.md.",
    )
    p.add_argument(
        "out",
        help="output file: .json, .csv or .pos; with several objects to .pos, put {name} in the "
        "path (one file per object)",
    )
    p.add_argument("--object", nargs="+", metavar="NAME", help="only these objects (name or id; default: all)")
    p.add_argument("--format", choices=("json", "csv", "pos"), help="the format (default: from the suffix)")
    p.add_argument(
        "--frame",
        choices=("world", "camera"),
        help="poses in the world frame (default for JSON and CSV) or the camera's (default for .pos; "
        "from the latest camera calibration)",
    )
    p.set_defaults(func=run(_cmd_export_poses))

    p = sub.add_parser(
        "feed",
        parents=[common],
        help="publish every pose change as JSON lines on a local socket or file until stopped",
        description="Publish every accepted change of an object (who, version, pose as 4×4 and "
        "xyz + quaternion, σ) as JSON lines, for a robot controller: on a Unix socket (each reader "
        "first gets every object as it stands) and/or appended to a file. Schema: docs/exchange.md. "
        "mcit serve --feed-socket also sends designated targets.",
    )
    p.add_argument("--socket", metavar="PATH", help="Unix socket to listen on (readers connect to it)")
    p.add_argument("--file", metavar="PATH", help="JSON-lines file to append to")
    p.add_argument("--interval-s", type=float, default=0.2, help="how often the database is read (default 0.2 s)")
    p.set_defaults(func=run(_feed_checked))


def _feed_checked(args) -> int:
    from app.exit_status import UsageError

    if not (args.socket or args.file):
        raise UsageError("give --socket PATH and/or --file PATH: where the feed is published")
    return _cmd_feed(args)
