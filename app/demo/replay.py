"""Replay a recorded operator script through the interface's own workflow layer.

Each action of the script goes to ``app.workflows.Session.run_action`` — the call the browser's
buttons make — on a ``Site`` holding a real SQLite database (seeded from the scene's known
objects) and the devices opened by ``app.devices.open_devices`` (the in-process emulators,
speaking the real serial protocols). The scene clock is set to each action's video time ``t``
before it runs, so the emulated range finder sees the moving bodies where the video shows them.

The replay records what the interface would show after every action (``OverlayState``: the
database's objects, the camera calibration, the workflow's marks, the beam spot) for the overlay
video, and every workflow run with its workflow object (candidates, refined pose, modelling
result, measurements) for the report. Any step that fails — a workflow error, a device fault
the drivers could not recover, a solve that fails, a run that ends without being accepted —
raises ``DemoStepError`` naming the action.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.operator.script import OperatorScript
from app.scene import Scene
from core.camera import Camera

__all__ = ["DEVICE_TIMING", "DemoStepError", "OverlayState", "RunRecord", "Replay", "replay_script"]

# Emulator timing (app.devices.EmulatedSite options, turret speed in steps/s).
# "realistic": the emulators' defaults (the DLS's 19200 baud line, 0.1 s + 5 ms/m a measurement,
# 0.3 s before a no-target error; the PTU's 9600 baud line) and the scene's turret speed.
# "fast": lines without delay, instant measurements and a turret that moves (almost) at once; the
# range finder's driver is told its line is that fast too (baudrate 0), so after each reply it
# listens 2 ms for a stray second one instead of a 19200-baud reply's time (10 ms a shot).
DEVICE_TIMING: dict[str, dict[str, Any]] = {
    "realistic": {"site_options": {}, "turret_speed_steps_s": None},
    "fast": {
        "site_options": dict(
            rangefinder_baud=0, turret_baud=0, measure_delay_s=0.0, delay_per_m_s=0.0, no_target_delay_s=0.0
        ),
        "rangefinder_options": dict(baudrate=0),
        "turret_speed_steps_s": 1e6,
    },
}


class DemoStepError(RuntimeError):
    """A step of the replay failed: ``index`` (into the script's actions), ``action`` (its step
    dict, truth left out) and the workflow's message."""

    def __init__(self, index: int, action: dict[str, Any], message: str):
        self.index = index
        self.action = action
        args = {k: v for k, v in action.items() if k not in ("t", "workflow", "action")}
        where = (
            f"actions[{index}] at t = {action.get('t', float('nan')):.2f} s: "
            f"{action.get('workflow')}.{action.get('action')}"
        )
        super().__init__(f"{where}{' ' + str(args) if args else ''}: {message}")


@dataclass(frozen=True)
class OverlayState:
    """What the interface shows from video time ``t_s`` on (until the next state).

    objects : tuple of SiteObject (the database). camera : the current calibration.
    marks : the workflow's Marks, or None when no workflow is under way. beam_X_world : (3,)
    the range finder's last measured point, or None. title, text : the workflow and its
    ``next_step`` / last message.
    """

    t_s: float
    objects: tuple
    camera: Camera
    marks: Any
    beam_X_world: np.ndarray | None
    title: str
    text: str


@dataclass
class RunRecord:
    """One workflow run of the script (``start`` to ``accept``/``cancel``) as it was replayed.

    workflow : the workflow object after its last action (its candidates, refined pose, modelling
    result, clicks and measurements stay readable). camera, T_world_turret (4, 4) : the site's
    calibrations when the run ended. actions : indices into the script. wall_s : seconds taken.
    script_actions : the run's ``app.operator.script.Action`` s (with their truth, for the report).
    calibration_covs : (camera_cov (12, 12) or None, turret_cov (6, 6) or None) of those calibrations.
    """

    name: str
    object_name: str | None
    t_start: float
    t_end: float
    workflow: Any
    camera: Camera
    T_world_turret: np.ndarray
    actions: tuple[int, ...]
    wall_s: float
    script_actions: tuple = ()
    calibration_covs: tuple = (None, None)

    @property
    def accepted(self) -> bool:
        return bool(self.workflow is not None and self.workflow.accepted)


@dataclass
class Replay:
    """The replayed session: its runs, the overlay timeline, the site (its database still open:
    close ``site.db`` when done; the devices are closed), the wall time in seconds and the
    device timing used."""

    runs: list[RunRecord]
    timeline: list[OverlayState]
    site: Any
    wall_s: float
    timing: str

    def runs_of(self, workflow: str) -> list[RunRecord]:
        return [r for r in self.runs if r.name == workflow]


def _state(site, session, t_s: float) -> OverlayState:
    wf = session.workflow
    if wf is None:
        marks, title, text = None, "", ""
    else:
        marks = None if wf.finished else wf.marks()
        title = wf.title + (f": {wf.object_name}" if getattr(wf, "object_name", None) else "")
        text = wf.message if wf.finished else wf.next_step
    beam = site.beam_X_world
    return OverlayState(
        float(t_s), site.objects(), site.camera, marks, None if beam is None else beam.copy(), title, text
    )


def replay_script(
    scene: Scene,
    script: OperatorScript,
    db_path: str | Path,
    *,
    timing: str = "realistic",
    client: str = "demo",
    progress: Callable[[int, int, str], None] | None = None,
) -> Replay:
    """Replay ``script`` on ``scene`` through Session.run_action with emulated devices and a new
    SQLite database at ``db_path`` (which must not hold a site yet).

    timing : "realistic" or "fast" (``DEVICE_TIMING``). progress : called as
    ``progress(done, total, what)`` after each action. Raises DemoStepError at the first failing
    step (the database keeps what was accepted before it) and ValueError when the script was
    recorded on another scene.
    """
    from app.db import Database, seed_from_scene
    from app.devices import open_devices
    from app.workflows import Session, Site, WorkflowError

    if script.scene != scene.name:
        raise ValueError(
            f"the script was recorded on scene {script.scene!r}, not on {scene.name!r}: give the matching --scene"
        )
    if timing not in DEVICE_TIMING:
        raise ValueError(f"timing must be one of {sorted(DEVICE_TIMING)}, got {timing!r}")
    opts = DEVICE_TIMING[timing]
    device_scene = scene
    if opts["turret_speed_steps_s"] is not None:
        device_scene = dataclasses.replace(
            scene, turret=dataclasses.replace(scene.turret, speed_steps_s=opts["turret_speed_steps_s"])
        )
    db = Database.open(db_path, client=client)
    seed_from_scene(db, scene)
    clock = {"t": 0.0}
    devices = open_devices(
        device_scene,
        clock=lambda: clock["t"],
        site_options=opts["site_options"],
        rangefinder_options=opts.get("rangefinder_options"),
    )
    site = Site(scene, db, devices=devices, clock=lambda: clock["t"])
    session = Session(site, client=client)
    timeline = [_state(site, session, 0.0)]
    runs: list[RunRecord] = []
    steps = script.steps()
    run_bounds = []
    i = 0
    for run in script.runs():
        run_bounds.append((run, tuple(range(i, i + len(run.actions)))))
        i += len(run.actions)
    t0 = time.perf_counter()
    try:
        for run, indices in run_bounds:
            t_run = time.perf_counter()
            for k in indices:
                step = steps[k]
                clock["t"] = float(step["t"])
                try:
                    session.run_action(step)
                except WorkflowError as exc:
                    raise DemoStepError(k, step, str(exc)) from exc
                except Exception as exc:  # a device fault or a bug the workflow did not turn into an operator message
                    raise DemoStepError(k, step, f"{type(exc).__name__}: {exc}") from exc
                timeline.append(_state(site, session, step["t"]))
                if progress is not None:
                    progress(k + 1, len(steps), f"{step['workflow']}.{step['action']}")
            wf = session.workflow
            last = steps[indices[-1]]
            if wf is None or not wf.finished or (wf.cancelled and last["action"] != "cancel"):
                state = "still open" if wf is not None and not wf.finished else "cancelled"
                raise DemoStepError(
                    indices[-1],
                    last,
                    f"the {run.workflow} run ended {state}: a run must end with accept "
                    f"(or an explicit cancel); last message: {getattr(wf, 'message', '')!r}",
                )
            runs.append(
                RunRecord(
                    run.workflow,
                    run.object_name,
                    run.t_start,
                    run.t_end,
                    wf,
                    site.camera,
                    site.T_world_turret,
                    indices,
                    time.perf_counter() - t_run,
                    run.actions,
                    site.calibration_covs,
                )
            )
    except BaseException:
        db.close()
        raise
    finally:
        devices.close()
    return Replay(runs, timeline, site, time.perf_counter() - t0, timing)
