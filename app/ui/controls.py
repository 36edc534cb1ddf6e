"""What the panel shows besides the workflow's own controls: the buttons that start a workflow,
how a workflow's results read (Markdown, numbers rounded to what they mean), and the Help.

Each workflow declares its own controls and steps (``app.workflows.base.Control`` / ``Step``);
the panel (app/ui/client.py) renders them.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from app.markup import Md

__all__ = ["START_BUTTONS", "report_markdown", "operator_help", "HELP_PATH", "format_value", "key_label"]

# The operator's quick reference, shown in the panel's Help folder (static/: files the UI shows).
HELP_PATH = Path(__file__).resolve().parents[2] / "static" / "help.md"

# Buttons that start a workflow: (label, workflow name).
START_BUTTONS: tuple[tuple[str, str], ...] = (
    ("Calibrate camera", "calibrate_camera"),
    ("Calibrate turret", "calibrate_turret"),
    ("Update pose", "update_pose"),
    ("Model object", "model_object"),
    ("Designate target", "designate"),
    ("Move robot", "move_robot"),
    ("Pick and place", "pick_place"),
    ("Calibrate robot", "calibrate_robot"),
    ("Calibrate camera from robot", "calibrate_camera_robot"),
    ("Track", "track"),
    ("History", "history"),
)

# Units a result key ends with → (shown unit, decimals): 0.01 px (an RMS of a few hundredths read "0"
# beside the message's "0.03 px"), 0.1 mm, 0.01°. Lengths kept in metres are shown in mm, as every other
# length in the panel (a new operator met "Range (m) 1.8688" beside "To surface (mm) 3.2").
_UNITS = (
    ("_px", "px", 2),
    ("_mm", "mm", 1),
    ("_cm", "cm", 2),
    ("_deg", "°", 2),
    ("_m", "mm", 1),
    ("_s", "s", 2),
    ("_pct", "%", 0),
)
_SCALE = {"_m": 1000.0}  # a key's value → the shown unit
_WORDS = {"rms": "RMS", "std": "σ", "sd": "σ", "sigma": "σ", "uv": "pixel", "x_world": "X (world)", "xyz": "x y z"}


def key_label(key: str) -> str:
    """A result key as the operator reads it: "rms_px" → "RMS (px)", "std_t_mm" → "σ t (mm)"."""
    unit = ""
    for suffix, shown, _ in _UNITS:
        if key.endswith(suffix) and len(key) > len(suffix):
            key, unit = key[: -len(suffix)], shown
            break
    words = [_WORDS.get(w.lower(), w) for w in key.replace("-", "_").split("_") if w]
    if words[:1] == ["σ"] and words[1:] in (["t"], ["rot"], ["r"]):  # a pose's σ: "σ translation", "σ rotation"
        words = ["σ", {"t": "translation", "rot": "rotation", "r": "rotation"}[words[1]]]
    text = " ".join(words)
    bare = [w for w in text.split(" ") if not (w.startswith("(") and w.endswith(")"))]  # "x y z (m)": its unit aside
    coordinates = bool(bare) and all(len(w) == 1 for w in bare)  # "x y z", "t" stay lower case
    if text[:1].isascii() and not coordinates:  # "σ" stays σ: its capital Σ reads as a sum
        text = text[:1].upper() + text[1:]
    return f"{text} ({unit})" if unit else text


def format_value(key: str, v: Any) -> str:
    """A number rounded to what it means (by the key's unit); other values as text."""
    if isinstance(v, (bool, np.bool_)):
        return "yes" if v else "no"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        x = float(v)
        if not math.isfinite(x):
            return "—"
        suffix = next((u for u, _, _ in _UNITS if key.endswith(u) and len(key) > len(u)), "")
        x *= _SCALE.get(suffix, 1.0)
        decimals = next((d for u, _, d in _UNITS if u == suffix), None)
        if decimals is None:
            decimals = 2 if abs(x) < 100 else 0
        text = f"{x:.{decimals}f}"
        return "0" if float(text) == 0 else text
    return str(v)


_UNIT_KEYS = {"deg", "cm", "m", "mm", "px"}


def _items(key: str, value: Any, indent: str) -> list[str]:
    """One result entry as Markdown list lines: a number or a list on one line, a {unit: value}
    dict as "49.04°, 224.8 mm", any other dict as a nested list of its own entries."""
    if isinstance(value, (list, tuple, np.ndarray)):
        arr = np.asarray(value, dtype=object).ravel()
        if not len(arr):
            return []
        shown = ", ".join(format_value(key, x) for x in arr[:12]) + (" …" if len(arr) > 12 else "")
        return [Md("{}- **{}**: {}").format(Md(indent), key_label(key), shown)]
    if isinstance(value, dict):
        if value and set(value) <= _UNIT_KEYS:
            shown = ", ".join(_with_unit(k, v) for k, v in value.items())
            return [Md("{}- **{}**: {}").format(Md(indent), key_label(key), shown)]
        out = [Md("{}- **{}**").format(Md(indent), key_label(key))]
        for k, v in value.items():
            out += _items(str(k), v, indent + "  ")
        return out
    return [Md("{}- **{}**: {}").format(Md(indent), key_label(key), format_value(key, value))]


_HEADLINE_WORDS = {"rms", "std", "sd", "sigma"}  # a result's σ and residuals: what says how good it is


def result_headline(summary: dict[str, Any]) -> Md:
    """A result's σ and residuals on one line, for under the action buttons (the Result section below can be
    under the fold at 1280×720): the summary's top-level numbers and lists whose key starts with rms, std, sd
    or sigma, e.g. "**Result**: RMS (px) 0.41 · σ translation (mm) 0.5, 0.8, 1.2". Empty when it has none."""
    parts = []
    for key, value in summary.items():
        if key.split("_")[0].lower() not in _HEADLINE_WORDS or isinstance(value, dict):
            continue
        values = np.asarray(value, dtype=object).ravel() if isinstance(value, (list, tuple, np.ndarray)) else [value]
        if len(values) and not isinstance(values[0], dict):
            parts.append(Md("{}: {}").format(key_label(key), ", ".join(format_value(key, v) for v in values[:6])))
    if not parts:
        return Md("")
    return Md("**Result**: ") + Md(" · ").join(parts[:4]) + Md(" _(the Result section below has the rest)_")


def _with_unit(unit: str, v: Any) -> str:
    """One entry of a {unit: value} result ({"deg": 49.04, "cm": 22.48}) as the messages say it:
    "49.04°", "224.8 mm" (lengths in mm, as everywhere else in the panel)."""
    if isinstance(v, (float, np.floating, int, np.integer)) and not isinstance(v, (bool, np.bool_)):
        if unit == "deg":
            return f"{float(v):.2f}°"
        if unit in ("cm", "m", "mm"):
            return f"{float(v) * {'cm': 10.0, 'm': 1000.0, 'mm': 1.0}[unit]:.1f} mm"
    return f"{format_value(unit, v)} {unit}"


def operator_help() -> str:
    """The Help folder's Markdown (static/help.md); a clear note if the file is missing."""
    try:
        return HELP_PATH.read_text(encoding="utf-8")
    except OSError as exc:
        return f"*Help not found ({HELP_PATH}: {exc.strerror}); see docs/interface.md.*"


def report_markdown(summary: dict[str, Any]) -> Md:
    """A workflow's ``summary()`` as Markdown: scalars as a list, per-item lists as a table, every
    key in words and every number rounded to what it means; keys and values are escaped (they may
    hold names, methods and notes from the database)."""
    if not summary:
        return Md("")
    lines = []
    tables = {k: v for k, v in summary.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
    for key, value in summary.items():
        if key in tables:
            continue
        lines += _items(key, value, "")
    for key, rows in tables.items():
        cols = list(rows[0].keys())
        lines.append(Md("\n**{}**\n").format(key_label(key)))
        lines.append(Md("| ") + Md(" | ").join(key_label(c) for c in cols) + Md(" |"))
        lines.append(Md("|" + "---|" * len(cols)))
        for row in rows[:30]:
            cells = []
            for c in cols:
                v = row.get(c, "")
                if isinstance(v, (list, tuple, np.ndarray)):
                    cells.append(" ".join(format_value(c, x) for x in np.asarray(v, dtype=object).ravel()))
                else:
                    cells.append(format_value(c, v))
            lines.append(Md("| ") + Md(" | ").join(cells) + Md(" |"))
        if len(rows) > 30:
            lines.append(Md("\n… and {} more").format(len(rows) - 30))
    return Md("\n").join(lines)
