"""Emulator of a Dimetix DLS laser range finder, speaking its ASCII protocol from the scene's geometry.

Protocol (shared/PROTOCOLS.md): host ``s<N><cmd>`` + CR LF, device ``g<N>…`` + CR LF, N the
device id. Supported: ``g`` (one distance, ``gNg+dddddddd`` in 0.1 mm), ``c`` (stop/clear),
``o``/``p`` (laser on/off), ``s`` (save), ``t`` (temperature, 0.1 °C), ``h`` (continuous
tracking until ``c``), ``f+t`` and ``q`` (buffered tracking every t ms), ``uof`` (user offset),
errors ``gN@Ezzz`` (203 syntax, 210 not tracking, 212 tracking active, 255 no target). At
power-up (start, replug) the device sends ``gN?``. Commands for another id are ignored.

The distance is a ray cast of the beam against the scene's true bodies (``BeamCaster``, exact) at
the scene time of the ``clock``, from where the turret points when the measurement starts
(``pointing``, e.g. ``MountState.angles_rad``), plus Gaussian noise σ_ρ from a seeded
generator, rounded to 0.1 mm. Outside [min_range_m, max_range_m] or with no hit: error 255.
A measurement takes ``measure_delay_s + delay_per_m_s × range`` (``no_target_delay_s`` before a
255); any new command cancels the measurement under way, which then never answers.
"""

from __future__ import annotations

import re
from collections import deque
from collections.abc import Callable

import numpy as np

from app.render.raycast import BeamCaster
from core.rangefinder import RangeFinderSpec, beam_ray

from ..faults import FaultInjector
from .line import LineEmulator, Timer

__all__ = ["RangeFinderEmulator", "format_distance"]

_CMD = re.compile(r"^s(\d)(.*)$", re.S)
_OFFSET = re.compile(r"^uof([+-]\d{8})$")
_BUFFERED = re.compile(r"^f\+(\d{1,8})$")


def _field(units: int) -> str:
    """A DLS number field: sign and 8 digits (ValueError when it does not fit)."""
    if abs(units) > 99_999_999:
        raise ValueError(f"{units} does not fit the 8-digit field")
    return f"{'+' if units >= 0 else '-'}{abs(units):08d}"


def format_distance(value_m: float) -> str:
    """A distance as the DLS writes it: sign and 8 digits of 0.1 mm (ValueError beyond ±9999.9999 m)."""
    return _field(int(np.round(value_m * 1e4)))


class RangeFinderEmulator(LineEmulator):
    """A DLS range finder on a serial line (see the module docstring).

    raycaster : BeamCaster (app.render.raycast) of the true scene. spec : RangeFinderSpec (σ_ρ, range limits).
    T_world_turret : array, shape (4, 4), the turret in the world (the beam leaves its origin).
    pointing : f(monotonic_time_s) -> (pan_rad, tilt_rad), where the turret points.
    clock : f() -> scene time (seconds) at which bodies are ray cast (default: 0, a static world).
    rng : seeded generator (or seed) for the range noise.
    """

    name = "rangefinder"
    terminators = b"\r\n"

    def __init__(
        self,
        raycaster: BeamCaster,
        spec: RangeFinderSpec,
        T_world_turret: np.ndarray,
        pointing: Callable[[float], tuple[float, float]],
        *,
        clock: Callable[[], float] | None = None,
        device_id: int = 0,
        baudrate: int | None = 19200,
        measure_delay_s: float = 0.1,
        delay_per_m_s: float = 0.005,
        no_target_delay_s: float = 0.3,
        temperature_c: float = 24.0,
        rng: np.random.Generator | int | None = None,
        faults: FaultInjector | None = None,
    ):
        if not 0 <= int(device_id) <= 9:
            raise ValueError(f"device_id is one digit 0-9, got {device_id}")
        if min(measure_delay_s, delay_per_m_s, no_target_delay_s) < 0:
            raise ValueError("measurement delays must be >= 0")
        self.raycaster = raycaster
        self.spec = spec
        self.T_world_turret = np.asarray(T_world_turret, dtype=float)
        self.pointing = pointing
        self.clock = clock if clock is not None else (lambda: 0.0)
        self.device_id = int(device_id)
        self.measure_delay_s = float(measure_delay_s)
        self.delay_per_m_s = float(delay_per_m_s)
        self.no_target_delay_s = float(no_target_delay_s)
        self.temperature_c = float(temperature_c)
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.laser_on = False
        self.user_offset_m = 0.0
        self._pending: Timer | None = None
        self._tracking: str | None = None
        self._buffer: str | None = None
        self._buffer_state = 0
        if faults is None:
            faults = FaultInjector()
        faults.error_line = faults.error_line or f"g{self.device_id}@E260\r\n".encode()
        faults.unsolicited_line = faults.unsolicited_line or f"g{self.device_id}?\r\n".encode()
        super().__init__(baudrate=baudrate, faults=faults)
        # the last shots, for tests and diagnostics: (pan_rad, tilt_rad, true range m, body hit)
        self.measurements: deque[tuple[float, float, float, str]] = deque(maxlen=10_000)

    # ---------------------------------------------------------------------- measuring
    def true_range(self, t: float) -> tuple[float, str | None]:
        """Distance (m) from the turret along the beam at monotonic time t to the first surface, and the body."""
        pan, tilt = self.pointing(t)
        origin, d = beam_ray(self.T_world_turret, pan, tilt)
        dist, body = self.raycaster.cast(origin, d, float(self.clock()))
        self.measurements.append((pan, tilt, dist, body or ""))
        return dist, body

    def _shot(self, t: float) -> tuple[str, float]:
        """One measurement started at t: (reply body after 'gN', its duration in seconds)."""
        dist, _ = self.true_range(t)
        if not np.isfinite(dist):
            return "@E255", self.no_target_delay_s
        measured = dist + self.spec.sigma_range_m * float(self.rng.standard_normal())
        duration = self.measure_delay_s + self.delay_per_m_s * dist
        if not self.spec.min_range_m <= measured <= self.spec.max_range_m:
            return "@E255", max(duration, self.no_target_delay_s)
        return format_distance(measured + self.user_offset_m), duration

    # ---------------------------------------------------------------------- protocol
    def on_power_up(self, t: float) -> None:
        self._stop()
        self.laser_on = False
        self.send_raw(f"g{self.device_id}?".encode() + self.eol, at=t)

    def on_power_down(self) -> None:
        self._stop()

    def _stop(self) -> None:
        if self._pending is not None:
            self._pending.cancel()
            self._pending = None
        self._tracking = None
        self._buffer = None
        self._buffer_state = 0

    def _out(self, body: str, at: float) -> None:
        self.reply(f"g{self.device_id}{body}", at)

    def handle_command(self, command: str, t: float) -> None:
        m = _CMD.match(command)
        if m is None:
            return  # not a DLS command (line noise): the device stays silent
        if int(m.group(1)) != self.device_id:
            return  # addressed to another device on the bus
        body = m.group(2)
        if self._pending is not None and self._tracking is None:  # any new command cancels a measurement
            self._pending.cancel()
            self._pending = None
        if body == "c":
            self._stop()
            return self._out("?", t)
        if self._tracking is not None and not (body == "q" and self._tracking == "f"):
            return self._out("@E212", t)
        if body == "g":
            self.laser_on = True
            text, duration = self._shot(t)
            body_text = text if text.startswith("@") else "g" + text
            self._pending = self.call_at(t + duration, self._finish, body_text)
            return
        if body in ("o", "p"):
            self.laser_on = body == "o"
            return self._out("?", t)
        if body == "s":
            return self._out("?", t)
        if body == "t":
            return self._out("t" + _field(int(np.round(self.temperature_c * 10))), t)
        if body == "h":
            self._tracking = "h"
            self.laser_on = True
            self._track(t)
            return
        m_f = _BUFFERED.match(body)
        if m_f:
            period = max(int(m_f.group(1)), 1) / 1000.0
            self._tracking = "f"
            self.laser_on = True
            self._buffer, self._buffer_state = None, 0
            self._fill(t, period)
            return self._out("f?", t)
        if body == "q":
            if self._tracking != "f":
                return self._out("@E210", t)
            if self._buffer is None:
                return self._out("@E255", t)
            if self._buffer.startswith("@"):
                state, self._buffer_state = self._buffer_state, 0
                return self._out(self._buffer, t)
            state, self._buffer_state = self._buffer_state, 0
            return self._out(f"q{self._buffer}+{state}", t)
        if body == "uof":
            return self._out("uof" + format_distance(self.user_offset_m), t)
        m_o = _OFFSET.match(body)
        if m_o:
            self.user_offset_m = int(m_o.group(1)) / 1e4
            return self._out("uof?", t)
        return self._out("@E203", t)

    def _finish(self, body_text: str) -> None:
        self._pending = None
        self._out(body_text, None)

    def _track(self, t: float) -> None:
        if self._tracking != "h":
            return
        text, duration = self._shot(t)
        self._pending = self.call_at(t + duration, self._track_reply, text, t + duration)

    def _track_reply(self, text: str, t: float) -> None:
        if self._tracking != "h":
            return
        self._out(text if text.startswith("@") else "h" + text, t)
        self._track(t)

    def _fill(self, t: float, period: float) -> None:
        if self._tracking != "f":
            return
        text, _ = self._shot(t)
        self._buffer_state = 2 if self._buffer_state == 1 else 1
        self._buffer = text
        self._pending = self.call_at(t + period, self._fill, t + period, period)
