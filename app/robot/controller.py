"""The robot's joint controller as mcit sees it, and an emulated one for the bundled site.

mcit talks to a robot's controller through four things: its joint state (``state()``, and listeners
called on every update), ``move(path)`` (follow a joint-space path, waypoints (k, n) in the
controller's joint order), ``stop()`` (halt at once, where it is) and ``close()``. A real controller
(ROS 2's ``joint_states`` and ``FollowJointTrajectory``) implements the same; ``EmulatedController``
is the bundled site's.

The emulated controller follows a path at each joint's speed limit times ``speed_scale``, each segment
timed by its slowest joint (all joints arrive together), and updates its state at ``rate_hz``. Faults
of a real robot can be switched on (``faults``): it stops answering (every call raises
``ControllerSilent``), or a joint does not reach its command (it stalls at a fraction of the motion and
the controller reports the fault when the path ends). A joint state always says what the robot did:
after a stop or a stall, ``q`` is where it is, not where it was sent.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

__all__ = [
    "path_times",
    "JointState",
    "StateListeners",
    "ControllerError",
    "ControllerSilent",
    "ControllerFaults",
    "EmulatedController",
]

log = logging.getLogger("mcit.robot")


def path_times(path: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """When each waypoint of ``path`` (k, n) is reached, seconds from the first: each segment timed by its
    slowest joint at ``velocity`` (n,), so that all joints arrive together."""
    steps = np.abs(np.diff(np.asarray(path, float), axis=0)) / np.asarray(velocity, float)
    return np.concatenate([[0.0], np.cumsum(steps.max(axis=1) if len(steps) else [])])


class ControllerError(RuntimeError):
    """The controller refused or could not do what was asked (one line, what to do)."""


class ControllerSilent(ControllerError):
    """The controller does not answer."""


@dataclass(frozen=True)
class JointState:
    """The robot's joints as its controller reports them.

    names : joint names in the controller's order. q : positions (rad, or m for prismatic joints).
    moving : a motion is under way. t_s : the controller's time of this state (monotonic seconds).
    fault : None, or one line saying what went wrong in the last motion.
    goal : the last motion's final waypoint (None before any motion).
    stamp : the controller's wall-clock time of this state (unix seconds; a ROS 2 message's header), None
    when it gives none.
    """

    names: tuple[str, ...]
    q: np.ndarray
    moving: bool
    t_s: float
    fault: str | None = None
    goal: np.ndarray | None = None
    stamp: float | None = None

    def by_name(self) -> dict[str, float]:
        return {n: float(v) for n, v in zip(self.names, self.q)}


@dataclass
class ControllerFaults:
    """Faults of a real robot, switched on by tests and the fault drills.

    silent : the controller stops answering. stall_joint, stall_at : that joint stops following its
    command once ``stall_at`` (0..1) of the motion's time has passed.
    """

    silent: bool = False
    stall_joint: str | None = None
    stall_at: float = 0.5


@dataclass
class _Motion:
    path: np.ndarray  # (k, n) waypoints, the first the state at the start
    times: np.ndarray  # (k,) seconds from the start at each waypoint
    t0: float
    stall: tuple[int, float] | None = None  # (joint index, share of the motion's time after which it stops)
    stalled_at: float | None = None  # the value the stalled joint stopped at
    told: int = 0  # the last waypoint the listeners were told of


class StateListeners:
    """What every controller shares: listeners of its joint states, told in order (a listener's bug is logged,
    never the robot's), and ``wait_idle`` on the controller's ``_idle()``."""

    def __init__(self) -> None:
        self._listeners: list[Callable[[JointState], None]] = []

    def add_listener(self, fn: Callable[[JointState], None]) -> None:
        self._listeners.append(fn)

    def remove_listener(self, fn: Callable[[JointState], None]) -> None:
        if fn in self._listeners:
            self._listeners.remove(fn)

    def wait_idle(self, timeout_s: float) -> bool:
        """Wait until no motion is under way; False on timeout."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if self._idle():
                return True
            time.sleep(0.01)
        return False

    def _idle(self) -> bool:  # pragma: no cover - each controller's
        raise NotImplementedError

    def _tell(self, state: JointState) -> None:
        for fn in list(self._listeners):
            try:
                fn(state)
            except Exception:  # noqa: BLE001 - a listener's bug never stops the robot's state
                log.exception("a joint-state listener failed")


class EmulatedController(StateListeners):
    """A joint controller that follows paths in time (see the module docstring).

    names, lower, upper, velocity : the joints (rad, rad/s). home : the start configuration.
    rate_hz : state updates per second while moving. speed_scale : fraction of the speed limits used.
    clock : monotonic seconds (tests pass their own). faults : a ControllerFaults to switch faults on.
    """

    def __init__(
        self,
        names: Sequence[str],
        lower: np.ndarray,
        upper: np.ndarray,
        velocity: np.ndarray,
        home: np.ndarray,
        *,
        rate_hz: float = 50.0,
        speed_scale: float = 0.5,
        clock: Callable[[], float] = time.monotonic,
        faults: ControllerFaults | None = None,
    ):
        self.names = tuple(names)
        n = len(self.names)
        self.lower, self.upper = np.asarray(lower, float).reshape(n), np.asarray(upper, float).reshape(n)
        self.velocity = np.asarray(velocity, float).reshape(n)
        if not (np.all(self.velocity > 0) and 0 < speed_scale <= 1 and rate_hz > 0):
            raise ValueError("a controller needs positive joint speeds, a speed scale in (0, 1] and a positive rate")
        self.speed_scale = float(speed_scale)
        self.rate_hz = float(rate_hz)
        self.clock = clock
        self.faults = faults if faults is not None else ControllerFaults()
        self._q = self._checked(home, "home")
        self._goal: np.ndarray | None = None
        self._fault: str | None = None
        self._motion: _Motion | None = None
        self._lock = threading.Lock()
        super().__init__()
        self._wake = threading.Event()
        self._closed = False
        self._thread = threading.Thread(target=self._run, name="robot-controller", daemon=True)
        self._thread.start()

    # ------------------------------------------------------------------ the interface
    def state(self) -> JointState:
        self._answering()
        with self._lock:
            return self._state_locked()

    def move(self, path: np.ndarray) -> None:
        """Follow ``path`` (k, n) from where the robot is; the first waypoint may be the current state."""
        self._answering()
        P = np.atleast_2d(np.asarray(path, float))
        if P.ndim != 2 or P.shape[1] != len(self.names) or len(P) == 0:
            raise ControllerError(
                f"a path needs waypoints of {len(self.names)} joints, got shape {P.shape}; plan it for this robot"
            )
        for k, q in enumerate(P):
            self._checked(q, f"waypoint {k}")
        with self._lock:
            if self._motion is not None:
                raise ControllerError("the robot is moving: stop it first, or wait for the motion to end")
            P = np.vstack([self._q, P])
            times = path_times(P, self.velocity * self.speed_scale)
            stall = None
            if self.faults.stall_joint in self.names:
                stall = (self.names.index(self.faults.stall_joint), float(self.faults.stall_at))
            self._motion = _Motion(P, times, self.clock(), stall)
            self._goal = P[-1].copy()
            self._fault = None
        self._wake.set()

    def stop(self) -> None:
        """Halt at once where the robot is (a stop is obeyed even by a controller that stopped answering
        its state: a real robot's stop is a separate circuit)."""
        with self._lock:
            if self._motion is None:
                return
            self._advance_locked()
            self._motion = None
            state = self._state_locked()
        self._tell(state)

    def _idle(self) -> bool:
        with self._lock:
            return self._motion is None

    def close(self) -> None:
        self._closed = True
        self._wake.set()
        self._thread.join(timeout=2.0)

    # ------------------------------------------------------------------ inside
    def _answering(self) -> None:
        if self.faults.silent:
            raise ControllerSilent("the robot's controller does not answer: check its link and power, then retry")

    def _checked(self, q, what: str) -> np.ndarray:
        q = np.asarray(q, float).reshape(-1)
        if q.shape != (len(self.names),) or not np.all(np.isfinite(q)):
            raise ControllerError(f"{what}: {len(self.names)} finite joint values needed, got {q.tolist()}")
        bad = np.flatnonzero((q < self.lower - 1e-9) | (q > self.upper + 1e-9))
        if len(bad):
            j = int(bad[0])
            raise ControllerError(
                f"{what}: joint {self.names[j]} at {np.degrees(q[j]):.1f}° is outside its limits "
                f"[{np.degrees(self.lower[j]):.1f}°, {np.degrees(self.upper[j]):.1f}°]"
            )
        return q

    def _state_locked(self) -> JointState:
        return JointState(
            self.names,
            self._q.copy(),
            self._motion is not None,
            self.clock(),
            self._fault,
            None if self._goal is None else self._goal.copy(),
        )

    def _advance_locked(self) -> bool:
        """Move the state to the motion's present; True when the motion has ended."""
        m = self._motion
        if m is None:
            return True
        t = self.clock() - m.t0
        done = t >= m.times[-1]
        q = _along(m, t)
        if m.stall is not None:
            j, share = m.stall
            if m.stalled_at is None and t >= share * m.times[-1]:
                m.stalled_at = float(_along(m, share * m.times[-1])[j])  # it stops following from there on
            if m.stalled_at is not None:
                q[j] = m.stalled_at
        self._q = q
        if done and m.stall is not None:
            j = m.stall[0]
            miss = float(np.max(np.abs(m.path[:, j] - self._q[j])))  # the farthest its command went from it
            if miss > 1e-6:
                self._fault = (
                    f"joint {self.names[j]} did not reach its command: it stopped following it, up to "
                    f"{np.degrees(miss):.1f}° short; the robot is stopped where it is"
                )
        return done

    def _run(self) -> None:
        period = 1.0 / self.rate_hz
        while not self._closed:
            with self._lock:
                moving = self._motion is not None
            if not moving:
                self._wake.wait(0.5)
                self._wake.clear()
                continue
            with self._lock:
                m = self._motion
                if m is None:
                    continue
                done = self._advance_locked()
                state = self._state_locked()
                passed = self._passed_locked(m, state)
            if done:
                state = dataclasses.replace(state, moving=False)
            for s in passed:  # a slow update (a loaded machine) still tells every waypoint the robot went through
                self._tell(s)
            self._tell(state)
            if done:
                # the motion ends once every listener has its last state: one that asks state() meanwhile still
                # hears "moving" (a frame drawn from the emulated world's joints after that is the robot at rest;
                # ending it first let a loaded machine's video draw the robot where it was, 0.6–0.8 m away)
                with self._lock:
                    if self._motion is m:
                        self._motion = None
            time.sleep(period)

    def _passed_locked(self, m: _Motion, now: JointState) -> list[JointState]:
        """The waypoints passed since the listeners were last told (a stalled joint where it stopped)."""
        k = int(np.searchsorted(m.times, self.clock() - m.t0, side="right")) - 1
        k = min(k, len(m.path) - 2)  # the last waypoint is the state itself at the end
        out = []
        for i in range(m.told + 1, k + 1):
            q = m.path[i].copy()
            if m.stalled_at is not None:
                q[m.stall[0]] = m.stalled_at
            out.append(JointState(self.names, q, True, now.t_s, None, now.goal))
        m.told = max(m.told, k)
        return out


def _along(m: _Motion, t: float) -> np.ndarray:
    """The motion's commanded joints at time t (s from its start; its end after it)."""
    if t >= m.times[-1]:
        return m.path[-1].copy()
    k = int(np.searchsorted(m.times, t, side="right")) - 1
    a = (t - m.times[k]) / max(m.times[k + 1] - m.times[k], 1e-12)
    return m.path[k] + a * (m.path[k + 1] - m.path[k])
