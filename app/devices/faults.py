"""Fault injection for the device emulators: what a real serial line and a real device do wrong.

A ``FaultInjector`` sits in an emulator's output: every reply line passes through it and may
come out dropped, late, truncated, split in two, preceded by junk, garbled, preceded by an
unsolicited line, replaced by a device error, or lost in an unplug. Faults are either queued one
by one (``push``: deterministic, for tests) or drawn at random per reply (``rates``: soak tests
and ``mcit emulate --fault-rate``), from a seeded generator.

Kinds (``Fault.kind``):

* ``drop``: the reply never comes.
* ``late``: the reply comes ``delay_s`` later than it should (and everything behind it too:
  a serial line keeps its order).
* ``truncate``: only the first ``at`` bytes come (default: half the line); with
  ``keep_terminator`` the short line still ends in CR LF, otherwise it stays open.
* ``split``: the reply comes in two parts (cut at ``at``, default the middle), ``delay_s`` apart.
* ``junk``: bytes ``data`` (default 1–8 random bytes, no CR/LF) come before the reply.
* ``garble``: the byte at index ``at`` (default: a random byte of the line's text) becomes
  ``data`` (default: a random other printable character). No checksum catches this.
* ``unsolicited``: a line the host did not ask for (``data``, default the device's own, e.g.
  ``g0?`` or ``!P``) comes before the reply.
* ``error``: the reply is replaced by a device error line (``data``, default the device's own).
* ``early``: a complete, well-formed reply comes just before the real one: ``data``, or by default
  the reply itself with every digit redrawn at random (same form, another value) — what a reply
  meant for another request, or a stray device on the line, looks like. No checksum catches it.
* ``unplug``: the device is unplugged instead of replying, and replugged after ``delay_s``
  (default 0.3 s; ``math.inf``: stays unplugged until the emulator's ``replug``).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field

import numpy as np

__all__ = ["FAULT_KINDS", "Fault", "Delivery", "FaultInjector"]

FAULT_KINDS = ("drop", "late", "truncate", "split", "junk", "garble", "unsolicited", "error", "early", "unplug")
_EOL = (b"\r\n", b"\n", b"\r")


@dataclass(frozen=True)
class Fault:
    """One fault, applied to the next reply (containing ``match`` when given); see the module docstring."""

    kind: str
    match: bytes | None = None
    delay_s: float | None = None
    at: int | None = None
    data: bytes | None = None
    keep_terminator: bool = False

    def __post_init__(self):
        if self.kind not in FAULT_KINDS:
            raise ValueError(f"unknown fault kind {self.kind!r}; use one of {FAULT_KINDS}")
        if self.delay_s is not None and self.delay_s < 0:
            raise ValueError(f"delay_s must be >= 0, got {self.delay_s}")
        if self.kind == "garble" and self.data is not None and len(self.data) != 1:
            raise ValueError(f"a garble replaces one byte: data must be 1 byte, got {self.data!r}")


@dataclass
class Delivery:
    """What becomes of one reply: ``chunks`` of (pause before, in seconds; bytes), and an unplug.

    unplug : True when the device unplugs instead of replying; ``replug_after_s`` then says when it
    comes back (inf: not by itself).
    """

    chunks: list[tuple[float, bytes]] = field(default_factory=list)
    unplug: bool = False
    replug_after_s: float = 0.0
    fault: Fault | None = None


def _split_eol(line: bytes) -> tuple[bytes, bytes]:
    for eol in _EOL:
        if line.endswith(eol):
            return line[: -len(eol)], eol
    return line, b""


class FaultInjector:
    """Applies queued and random faults to an emulator's replies (thread-safe).

    rng : seeded generator (or a seed). rates : {kind: probability per reply}, drawn after the
    queue is empty; at most one fault per reply. error_line / unsolicited_line : the device's
    defaults for ``error`` and ``unsolicited`` (bytes with their CR LF).
    ``applied`` logs every fault used as (kind, reply) for tests and diagnostics.
    """

    def __init__(
        self,
        rng: np.random.Generator | int | None = None,
        rates: dict[str, float] | None = None,
        *,
        error_line: bytes = b"",
        unsolicited_line: bytes = b"",
        default_delay_s: float = 0.3,
    ):
        self.rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        self.rates = self.check_rates(rates or {})
        self.error_line = error_line
        self.unsolicited_line = unsolicited_line
        self.default_delay_s = float(default_delay_s)
        self._queue: list[Fault] = []
        self._lock = threading.Lock()
        self.applied: list[tuple[str, bytes]] = []

    @staticmethod
    def check_rates(rates: dict[str, float]) -> dict[str, float]:
        """``rates`` (fault kind → probability a reply) once each kind is known and each rate and their sum
        lie in [0, 1]; ValueError saying which is not."""
        for kind, p in rates.items():
            if kind not in FAULT_KINDS:
                raise ValueError(f"unknown fault kind {kind!r} in rates; use one of {FAULT_KINDS}")
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"fault rate for {kind!r} must be within [0, 1], got {p}")
        if sum(rates.values()) > 1.0:
            raise ValueError(f"fault rates add up to {sum(rates.values())} > 1 (one fault per reply at most)")
        return dict(rates)

    def set_rates(self, rates: dict[str, float]) -> None:
        with self._lock:
            self.rates = self.check_rates(rates)

    def push(self, *faults: Fault | str) -> None:
        """Queue faults (a Fault or a kind name); each applies to one later reply, in order."""
        items = [Fault(f) if isinstance(f, str) else f for f in faults]
        with self._lock:
            self._queue.extend(items)

    def clear(self) -> None:
        with self._lock:
            self._queue.clear()

    @property
    def pending(self) -> int:
        with self._lock:
            return len(self._queue)

    def _next(self, reply: bytes) -> Fault | None:
        with self._lock:
            for i, f in enumerate(self._queue):
                if f.match is None or f.match in reply:
                    return self._queue.pop(i)
                break  # faults apply in order: a waiting match blocks the ones behind it
            if self.rates:
                u = float(self.rng.random())
                acc = 0.0
                for kind, p in self.rates.items():
                    acc += p
                    if u < acc:
                        return Fault(kind)
        return None

    def process(self, reply: bytes) -> Delivery:
        """What becomes of one reply line (with its terminator)."""
        fault = self._next(reply)
        if fault is None:
            return Delivery([(0.0, reply)])
        with self._lock:
            self.applied.append((fault.kind, reply))
        return self._apply(fault, reply)

    def _apply(self, f: Fault, reply: bytes) -> Delivery:
        text, eol = _split_eol(reply)
        rng = self.rng
        delay = self.default_delay_s if f.delay_s is None else f.delay_s
        if f.kind == "drop":
            return Delivery([], fault=f)
        if f.kind == "late":
            return Delivery([(delay, reply)], fault=f)
        if f.kind == "truncate":
            keep = len(text) // 2 if f.at is None else max(0, min(int(f.at), len(text) - 1))
            return Delivery([(0.0, text[:keep] + (eol if f.keep_terminator else b""))], fault=f)
        if f.kind == "split":
            cut = len(reply) // 2 if f.at is None else max(1, min(int(f.at), len(reply) - 1))
            return Delivery([(0.0, reply[:cut]), (delay, reply[cut:])], fault=f)
        if f.kind == "junk":
            junk = f.data
            if junk is None:
                pool = np.setdiff1d(np.arange(256), [10, 13])
                junk = bytes(rng.choice(pool, size=int(rng.integers(1, 9))).astype(np.uint8).tolist())
            return Delivery([(0.0, junk + reply)], fault=f)
        if f.kind == "garble":
            if not text:
                return Delivery([(0.0, reply)], fault=f)
            i = int(rng.integers(len(text))) if f.at is None else int(f.at) % len(text)
            new = f.data
            if new is None:
                pool = [c for c in range(33, 127) if c != text[i]]
                new = bytes([int(rng.choice(pool))])
            return Delivery([(0.0, text[:i] + new + text[i + 1 :] + eol)], fault=f)
        if f.kind == "unsolicited":
            extra = f.data if f.data is not None else self.unsolicited_line
            return Delivery([(0.0, extra), (0.0, reply)], fault=f)
        if f.kind == "error":
            line = f.data if f.data is not None else self.error_line
            return Delivery([(0.0, line)], fault=f)
        if f.kind == "early":
            fake = f.data
            if fake is None:
                start = min(
                    [i for i in (text.find(b"+"), text.find(b"-"), text.find(b"*")) if i >= 0], default=len(text)
                )
                digits = [i for i, c in enumerate(text) if 48 <= c <= 57 and i > start]  # the value's, not an address
                fake = bytearray(text)
                for i in digits:
                    fake[i] = 48 + int(rng.integers(10))
                if digits and bytes(fake) == text:  # another value, not the same one again
                    i = digits[-1]
                    fake[i] = 48 + (text[i] - 48 + 1 + int(rng.integers(9))) % 10
                fake = bytes(fake) + eol
            return Delivery([(0.0, fake), (0.0, reply)], fault=f)
        assert f.kind == "unplug"
        return Delivery([], unplug=True, replug_after_s=f.delay_s if f.delay_s is not None else delay, fault=f)
