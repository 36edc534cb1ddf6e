"""Driver of a Dimetix DLS laser range finder (ASCII protocol) over ``serial.serial_for_url``.

Protocol (shared/PROTOCOLS.md): ``s<N><cmd>`` + CR LF out, ``g<N>…`` + CR LF back; one distance
``gNg+dddddddd`` in 0.1 mm; errors ``gN@Ezzz``. Delivered at 19200 baud 7E1 (the default here;
pseudo-terminals ignore the setting).

Robustness (no checksum on the wire):

* every call has a deadline (``timeout_s``, by default attempts × ``attempt_timeout_s`` plus
  ``reconnect_timeout_s``);
* a reply is recognised by its ending (``gNg±dddddddd`` at the end of the line), so junk before
  it, replies split across reads and unsolicited lines (``gN?``) do no harm;
* a malformed reply (truncated, a garbled character, an unknown error code) or an implausible
  distance (outside ``plausible_range_m``, default 0.05–100 m) is rejected; so is silence past
  the deadline. Then the driver sends ``sNc`` and discards input up to its ``gN?`` (stale
  replies) and measures again — a measurement is idempotent;
* the device's error codes raise ``RangeFinderError`` subclasses (``NoTargetError`` for 255);
* an unplugged port is reopened with back-off, the handshake (``sNc`` → ``gN?``) redone, and
  the shot retried;
* a reply must answer the request it is read for (the protocol has no echo and no sequence
  number): after a distance the driver listens for one line's time more, and a second distance
  arriving then (a complete reply pushed in ahead of the real one) voids the exchange, which is
  measured again after a resynchronisation; a distance that jumps more than ``jump_sigmas`` × σ
  (``sigma_m``) from the median of the last ones (and the first one, with none before it) is
  measured a second time and kept only when two consecutive readings agree — a garbled digit
  that still parses, or a stray reply, is not returned as the distance. ``stats["jumps"]``,
  ``stats["two_replies"]`` count them;
* a line that brings only garbage (noise, a wrong baud rate) ends in ``NoisyLineError``: the
  range finder's line is noisy, check the cable and the baud rate;
* ``measure_n`` takes the median of several shots for precision and flags outliers.
"""

from __future__ import annotations

import re
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from .errors import RANGEFINDER_ERRORS, NoTargetError, ProtocolError, rangefinder_error
from .transport import NOISE, LineDriver, clip, deadline_after

__all__ = ["RangeFinder", "RangeMeasurement"]

EOL = "\r\n"
_OWN_LINE = re.compile(
    r"g\d(?:\?|@E\d{3}|[a-z]{1,3}[+-]\d{8}(?:\+\d)?|[a-z]{1,3}\?)$"
)  # any DLS reply, at a line's end


@dataclass(frozen=True)
class RangeMeasurement:
    """The result of n shots at one pointing.

    range_m : median of the shots kept (metres). spread_m : standard deviation of the shots kept
    (metres; 0 for one shot). shots_m : array, shape (n,), every shot, NaN for a miss (error 255).
    outliers : array, shape (n,), bool, shots rejected as farther than ``outlier_m`` from the
    median of all valid shots. n_valid : shots that returned a distance.
    """

    range_m: float
    spread_m: float
    shots_m: np.ndarray
    outliers: np.ndarray
    n_valid: int

    @property
    def n_kept(self) -> int:
        return int(np.sum(np.isfinite(self.shots_m) & ~self.outliers))


class RangeFinder(LineDriver):
    """A DLS range finder (see the module docstring).

    url : device path, pty, ``socket://host:port`` or ``mcit://NAME``. device_id : N (0–9).
    baudrate, bytesize, parity, stopbits : line settings (DLS delivery: 19200 7E1).
    attempt_timeout_s : deadline of one shot (a measurement takes ~0.1 s, longer on dark or far
    targets). retries, reconnect_timeout_s : see ``LineDriver``. plausible_range_m : distances
    outside are taken for garbled. sigma_m : the range noise σ (metres, one shot);
    jump_sigmas : a distance farther than this many σ from the median of the last ``history``
    ones is read a second time. connect : open and handshake now.
    """

    device = "rangefinder"
    display_name = "range finder"

    def __init__(
        self,
        url: str,
        *,
        device_id: int = 0,
        baudrate: int = 19200,
        bytesize: int = 7,
        parity: str = "E",
        stopbits: float = 1,
        attempt_timeout_s: float = 1.0,
        retries: int = 2,
        reconnect_timeout_s: float = 5.0,
        plausible_range_m: tuple[float, float] = (0.05, 100.0),
        sigma_m: float = 0.005,
        jump_sigmas: float = 5.0,
        history: int = 3,
        connect: bool = True,
    ):
        if not (isinstance(device_id, (int, np.integer)) and 0 <= device_id <= 9):
            raise ValueError(f"device_id is one digit 0-9, got {device_id!r}")
        lo, hi = (float(v) for v in plausible_range_m)
        if not 0 <= lo < hi:
            raise ValueError(f"plausible_range_m must be (low, high) with 0 <= low < high, got {plausible_range_m}")
        if not (sigma_m > 0 and jump_sigmas > 0 and np.isfinite(sigma_m * jump_sigmas)):  # NaN fails too
            raise ValueError(f"sigma_m and jump_sigmas must be positive and finite, got {sigma_m}, {jump_sigmas}")
        if not (isinstance(history, (int, np.integer)) and history >= 1):
            raise ValueError(f"history must be a positive integer, got {history!r}")
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
        self.device_id = int(device_id)
        self.plausible_range_m = (lo, hi)
        self.jump_m = float(sigma_m) * float(jump_sigmas)
        self._recent: deque[float] = deque(maxlen=int(history))
        n = self.device_id
        self._re_ready = re.compile(rf"g{n}\?$")
        self._re_error = re.compile(rf"g{n}@E(\d{{3}})$")
        self._re_value = {k: re.compile(rf"g{n}{k}([+-]\d{{8}})$") for k in ("g", "t", "uof")}
        if connect:
            self.connect()

    # ---------------------------------------------------------------------- plumbing
    def _command(self, body: str) -> str:
        return f"s{self.device_id}{body}"

    def _check_error(self, line: str, command: str) -> None:
        m = self._re_error.search(line)
        if m is None:
            return
        code = int(m.group(1))
        if code in RANGEFINDER_ERRORS:
            raise rangefinder_error(code, command)
        raise ProtocolError(
            f"rangefinder: unknown error code in {clip(line)} (garbled?)", device=self.device, command=command
        )

    def _parse_ready(self, command: str):
        def parse(line: str):
            if self._re_ready.search(line):
                return True
            self._check_error(line, command)
            return NOISE

        return parse

    def _parse_value(self, kind: str, command: str, scale: float):
        tag = f"g{self.device_id}{kind}"
        regex = self._re_value[kind]

        def parse(line: str):
            m = regex.search(line)
            if m:
                return int(m.group(1)) * scale
            self._check_error(line, command)
            if tag in line or f"g{self.device_id}@" in line:
                raise ProtocolError(
                    f"rangefinder: malformed reply {clip(line)} to {command!r}", device=self.device, command=command
                )
            return NOISE

        return parse

    def _is_garbage(self, line: str) -> bool:
        return _OWN_LINE.search(line) is None

    def _handshake(self, deadline: float) -> None:
        self._resync(deadline)

    def _no_second_reply(self, regex: re.Pattern, command: str, deadline: float) -> None:
        """ProtocolError when another complete reply of the same kind follows within one reply's line
        time (and a few ms): the one taken may have been pushed in ahead of the real one."""
        chars = 16  # 'gNg+dddddddd' CR LF, and a margin
        guard = chars * 10.0 / self._line.baudrate + 0.002 if self._line.baudrate else 0.002
        end = min(deadline, time.monotonic() + guard)
        while True:
            line = self._line.read_line_soon(end)
            if line is None:
                return
            if regex.search(line):
                self.stats["two_replies"] += 1
                raise ProtocolError(f"rangefinder: two replies to one {command!r}", device=self.device, command=command)

    def _resync(self, deadline: float) -> None:
        """Stop any measurement (``sNc``) and discard everything up to its ``gN?``."""
        command = self._command("c")
        self._request(command, self._parse_ready(command), deadline, EOL)

    def _simple(self, body: str, timeout_s: float | None) -> None:
        command = self._command(body)
        self._transact(
            lambda dl: self._request(command, self._parse_ready(command), dl, EOL),
            what=command,
            idempotent=True,
            deadline=deadline_after(timeout_s),
        )

    # ---------------------------------------------------------------------- commands
    def measure(self, timeout_s: float | None = None, *, confirm: bool = True) -> float:
        """One distance (metres). NoTargetError on error 255; other codes raise their RangeFinderError.

        confirm : read again a distance that jumps from the last ones, or a first one (see the
        module docstring); ``measure_n`` of 3 shots or more leaves it to its median instead."""
        command = self._command("g")
        lo, hi = self.plausible_range_m

        def shot(deadline: float) -> float:
            value = self._request(command, self._parse_value("g", command, 1e-4), deadline, EOL)
            if not lo <= value <= hi:
                raise ProtocolError(
                    f"rangefinder: implausible distance {value} m (outside {lo}-{hi} m; garbled?)",
                    device=self.device,
                    command=command,
                )
            self._no_second_reply(self._re_value["g"], command, deadline)
            return float(value)

        def checked(deadline: float) -> float:
            first = shot(deadline)
            if not confirm or (self._recent and abs(first - float(np.median(self._recent))) <= self.jump_m):
                self._recent.append(first)
                return first
            # read again: keep a distance only when two readings in a row agree (also the first one,
            # which has nothing to be compared with)
            self.stats["jumps" if self._recent else "unconfirmed"] += 1
            readings = [first]
            for _ in range(2):
                readings.append(self._step(shot))
                if abs(readings[-1] - readings[-2]) <= self.jump_m:
                    self._recent.clear()
                    self._recent.append(readings[-2])
                    return readings[-2]
            raise ProtocolError(
                f"rangefinder: three readings in a row disagree ({', '.join(f'{r:.4f}' for r in readings)} m)",
                device=self.device,
                command=command,
            )

        deadline = deadline_after(timeout_s)
        return self._transact(checked, what=command, idempotent=True, deadline=deadline)

    def measure_n(
        self, n: int, *, outlier_m: float = 0.05, timeout_s: float | None = None, confirm: bool | None = None
    ) -> RangeMeasurement:
        """n shots at the current pointing: their median, spread and outliers (see RangeMeasurement).

        A shot with error 255 counts as a miss (NaN); other device errors are raised. A shot
        farther than outlier_m (metres) from the median of the valid shots is an outlier and left
        out of range_m and spread_m. NoTargetError when every shot misses. confirm : read again a
        shot that jumps (see ``measure``); by default only for fewer than 3 shots.
        """
        if not (isinstance(n, (int, np.integer)) and n >= 1):
            raise ValueError(f"n must be a positive integer, got {n!r}")
        if not (outlier_m > 0):  # NaN is refused too
            raise ValueError(f"outlier_m must be positive, got {outlier_m}")
        deadline = deadline_after(timeout_s)
        shots = np.full(int(n), np.nan)
        for i in range(int(n)):
            left = None if deadline is None else max(deadline - time.monotonic(), 1e-3)
            try:
                shots[i] = self.measure(
                    timeout_s=left, confirm=n < 3 if confirm is None else confirm
                )  # 3 or more: the median outvotes a stray
            except NoTargetError:
                pass
        valid = np.isfinite(shots)
        if not valid.any():
            raise NoTargetError(
                f"range finder error 255: none of {n} shots returned a distance", command=self._command("g")
            )
        median_all = float(np.median(shots[valid]))
        outliers = valid & (np.abs(shots - median_all) > outlier_m)
        kept = shots[valid & ~outliers]
        spread = float(np.std(kept, ddof=1)) if len(kept) > 1 else 0.0
        return RangeMeasurement(float(np.median(kept)), spread, shots, outliers, int(valid.sum()))

    def stop(self, timeout_s: float | None = None) -> None:
        """Stop a measurement or tracking under way (``sNc``)."""
        self._simple("c", timeout_s)

    def laser_on(self, timeout_s: float | None = None) -> None:
        self._simple("o", timeout_s)

    def laser_off(self, timeout_s: float | None = None) -> None:
        self._simple("p", timeout_s)

    def temperature_c(self, timeout_s: float | None = None) -> float:
        """The device's temperature (°C); ProtocolError if outside −40…+85 °C (garbled)."""
        command = self._command("t")

        def ask(deadline: float) -> float:
            value = self._request(command, self._parse_value("t", command, 0.1), deadline, EOL)
            if not -40.0 <= value <= 85.0:
                raise ProtocolError(
                    f"rangefinder: implausible temperature {value} °C (garbled?)", device=self.device, command=command
                )
            return float(value)

        return self._transact(ask, what=command, idempotent=True, deadline=deadline_after(timeout_s))

    def user_offset_m(self, timeout_s: float | None = None) -> float:
        """The user offset added to every distance (metres)."""
        command = self._command("uof")
        return self._transact(
            lambda dl: float(self._request(command, self._parse_value("uof", command, 1e-4), dl, EOL)),
            what=command,
            idempotent=True,
            deadline=deadline_after(timeout_s),
        )

    def set_user_offset_m(self, offset_m: float, timeout_s: float | None = None) -> None:
        """Set the user offset (metres, ±9999.9999); an absolute value, so retried safely."""
        if not np.isfinite(float(offset_m)):
            raise ValueError(f"offset_m must be a finite number of metres, got {offset_m!r}")
        deadline = deadline_after(timeout_s)
        units = int(np.round(float(offset_m) * 1e4))
        if abs(units) > 99_999_999:
            raise ValueError(f"offset {offset_m} m does not fit the device's 8-digit field")
        body = f"uof{'+' if units >= 0 else '-'}{abs(units):08d}"
        command = self._command(body)
        ready = re.compile(rf"g{self.device_id}uof\?$")

        def parse(line: str):
            if ready.search(line):
                return True
            self._check_error(line, command)
            return NOISE

        self._transact(
            lambda dl: self._request(command, parse, dl, EOL),
            what=command,
            idempotent=True,
            deadline=deadline,
        )
