"""Devices: the laser range finder (Dimetix DLS) and its pan/tilt turret (FLIR PTU-D46).

Three concerns, three places:

* ``drivers``: ``drivers.rangefinder.RangeFinder``, ``drivers.turret.Turret`` over
  ``serial.serial_for_url`` (``drivers.transport``), and their exceptions (``drivers.errors``);
* ``emulators``: the same bytes spoken from a scene's geometry (``emulators.rangefinder``,
  ``emulators.turret``, on the line model ``emulators.line``, behind ``emulators.ports``);
* ``faults``: what a real line and device do wrong, injected into the emulators' replies.

Built on them: acquisition (``acquisition``: scans), the emulated site and the factory the
interface uses (``site``: ``open_devices(scene, rangefinder_url=None, turret_url=None, clock=None)``)
and ``mcit emulate`` (``cli``). See docs/devices.md. Names below load lazily, so that
``mcit --help`` stays fast.
"""

from __future__ import annotations

import importlib

_EXPORTS = {
    "open_devices": "site",
    "Devices": "site",
    "EmulatedSite": "site",
    "scene_clock": "site",
    "video_duration_s": "site",
    "RangeFinder": "drivers.rangefinder",
    "RangeMeasurement": "drivers.rangefinder",
    "Turret": "drivers.turret",
    "SerialLine": "drivers.transport",
    "LineDriver": "drivers.transport",
    "RangeFinderEmulator": "emulators.rangefinder",
    "TurretEmulator": "emulators.turret",
    "MountState": "emulators.turret",
    "InProcessPort": "emulators.ports",
    "PtyPort": "emulators.ports",
    "Fault": "faults",
    "FaultInjector": "faults",
    "FAULT_KINDS": "faults",
    "face_patch_scan": "acquisition",
    "profile_scan": "acquisition",
    "measure_at_pixel": "acquisition",
    "AcquisitionCancelled": "acquisition",
}
_ERRORS = (
    "DeviceError DeviceTimeout ProtocolError NoisyLineError DeviceDisconnected MotionUnconfirmedError RangeFinderError "
    "CommandSyntaxError NotTrackingError TrackingActiveError NoTargetError SignalTooStrongError "
    "AmbiguousMeasurementError TooMuchLightError TurretError TurretLimitError"
).split()
_EXPORTS.update({name: "drivers.errors" for name in _ERRORS})

__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(f"{__name__}.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
