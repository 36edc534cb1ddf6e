"""The ``mcit`` command line: one entry point, one sub-command per job."""

from __future__ import annotations

import argparse
import sys


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="mcit", description="Keep a remote site's 3D model true to its live video.")
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
    from app.demo.cli import add_demo_parser  # argparse only: the replay, solvers and report load when the command runs

    add_demo_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
    return int(args.func(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
