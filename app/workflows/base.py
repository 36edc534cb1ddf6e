"""What every workflow shares: operator errors, the marks a workflow asks the overlay to draw,
and the small state-machine base class.

A workflow is a guided sequence of operator actions (``click(uv)``, ``solve()``, ``accept()``,
``cancel()``, ...) with a ``next_step`` sentence telling the operator what to do now. It knows
nothing of the browser: the viser interface and the headless demo call the same methods.
Nothing reaches the database before ``accept()``; ``accept()`` writes in one transaction.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from core.brep import BRep

if TYPE_CHECKING:  # pragma: no cover
    from .site import Site

__all__ = ["WorkflowError", "Cancelled", "Ghost", "Marks", "Workflow", "as_pixel"]


class WorkflowError(ValueError):
    """An operator-level failure: the message says what went wrong and what to do next.

    Raised by workflow actions for degenerate clicks, missing steps, device faults, no range
    return, database conflicts. The workflow's state is unchanged by a failed action.
    """


class Cancelled(Exception):
    """A long action (aiming, scanning) was cancelled by the operator."""


@dataclass(frozen=True)
class Ghost:
    """A model drawn at a candidate pose: ``model`` (obj frame), ``T_world_obj`` (4, 4), ``label``;
    ``chosen`` draws it brighter."""

    model: BRep
    T_world_obj: np.ndarray
    label: str = ""
    chosen: bool = False


@dataclass
class Marks:
    """What a workflow wants drawn on the video, all in pixels of the current camera.

    points : (N, 2) accepted clicked points. pending : (M, 2) clicks waiting for their partner
    (the first end of a segment). segments : (K, 2, 2) clicked image segments.
    labels : list of (uv (2,), text). ghosts : candidate poses or a modelled preview.
    highlight : list of (object name, model edge index) to emphasise (assigned edges).
    residuals : (R, 2, 2) short lines from a clicked point to where the solution puts it.
    beam_uv : (2,) where the range finder's last measurement projects, or None.
    targets : (T, 2) designated targets. selected : the object the workflow is about.
    raw_segments : (K, 2, 2) / raw_points : (N, 2) the operator's clicks where a snapped click is
    used instead (drawn beside it in another colour). snap_lines : (M, 2, 2) image edges a snapped
    corner was found on. tracked : Ghosts of tracked poses (their own colour). found_points :
    (F, 2) image edge points that support a tracked pose; rejected_points : (R, 2) those the
    robust fit rejected.
    """

    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    pending: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    labels: list = field(default_factory=list)
    ghosts: list = field(default_factory=list)
    highlight: list = field(default_factory=list)
    residuals: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    beam_uv: np.ndarray | None = None
    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    selected: str | None = None
    raw_segments: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    raw_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    snap_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))
    tracked: list = field(default_factory=list)
    found_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    rejected_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))


def as_pixel(uv: Any) -> np.ndarray:
    """A clicked pixel as a finite array (2,); WorkflowError otherwise."""
    try:
        p = np.asarray(uv, dtype=float).reshape(2)
    except (TypeError, ValueError):
        raise WorkflowError(f"a click is a pixel (u, v), got {uv!r}") from None
    if not np.all(np.isfinite(p)):
        raise WorkflowError(f"the click {p.tolist()} is not a finite pixel; click on the video")
    return p


class Workflow:
    """Base class: a state machine driven by explicit operator actions.

    Subclasses set ``name`` (the id used by scripts and the UI), ``title``, ``actions`` (the
    public action method names a script may call) and implement ``next_step``, ``marks`` and
    ``summary``. ``state`` is a short string; ``finished`` is True once accepted or cancelled.
    Every action holds the workflow's lock: the UI's callbacks may arrive on several threads.
    """

    name: ClassVar[str] = ""
    title: ClassVar[str] = ""
    actions: ClassVar[tuple[str, ...]] = ("cancel",)
    snapping: ClassVar[bool] = False  # True: takes a ``snap`` option (clicks snapped to the image)

    def __init__(self, site: "Site", client: str = "operator"):
        self.site = site
        self.client = client
        self.state = "start"
        self.accepted = False
        self.cancelled = False
        self.message = ""  # the last outcome, shown under next_step
        self.lock = threading.RLock()
        self.cancel_event = threading.Event()

    # ------------------------------------------------------------------ common actions
    @property
    def finished(self) -> bool:
        return self.accepted or self.cancelled

    def cancel(self) -> None:
        """Abandon the workflow: nothing is written; a running measurement stops."""
        self.cancel_event.set()
        with self.lock:
            self.cancelled = True
            self.state = "cancelled"
            self.message = "Cancelled: nothing was written."

    def _check_open(self) -> None:
        if self.finished:
            raise WorkflowError(f"the {self.title} workflow is {'accepted' if self.accepted else 'cancelled'}; start a new one")

    # ------------------------------------------------------------------ what to show
    @property
    def next_step(self) -> str:  # pragma: no cover - abstract
        raise NotImplementedError

    def marks(self) -> Marks:
        """What to draw on the video now (pixels of the site's current camera)."""
        return Marks()

    def summary(self) -> dict[str, Any]:
        """Numbers to show the operator (RMS, residuals, σ ...), JSON-ready."""
        return {}

    def perform(self, action: str, **kwargs: Any) -> Any:
        """Call an action by name (for recorded scripts); WorkflowError for an unknown one."""
        if action not in self.actions:
            raise WorkflowError(f"{self.title} has no action {action!r}; it has {', '.join(self.actions)}")
        return getattr(self, action)(**kwargs)
