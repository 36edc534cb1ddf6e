"""Driver of a FLIR (Directed Perception) PTU-D46/E46 pan/tilt unit (ASCII commands) over serial.

Angles follow the turret convention of core/rangefinder.py, with the resolution the unit
reports (``PR``/``TR``, arc-seconds a step): **pan_rad = pan steps × resolution** (positive
pans left, counter-clockwise seen from above) and **tilt_rad = tilt steps × resolution**
(positive tilts the beam up). Mount the unit (or calibrate ``T_world_turret``) so that holds.

Protocol (shared/PROTOCOLS.md): commands end with a space; replies end CR LF: ``*`` done,
``* <value>`` a query's answer (terse feedback), ``! <message>`` a failure, ``!P``/``!T``
unprompted at a limit. 9600 baud 8N1 (E-series also ``socket://HOST:4000``).

Robustness:

* connect handshake: ``EE`` (echo on) and ``FT`` (terse), then resolution and limits, each
  asked until two answers agree (a garbled resolution would scale every angle silently);
* echo stays on: the unit sends every command back before its reply, so a reply counts only after
  its own command's echo. A stale reply (late, or one a fault pushed behind) or a complete reply
  injected ahead of the echo is skipped, never taken for the answer to the next command; the
  values that matter are read twice (positions, resolution, limits) or checked against the
  target (a move's read-back), so one wrong line after the echo is outvoted;
* a reply is read from its last ``*``: junk before it, split reads and unprompted ``!P``/``!T``
  lines (kept in ``limit_events``) do no harm; a malformed or implausible answer (a position
  outside the limits) is rejected; a ``!`` failure counts only as printable text after the echo,
  so garbage is never reported as the turret refusing a command;
* a line that brings only garbage (noise, a wrong baud rate) ends in ``NoisyLineError``: the
  turret's line is noisy, check the cable and the baud rate;
* after a timeout or a malformed reply the driver resynchronises (asks ``PR`` and discards
  every line up to its known answer) and retries — only idempotent commands: absolute moves,
  queries, speed, ``A``; a relative move (``PO``/``TO``) is never re-sent: if its ``*`` does not
  come, ``MotionUnconfirmedError`` says so;
* an absolute move with ``wait=True`` sends ``PP``/``TP``, waits for ``A`` (deadline from the
  distance and the speed) and reads the position back: it must equal the target;
* after an unplug the port is reopened with back-off, ``ED``/``FT`` re-sent, the speed restored
  and the whole absolute move re-sent (the unit homes at power-up);
* the driver keeps the absolute position it last commanded on each axis (``_goal``) across
  reconnects; an axis a move leaves alone (None) is sent again unless the last move's read-back
  confirmed it and nothing (a reconnect, an error, a relative move, a halt) happened since, so a
  replugged unit that homed itself is put back on both axes; a move with ``wait`` reads both axes
  back and returns where the head is: no caller is told a position the head is not at.
"""

from __future__ import annotations

import logging
import math
import re
import time

import numpy as np

from .errors import DeviceError, ProtocolError, TurretError, TurretLimitError
from .transport import NOISE, LineDriver, clip, deadline_after

__all__ = ["Turret"]

log = logging.getLogger("mcit.devices")

EOL = " "
_LIMIT_EVENT = re.compile(r"^(?:\s*![PT])+\s*$")
_REPLY = re.compile(r"^\s*(?:\*[ -~]*|![ -~]*)$")  # a line of the PTU's own: '*…' or '!…', printable
_MESSAGE = re.compile(r"^[ -~]{0,120}$")  # a failure message is printable text
_INT = re.compile(r"^[+-]?\d+$")
_FLOAT = re.compile(r"^[+-]?\d+(?:\.\d+)?$")


def _arcsec_to_rad(arcsec: float) -> float:
    return math.radians(arcsec / 3600.0)


class Turret(LineDriver):
    """A PTU-D46 pan/tilt unit (see the module docstring).

    url : device path, pty, ``socket://host:port`` or ``mcit://NAME``.
    attempt_timeout_s : deadline of one command and its reply (a motion's wait adds its
    expected duration). retries, reconnect_timeout_s : see ``LineDriver``.
    motion_margin_s : slack added to a motion's expected duration before ``A`` times out.
    connect : open and handshake now.
    """

    device = "turret"
    display_name = "turret"

    def __init__(
        self,
        url: str,
        *,
        baudrate: int = 9600,
        bytesize: int = 8,
        parity: str = "N",
        stopbits: float = 1,
        attempt_timeout_s: float = 1.0,
        retries: int = 2,
        reconnect_timeout_s: float = 5.0,
        motion_margin_s: float = 1.0,
        connect: bool = True,
    ):
        super().__init__(
            url,
            baudrate=baudrate,
            bytesize=bytesize,
            parity=parity,
            stopbits=stopbits,
            attempt_timeout_s=attempt_timeout_s,
            retries=retries,
            reconnect_timeout_s=reconnect_timeout_s,
        )
        if not (motion_margin_s >= 0):  # NaN fails too
            raise ValueError(f"motion_margin_s must be >= 0, got {motion_margin_s}")
        self.motion_margin_s = float(motion_margin_s)
        self.resolution_arcsec: tuple[float, float] | None = None  # (pan, tilt)
        self._resolution_text: str | None = None
        self.pan_limits_steps: tuple[int, int] | None = None
        self.tilt_limits_steps: tuple[int, int] | None = None
        self._speed_set: tuple[int, int] | None = None
        self._speed_known: tuple[int, int] | None = None
        self._target: tuple[int, int] | None = None
        # the absolute position last commanded per axis (None: unknown), kept across reconnects,
        # and whether a read-back has confirmed it with no reconnect, error or other motion since
        self._goal: list[int | None] = [None, None]
        self._goal_confirmed = False
        self._maybe_moving = True  # until an ``A`` confirms that both axes stopped
        self.limit_events: list[tuple[float, str]] = []
        if connect:
            self.connect()

    # ------------------------------------------------------------------- units
    def _need_connected(self) -> None:
        if self.resolution_arcsec is None:
            raise DeviceError("turret: not connected yet (call connect())", device=self.device)

    @property
    def pan_step_rad(self) -> float:
        """One pan step in radians, from the resolution the unit reported."""
        self._need_connected()
        return _arcsec_to_rad(self.resolution_arcsec[0])

    @property
    def tilt_step_rad(self) -> float:
        """One tilt step in radians, from the resolution the unit reported."""
        self._need_connected()
        return _arcsec_to_rad(self.resolution_arcsec[1])

    def steps_to_rad(self, pan_steps: float, tilt_steps: float) -> tuple[float, float]:
        return pan_steps * self.pan_step_rad, tilt_steps * self.tilt_step_rad

    def rad_to_steps(self, pan_rad: float, tilt_rad: float) -> tuple[int, int]:
        """Nearest whole steps for angles in radians."""
        for name, v in (("pan_rad", pan_rad), ("tilt_rad", tilt_rad)):
            if not np.isfinite(v):
                raise ValueError(f"{name} must be finite, got {v}")
        return int(np.round(pan_rad / self.pan_step_rad)), int(np.round(tilt_rad / self.tilt_step_rad))

    @property
    def pan_limits_rad(self) -> tuple[float, float]:
        lo, hi = self.pan_limits_steps
        return lo * self.pan_step_rad, hi * self.pan_step_rad

    @property
    def tilt_limits_rad(self) -> tuple[float, float]:
        lo, hi = self.tilt_limits_steps
        return lo * self.tilt_step_rad, hi * self.tilt_step_rad

    # ----------------------------------------------------------------- parsing
    def _limit_event(self, text: str) -> bool:
        if not _LIMIT_EVENT.match(text):
            return False
        for axis in re.findall(r"!([PT])", text):
            self.limit_events.append((time.monotonic(), axis))
        log.warning("turret: unprompted limit event %s", clip(text))
        return True

    def _is_garbage(self, line: str) -> bool:
        return not (_REPLY.match(line) or _LIMIT_EVENT.match(line))

    def _parser(self, expect: str, command: str, echo_optional: bool = False):
        """Parse the lines after ``command`` was sent: expect "ack" (bare ``*``), "int" or "float" (``* <value>``).

        The reply counts only after the command's echo (``command`` + space, case-insensitive) —
        on the echo's line or on a line after it; lines before the echo are stale or noise.
        echo_optional : also take a reply with no echo (``EE``, sent when echo may be off).
        """
        echo = (command + EOL).upper()
        seen = [False]

        def parse(line: str):
            if not seen[0]:
                at = line.upper().rfind(echo)
                if at >= 0:
                    seen[0] = True
                    line = line[at + len(echo) :]
                elif not echo_optional:
                    if not _REPLY.match(line):
                        return NOISE
                    self._limit_event(line)
                    self.stats["stale"] += 1
                    return NOISE  # a reply to something else (stale, or pushed ahead of ours)
            if not line.strip() or self._limit_event(line):
                return NOISE
            star = line.rfind("*")
            if star < 0:
                bang = line.find("!")
                message = line[bang + 1 :].strip() if bang >= 0 else ""
                if bang >= 0 and not line[:bang].strip() and _MESSAGE.match(message):
                    cls = (
                        TurretLimitError
                        if ("position" in message.lower() or "limit" in message.lower())
                        else TurretError
                    )
                    raise cls(f"turret refused {command!r}: {message}", command=command)
                raise ProtocolError(
                    f"turret: garbled reply {clip(line)} to {command!r}", device=self.device, command=command
                )
            rest = line[star + 1 :].strip()
            if expect == "ack":
                if rest:
                    raise ProtocolError(
                        f"turret: expected '*' for {command!r}, got {clip(line)}", device=self.device, command=command
                    )
                return None
            pattern = _INT if expect == "int" else _FLOAT
            if not pattern.match(rest):
                raise ProtocolError(
                    f"turret: malformed answer {clip(line)} to {command!r}", device=self.device, command=command
                )
            return int(rest) if expect == "int" else float(rest)

        return parse

    def _ask(self, command: str, expect: str, deadline: float, echo_optional: bool = False):
        return self._request(command, self._parser(expect, command, echo_optional), deadline, EOL)

    def _ask_step(self, command: str, expect: str, timeout_s: float | None = None):
        """An idempotent command as one step of a longer operation: retried on its own (see LineDriver._step)."""
        return self._step(lambda dl: self._ask(command, expect, dl), timeout_s)

    def _ask_agreed(self, command: str, expect: str, deadline: float, tries: int = 4):
        """Ask until two consecutive answers agree (values that must not be garbled)."""
        last = None
        for _ in range(tries):
            value = self._ask_step(command, expect)
            if last is not None and value == last:
                return value
            last = value
        raise ProtocolError(
            f"turret: {tries} answers to {command!r} never agreed twice in a row", device=self.device, command=command
        )

    # ------------------------------------------------------- handshake, resync
    def _handshake(self, deadline: float) -> None:
        self._step(lambda dl: self._ask("EE", "ack", dl, echo_optional=True))  # echo on: replies are told apart by it
        self._ask_step("FT", "ack")
        res_p = self._ask_agreed("PR", "float", deadline)
        res_t = self._ask_agreed("TR", "float", deadline)
        if not (0.0 < res_p < 3600.0 and 0.0 < res_t < 3600.0):
            raise ProtocolError(
                f"turret: implausible resolution {res_p}, {res_t} arc-seconds a step", device=self.device
            )
        limits = tuple(self._ask_agreed(c, "int", deadline) for c in ("PN", "PX", "TN", "TX"))
        if not (limits[0] < limits[1] and limits[2] < limits[3]):
            raise ProtocolError(f"turret: implausible limits {limits}", device=self.device)
        if self.resolution_arcsec is not None and (res_p, res_t) != self.resolution_arcsec:
            raise DeviceError(
                "turret: after reconnecting, the resolution is "
                f"{res_p, res_t}, was {self.resolution_arcsec}: another unit?",
                device=self.device,
            )
        self.resolution_arcsec = (res_p, res_t)
        self.pan_limits_steps = (limits[0], limits[1])
        self.tilt_limits_steps = (limits[2], limits[3])
        if self._speed_set is not None:  # a power cycle forgets the speed
            self._ask_step(f"PS{self._speed_set[0]}", "ack")
            self._ask_step(f"TS{self._speed_set[1]}", "ack")
        self._speed_known = None
        self._target = None
        self._goal_confirmed = False  # a unit powering up homes itself: every axis is sent again
        self._maybe_moving = True  # a unit powering up homes itself

    def _resync(self, deadline: float) -> None:
        """Discard every reply up to the answer of a ``PR`` whose value is known."""
        if self.resolution_arcsec is None:
            time.sleep(0.05)
            self._line.discard_input()
            return
        known = self.resolution_arcsec[0]
        answer = self._parser("float", "PR")  # keeps whether PR's echo has come

        def parse(line: str):
            try:
                value = answer(line)
            except (ProtocolError, TurretError):
                return NOISE
            if value is NOISE or abs(value - known) > 1e-9:
                return NOISE
            return True

        self._request("PR", parse, deadline, EOL)

    # ------------------------------------------------------------------ queries
    def _deadline(self, timeout_s: float | None) -> float | None:
        return deadline_after(timeout_s)  # ValueError for NaN or a negative time

    def _read_axes(self, pan: bool = True, tilt: bool = True) -> tuple[int | None, int | None]:
        pos = []
        for wanted, cmd, (lo, hi) in ((pan, "PP", self.pan_limits_steps), (tilt, "TP", self.tilt_limits_steps)):
            if not wanted:
                pos.append(None)
                continue
            v = self._ask_step(cmd, "int")
            if not lo <= v <= hi:
                raise ProtocolError(
                    f"turret: position {v} from {cmd!r} is outside the limits {lo}..{hi} (garbled?)",
                    device=self.device,
                    command=cmd,
                )
            pos.append(v)
        return pos[0], pos[1]

    def _read_position(self, deadline: float, tries: int = 4) -> tuple[int, int]:
        """Read (pan, tilt) until two reads in a row agree within what the axes can travel between them.

        A reply cut short but still terminated (``* 1234`` → ``* 12``) or a garbled digit parses
        as a valid position; a second read exposes it. While moving, two reads may differ by
        speed × the time between them (plus a step); once a wait (``A``) has confirmed the motion
        end and no move was sent since, they must be equal.
        """
        speeds = (self._speed_known or self._speed_set or (0, 0)) if self._maybe_moving else (0, 0)
        prev, t_prev = self._read_axes(), time.monotonic()
        for _ in range(tries - 1):
            cur, t = self._read_axes(), time.monotonic()
            if all(abs(c - p) <= (v * (t - t_prev + 0.005) + 1 if v else 0) for c, p, v in zip(cur, prev, speeds)):
                return cur
            prev, t_prev = cur, t
        raise ProtocolError(
            f"turret: {tries} position reads never agreed (last {prev})", device=self.device, command="PP"
        )

    def position_steps(self, timeout_s: float | None = None) -> tuple[int, int]:
        """Current (pan, tilt) in steps (while moving: where the axes are now); read twice to be sure."""
        self._need_connected()
        self._ensure_speed_known()
        return self._transact(
            self._read_position, what="position query", idempotent=True, deadline=self._deadline(timeout_s)
        )

    def still_at(self, pan: int, tilt: int, timeout_s: float | None = None) -> bool:
        """True when one read of both axes gives (pan, tilt) steps: the head stayed there (e.g. during a
        measurement). False when it is elsewhere — a unit that powered up in between homed itself —
        or a read was garbled; the next move then sends both axes again."""
        self._need_connected()
        deadline = self._deadline(timeout_s)
        here = self._transact(lambda dl: self._read_axes(), what="position check", idempotent=True, deadline=deadline)
        if here != (int(pan), int(tilt)):
            self._goal_confirmed = False
            return False
        return True

    def position_rad(self, timeout_s: float | None = None) -> tuple[float, float]:
        """Current (pan_rad, tilt_rad) in the core/rangefinder.py convention."""
        return self.steps_to_rad(*self.position_steps(timeout_s))

    def position_deg(self, timeout_s: float | None = None) -> tuple[float, float]:
        return tuple(math.degrees(a) for a in self.position_rad(timeout_s))

    def speed_steps_s(self, timeout_s: float | None = None) -> tuple[int, int]:
        """(pan, tilt) speeds in steps/s."""
        self._need_connected()

        def ask(deadline: float) -> tuple[int, int]:
            return self._ask_agreed("PS", "int", deadline), self._ask_agreed("TS", "int", deadline)

        speeds = self._transact(ask, what="speed query", idempotent=True, deadline=self._deadline(timeout_s))
        self._speed_known = speeds
        return speeds

    def set_speed_steps_s(self, pan: int, tilt: int | None = None, timeout_s: float | None = None) -> None:
        """Set the (pan, tilt) speeds in steps/s (tilt defaults to pan); restored after a replug."""
        self._need_connected()
        tilt = pan if tilt is None else tilt
        for name, v in (("pan", pan), ("tilt", tilt)):
            if not (isinstance(v, (int, np.integer)) and v > 0):
                raise ValueError(f"{name} speed must be a positive whole number of steps/s, got {v!r}")

        def send(deadline: float) -> None:
            self._ask_step(f"PS{int(pan)}", "ack")
            self._ask_step(f"TS{int(tilt)}", "ack")

        self._transact(send, what="speed setting", idempotent=True, deadline=self._deadline(timeout_s))
        self._speed_set = self._speed_known = (int(pan), int(tilt))

    def set_speed_deg_s(
        self, pan_deg_s: float, tilt_deg_s: float | None = None, timeout_s: float | None = None
    ) -> None:
        """Set the speeds in degrees/s (rounded to whole steps/s)."""
        tilt_deg_s = _finite(pan_deg_s if tilt_deg_s is None else tilt_deg_s, "tilt_deg_s")
        pan_deg_s = _finite(pan_deg_s, "pan_deg_s")
        self.set_speed_steps_s(
            max(1, int(round(math.radians(pan_deg_s) / self.pan_step_rad))),
            max(1, int(round(math.radians(tilt_deg_s) / self.tilt_step_rad))),
            timeout_s,
        )

    # ------------------------------------------------------------------- motion
    def check_limits(self, pan: int | None, tilt: int | None) -> None:
        """TurretLimitError when a (pan, tilt) position in steps (None: not checked) is beyond the limits."""
        for name, v, (lo, hi), step in (
            ("pan", pan, self.pan_limits_steps, self.pan_step_rad),
            ("tilt", tilt, self.tilt_limits_steps, self.tilt_step_rad),
        ):
            if v is not None and not lo <= v <= hi:
                raise TurretLimitError(
                    f"turret: {name} {v} steps ({math.degrees(v * step):.3f}°) is beyond the limits {lo}..{hi} steps "
                    f"({math.degrees(lo * step):.3f}°..{math.degrees(hi * step):.3f}°)",
                    command=None,
                )

    def _motion_time_s(self, pan: int | None, tilt: int | None) -> float:
        """Upper estimate of a move's duration from the last known target (full travel if unknown)."""
        speeds = self._speed_known or self._speed_set or (1, 1)
        spans = []
        for i, (v, (lo, hi)) in enumerate(((pan, self.pan_limits_steps), (tilt, self.tilt_limits_steps))):
            if v is None:
                continue
            start = None if self._target is None else self._target[i]
            spans.append((abs(v - start) if start is not None else hi - lo) / max(speeds[i], 1))
        return max(spans, default=0.0)

    def _full_travel_s(self) -> float:
        """Time of the longest possible move at the known speeds."""
        speeds = self._speed_known or self._speed_set or (1, 1)
        return max(
            (self.pan_limits_steps[1] - self.pan_limits_steps[0]) / max(speeds[0], 1),
            (self.tilt_limits_steps[1] - self.tilt_limits_steps[0]) / max(speeds[1], 1),
        )

    def _ensure_speed_known(self) -> None:
        if self._speed_known is None:
            self.speed_steps_s()

    def wait(self, timeout_s: float | None = None) -> None:
        """Return when both axes have stopped (``A``); its deadline covers a full travel by default."""
        self._need_connected()
        deadline_after(timeout_s)  # NaN or negative: ValueError
        self._ensure_speed_known()
        budget = (
            self.attempt_timeout_s + self._full_travel_s() + self.motion_margin_s if timeout_s is None else timeout_s
        )
        self._transact(
            lambda dl: self._ask("A", "ack", time.monotonic() + budget),
            what="wait for motion end",
            idempotent=True,
            deadline=time.monotonic() + (self.retries + 1) * budget + self.reconnect_timeout_s,
        )
        self._maybe_moving = False

    def move_to_steps(
        self, pan: int | None = None, tilt: int | None = None, *, wait: bool = True, timeout_s: float | None = None
    ) -> tuple[int, int]:
        """Absolute move (steps); None keeps an axis at its last commanded position.

        Returns (pan, tilt): with wait, where the head is (both axes read back, equal to the
        targets, else an error); without, the targets. An axis left None is sent again whenever
        its position is not confirmed (first move, after a reconnect — the unit homes at power-up —
        an error, a halt or a relative move); one never commanded is read first.
        Retried as a whole after a timeout, a malformed reply or an unplug (absolute: safe).
        """
        self._need_connected()
        for name, v in (("pan", pan), ("tilt", tilt)):
            if v is not None and not isinstance(v, (int, np.integer)):
                raise ValueError(f"{name} must be a whole number of steps, got {v!r}")
        deadline_after(timeout_s)  # NaN or negative: ValueError before anything is sent
        pan = None if pan is None else int(pan)
        tilt = None if tilt is None else int(tilt)
        self.check_limits(pan, tilt)
        self._ensure_speed_known()
        motion_s = self._motion_time_s(pan, tilt)
        budget = 5 * (self.retries + 1) * self.attempt_timeout_s + (
            motion_s + self.motion_margin_s if wait else 0.0
        )  # one attempt's worst case

        def move(_deadline: float) -> tuple[int, int]:
            asked = (pan, tilt)
            if None in asked and None in [g for a, g in zip(asked, self._goal) if a is None]:
                # an axis left alone was never commanded: it stays where it is, read it once stopped
                self._ask_step("A", "ack", self.attempt_timeout_s + self._full_travel_s() + self.motion_margin_s)
                self._maybe_moving = False
                here = self._read_axes(pan is None and self._goal[0] is None, tilt is None and self._goal[1] is None)
                self._goal = [g if h is None else h for g, h in zip(self._goal, here)]
                self._goal_confirmed = False
            want = tuple(a if a is not None else g for a, g in zip(asked, self._goal))
            self.check_limits(*want)
            confirmed = self._goal_confirmed
            self._goal_confirmed = False
            self._maybe_moving = True
            for i, cmd in enumerate(("PP", "TP")):
                if asked[i] is not None or not confirmed:
                    self._ask_step(f"{cmd}{want[i]}", "ack")
                    self._goal[i] = want[i]
            if not wait:
                return want
            self._ask_step("A", "ack", self.attempt_timeout_s + self._motion_time_s(*want) + self.motion_margin_s)
            self._maybe_moving = False
            got = self._read_axes()
            if got != want:  # a garbled digit, or the unit really stopped elsewhere: read again
                again = self._read_axes()
                if again != want:
                    if again == got:
                        raise TurretError(f"turret stopped at {got} steps instead of {want}", command="A")
                    raise ProtocolError(f"turret: position reads {got} then {again}, target {want}", device=self.device)
            self._goal_confirmed = True
            return want

        total = None if timeout_s is None else time.monotonic() + timeout_s
        if total is None:  # a reconnect re-sends both axes from home: a full travel more at most
            total = time.monotonic() + (self.retries + 1) * budget + self.reconnect_timeout_s + self._full_travel_s()
        result = self._transact(move, what=f"absolute move to {pan}, {tilt}", idempotent=True, deadline=total)
        self._target = result
        return result

    def move_to(
        self,
        pan_rad: float | None = None,
        tilt_rad: float | None = None,
        *,
        wait: bool = True,
        timeout_s: float | None = None,
    ) -> tuple[float, float]:
        """Absolute move in radians (rounded to whole steps); returns the angles commanded or reached."""
        self._need_connected()
        pan = None if pan_rad is None else int(np.round(_finite(pan_rad, "pan_rad") / self.pan_step_rad))
        tilt = None if tilt_rad is None else int(np.round(_finite(tilt_rad, "tilt_rad") / self.tilt_step_rad))
        p, t = self.move_to_steps(pan, tilt, wait=wait, timeout_s=timeout_s)
        return (None if p is None else p * self.pan_step_rad, None if t is None else t * self.tilt_step_rad)

    def move_to_deg(
        self,
        pan_deg: float | None = None,
        tilt_deg: float | None = None,
        *,
        wait: bool = True,
        timeout_s: float | None = None,
    ):
        """Absolute move in degrees (rounded to whole steps); returns the angles in degrees."""
        p, t = self.move_to(
            None if pan_deg is None else math.radians(pan_deg),
            None if tilt_deg is None else math.radians(tilt_deg),
            wait=wait,
            timeout_s=timeout_s,
        )
        return (None if p is None else math.degrees(p), None if t is None else math.degrees(t))

    def move_by_steps(
        self, pan: int = 0, tilt: int = 0, *, wait: bool = True, timeout_s: float | None = None
    ) -> tuple[int, int]:
        """Relative move (steps). Never retried: a lost confirmation raises MotionUnconfirmedError.

        The current position is read first (to refuse a move beyond the limits); returns the new
        position (wait) or the targets.
        """
        self._need_connected()
        for name, v in (("pan", pan), ("tilt", tilt)):
            if not isinstance(v, (int, np.integer)):
                raise ValueError(f"{name} must be a whole number of steps, got {v!r}")
        deadline_after(timeout_s)  # NaN or negative: ValueError before anything is sent
        here = self.position_steps(timeout_s)
        target = (here[0] + int(pan), here[1] + int(tilt))
        self.check_limits(*target)
        deadline = None if timeout_s is None else time.monotonic() + timeout_s

        def send(dl: float) -> None:
            self._maybe_moving = True
            self._goal, self._goal_confirmed = list(target), False
            if pan:
                self._ask(f"PO{int(pan)}", "ack", dl)
            if tilt:
                self._ask(f"TO{int(tilt)}", "ack", dl)

        self._transact(send, what=f"relative move by {pan}, {tilt}", idempotent=False, deadline=deadline)
        self._target = target
        if wait:
            self.wait(None if timeout_s is None else max(deadline - time.monotonic(), 1e-3))
            return self.position_steps(timeout_s)
        return target

    def move_by_deg(
        self, pan_deg: float = 0.0, tilt_deg: float = 0.0, *, wait: bool = True, timeout_s: float | None = None
    ):
        """Relative move in degrees (rounded to whole steps); returns the new angles in degrees."""
        pan_deg, tilt_deg = _finite(pan_deg, "pan_deg"), _finite(tilt_deg, "tilt_deg")
        p, t = self.move_by_steps(
            int(np.round(math.radians(pan_deg) / self.pan_step_rad)),
            int(np.round(math.radians(tilt_deg) / self.tilt_step_rad)),
            wait=wait,
            timeout_s=timeout_s,
        )
        return math.degrees(p * self.pan_step_rad), math.degrees(t * self.tilt_step_rad)

    def halt(self, timeout_s: float | None = None) -> None:
        """Stop both axes where they are (``H``)."""
        self._need_connected()
        deadline = self._deadline(timeout_s)
        self._goal, self._goal_confirmed = [None, None], False  # stopped wherever it was
        self._transact(lambda dl: self._ask("H", "ack", dl), what="halt", idempotent=True, deadline=deadline)
        self._target = None

    def home(self, timeout_s: float | None = None) -> None:
        """Reset and home both axes (``R``; answers when done)."""
        self._need_connected()
        deadline_after(timeout_s)  # NaN or negative: ValueError before anything is sent
        self._ensure_speed_known()
        budget = self.attempt_timeout_s + self._full_travel_s() + self.motion_margin_s
        self._goal, self._goal_confirmed = [0, 0], False
        self._transact(
            lambda dl: self._ask("R", "ack", time.monotonic() + budget),
            what="reset",
            idempotent=True,
            deadline=self._deadline(timeout_s) or time.monotonic() + (self.retries + 1) * budget,
        )
        self._target = (0, 0)
        self._maybe_moving = False


def _finite(v: float, name: str) -> float:
    v = float(v)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be finite, got {v}")
    return v
