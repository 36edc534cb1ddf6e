"""The ``mcit`` command line: one entry point, one sub-command per job.

Every failure is one line on stderr, ``mcit COMMAND: error: what happened; what to do``, and every
warning one line, ``mcit COMMAND: warning: what``: never a traceback, nor Python's warning form with
mcit's own source file and line. ``mcit --version`` prints the installed version.

Exit status, one scheme for every command (``app/exit_status.py``; README "Exit status"):

    0    done
    1    the command could not do its job: a file, device, database or value it was given is wrong or
         unavailable, or the machine refused (a full disk, no port to listen on); the line says which and what to do
    2    the command line is wrong: an unknown option, a bad value, options that do not go together
    3    mcit track: the object was lost (the line says at which frame and how to restart)
    70   a bug in mcit (the line says so; set MCIT_TRACEBACK=1 to see the traceback)
    130  stopped by Ctrl-C
    141  the reader of the output left (``mcit db history | head``)
"""

from __future__ import annotations

import argparse
import os
import sys
import traceback
import warnings

from app import exit_status
from app.exit_status import UsageError
from app.oserrors import os_error_advice
from app.terminal import visible


class _Parser(argparse.ArgumentParser):
    """argparse, with its refusals in one line (sub-command parsers inherit the class)."""

    def error(self, message: str):
        self.exit(exit_status.USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


class _Version(argparse.Action):
    """``--version``: the installed distribution's version, looked up only when asked (importlib.metadata
    costs ~30 ms, which every other command would pay)."""

    def __init__(self, option_strings, dest, **kwargs):
        super().__init__(option_strings, dest, nargs=0, help="print mcit's version and exit")

    def __call__(self, parser, namespace, values, option_string=None):
        from importlib.metadata import PackageNotFoundError, version

        try:
            text = version("mcit")
        except PackageNotFoundError:
            text = "(not installed: run from its source folder)"
        print(f"mcit {text}")  # on stdout, as argparse's own version action
        parser.exit(0)


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
        prog="mcit",
        description="Keep a remote site's 3D model true to its live video.",
        epilog="exit status: 0 done, 1 the command could not do its job (the line on stderr says why), "
        "2 a wrong command line, 3 mcit track lost the object, 70 a bug in mcit, 130 Ctrl-C",
    )
    parser.add_argument("--version", action=_Version)
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
    if isinstance(exc, UsageError):
        return _one_line(str(exc)), exit_status.USAGE
    if isinstance(exc, OSError) and exc.strerror:
        where = f"{exc.filename}: " if exc.filename else ""
        return _one_line(f"{where}{exc.strerror}; {os_error_advice(exc)}"), exit_status.FAILED
    from app.db import NotFoundError  # here: the commands that never open a database start without it

    if isinstance(exc, NotFoundError):  # a name the database does not hold: where the names are
        return _one_line(f"{exc}; mcit db list names the objects"), exit_status.FAILED
    if isinstance(exc, (ValueError, OSError)) or type(exc).__module__.split(".")[0] == "app":
        return _one_line(str(exc) or type(exc).__name__), exit_status.FAILED  # mcit's own errors say what to do
    if isinstance(exc, MemoryError):
        return "ran out of memory; close other programs or give smaller input", exit_status.FAILED
    return _one_line(
        f"internal error ({type(exc).__name__}: {exc}); this is a bug in mcit: please report it with the "
        "command you ran (MCIT_TRACEBACK=1 shows where it happened)"
    ), exit_status.BUG


def _ours(category: type) -> bool:
    """A warning class of mcit's own (its message is written for the operator)."""
    return str(getattr(category, "__module__", "")).split(".")[0] in ("app", "core")


def warn_in_one_line(prefix: str) -> None:
    """Show every warning as one line on stderr, ``{prefix}: warning: what`` (a warning of another library
    named by its category); each distinct one once, as Python does. Call inside ``warnings.catch_warnings()``."""

    def show(message, category, filename, lineno, file=None, line=None) -> None:
        text = _one_line(str(message))
        if not _ours(category):
            text = f"{category.__name__}: {text}"
        print(f"{prefix}: warning: {visible(text)}", file=sys.stderr if file is None else file, flush=True)

    warnings.showwarning = show


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args, extra = parser.parse_known_args(argv)
    if extra:  # said by the command's own name, as its other refusals are (argparse names the top parser)
        words = (getattr(args, "command", None), getattr(args, f"{getattr(args, 'command', None)}_command", None))
        prog = " ".join(["mcit", *(w for w in words if w)])
        print(f"{prog}: error: unrecognized arguments: {' '.join(extra)} (see {prog} --help)", file=sys.stderr)
        return 2
    if args.command is None:
        parser.print_help()
        return exit_status.USAGE
    # OpenCV and FFmpeg print their own lines when a video cannot be opened ("moov atom not found",
    # "can't open camera by index"); mcit's one line says it instead (app.video.why_not_opened).
    # Set these variables to see them.
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")  # AV_LOG_QUIET
    command = " ".join(c for c in (args.command, getattr(args, f"{args.command}_command", None)) if c)
    with warnings.catch_warnings():
        warn_in_one_line(f"mcit {command}")
        return _run(args, command)


def _run(args: argparse.Namespace, command: str) -> int:
    try:
        return int(args.func(args) or 0)
    except KeyboardInterrupt:
        print(f"mcit {command}: stopped (Ctrl-C)", file=sys.stderr)
        return exit_status.INTERRUPTED
    except BrokenPipeError:  # the reader of the output left (``mcit db history | head``): nothing to say
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # so that Python's exit flush is quiet
        return exit_status.PIPE_CLOSED
    except Exception as exc:  # noqa: BLE001 - the one place a command's failure becomes its line
        if os.environ.get("MCIT_TRACEBACK"):
            traceback.print_exc()
        line, status = explain(exc)
        if status == exit_status.USAGE:
            line += f" (see mcit {command} --help)"
        print(f"mcit {command}: error: {visible(line)}", file=sys.stderr)  # names from a database may hold escapes
        return status


if __name__ == "__main__":
    sys.exit(main())
