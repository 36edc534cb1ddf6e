"""Devices: the laser range finder (Dimetix DLS) and its pan/tilt turret (FLIR PTU-D46).

Drivers over ``serial.serial_for_url`` (``rangefinder.RangeFinder``, ``turret.Turret``), emulators
speaking the same bytes from a scene's geometry (``emulator_rangefinder``, ``emulator_turret``,
``site.EmulatedSite``), fault injection (``faults``), acquisition (``acquisition``) and the
factory the interface uses, ``open_devices(scene, rangefinder_url=None, turret_url=None, clock=None)``.
See docs/devices.md. Names below load lazily, so that ``mcit --help`` stays fast.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "open_devices": "site",
    "Devices": "site",
    "EmulatedSite": "site",
    "scene_clock": "site",
    "RangeFinder": "rangefinder",
    "RangeMeasurement": "rangefinder",
    "Turret": "turret",
    "Fault": "faults",
    "FaultInjector": "faults",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
