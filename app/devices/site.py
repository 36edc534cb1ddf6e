"""A scene's range finder and turret, emulated together, and the factory the interface opens devices with.

* ``EmulatedSite(scene)``: a turret emulator and a range-finder emulator sharing one
  ``MountState`` (the range finder rides on the turret), answering from the scene's true
  geometry; serve them in process (``mcit://…``) or on pseudo-terminals with stable links.
* ``open_devices(scene, rangefinder_url=None, turret_url=None, clock=None)``: connected drivers
  (``Devices.rangefinder``, ``Devices.turret``); with no URLs it starts an ``EmulatedSite`` in
  process first. ``mcit serve`` uses this.
* ``scene_clock(scene)``: seconds since start, looping with the scene's video when its length is
  known — the time at which the emulated range finder sees moving bodies.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from app.render.raycast import BeamCaster
from app.scene import Scene

from .drivers.rangefinder import RangeFinder
from .drivers.turret import Turret
from .emulators.rangefinder import RangeFinderEmulator
from .emulators.turret import MountState, TurretEmulator
from .faults import FaultInjector

__all__ = ["EmulatedSite", "Devices", "open_devices", "scene_clock", "video_duration_s"]

log = logging.getLogger("mcit.devices")


def video_duration_s(path) -> float | None:
    """Length of a video file in seconds (OpenCV), or None when it cannot be read."""
    if path is None:
        return None
    import cv2

    cap = cv2.VideoCapture(str(path))
    try:
        if not cap.isOpened():
            return None
        frames = cap.get(cv2.CAP_PROP_FRAME_COUNT)
        fps = cap.get(cv2.CAP_PROP_FPS)
    finally:
        cap.release()
    if not (frames > 0 and fps > 0):
        return None
    return float(frames / fps)


def scene_clock(scene: Scene | None = None, *, loop_s: float | None = None) -> Callable[[], float]:
    """A clock for the emulators: seconds since now, modulo loop_s (default: the scene's video length)."""
    if loop_s is None and scene is not None and scene.video_path is not None:
        loop_s = video_duration_s(scene.video_path)
    start = time.monotonic()
    if loop_s is not None and loop_s > 0:
        return lambda: (time.monotonic() - start) % loop_s
    return lambda: time.monotonic() - start


def _check_turret(scene: Scene) -> None:
    """ValueError for a camera-only scene (no turret block): it has no devices to emulate or drive."""
    if scene.turret is None:
        raise ValueError(
            f"scene {scene.name!r} is camera-only (no 'turret' block), so it has no range finder and turret; give "
            "the scene a turret block (docs/scene-format.md) to use them"
        )


class EmulatedSite:
    """The scene's turret and range finder, emulated and mounted together.

    scene : the loaded Scene (turret spec and pose, range-finder spec, true bodies).
    clock : scene time for moving bodies (default: 0, a static world; ``scene_clock(scene)`` for
    a live one). seed : seeds the range noise and the random faults.
    rangefinder_baud, turret_baud : modelled line rates (0: infinitely fast lines).
    measure_delay_s, delay_per_m_s, no_target_delay_s : range-finder timing (see its emulator).
    fault_rates : {kind: probability per reply} for both emulators (see app.devices.faults).
    bodies : what the range finder sees (app.render.raycast.BeamCaster's bodies), default the scene's (a site
    with a robot passes its emulated world's: the robot's links, and bodies where the robot left them).
    """

    def __init__(
        self,
        scene: Scene,
        *,
        clock: Callable[[], float] | None = None,
        seed: int | None = 0,
        rangefinder_baud: int = 19200,
        turret_baud: int = 9600,
        measure_delay_s: float = 0.1,
        delay_per_m_s: float = 0.005,
        no_target_delay_s: float = 0.3,
        fault_rates: dict[str, float] | None = None,
        bodies=None,
    ):
        _check_turret(scene)
        self.scene = scene
        rng = np.random.default_rng(seed)
        rng_noise, rng_rf_faults, rng_turret_faults = rng.spawn(3)
        self.mount = MountState(scene.turret.step_rad)
        self.turret = TurretEmulator(
            scene.turret, mount=self.mount, baudrate=turret_baud, faults=FaultInjector(rng_turret_faults, fault_rates)
        )
        try:
            self.rangefinder = RangeFinderEmulator(
                BeamCaster(scene if bodies is None else bodies),
                scene.rangefinder,
                scene.turret.T_world_turret,
                self.mount.angles_rad,
                clock=clock,
                baudrate=rangefinder_baud,
                measure_delay_s=measure_delay_s,
                delay_per_m_s=delay_per_m_s,
                no_target_delay_s=no_target_delay_s,
                rng=rng_noise,
                faults=FaultInjector(rng_rf_faults, fault_rates),
            )
        except BaseException:
            self.turret.close()
            raise

    def serve_inprocess(self, prefix: str | None = None) -> tuple[str, str]:
        """Serve both in process; returns (rangefinder_url, turret_url), ``mcit://…``."""
        tag = prefix or f"site-{id(self):x}"
        return self.rangefinder.serve_inprocess(f"{tag}-rangefinder"), self.turret.serve_inprocess(f"{tag}-turret")

    def serve_pty(self, rangefinder_link=None, turret_link=None) -> tuple[str, str]:
        """Serve both on pseudo-terminals (with stable symlinks when given); returns the two paths."""
        return self.rangefinder.serve_pty(rangefinder_link), self.turret.serve_pty(turret_link)

    def close(self) -> None:
        self.rangefinder.close()
        self.turret.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass
class Devices:
    """Connected drivers, the turret's pose in the world, and the emulators when they are emulated."""

    rangefinder: RangeFinder
    turret: Turret
    T_world_turret: np.ndarray
    site: EmulatedSite | None = None
    urls: tuple[str, str] = field(default=("", ""))

    @property
    def emulated(self) -> bool:
        return self.site is not None

    def close(self) -> None:
        self.rangefinder.close()
        self.turret.close()
        if self.site is not None:
            self.site.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def open_devices(
    scene: Scene,
    rangefinder_url: str | None = None,
    turret_url: str | None = None,
    clock: Callable[[], float] | None = None,
    *,
    transport: str = "inprocess",
    site_options: dict | None = None,
    rangefinder_options: dict | None = None,
    turret_options: dict | None = None,
) -> Devices:
    """Connect to the range finder and the turret, emulating both when no URL is given.

    scene : the scene (its ``turret.T_world_turret`` is the turret's pose; with emulation, its
    geometry is what the emulators see). rangefinder_url, turret_url : device paths or URLs
    (both, or neither). clock : scene time for the emulators (default ``scene_clock(scene)``).
    transport : "inprocess" (``mcit://``) or "pty" for the emulators. site_options,
    rangefinder_options, turret_options : keyword arguments of EmulatedSite, RangeFinder, Turret.
    """
    _check_turret(scene)
    if (rangefinder_url is None) != (turret_url is None):
        raise ValueError(
            "give both --rangefinder and --turret (real devices) or neither (emulated devices), "
            f"got rangefinder={rangefinder_url!r}, turret={turret_url!r}"
        )
    if transport not in ("inprocess", "pty"):
        raise ValueError(f"transport must be 'inprocess' or 'pty', got {transport!r}")
    site = None
    if rangefinder_url is None:
        site = EmulatedSite(scene, clock=clock if clock is not None else scene_clock(scene), **(site_options or {}))
        rangefinder_url, turret_url = site.serve_inprocess() if transport == "inprocess" else site.serve_pty()
        if transport == "inprocess":  # the drivers time their listening by the line's rate: the emulated line's
            rangefinder_options = {"baudrate": site.rangefinder.baudrate} | (rangefinder_options or {})
            turret_options = {"baudrate": site.turret.baudrate} | (turret_options or {})
    rf = turret = None
    try:
        rf = RangeFinder(rangefinder_url, **(rangefinder_options or {}))
        turret = Turret(turret_url, **(turret_options or {}))
    except BaseException:
        for thing in (rf, turret, site):
            if thing is not None:
                thing.close()
        raise
    log.info("devices: range finder on %s, turret on %s%s", rangefinder_url, turret_url, " (emulated)" if site else "")
    return Devices(
        rf, turret, np.asarray(scene.turret.T_world_turret, dtype=float).copy(), site, (rangefinder_url, turret_url)
    )
