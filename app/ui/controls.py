"""Which buttons and inputs each workflow shows, and how its results read (Markdown).

A control is (label, action, kind): ``kind`` "button" calls the workflow action at once,
"long" runs it on a worker thread with the progress bar and Cancel live. Workflow-specific
inputs (the candidate chooser, the history's change number) are built by the client panel.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["CONTROLS", "START_BUTTONS", "report_markdown", "operator_help", "HELP_PATH"]

# The operator's quick reference, shown in the panel's Help folder (static/: files the UI shows).
HELP_PATH = Path(__file__).resolve().parents[2] / "static" / "help.md"

# Buttons that start a workflow: (label, workflow name).
START_BUTTONS: tuple[tuple[str, str], ...] = (
    ("Calibrate camera", "calibrate_camera"),
    ("Calibrate turret", "calibrate_turret"),
    ("Update pose", "update_pose"),
    ("Model object", "model_object"),
    ("Designate target", "designate"),
    ("Track", "track"),
    ("History", "history"),
)

CONTROLS: dict[str, tuple[tuple[str, str, str], ...]] = {
    "calibrate_camera": (
        ("Solve", "solve", "button"),
        ("Accept", "accept", "button"),
        ("Refuse snap", "refuse_snap", "button"),
        ("Remove last", "remove_last", "button"),
        ("Redo", "redo", "button"),
        ("Cancel", "cancel", "button"),
    ),
    "designate": (
        ("Clear", "clear", "button"),
        ("Done", "accept", "button"),
    ),
    "update_pose": (
        ("Solve (P3L)", "solve", "button"),
        ("Auto match", "auto_match", "long"),
        ("Confirm match", "confirm_match", "button"),
        ("Refine", "refine", "button"),
        ("Add point", "start_point", "button"),
        ("Refuse snap", "refuse_snap", "button"),
        ("Remove last", "remove_last", "button"),
        ("Accept", "accept", "button"),
        ("Cancel", "cancel", "button"),
    ),
    "model_object": (
        ("Measure face", "measure", "long"),
        ("Scan profile", "scan", "long"),
        ("Solve", "solve", "button"),
        ("Refuse snap", "refuse_snap", "button"),
        ("Remove last", "remove_last", "button"),
        ("Accept", "accept", "button"),
        ("Cancel", "cancel", "button"),
    ),
    "track": (
        ("Pause", "pause", "button"),
        ("Resume", "resume", "button"),
        ("Re-initialise", "reinit", "long"),
        ("Restart", "restart", "button"),
        ("Remove last", "remove_last", "button"),
        ("Accept", "accept", "button"),
        ("Cancel", "cancel", "button"),
    ),
    "calibrate_turret": (
        ("Measure", "measure", "long"),
        ("Solve", "solve", "button"),
        ("Remove last", "remove_last", "button"),
        ("Accept", "accept", "button"),
        ("Cancel", "cancel", "button"),
    ),
    "history": (
        ("Refresh", "refresh", "button"),
        ("Close", "accept", "button"),
    ),
}


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def operator_help() -> str:
    """The Help folder's Markdown (static/help.md); a clear note if the file is missing."""
    try:
        return HELP_PATH.read_text(encoding="utf-8")
    except OSError as exc:
        return f"*Help not found ({HELP_PATH}: {exc.strerror}); see docs/interface.md.*"


def report_markdown(summary: dict[str, Any]) -> str:
    """A workflow's ``summary()`` as Markdown: scalars as a list, per-item lists as a table."""
    if not summary:
        return ""
    lines = []
    tables = {k: v for k, v in summary.items() if isinstance(v, list) and v and isinstance(v[0], dict)}
    for key, value in summary.items():
        if key in tables:
            continue
        if isinstance(value, (list, tuple, np.ndarray)):
            arr = np.asarray(value, dtype=object).ravel()
            shown = ", ".join(_fmt(x) for x in arr[:12]) + (" …" if len(arr) > 12 else "")
            lines.append(f"- **{key}**: {shown}")
        elif isinstance(value, dict):
            lines.append(f"- **{key}**: " + ", ".join(f"{k} {_fmt(v)}" for k, v in value.items()))
        else:
            lines.append(f"- **{key}**: {_fmt(value)}")
    for key, rows in tables.items():
        cols = list(rows[0].keys())
        lines.append(f"\n**{key}**\n")
        lines.append("| " + " | ".join(cols) + " |")
        lines.append("|" + "---|" * len(cols))
        for row in rows[:30]:
            lines.append("| " + " | ".join(_fmt(row.get(c, "")) for c in cols) + " |")
    return "\n".join(lines)
