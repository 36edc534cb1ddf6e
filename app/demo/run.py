"""``run_demo``: the whole headless demo — replay, overlay video, database, simulations, report."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from app.operator.script import OperatorScript, load_script
from app.scene import Scene, load_scene

from .replay import Replay, replay_script
from .results import DemoResults, demo_results

__all__ = ["DemoOutcome", "run_demo", "DB_NAME", "VIDEO_NAME", "REPORT_NAME"]

DB_NAME, VIDEO_NAME, REPORT_NAME = "site.sqlite", "overlay.mp4", "report.md"
BOX_DISTANCES_M = (1.3, 1.4, 1.5, 1.6)  # Table III.1's
CYLINDER_DISTANCES_M = (1.0, 1.2, 1.4, 1.6)  # Table III.2's


@dataclass
class DemoOutcome:
    """What ``run_demo`` wrote and measured: out_dir, the report, the database, the video (None
    without), the replay, the results and the wall time of each phase (seconds)."""

    out_dir: Path
    report: Path
    db: Path
    video: Path | None
    replay: Replay
    results: DemoResults
    wall_s: dict


def _bar(stream: TextIO | None, label: str):
    """A progress callback ``show(done, total)`` on stream (app.progress: a bar while it is a terminal),
    or None when stream is None."""
    if stream is None:
        return None
    from app.progress import progress_bar

    return progress_bar(label, stream=stream)


def _stills(script: OperatorScript, fps: float) -> list[tuple[str, str, float]]:
    """Overlay frames for the report: (file name, caption, video time) — the first modelling
    solve and the first pose refinement of the script, when it has them."""
    from .overlay_video import still_frame

    wanted = {
        ("model_object", "solve"): ("overlay_model.png", "{name} modelled (the preview before Accept)"),
        ("update_pose", "refine"): ("overlay_pose.png", "{name}'s pose refined (before Accept)"),
    }
    out: dict[str, tuple[str, str, float]] = {}
    for run in script.runs():
        for a in run.actions:
            name, caption = wanted.get((run.workflow, a.action), (None, ""))
            if name is not None and name not in out:
                t_frame = still_frame(a.t, fps) / fps
                out[name] = (
                    name,
                    f"The overlay video at t = {t_frame:.2f} s: " + caption.format(name=run.object_name),
                    a.t,
                )
    return list(out.values())


def _clear_db(path: Path) -> None:
    for suffix in ("", "-wal", "-shm"):
        p = path.with_name(path.name + suffix)
        if p.exists():
            p.unlink()


def run_demo(
    scene: Scene | str | Path,
    script: OperatorScript | str | Path | None = None,
    out_dir: str | Path = "mcit-demo-out",
    *,
    timing: str = "realistic",
    video: bool = True,
    frames: int | None = None,
    sim_trials: int = 100,
    pose_trials: int | None = None,
    seed: int = 0,
    stream: TextIO | None = sys.stderr,
) -> DemoOutcome:
    """Replay the scene's operator script and write the demo's outputs in ``out_dir``.

    scene : a Scene or its folder. script : an OperatorScript or its file (default: the scene's
    ``operator.json``). out_dir : created if needed; its ``site.sqlite`` is replaced. timing :
    "realistic" or "fast" emulated devices (``app.demo.replay.DEVICE_TIMING``). video : write
    ``overlay.mp4`` (``frames``: only the first N). sim_trials : simulated trials per distance
    for Tables III.1/III.2 (0: no simulation); pose_trials : simulated pose problems (default
    5 × sim_trials). seed : the simulations' seed. stream : where progress goes (None: quiet).

    Raises DemoStepError (app.demo.replay) naming the failing step; ValueError for a scene or
    script that cannot be used.
    """
    wall: dict[str, float] = {}
    t_all = time.perf_counter()
    scene = scene if isinstance(scene, Scene) else load_scene(scene)
    if script is None:
        script = scene.root / "operator.json"
    script = script if isinstance(script, OperatorScript) else load_script(script)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    db_path = out / DB_NAME
    _clear_db(db_path)

    def say(text: str) -> None:
        if stream is not None:
            stream.write(f"mcit demo: {text}\n")
            stream.flush()

    n_pose = pose_trials if pose_trials is not None else 5 * sim_trials
    beside = None
    if sim_trials > 0:  # the sweeps need only the scene and the script: a second process runs them meanwhile
        t_sim = time.perf_counter()
        # What both processes use is loaded once, before the fork (the solvers' modules, numba and the
        # compiled pose kernels: ~0.6 s that the second process would otherwise load again).
        from core.pose import warm_up

        from . import report, simulation  # noqa: F401

        warm_up()
        beside = _SimulationBeside.start(scene, script, sim_trials, n_pose, seed)
        if beside is not None:
            say(_simulating(sim_trials, n_pose, seed) + " in a second process, beside the replay")
    try:
        return _run(
            scene,
            script,
            out,
            db_path,
            timing,
            video,
            frames,
            sim_trials,
            n_pose,
            seed,
            stream,
            say,
            wall,
            t_all,
            beside,
            t_sim if beside is not None else 0.0,
        )
    finally:
        if beside is not None:
            beside.cancel()


def _run(
    scene,
    script,
    out,
    db_path,
    timing,
    video,
    frames,
    sim_trials,
    n_pose,
    seed,
    stream,
    say,
    wall,
    t_all,
    beside,
    t_sim,
) -> DemoOutcome:
    from .report import write_report

    say(f"replaying {len(script.actions)} actions of {script.scene!r} through the workflows ({timing} device timing)")
    bar = _bar(stream, "actions")
    t0 = time.perf_counter()
    replay = replay_script(
        scene, script, db_path, timing=timing, progress=(lambda d, n, _w: bar(d, n)) if bar else None
    )
    wall["replay"] = time.perf_counter() - t0
    drawing = None
    try:
        stills = _stills(script, scene.video.fps) if scene.video is not None else []
        video_path = None
        if video:
            if scene.video is None or not scene.video.path.is_file():
                raise ValueError(
                    f"scene {scene.name!r} has no video file to draw over; run with --no-video or render it"
                )
            video_path = out / VIDEO_NAME
            from .overlay_video import write_overlay_video

            def draw(progress) -> float:
                t0 = time.perf_counter()
                write_overlay_video(
                    scene.video.path,
                    replay.timeline,
                    video_path,
                    fps=scene.video.fps,
                    frames=frames,
                    stills={name: t for name, _, t in stills},
                    progress=progress,
                    lens=scene.lens,
                )
                return time.perf_counter() - t0

            # the video needs only the replay's timeline: a second process draws it beside the analysis
            drawing = _Beside.fork(draw, scene.video.frame_count if frames is None else frames, "mcit-demo-video")
            say(f"drawing the overlay over {scene.video.path.name}" + (" in a second process" if drawing else ""))
            if drawing is None:
                wall["overlay video"] = draw(_bar(stream, "frames"))
        t0 = time.perf_counter()
        results = demo_results(replay, scene)
        wall["analysis"] = time.perf_counter() - t0
        if drawing is not None:
            wall["overlay video (a second process)"] = drawing.result(_bar(stream, "frames"))
        sims = None
        if beside is not None:
            sims = beside.result(_bar(stream, "trials"))
            wall["simulation (a second process, from the start)"] = time.perf_counter() - t_sim
        elif sim_trials > 0:
            t0 = time.perf_counter()
            say(_simulating(sim_trials, n_pose, seed))
            sims = _simulate(scene, script, sim_trials, n_pose, seed, _bar(stream, "trials"))
            wall["simulation"] = time.perf_counter() - t0
        wall["total"] = time.perf_counter() - t_all
        shown = [(name, caption) for name, caption, _ in stills if (out / name).is_file() and video_path is not None]
        report = write_report(out, scene, script, replay, results, sims, wall, shown)
        say(f"wrote {report}, {db_path}" + (f", {video_path}" if video_path else ""))
        return DemoOutcome(out, report, db_path, video_path, replay, results, wall)
    finally:
        if drawing is not None:
            drawing.cancel()
        replay.site.db.close()


def _simulating(trials: int, pose_trials: int, seed: int) -> str:
    return f"simulating the paper's sweeps: {trials} trials per distance, {pose_trials} pose problems (seed {seed})"


def _sim_total(trials: int, pose_trials: int) -> int:
    return trials * (len(BOX_DISTANCES_M) + len(CYLINDER_DISTANCES_M)) + pose_trials


class _Beside:
    """A job in a forked process, so that it runs on the second core while this one goes on: its
    result sent back pickled, its progress ``(done, total)`` counted in shared memory, an exception
    in it raised again here."""

    def __init__(self, process, conn, count):
        self._process, self._conn, self._count = process, conn, count

    @classmethod
    def fork(cls, job: Callable[[Callable[[int, int], None]], object], total: int, name: str):
        """Start ``job(progress)``; None where processes cannot be forked (then run it in this one)."""
        import gc
        import multiprocessing as mp

        if "fork" not in mp.get_all_start_methods():
            return None
        ctx = mp.get_context("fork")
        count = ctx.Array("q", [0, max(int(total), 1)], lock=False)
        recv, send = ctx.Pipe(duplex=False)

        def child() -> None:
            def progress(n: int, of: int) -> None:
                count[1] = max(int(of), 1)
                count[0] = int(n)

            try:
                out = ("ok", job(progress))
            except BaseException as exc:  # noqa: BLE001 - raised again in the parent
                import traceback

                out = ("error", (exc, traceback.format_exc()))
            try:
                send.send(out)
            except Exception as exc:  # an exception that does not pickle
                send.send(("error", (RuntimeError(str(exc)), "")))
            send.close()

        process = ctx.Process(target=child, name=name, daemon=True)
        # Garbage collected here, not in the child: garbage holding a resource of another of this process's
        # threads (a video reader's, a library's pool), collected in the child where those threads are gone,
        # can wait for them for ever (the simulation test's child hung in a numpy call without this).
        gc.collect()
        process.start()
        send.close()
        return cls(process, recv, count)

    def cancel(self) -> None:
        """Stop the job if it still runs (the demo failed, or its result was taken)."""
        if self._process.is_alive():
            self._process.terminate()
        self._process.join(timeout=5)
        if not self._conn.closed:
            self._conn.close()

    def result(self, progress: Callable[[int, int], None] | None = None):
        """Wait for the job (showing its progress) and return its result; raises what it raised."""
        try:
            while not self._conn.poll(0.1):
                if progress:
                    progress(min(self._count[0], self._count[1] - 1), self._count[1])
                if not self._process.is_alive() and not self._conn.poll(0):
                    raise RuntimeError(
                        f"the {self._process.name} process ended without a result (exit code {self._process.exitcode})"
                    )
            status, value = self._conn.recv()
        finally:
            self._conn.close()
            self._process.join(timeout=5)
        if status == "error":
            exc, tb = value
            raise exc from RuntimeError("in the second process:\n" + tb) if tb else exc
        if progress:
            progress(self._count[1], self._count[1])
        return value


class _SimulationBeside(_Beside):
    """The simulated sweeps (``_simulate``, the same seeded sweeps) in a second process."""

    @classmethod
    def start(cls, scene: Scene, script: OperatorScript, trials: int, pose_trials: int, seed: int):
        return cls.fork(
            lambda progress: _simulate(scene, script, trials, pose_trials, seed, progress),
            _sim_total(trials, pose_trials),
            "mcit-demo-simulation",
        )


def _simulate(
    scene: Scene,
    script: OperatorScript,
    trials: int,
    pose_trials: int,
    seed: int,
    progress: Callable[[int, int], None] | None = None,
):
    """The simulated sweeps (Simulations) with the script's click noise, for the scene's unknown
    box and cylinder and the paper's pose problems. progress : ``progress(done, total)`` per trial."""
    from .report import Simulations
    from .simulation import box_sweep, cylinder_sweep, pose_sweep, sim_setup

    sigma = float(script.generator.get("click_sigma_px", 1.0))
    setup = sim_setup(scene, sigma)
    rng = np.random.default_rng(seed)
    total = _sim_total(trials, pose_trials)
    bar = progress
    done = [0]

    def tick() -> None:
        done[0] += 1
        if bar:
            bar(done[0], total)

    box = cylinder = None
    for body in scene.unknown:
        dims = body.model.bounds()[1] - body.model.bounds()[0]
        if body.kind == "box" and box is None:
            box = box_sweep(setup, dims, BOX_DISTANCES_M, trials, rng, tick)
        elif body.kind == "cylinder" and cylinder is None and body.model.solids:
            s = body.model.solids[0]
            cylinder = cylinder_sweep(setup, s.r0, s.height, CYLINDER_DISTANCES_M, trials, rng, tick)
    pose = pose_sweep(pose_trials, sigma, rng, tick) if pose_trials > 0 else None
    if bar and done[0] < total:
        bar(total, total)
    return Simulations(setup, seed, box, cylinder, pose)
