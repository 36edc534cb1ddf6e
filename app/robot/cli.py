"""``mcit robot``: the robot's files. ``mcit robot urdf [--out FILE]`` writes the bundled arm's URDF.

Only argparse here; the arm's description loads when the command runs.
"""

from __future__ import annotations

import sys
from pathlib import Path

__all__ = ["add_robot_parser", "cli_robot_urdf"]


def add_robot_parser(subparsers) -> None:
    """Register ``mcit robot`` and its sub-commands on the CLI's sub-parsers."""
    robot = subparsers.add_parser(
        "robot", help="the robot: write the bundled arm's URDF", description="The site's robot and its files."
    )
    sub = robot.add_subparsers(dest="robot_command", metavar="ROBOT_COMMAND", required=True)
    p = sub.add_parser(
        "urdf",
        help="write the bundled arm's URDF (scenes/workcell/arm.urdf is this text)",
        description="Write the workcell's 6-axis arm with its two-finger gripper as URDF (links of boxes and "
        "cylinders; a UR5's kinematics).",
    )
    p.add_argument("--out", metavar="FILE", default=None, help="write to FILE (default: standard output)")
    p.set_defaults(func=cli_robot_urdf)


def cli_robot_urdf(args) -> int:
    from app.robot.arm import arm_urdf

    text = arm_urdf()
    if args.out is None:
        sys.stdout.write(text)
        return 0
    Path(args.out).write_text(text, encoding="utf-8")
    print(f"wrote {args.out}", file=sys.stderr)
    return 0
