"""The headless demo (``mcit demo``): the recorded operator session replayed through the
interface's workflows, the emulated devices and a real database, with the paper's tables beside
ours.

* ``replay`` — ``replay_script``: every action through ``Session.run_action``; the overlay
  timeline and the workflow runs; ``DemoStepError`` names a failing step;
* ``results`` — the run's numbers against the scene's truth (Tables III.1, III.2, V.1);
* ``simulation`` — the simulated sweeps one run cannot give (distances, statistics);
* ``overlay_video`` — the recorded frames with the interface's overlay;
* ``report`` — report.md and its figures; ``run`` — ``run_demo``, all of it; ``cli`` — the command.

See docs/demo.md. Names load lazily so that ``mcit --help`` stays fast.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "run_demo": "run",
    "DemoOutcome": "run",
    "replay_script": "replay",
    "Replay": "replay",
    "DemoStepError": "replay",
    "demo_results": "results",
    "DemoResults": "results",
    "write_overlay_video": "overlay_video",
    "write_report": "report",
    "summary_table": "report",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
