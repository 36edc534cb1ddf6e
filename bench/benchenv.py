"""What every benchmark does to the machine before timing, and says about it.

Benchmarks run as scripts (``python bench/<name>.py``), so this module is imported from the
script's own folder: ``from benchenv import pin_one_core``.
"""

from __future__ import annotations

import os


def pin_one_core() -> str:
    """Pin this process to its first allowed CPU (the targets are "on one core"); says what it did."""
    if hasattr(os, "sched_setaffinity"):
        cpu = sorted(os.sched_getaffinity(0))[0]
        os.sched_setaffinity(0, {cpu})
        return f"pinned to CPU {cpu}"
    return "not pinned (no sched_setaffinity)"
