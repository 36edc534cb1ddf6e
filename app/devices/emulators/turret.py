"""Emulator of a FLIR (Directed Perception) PTU-D46 pan/tilt unit, speaking its ASCII command set.

Protocol (shared/PROTOCOLS.md): commands are case-insensitive and end with a space or CR;
replies end with CR LF: ``*`` done, ``* <value>`` a query's answer (terse mode), ``! <message>``
a failure, ``!P`` / ``!T`` unprompted at a limit. At power-up echo is on and feedback verbose,
as on the real unit: a driver sends ``ED`` and ``FT`` first.

Supported: ``PP``/``TP`` (query or absolute move, steps), ``PO``/``TO`` (relative move),
``PS``/``TS`` (speed, steps/s), ``PN PX TN TX`` (limits), ``PR TR`` (resolution, arc-seconds a
step), ``A`` (answers when motion has ended; later commands wait), ``H``/``PH``/``TH`` (halt),
``R`` (reset and home, answers ``!T!T!P!P*``), ``ED EE FT FV``, ``V`` (version).

Motion: each axis moves at its speed (constant, no acceleration ramp) toward its target, within
its limits; a move beyond a limit is refused with ``!`` and no motion. The head's pose over time
is a ``MountState`` that the range-finder emulator reads (they are mounted together).
"""

from __future__ import annotations

import math
import re
import threading
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from app.scene import TurretSpec

from ..faults import FaultInjector
from .line import LineEmulator

__all__ = ["MountState", "TurretEmulator"]


@dataclass
class _Axis:
    start: float = 0.0
    target: float = 0.0
    speed: float = 1000.0
    t0: float = 0.0

    def at(self, t: float) -> float:
        delta = self.target - self.start
        travelled = self.speed * max(0.0, t - self.t0)
        if travelled >= abs(delta):
            return self.target
        return self.start + math.copysign(travelled, delta)

    def end(self) -> float:
        return self.t0 + abs(self.target - self.start) / self.speed


class MountState:
    """The pan/tilt head's position over time (thread-safe), in steps and in radians.

    step_rad : one step (radians) of both axes. Angles follow core/rangefinder.py: pan_rad =
    pan steps × step (positive left), tilt_rad = tilt steps × step (positive up).
    """

    def __init__(self, step_rad: float):
        if not step_rad > 0:
            raise ValueError(f"step_rad must be positive, got {step_rad}")
        self.step_rad = float(step_rad)
        self._lock = threading.Lock()
        self._axes = {"P": _Axis(), "T": _Axis()}

    def steps_at(self, t: float | None = None) -> tuple[float, float]:
        """(pan, tilt) positions in steps (fractional while moving) at monotonic time t (default now)."""
        t = time.monotonic() if t is None else t
        with self._lock:
            return self._axes["P"].at(t), self._axes["T"].at(t)

    def angles_rad(self, t: float | None = None) -> tuple[float, float]:
        """(pan_rad, tilt_rad) of the beam at monotonic time t (default now)."""
        p, q = self.steps_at(t)
        return p * self.step_rad, q * self.step_rad

    def target(self, axis: str) -> float:
        with self._lock:
            return self._axes[axis].target

    def move(self, axis: str, target: float, speed: float, t: float) -> float:
        """Start moving an axis ("P" or "T") from where it is at time t; returns when it will arrive."""
        with self._lock:
            a = self._axes[axis]
            here = a.at(t)
            self._axes[axis] = _Axis(here, float(target), float(speed), t)
            return self._axes[axis].end()

    def halt(self, axis: str, t: float) -> None:
        with self._lock:
            a = self._axes[axis]
            here = float(np.round(a.at(t)))
            self._axes[axis] = _Axis(here, here, a.speed, t)

    def place(self, pan_steps: float, tilt_steps: float) -> None:
        """Put the head at a position at once (power-up, tests)."""
        with self._lock:
            self._axes = {"P": _Axis(pan_steps, pan_steps), "T": _Axis(tilt_steps, tilt_steps)}

    def motion_end(self) -> float:
        """Monotonic time when both axes will have stopped."""
        with self._lock:
            return max(a.end() for a in self._axes.values())


_NUM = re.compile(r"^[+-]?\d+$")


class TurretEmulator(LineEmulator):
    """A PTU-D46 on a serial line (see the module docstring).

    spec : TurretSpec (resolution, limits, start speed). mount : the shared MountState (made
    when None). baudrate : modelled line rate (9600 by default). speed_limits_steps_s : the
    speeds a ``PS``/``TS`` may set. faults : FaultInjector for the replies.
    """

    name = "turret"
    terminators = b" \r"

    def __init__(
        self,
        spec: TurretSpec,
        *,
        mount: MountState | None = None,
        baudrate: int | None = 9600,
        speed_limits_steps_s: tuple[float, float] = (1.0, 4000.0),
        faults: FaultInjector | None = None,
    ):
        self.spec = spec
        self.mount = mount if mount is not None else MountState(spec.step_rad)
        self.speed_limits = tuple(float(v) for v in speed_limits_steps_s)
        self.limits = {"P": tuple(spec.pan_limits_steps), "T": tuple(spec.tilt_limits_steps)}
        self.speed = {"P": float(spec.speed_steps_s), "T": float(spec.speed_steps_s)}
        self.terse = False
        self._queue: deque[str] = deque()
        self._busy_until = 0.0
        self._pump_timer = None
        if faults is None:
            faults = FaultInjector()
        faults.error_line = faults.error_line or b"! Illegal command\r\n"
        faults.unsolicited_line = faults.unsolicited_line or b"!P\r\n"
        super().__init__(baudrate=baudrate, faults=faults)

    # -------------------------------------------------------------------------- life
    def on_power_up(self, t: float) -> None:
        self.echo = True
        self.terse = False
        self.speed = {"P": float(self.spec.speed_steps_s), "T": float(self.spec.speed_steps_s)}
        self._queue.clear()
        self._busy_until = t
        self.mount.place(0.0, 0.0)

    def on_power_down(self) -> None:
        # the head stays where it was; it is homed again at power-up
        self._queue.clear()

    # ---------------------------------------------------------------------- commands
    def handle_command(self, command: str, t: float) -> None:
        self._queue.append(command.upper())
        self._pump()

    def _pump(self) -> None:
        while self._queue:
            now = time.monotonic()
            if now < self._busy_until:
                self.call_at(self._busy_until, self._pump)
                return
            self._execute(self._queue.popleft(), now)

    def _answer(self, value: str, verbose: str) -> str:
        return f"* {value}" if self.terse else f"* {verbose}"

    def _execute(self, cmd: str, t: float) -> None:
        axis_name = {"P": "Pan", "T": "Tilt"}
        if cmd in ("ED", "EE"):
            self.echo = cmd == "EE"
            return self.reply("*", t)
        if cmd in ("FT", "FV"):
            self.terse = cmd == "FT"
            return self.reply("*", t)
        if cmd == "V":
            return self.reply(
                self._answer("mcit PTU-D46 emulator v1", "Pan-Tilt Controller emulator (mcit), PTU-D46"), t
            )
        if cmd == "A":
            end = max(t, self.mount.motion_end())
            self._busy_until = end
            return self.reply("*", end)
        if cmd in ("H", "PH", "TH"):
            for ax in ("P", "T") if cmd == "H" else (cmd[0],):
                self.mount.halt(ax, t)
            return self.reply("*", t)
        if cmd == "R":
            end = t
            for ax in ("P", "T"):
                end = max(end, self.mount.move(ax, 0.0, self.speed[ax], t))
            self._busy_until = end
            return self.reply("!T!T!P!P*", end)
        if len(cmd) >= 2 and cmd[0] in "PT":
            ax, op, arg = cmd[0], cmd[1], cmd[2:]
            if arg and not _NUM.match(arg):
                return self.reply("! Illegal command argument", t)
            lo, hi = self.limits[ax]
            if op == "P" and not arg:
                pos = int(np.round(self.mount.steps_at(t)[0 if ax == "P" else 1]))
                return self.reply(self._answer(str(pos), f"Current {axis_name[ax]} position is {pos}"), t)
            if op in ("P", "O") and arg:
                target = int(arg) + (int(np.round(self.mount.target(ax))) if op == "O" else 0)
                if target > hi:
                    return self.reply(f"! Maximum allowable {axis_name[ax]} position exceeded", t)
                if target < lo:
                    return self.reply(f"! Minimum allowable {axis_name[ax]} position exceeded", t)
                self.mount.move(ax, target, self.speed[ax], t)
                return self.reply("*", t)
            if op == "S":
                if not arg:
                    v = int(round(self.speed[ax]))
                    return self.reply(self._answer(str(v), f"Target {axis_name[ax]} speed is {v} positions/sec"), t)
                v = int(arg)
                if not self.speed_limits[0] <= v <= self.speed_limits[1]:
                    return self.reply(f"! {axis_name[ax]} speed out of range", t)
                self.speed[ax] = float(v)
                return self.reply("*", t)
            if op in ("N", "X") and not arg:
                v = lo if op == "N" else hi
                word = "Minimum" if op == "N" else "Maximum"
                return self.reply(self._answer(str(v), f"{word} {axis_name[ax]} position is {v}"), t)
            if op == "R" and not arg:
                res = f"{self.spec.resolution_arcsec:.4f}"
                return self.reply(self._answer(res, f"{res} seconds arc per {axis_name[ax]} position"), t)
        return self.reply("! Illegal command", t)
