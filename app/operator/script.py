"""The recorded operator script: timed clicks and actions, as the interface produces them.

A script (``"format": "mcit-operator-script/1"``, docs/operator-script.md) is a list of actions::

    {"t": 3.2, "workflow": "calibrate_camera", "action": "click", "uv": [231.4, 88.9],
     "truth": {...}}

* ``t`` — the video time (seconds from the start of the scene's video) at which the operator acts;
  non-decreasing. The demo shows the frame at ``t`` and runs the emulated devices at that time.
* ``workflow`` — which guided workflow the action belongs to; ``action`` — the workflow's method
  (app/workflows); the other keys are that method's keyword arguments (pixels ``uv``, a model
  ``edge`` or vertex ``index``, ``object_name`` ...), exactly what a browser click or button
  produces. ``start`` begins a workflow with its options.
* ``truth`` — optional ground truth for tests and the report (the true pixel before click noise,
  the 3D point or model edge meant). The replay must not use it: ``OperatorScript.steps()``
  leaves it out.

``load_script`` validates every action against ``WORKFLOWS`` (the action names and their
arguments) and raises ``ScriptError`` (a ``ValueError``) naming the action index and the field.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = [
    "FORMAT",
    "WORKFLOWS",
    "ScriptError",
    "Action",
    "Run",
    "OperatorScript",
    "load_script",
    "save_script",
    "script_from_dict",
]

FORMAT = "mcit-operator-script/1"

# Argument kinds: "uv" a pixel [u, v]; "seg" two pixels [[u1, v1], [u2, v2]]; "xyz" a point
# [x, y, z] (m); "int"; "float"; "bool"; "str"; "dict". The names and arguments are those of the
# workflow layer's actions (app/workflows: Workflow.perform), so that a replay is a call per action.
_END = {"remove_last": ({}, {}), "solve": ({}, {}), "accept": ({}, {}), "cancel": ({}, {})}
WORKFLOWS: dict[str, dict[str, tuple[dict[str, str], dict[str, str]]]] = {
    # action: (required arguments, optional arguments)
    "calibrate_camera": {
        "start": ({}, {}),
        "choose_vertex": ({"name": "str", "index": "int"}, {}),
        "choose_point": ({"X_world": "xyz"}, {"label": "str"}),
        "click": ({"uv": "uv"}, {}),
        "redo": ({}, {}),
        **_END,
    },
    "calibrate_turret": {
        "start": ({}, {"shots": "int"}),
        "click": ({"uv": "uv"}, {}),
        "choose_point": ({"X_world": "xyz"}, {"label": "str"}),
        "measure": ({}, {}),
        **_END,
    },
    "model_object": {
        "start": ({"object_name": "str", "shape": "str"}, {"vertical": "bool", "on_table": "bool", "method": "str"}),
        "click": ({"uv": "uv"}, {}),
        "add_segment": ({"seg_uv": "seg"}, {}),
        "measure": ({}, {}),
        "next_face": ({}, {}),
        "scan": ({}, {}),
        **_END,
        "solve": ({}, {"method": "str"}),
    },
    "update_pose": {
        "start": ({"object_name": "str"}, {}),
        "click": ({"uv": "uv"}, {}),
        "assign_edge": ({"edge": "int"}, {}),
        "add_segment": ({"seg_uv": "seg", "edge": "int"}, {}),
        "start_point": ({}, {}),
        "add_point": ({"uv": "uv", "vertex": "int"}, {}),
        "choose_candidate": ({"index": "int"}, {}),
        "refine": ({}, {}),
        **_END,
    },
}


class ScriptError(ValueError):
    """A malformed operator script; the message names the action and the field."""


@dataclass(frozen=True)
class Action:
    """One recorded operator action.

    t : video time, seconds. workflow, action : names (see ``WORKFLOWS``). args : the action's
    keyword arguments (JSON values). truth : ground truth for tests/reports, or None.
    """

    t: float
    workflow: str
    action: str
    args: dict = field(default_factory=dict)
    truth: dict | None = None

    def step(self) -> dict[str, Any]:
        """What the replay passes to the workflow layer: {"t", "workflow", "action", **args} (no truth)."""
        return {"t": self.t, "workflow": self.workflow, "action": self.action, **self.args}

    def to_dict(self) -> dict[str, Any]:
        d = self.step()
        if self.truth is not None:
            d["truth"] = self.truth
        return d


@dataclass(frozen=True)
class Run:
    """One workflow from its ``start`` to its ``accept`` (or ``cancel``): workflow name and actions."""

    workflow: str
    actions: tuple[Action, ...]

    @property
    def object_name(self) -> str | None:
        """The object the run is about (``object_name`` of update_pose and model_object)."""
        return self.actions[0].args.get("object_name") if self.actions else None

    @property
    def t_start(self) -> float:
        return self.actions[0].t

    @property
    def t_end(self) -> float:
        return self.actions[-1].t


@dataclass(frozen=True)
class OperatorScript:
    """A validated script. scene : the scene's name. actions : in time order."""

    scene: str
    actions: tuple[Action, ...]
    description: str = ""
    generator: dict = field(default_factory=dict)

    def steps(self) -> list[dict[str, Any]]:
        """Every action as the replay passes it on (``Action.step``), truth left out."""
        return [a.step() for a in self.actions]

    def runs(self) -> tuple[Run, ...]:
        """The script cut into workflow runs (each begins with a ``start``)."""
        runs, cur = [], []
        for a in self.actions:
            if a.action == "start" and cur:
                runs.append(Run(cur[0].workflow, tuple(cur)))
                cur = []
            cur.append(a)
        if cur:
            runs.append(Run(cur[0].workflow, tuple(cur)))
        return tuple(runs)

    def with_runs(self, runs: Iterable[Run]) -> OperatorScript:
        """A shorter script made of some of this script's runs (e.g. for a quick demo test)."""
        actions = tuple(a for r in runs for a in r.actions)
        return OperatorScript(self.scene, actions, self.description, dict(self.generator, shortened=True))

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": FORMAT,
            "scene": self.scene,
            "description": self.description,
            "generator": self.generator,
            "actions": [a.to_dict() for a in self.actions],
        }


# ---------------------------------------------------------------------- validation
def _check_arg(value: Any, kind: str, where: str) -> Any:
    if kind == "seg":
        if not isinstance(value, (list, tuple)) or len(value) != 2:
            raise ScriptError(f"{where}: two pixels [[u1, v1], [u2, v2]] expected, got {value!r}")
        return [_check_arg(p, "uv", f"{where}[{i}]") for i, p in enumerate(value)]
    if kind == "bool":
        if not isinstance(value, bool):
            raise ScriptError(f"{where}: true or false expected, got {value!r}")
        return value
    if kind in ("uv", "xyz"):
        n = 2 if kind == "uv" else 3
        if not isinstance(value, (list, tuple)) or len(value) != n:
            raise ScriptError(f"{where}: a list of {n} numbers expected, got {value!r}")
        out = []
        for v in value:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v):
                raise ScriptError(f"{where}: finite numbers expected, got {value!r}")
            out.append(float(v))
        return out
    if kind == "int":
        if isinstance(value, bool) or not isinstance(value, int):
            raise ScriptError(f"{where}: an integer expected, got {value!r}")
        return int(value)
    if kind == "float":
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise ScriptError(f"{where}: a finite number expected, got {value!r}")
        return float(value)
    if kind == "str":
        if not isinstance(value, str) or not value:
            raise ScriptError(f"{where}: a non-empty string expected, got {value!r}")
        return value
    if kind == "dict":
        if not isinstance(value, dict):
            raise ScriptError(f"{where}: an object expected, got {value!r}")
        return value
    raise AssertionError(kind)


def _action(d: Any, i: int, last_t: float) -> Action:
    where = f"actions[{i}]"
    if not isinstance(d, dict):
        raise ScriptError(f"{where}: an object {{t, workflow, action, ...}} expected, got {type(d).__name__}")
    for key in ("t", "workflow", "action"):
        if key not in d:
            raise ScriptError(f"{where}: missing field '{key}'")
    t = d["t"]
    if isinstance(t, bool) or not isinstance(t, (int, float)) or not np.isfinite(t) or t < 0:
        raise ScriptError(f"{where}.t: a video time ≥ 0 in seconds expected, got {t!r}")
    if t < last_t:
        raise ScriptError(f"{where}.t: times must not decrease, got {t} after {last_t}")
    wf, act = d["workflow"], d["action"]
    if wf not in WORKFLOWS:
        raise ScriptError(f"{where}.workflow: unknown workflow {wf!r}; use one of {list(WORKFLOWS)}")
    if act not in WORKFLOWS[wf]:
        raise ScriptError(f"{where}.action: {wf} has no action {act!r}; it has {list(WORKFLOWS[wf])}")
    required, optional = WORKFLOWS[wf][act]
    args = {}
    for key, value in d.items():
        if key in ("t", "workflow", "action", "truth"):
            continue
        kind = required.get(key) or optional.get(key)
        if kind is None:
            raise ScriptError(
                f"{where} ({wf}.{act}): unknown argument '{key}'; allowed: {sorted(required) + sorted(optional)}"
            )
        args[key] = _check_arg(value, kind, f"{where}.{key}")
    for key in required:
        if key not in args:
            raise ScriptError(f"{where} ({wf}.{act}): missing argument '{key}'")
    truth = d.get("truth")
    if truth is not None and not isinstance(truth, dict):
        raise ScriptError(f"{where}.truth: an object expected, got {type(truth).__name__}")
    return Action(float(t), wf, act, args, truth)


def script_from_dict(d: Any) -> OperatorScript:
    """Validate a parsed script; ScriptError naming the action index and field on bad input."""
    if not isinstance(d, dict):
        raise ScriptError(f"a script is a JSON object, got {type(d).__name__}")
    if d.get("format") != FORMAT:
        raise ScriptError(f"'format' must be {FORMAT!r}, got {d.get('format')!r}")
    unknown = sorted(set(d) - {"format", "scene", "description", "generator", "actions"})
    if unknown:
        raise ScriptError(f"unknown top-level field(s) {unknown}")
    scene = d.get("scene")
    if not isinstance(scene, str) or not scene:
        raise ScriptError(f"'scene' must name the scene the script was recorded on, got {scene!r}")
    raw = d.get("actions")
    if not isinstance(raw, list) or not raw:
        raise ScriptError("'actions' must be a non-empty list")
    actions, last_t = [], 0.0
    for i, a in enumerate(raw):
        act = _action(a, i, last_t)
        last_t = act.t
        actions.append(act)
    first = actions[0]
    if first.action != "start":
        raise ScriptError(f"actions[0]: a script begins with a workflow's 'start', got {first.workflow}.{first.action}")
    for i, (prev, cur) in enumerate(zip(actions, actions[1:]), start=1):
        if cur.action != "start" and cur.workflow != prev.workflow:
            raise ScriptError(
                f"actions[{i}]: {cur.workflow}.{cur.action} follows a {prev.workflow} action without a 'start'"
            )
    return OperatorScript(scene, tuple(actions), str(d.get("description", "")), dict(d.get("generator") or {}))


def load_script(path: str | Path) -> OperatorScript:
    """Read and validate an operator script file."""
    path = Path(path)
    if not path.is_file():
        raise ScriptError(f"{path}: no such operator script")
    try:
        d = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ScriptError(f"{path}: not valid JSON: {exc}") from None
    try:
        return script_from_dict(d)
    except ScriptError as exc:
        raise ScriptError(f"{path}: {exc}") from None


def save_script(script: OperatorScript, path: str | Path) -> None:
    """Write a script as JSON, one action per line (diff-friendly), validated on the way out."""
    d = script.to_dict()
    script_from_dict(json.loads(json.dumps(d)))
    head = {k: v for k, v in d.items() if k != "actions"}
    lines = ["{"]
    for k, v in head.items():
        lines.append(f" {json.dumps(k)}: {json.dumps(v)},")
    lines.append(' "actions": [')
    acts = [json.dumps(a, separators=(", ", ": ")) for a in d["actions"]]
    lines += [f"  {a}," for a in acts[:-1]] + [f"  {acts[-1]}"]
    lines += [" ]", "}"]
    Path(path).write_text("\n".join(lines) + "\n")
