"""``mcit render`` and ``mcit script``: make a scene's prerecorded video and its operator script.

Only argparse here; the renderer and the generator load when a command runs (``mcit --help``
stays fast).
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["add_scene_parsers", "cli_render", "cli_script"]


def add_scene_parsers(subparsers) -> None:
    """Register ``mcit render`` and ``mcit script`` on the CLI's sub-parsers."""
    p = subparsers.add_parser(
        "render",
        help="render a scene's prerecorded video (deterministic)",
        description="Render the scene's video with mcit's renderer (shaded bodies seen through C, sensor noise). "
        "Same scene, same bytes.",
    )
    p.add_argument("--scene", default=None, help="scene folder (default: the bundled workcell)")
    p.add_argument(
        "--camera",
        default=None,
        metavar="NAME",
        help="render this camera's video (default: every camera of the scene that has a video block)",
    )
    p.add_argument("--out", default=None, help="output file (default: the camera's video.file)")
    p.add_argument("--frames", type=int, default=None, help="render only the first N frames")
    p.add_argument("--frame", type=float, default=None, metavar="T_S", help="write one PNG frame at time T_S instead")
    p.add_argument("--quiet", action="store_true", help="no progress bar (there is none when stderr is not a terminal)")
    p.set_defaults(func=cli_render)

    q = subparsers.add_parser(
        "script",
        help="generate a scene's recorded operator script from its truth",
        description="Write the operator script (timed clicks and actions with human-like click noise) that the "
        "headless demo replays: calibrate the camera and the turret, model the unknown objects, update the "
        "known objects' poses after each motion.",
    )
    q.add_argument("--scene", default=None, help="scene folder (default: the bundled workcell)")
    q.add_argument("--out", default=None, help="output file (default: <scene>/operator.json)")
    q.add_argument("--seed", type=int, default=None, help="click-noise seed (default: the script generator's)")
    q.add_argument(
        "--click-sigma", type=float, default=None, metavar="PX", help="click noise σ in pixels (default 1.0)"
    )
    q.set_defaults(func=cli_script)


def cli_render(args) -> int:
    """``mcit render``: render the video (or one frame with ``--frame``)."""
    from app.exit_status import UsageError
    from app.progress import progress_bar
    from app.render.renderer import Renderer
    from app.render.video import render_video
    from app.scene import default_scene_path, load_scene

    scene = load_scene(args.scene or default_scene_path())
    view = scene.view(args.camera)  # SceneError naming the cameras for an unknown one
    if args.frame is not None:
        import cv2

        out = Path(args.out or f"{scene.name}_{view.name}_t{args.frame:g}.png")
        k = view.video.frame_index(args.frame) if view.video else 0
        cv2.imwrite(str(out), Renderer(scene, camera=view.camera, lens=view.lens).render(args.frame, k))
        print(f"wrote {out}")
        return 0
    names = [args.camera] if args.camera else [v.name for v in scene.views if v.video is not None] or [view.name]
    if args.out and len(names) > 1:
        raise UsageError(f"--out writes one video and the scene has {len(names)}: add --camera NAME")
    for name in names:
        with progress_bar(f"{name} frames", quiet=args.quiet) as progress:
            info = render_video(scene, args.out, frames=args.frames, progress=progress, view=name)
        size_mb = info.path.stat().st_size / 1e6
        print(
            f"wrote {info.path} ({name}): {info.frame_count} frames, {info.width}×{info.height}, {info.fps:g} fps, "
            f"{size_mb:.2f} MB"
        )
    return 0


def cli_script(args) -> int:
    """``mcit script``: generate the operator script of a scene."""
    from app.operator.generate import ScriptOptions, generate_script
    from app.operator.script import save_script
    from app.scene import default_scene_path, load_scene

    scene = load_scene(args.scene or default_scene_path())
    options = ScriptOptions()
    if args.seed is not None:
        options = options.replace(seed=args.seed)
    if args.click_sigma is not None:
        options = options.replace(click_sigma_px=args.click_sigma)
    script = generate_script(scene, options)
    out = Path(args.out) if args.out else scene.root / "operator.json"
    save_script(script, out)
    print(f"wrote {out}: {len(script.actions)} actions over {script.actions[-1].t:.1f} s of video")
    return 0
