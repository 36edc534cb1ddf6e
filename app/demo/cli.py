"""``mcit demo``: the headless demo from the command line.

Only argparse here; the workflows, devices and solvers load when the command runs (``mcit
--help`` stays fast). Exit status (app/exit_status.py): 0 when every step succeeded and the outputs are
written; 1 when a step of the replay failed (named on stderr) or the scene or script cannot be used; 2
for options out of range.
"""

from __future__ import annotations

import sys
import traceback

from app.exit_status import UsageError

__all__ = ["add_demo_parser", "cli_demo"]


def add_demo_parser(subparsers) -> None:
    """Register ``mcit demo`` on the CLI's sub-parsers."""
    p = subparsers.add_parser(
        "demo",
        help="replay the recorded operator session headless and write the paper-vs-ours report",
        description="Replay a scene's recorded operator script through the interface's workflows, the emulated "
        "range finder and turret (serial protocols) and a new SQLite database; write the overlay video, the "
        "database and a report (Markdown + PNG) with the source paper's Tables III.1, III.2, V.1 and Figures "
        "III.6, V.1, V.2 beside ours. Exits non-zero if any step fails.",
    )
    p.add_argument("--scene", default=None, help="scene folder (default: the bundled workcell)")
    p.add_argument("--script", default=None, help="operator script (default: <scene>/operator.json)")
    p.add_argument(
        "--out", default="mcit-demo-out", help="output folder (default: ./mcit-demo-out; its site.sqlite is replaced)"
    )
    p.add_argument(
        "--fast",
        action="store_true",
        help="instant emulated devices (no line or measurement delay) and 20 simulated trials, for a quick look",
    )
    p.add_argument("--no-video", action="store_true", help="do not write the overlay video")
    p.add_argument(
        "--frames", type=int, default=None, metavar="N", help="write only the first N frames of the overlay video"
    )
    p.add_argument(
        "--sim-trials",
        type=int,
        default=None,
        metavar="N",
        help="simulated trials per distance for Tables III.1/III.2, and 5N pose problems (default 100, "
        "20 with --fast; 0: no simulation)",
    )
    p.add_argument("--seed", type=int, default=0, help="the simulations' seed (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    p.set_defaults(func=cli_demo)


def cli_demo(args) -> int:
    """Run the demo; print the outputs and the main table; return the exit status."""
    from app.demo.replay import DemoStepError
    from app.demo.run import run_demo
    from app.scene import default_scene_path

    trials = args.sim_trials if args.sim_trials is not None else (20 if args.fast else 100)
    if trials < 0 or (args.frames is not None and args.frames < 1):
        raise UsageError("--sim-trials must be ≥ 0 and --frames ≥ 1")
    from app.operator.script import load_script
    from app.scene import load_scene

    # a scene or script that cannot be used (SceneError, ScriptError): app.cli says it, status 1
    scene = load_scene(args.scene or default_scene_path())
    script = load_script(args.script or scene.root / "operator.json")
    if script.scene != scene.name:
        raise ValueError(f"the script {args.script} was recorded on scene {script.scene!r}, not on {scene.name!r}")
    if not args.no_video and (scene.video is None or not scene.video.path.is_file()):
        raise ValueError(
            f"scene {scene.name!r} has no video file to draw over: render it (mcit render) or use --no-video"
        )
    try:
        outcome = run_demo(
            scene,
            script,
            args.out,
            timing="fast" if args.fast else "realistic",
            video=not args.no_video,
            frames=args.frames,
            sim_trials=trials,
            seed=args.seed,
            stream=None if args.quiet else sys.stderr,
        )
    except DemoStepError as exc:
        print(f"mcit demo: error: FAILED at {exc}", file=sys.stderr)
        cause = exc.__cause__
        from app.workflows import WorkflowError

        if cause is not None and not isinstance(cause, WorkflowError):
            traceback.print_exception(cause, file=sys.stderr)
        return 1
    from app.demo.report import summary_table

    print(summary_table(outcome.results))
    print(
        f"report: {outcome.report}\ndatabase: {outcome.db}"
        + (f"\noverlay video: {outcome.video}" if outcome.video else "")
    )
    print("wall time: " + ", ".join(f"{k} {v:.1f} s" for k, v in outcome.wall_s.items()))
    return 0
