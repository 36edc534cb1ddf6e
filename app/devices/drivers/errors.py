"""Exceptions of the device drivers: one class per failure the caller may want to tell apart.

Every driver call either returns a value it has checked or raises one of these; none returns a
doubtful value silently.

* ``DeviceError``: base class; ``device`` names the device (``"rangefinder"``, ``"turret"``),
  ``command`` the command that failed (``None`` when not tied to one).
* ``DeviceTimeout``: no valid reply before the call's deadline, retries included.
* ``ProtocolError``: replies kept arriving malformed or implausible (garbled, truncated) after the
  allowed retries.
* ``NoisyLineError`` (a ``ProtocolError``): what came back was mostly not the device's protocol
  (line noise, garbage, a wrong baud rate); the message says so and what to check.
* ``DeviceDisconnected``: the port vanished (unplug) and could not be reopened before the deadline.
* ``MotionUnconfirmedError``: a relative move was sent but not confirmed; it is never retried,
  since it may already have happened. Query the position before moving again.
* ``RangeFinderError`` and its subclasses: the range finder's own error codes (``gN@Ezzz``);
  ``NoTargetError`` (255: weak signal, no target, or beyond the measuring range) is the one a scan
  turns into a miss.
* ``TurretError``: a ``!`` reply of the turret; ``TurretLimitError`` (also a ``ValueError``) for a
  position beyond the limits, refused before sending or reported by the turret.
"""

from __future__ import annotations

__all__ = [
    "DeviceError",
    "DeviceTimeout",
    "ProtocolError",
    "NoisyLineError",
    "DeviceDisconnected",
    "MotionUnconfirmedError",
    "RangeFinderError",
    "CommandSyntaxError",
    "NotTrackingError",
    "TrackingActiveError",
    "NoTargetError",
    "SignalTooStrongError",
    "AmbiguousMeasurementError",
    "TooMuchLightError",
    "RANGEFINDER_ERRORS",
    "rangefinder_error",
    "TurretError",
    "TurretLimitError",
]


class DeviceError(Exception):
    """A device could not do what was asked; the message says what and what to do."""

    def __init__(self, message: str, *, device: str | None = None, command: str | None = None):
        super().__init__(message)
        self.device = device
        self.command = command


class DeviceTimeout(DeviceError):
    """No valid reply before the deadline (retries included)."""


class ProtocolError(DeviceError):
    """Replies were malformed or implausible (garbled, truncated) after every allowed retry."""


class NoisyLineError(ProtocolError):
    """The line carried garbage instead of replies (noise, a bad cable, a wrong baud rate)."""


class DeviceDisconnected(DeviceError):
    """The port is gone (device unplugged or powered off) and reconnecting failed before the deadline."""


class MotionUnconfirmedError(DeviceTimeout):
    """A relative move was sent but not confirmed; it may or may not have happened (never retried)."""


class RangeFinderError(DeviceError):
    """An error code reported by the range finder (``gN@Ezzz``); ``code`` is the number."""

    code: int = 0
    meaning: str = "unknown error code"

    def __init__(self, message: str | None = None, *, code: int | None = None, command: str | None = None):
        if code is not None:
            self.code = int(code)
        super().__init__(
            message or f"range finder error {self.code}: {self.meaning}", device="rangefinder", command=command
        )


class CommandSyntaxError(RangeFinderError):
    code = 203
    meaning = "syntax error: the device did not understand the command"


class NotTrackingError(RangeFinderError):
    code = 210
    meaning = "not in tracking mode (start tracking before reading the buffer)"


class TrackingActiveError(RangeFinderError):
    code = 212
    meaning = "tracking is active: stop it (sNc) first"


class NoTargetError(RangeFinderError):
    code = 255
    meaning = "no return: weak signal, no target, or beyond the measuring range"


class SignalTooStrongError(RangeFinderError):
    code = 256
    meaning = "signal too strong (a retro-reflector or a mirror-like target)"


class AmbiguousMeasurementError(RangeFinderError):
    code = 260
    meaning = "ambiguous measurement (several targets in the beam, or moving target)"


class TooMuchLightError(RangeFinderError):
    code = 263
    meaning = "too much background light"


RANGEFINDER_ERRORS: dict[int, type[RangeFinderError]] = {
    203: CommandSyntaxError,
    210: NotTrackingError,
    212: TrackingActiveError,
    255: NoTargetError,
    256: SignalTooStrongError,
    260: AmbiguousMeasurementError,
    263: TooMuchLightError,
    264: TooMuchLightError,
}


def rangefinder_error(code: int, command: str | None = None) -> RangeFinderError:
    """The exception for a range-finder error code (a plain ``RangeFinderError`` for unknown codes)."""
    cls = RANGEFINDER_ERRORS.get(int(code), RangeFinderError)
    return cls(code=int(code), command=command)


class TurretError(DeviceError):
    """The turret answered ``!`` (a failure) to a command; the message carries its text."""

    def __init__(self, message: str, *, command: str | None = None):
        super().__init__(message, device="turret", command=command)


class TurretLimitError(TurretError, ValueError):
    """A position beyond the turret's limits (refused before sending, or reported by the turret)."""
