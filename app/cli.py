"""The ``mcit`` command line: one entry point, one sub-command per job.

Every failure is one line on stderr, ``mcit COMMAND: error: what happened; what to do``, and a
non-zero exit status: 2 for a command line argparse refuses, 1 for what the operator can fix (mcit's
own errors, ``ValueError``, ``OSError``), 70 for a bug in mcit (the line says so; set
``MCIT_TRACEBACK=1`` to see the traceback), 130 after Ctrl-C. A command may return its own status
(``mcit track``: 3 when the object is lost).
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback

from app.oserrors import os_error_advice


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals in one line (sub-command parsers inherit the class)."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="mcit", description="Keep a remote site's 3D model true to its live video.")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    from app.db_cli import add_db_parser  # argparse only: the database modules load when a db command runs

    add_db_parser(sub)
    from app.devices.cli import add_emulate_parser  # argparse only: the emulators load when the command runs

    add_emulate_parser(sub)
    from app.ui.serve import add_serve_parser  # argparse only: viser loads when the command runs

    add_serve_parser(sub)
    from app.scene_cli import add_scene_parsers  # argparse only: the renderer loads when the command runs

    add_scene_parsers(sub)
    from app.vision.track_cli import add_track_parser  # argparse only: the tracker loads when the command runs

    add_track_parser(sub)
    from app.vision.intrinsics_cli import add_calibrate_intrinsics_parser  # argparse only: OpenCV loads when it runs

    add_calibrate_intrinsics_parser(sub)
    from app.demo.cli import add_demo_parser  # argparse only: the replay, solvers and report load when the command runs

    add_demo_parser(sub)
    from app.robot.cli import add_robot_parser  # argparse only: the arm's description loads when the command runs

    add_robot_parser(sub)
    from app.site_cli import add_site_parser  # argparse only: the site's modules load when the command runs

    add_site_parser(sub)
    return parser


def _one_line(text: str, limit: int = 1000) -> str:
    text = " ".join(part.strip() for part in str(text).splitlines() if part.strip())
    return text if len(text) <= limit else text[: limit - 1] + "…"


def explain(exc: BaseException) -> tuple[str, int]:
    """(one line saying what happened and what to do, exit status) for an error that ended a command."""
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename}: " if exc.filename else ""
        return _one_line(f"{where}{exc.strerror}; {os_error_advice(exc)}"), 1
    if isinstance(exc, (ValueError, OSError)) or type(exc).__module__.split(".")[0] == "app":
        return _one_line(str(exc) or type(exc).__name__), 1  # mcit's own errors say what to do
    if isinstance(exc, MemoryError):
        return "ran out of memory; close other programs or give smaller input", 1
    return _one_line(
        f"internal error ({type(exc).__name__}: {exc}); this is a bug in mcit: please report it with the "
        "command you ran (MCIT_TRACEBACK=1 shows where it happened)"
    ), 70


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    # OpenCV and FFmpeg print their own lines when a video cannot be opened ("moov atom not found",
    # "can't open camera by index"); mcit's one line says it instead (app.video.why_not_opened).
    # Set these variables to see them.
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"mcit {args.command}: stopped (Ctrl-C)", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader of the output left (``mcit db history | head``): nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so that Python's exit flush is quiet
        return 141
    except Exception as exc:  # noqa: BLE001 - the one place a command's failure becomes its line
        if os.environ.get("MCIT_TRACEBACK"):
            traceback.print_exc()
        line, status = explain(exc)
        command = " ".join(c for c in (args.command, getattr(args, f"{args.command}_command", None)) if c)
        print(f"mcit {command}: error: {line}", file=sys.stderr)
        return status


if __name__ == "__main__":
    sys.exit(main())
