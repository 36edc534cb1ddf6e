"""What every workflow shares: operator errors, the marks a workflow asks the overlay to draw,
and the small state-machine base class.

A workflow is a guided sequence of operator actions (``click(uv)``, ``solve()``, ``accept()``,
``cancel()``, ...) with a ``next_step`` sentence telling the operator what to do now. It knows
nothing of the browser: the viser interface and the headless demo call the same methods.
Nothing reaches the database before ``accept()``; ``accept()`` writes in one transaction.
"""

from __future__ import annotations

import re
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np

from app.markup import Md, escape
from core.brep import BRep

if TYPE_CHECKING:  # pragma: no cover
    from .site import Site

__all__ = [
    "WorkflowError",
    "Cancelled",
    "Ghost",
    "Marks",
    "Workflow",
    "PICK_RADIUS_SCREEN_PX",
    "pick_radius_px",
    "as_pixel",
    "Control",
    "Step",
    "FrameRef",
    "CANCEL",
    "KEY_TEXT",
    "AS_CLICK",
    "Detour",
]

# What a click picks (a model's corner or edge, the white robot's edge, a face's centre) lies within this many screen
# pixels of it; in video pixels it depends on the page's zoom (``pick_radius_px``).
PICK_RADIUS_SCREEN_PX = 12.0


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
    highlight : list of (object name, model edge index[, T_world_obj (4, 4)]) to emphasise (assigned
    edges), at the object's database pose or at the pose given.
    residuals : (R, 2, 2) short lines from a clicked point to where the solution puts it.
    beam_uv : (2,) where the range finder's last measurement projects, or None.
    targets : (T, 2) designated targets. selected : the object the workflow is about.
    raw_segments : (K, 2, 2) / raw_points : (N, 2) the operator's clicks where a snapped click is
    used instead (drawn beside it in another colour). snap_lines : (M, 2, 2) image edges a snapped
    corner was found on. tracked : Ghosts of tracked poses (their own colour). found_points :
    (F, 2) image edge points that support a tracked pose; rejected_points : (R, 2) those the
    robust fit rejected. circles : (C, 2) pixels to circle (the picked model corner). live_points :
    (L, 2) range points of a scan under way. assigned_lines : (A, 2, 2) the model edges (not an object's: the
    robot's) that clicked edges are assigned to, highlighted as ``highlight``'s.
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
    circles: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # pixels to circle (a picked corner)
    live_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # range points measured so far
    robot_ghost: list = field(default_factory=list)  # [(link, BRep, T_world)] the robot where a motion ends
    robot_contact: list = field(default_factory=list)  # [(link, BRep, T_world)] the robot where a refused one hits
    robot_path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))  # the tool's way there, pixels
    assigned_lines: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))  # the model edges assigned, px


# How a shortcut key reads on a button (viser's hotkey names → what the keyboard shows).
KEY_TEXT = {"enter": "Enter", "escape": "Esc", "backspace": "Backspace", "delete": "Del", "space": "Space"}


@dataclass(frozen=True)
class Control:
    """A control a workflow owns: a button (or a chooser) the panel shows while the workflow runs.

    action : the workflow method it calls (also the name a step's prompt uses: ``{solve}``).
    label : what the button says; the panel adds the shortcut key, e.g. "Solve (R)".
    key : a viser hotkey ("R", "enter", "escape", "backspace", ...) or None. Keys the viewer uses
        to move its camera (W A S D Q E, arrows) are not allowed.
    kind : "button" (runs at once), "long" (a device measurement: runs on a worker, the progress
        bar and Cancel stay live), "choice" (a dropdown: choosing an option calls ``action(value)``;
        its options come from ``Workflow.choices(action)``).
    arg : for a button that acts on one item, the ``choice`` control whose value it takes
        (e.g. "Delete click" takes the click chosen in the residual table's chooser).
    color : the button's colour (viser's names), None for the default.
    confirm : a question asked once more before the action runs (e.g. Redo, which forgets every click).
    """

    action: str
    label: str
    key: str | None = None
    kind: str = "button"
    arg: str | None = None
    color: str | None = None
    hint: str = ""
    confirm: str = ""

    def __post_init__(self) -> None:
        if self.kind not in ("button", "long", "choice"):
            raise ValueError(f"a control's kind is button, long or choice, got {self.kind!r}")
        if self.key is not None and self.key.upper() in set("WASDQE"):
            raise ValueError(f"key {self.key!r} moves the viewer's camera; choose another for {self.label!r}")

    @property
    def key_text(self) -> str:
        return "" if self.key is None else KEY_TEXT.get(self.key, self.key.upper())

    @property
    def button_label(self) -> str:
        """The label with its shortcut: "Solve (R)"."""
        return f"{self.label} ({self.key_text})" if self.key else self.label


CANCEL = Control("cancel", "Cancel", "escape", color="red", hint="Abandon this workflow: nothing is written")

AS_CLICK = "click"  # Workflow.on_double_click: the second click is one more click


@dataclass(frozen=True)
class Detour:
    """What an action returns to have another workflow run while its own waits with its work kept
    (``Session.act``): ``workflow`` started with ``options``; once it is accepted or cancelled the waiting one
    is back, and ``returned`` is called with the detour (the waiting one's method: it checks again what the
    detour changed, and says so). Calibrate turret asks for Update pose of an object its beams or its frame
    found moved: the turret's measurements stay."""

    workflow: str
    options: dict = field(default_factory=dict)
    returned: Callable[[Any], None] | None = field(default=None, compare=False)


_PLACEHOLDER = re.compile(r"\{([a-z_]+)\}")


@dataclass(frozen=True)
class Step:
    """Where a workflow stands: what the operator is asked to do and which controls apply.

    name : a short state name (tests walk them). prompt : the instruction; ``{action}`` names a
    control (rendered as its label), and may only name an enabled one. enabled : the actions whose
    controls are enabled now (others are disabled). clicks : True when clicks on the video are
    taken now (False: a click selects an object instead, or is refused while measuring).
    """

    name: str
    prompt: str
    enabled: frozenset = frozenset()
    clicks: bool = True

    def named(self) -> list[str]:
        """The actions the prompt names."""
        return _PLACEHOLDER.findall(self.prompt)


MOTION_GAP_S = 0.3  # FrameRef.previous: how long before the frozen frame (a few video frames)
# A frozen frame taken this long before its camera's newest may no longer show the site: what is measured
# or looked up now is said to be of the site now, with the frame's age (a new operator designated a point
# drawn on a box in a frame frozen 30 s before and was told "on table, range finder agrees").
STALE_FRAME_S = 10.0


@dataclass(frozen=True)
class FrameRef:
    """The video frame a workflow's clicks, snapping and solving use (frozen when it starts).

    image : (H, W, 3) or (H, W) uint8. t_s : its scene time (seconds). index : its frame number in
    the source (-1 when unknown). source : where it came from ("live", "scrubbed", "scene video"). view :
    the camera it came from.
    previous : the frame shown about ``MOTION_GAP_S`` before it, when the interface kept one (to see
    whether what was clicked on was moving: ``Workflow.moving_share``), else None."""

    image: np.ndarray
    t_s: float
    index: int = -1
    source: str = "live"
    previous: np.ndarray | None = field(default=None, compare=False, repr=False)
    view: str = ""  # the camera it came from ("": not said, the site's first)
    # the other cameras' frames shown at the same moment (camera name → FrameRef): clicks in them use these
    others: dict = field(default_factory=dict, compare=False, repr=False)
    gap_s: float = 0.0  # for one of ``others``: how long after the frozen frame it arrived (seconds)
    stamp: float | None = None  # when the image was taken (unix seconds, ``app.video.Frame.stamp``)

    def record(self) -> dict[str, Any]:
        """JSON-ready: which frame was used (for the history)."""
        out = {"t_s": round(float(self.t_s), 3), "index": int(self.index), "source": self.source}
        if self.stamp is not None:
            out["stamp"] = round(float(self.stamp), 6)
        return {**out, "view": self.view} if self.view else out

    def changed_in(self, live: np.ndarray | None, uv: Any) -> str:
        """ "" when the ``live`` image around the pixels ``uv`` (N, 2) still looks as in this frame (or
        there is no live image); otherwise why not, as a sentence's start. The range finder and the
        turret measure the site as it is now: a measurement where the site changed since this frame lands
        on something it does not show (app.vision.change)."""
        if live is None or live is self.image or np.shape(live) != np.shape(self.image):
            return ""
        from app.vision.change import CHANGED_SHARE, changed_share

        if changed_share(self.image, live, np.asarray(uv, float).reshape(-1, 2)) <= CHANGED_SHARE:
            return ""
        return (
            f"the live video here differs from the frozen frame (t = {self.t_s:.1f} s): something moved since, "
            "and the range finder measures the site as it is now"
        )

    def moving_share(self, uv: Any) -> float | None:
        """The largest share of changed pixels around the pixels ``uv`` (N, 2) between ``previous`` and this
        frame (``app.vision.change.changed_share``): above ``CHANGED_SHARE`` what lies there was moving when
        the frame was taken. None when no earlier frame is known."""
        if self.previous is None or np.shape(self.previous) != np.shape(self.image):
            return None
        from app.vision.change import changed_share

        # the view's own motion taken off (a camera turned or carried): what moved with it was not moving
        return changed_share(self.previous, self.image, np.asarray(uv, float).reshape(-1, 2), follow_camera=True)

    def object_motion_px(self, outline_uv: Any) -> float | None:
        """How far the object inside ``outline_uv`` (N, 2) moved between ``previous`` and this frame against
        what is around it (``app.vision.change.object_motion_px``); None when no earlier frame is known or its
        image gives too little to follow."""
        if self.previous is None or np.shape(self.previous) != np.shape(self.image):
            return None
        from app.vision.change import object_motion_px

        return object_motion_px(self.previous, self.image, outline_uv)


def sigma_over(sd_deg: float, sd_mm: float, max_deg: float, max_mm: float) -> str:
    """ "σ up to 1.17° and 26.4 mm: the position's is above 20 mm" — which of the two exceeds its limit
    (a weak result's reason, said so that 1.17° does not read as above 2°)."""
    over = [f"the rotation's is above {max_deg:g}°"] if sd_deg > max_deg else []
    over += [f"the position's is above {max_mm:g} mm"] if sd_mm > max_mm else []
    return f"σ up to {sd_deg:.2f}° and {sd_mm:.1f} mm" + (f": {' and '.join(over)}" if over else "")


def as_pixel(uv: Any) -> np.ndarray:
    """A clicked pixel as a finite array (2,); WorkflowError otherwise."""
    try:
        p = np.asarray(uv, dtype=float).reshape(2)
    except (TypeError, ValueError):
        raise WorkflowError(f"a click is a pixel (u, v), got {uv!r}") from None
    if not np.all(np.isfinite(p)):
        raise WorkflowError(f"the click {p.tolist()} is not a finite pixel; click on the video")
    return p


def pick_radius_px(wf: Workflow) -> float:
    """PICK_RADIUS_SCREEN_PX in video pixels at the zoom of ``wf``'s last click (its ``click_px_per_screen_px``)."""
    return PICK_RADIUS_SCREEN_PX * wf.click_px_per_screen_px


class Workflow:
    """Base class: a state machine driven by explicit operator actions. Subclasses set ``name`` (the id used by
    scripts and the UI), ``title``, ``actions`` (the public action method names a script may call) and implement
    ``next_step``, ``marks`` and ``summary``. ``state`` is a short string; ``finished`` is True once accepted or
    cancelled. Every action holds the workflow's lock (the UI's callbacks may arrive on several threads)."""

    name: ClassVar[str] = ""
    title: ClassVar[str] = ""
    actions: ClassVar[tuple[str, ...]] = ("cancel",)
    controls: ClassVar[tuple[Control, ...]] = (CANCEL,)  # what the panel shows, in order
    object_name: str | None = None  # the object the workflow is about (shown in its title), if any
    obj: Any = None  # a pose workflow's snapshot of that object (SiteObject) it started from
    progress: float | None = None  # a measurement under way: 0..1 (the panel's progress bar), else None
    progress_text: str = ""
    stepped_on: Any = None  # the video frame its last step was on (Track's): frozen when it stops following
    snapping: ClassVar[bool] = False  # True: takes a ``snap`` option (clicks snapped to the image)
    form: ClassVar[tuple[str, ...]] = ()  # the Start form's options it takes (shape, vertical, on_table)
    follows_video: ClassVar[bool] = False  # True: the interface feeds it the live video while it runs
    shows_beam: ClassVar[bool] = False  # True: the range finder's spot it showed goes when it ends
    selects_result: ClassVar[bool] = False  # True: the object it made is selected once accepted
    click_px_per_screen_px: float = 1.0  # video pixels per screen pixel where the last click was made (Session.click)

    def __init__(self, site: Site, client: str = "operator", view: str | None = None):
        self.site = site
        self.client = client
        try:  # the camera (view) it works in: its clicks, frame and calibration are that view's
            self.view = site.view_name(view)
        except ValueError as exc:
            raise WorkflowError(str(exc)) from None
        self.state = "start"
        self.accepted = False
        self.cancelled = False
        self.message = ""  # the last outcome, shown under next_step
        self.lock = threading.RLock()
        self.cancel_event = threading.Event()
        self.frame: FrameRef | None = None  # the frozen frame (None: the site's frame at the scene time)

    @property
    def camera(self):
        """The current calibration of the workflow's camera (``view``): the global model C."""
        return self.site.camera_of(self.view)

    click_view: str | None = None  # the camera of the click being handled (a workflow taking several: its own)

    def _click_camera(self):
        """The calibration of the camera the click being handled was made in."""
        return self.site.camera_of(self.click_view or self.view)

    def frame_in(self, view: str) -> FrameRef | None:
        """The frame the clicks in camera ``view`` use: the frozen frame in its own, the other cameras'
        frames frozen with it in theirs; None when none was frozen."""
        if self.frame is None:
            return None
        return self.frame if view == self.view else self.frame.others.get(view)

    def click_in(self, view: str, uv) -> None:
        """A click at pixel uv of camera ``view``: this workflow's clicks are in its own camera only."""
        if view != self.view:
            raise WorkflowError(
                f"{self.title} works in camera {self.view}: show it (the Camera chooser, or N) to click, or Cancel "
                f"and start it again in camera {view}"
            )
        self.click(uv)

    def on_double_click(self, view: str, uv) -> str | None:
        """The second click of a double click at pixel uv of camera ``view`` (its first came as a click):
        the action it presses, ``AS_CLICK`` to take it as one more click, or None to drop it."""
        return AS_CLICK

    def follows_live(self) -> str:
        """Why it works on the live video now and takes no frozen frame, as a sentence ("": it takes one)."""
        return ""

    @classmethod
    def available(cls, site: Any) -> str:
        """Why this workflow cannot run on ``site`` ("" when it can): the panel offers only those that can."""
        return ""

    def tick(self) -> bool:
        """Called at the interface's frame rate: follow what changes without the operator (a robot moving);
        True when what the panel shows changed."""
        return False

    def has_work(self) -> bool:
        """Cancel would throw work away (clicks, measurements): the panel asks once more first."""
        return "remove_last" in self.current_step().enabled

    def marks_in(self, view: str) -> Marks:
        """What to draw on camera ``view``'s image: ``marks()`` on the workflow's own camera, nothing elsewhere."""
        return self.marks() if view == self.view else Marks()

    # ------------------------------------------------------------------ common actions
    @property
    def finished(self) -> bool:
        return self.accepted or self.cancelled

    def stop_measurement(self) -> None:
        """Stop the measurement (or search) under way, keeping the workflow and what was done before it
        (the acquisition raises Cancelled; the next one clears the request)."""
        self.cancel_event.set()

    def cancel(self) -> None:
        """Abandon the workflow: nothing is written; a running measurement stops."""
        self.cancel_event.set()
        with self.lock:
            self.cancelled = True
            self.state = "cancelled"
            self.message = "Cancelled: nothing was written."

    def _check_open(self) -> None:
        if self.finished:
            raise WorkflowError(
                f"the {self.title} workflow is {'accepted' if self.accepted else 'cancelled'}; start a new one"
            )

    # ------------------------------------------------------------------ the frame used
    def use_frame(self, frame: FrameRef | None) -> None:
        """Work on ``frame`` from now on (the panel freezes one when the workflow starts)."""
        with self.lock:
            self.frame = frame

    def scene_changed(self, uv: Any) -> str:
        """``FrameRef.changed_in`` of the frozen frame against the live video of the workflow's camera."""
        return "" if self.frame is None else self.frame.changed_in(self.site.frame_at(None, self.view), uv)

    def moving_share(self, uv: Any) -> float | None:
        """``FrameRef.moving_share`` of the frozen frame (None: no frame frozen)."""
        return None if self.frame is None else self.frame.moving_share(uv)

    def seen_at(self) -> float | None:
        """When the clicked image was taken (unix s): the frozen frame's, else the camera's newest (None: unknown)."""
        frame = self.frame if self.frame is not None else self.site.latest_frame(self.view)
        return None if frame is None else getattr(frame, "stamp", None)

    def frame_record(self) -> dict[str, Any] | None:
        """Which frame the clicks were made on, for the history (None: the site's frame at the time)."""
        return None if self.frame is None else self.frame.record()

    # ------------------------------------------------------------------ steps and controls
    def _step(self) -> Step:
        """The current step: prompt and enabled controls (each workflow declares its own; use ``current_step``)."""
        if self.finished:
            return self._finished_step()
        return Step("open", "Cancel to close.", frozenset({"cancel"}))

    def _finished_step(self) -> Step:
        return Step(
            "accepted" if self.accepted else "cancelled",
            self.message or ("Done." if self.accepted else "Cancelled: nothing was written."),
            frozenset(),
            False,
        )

    def control(self, action: str) -> Control | None:
        """This workflow's control for ``action``, or None."""
        return next((c for c in self.controls if c.action == action), None)

    def current_step(self) -> Step:
        """``_step()`` checked: every enabled action has a control, and the prompt names only enabled
        controls (an internal invariant: tests walk every state)."""
        with self.lock:
            st = self._step()
        known = {c.action for c in self.controls}
        assert st.enabled <= known, f"{self.name}/{st.name}: enabled {sorted(st.enabled - known)} have no control"
        named = set(st.named())
        assert named <= st.enabled, f"{self.name}/{st.name}: the prompt names {sorted(named - st.enabled)}, not enabled"
        return st

    def prompt_text(self, markdown: bool = True) -> str:
        """The current prompt with each named control as its label: plain text, or ``Md`` with the
        labels in bold and the rest escaped (a prompt may name an object)."""
        st = self.current_step()

        def label(action: str) -> str:
            c = self.control(action)
            return c.label if c is not None else action

        if not markdown:
            return _PLACEHOLDER.sub(lambda m: label(m.group(1)), st.prompt)
        parts, pos = [], 0
        for m in _PLACEHOLDER.finditer(st.prompt):
            parts += [escape(st.prompt[pos : m.start()]), Md("**{}**").format(label(m.group(1)))]
            pos = m.end()
        return Md("").join(parts + [escape(st.prompt[pos:])])

    @property
    def next_step(self) -> str:
        """The instruction in plain text (the current step's prompt)."""
        return self.prompt_text(markdown=False)

    def choices(self, action: str) -> list[tuple[str, Any]]:
        """Options (text, value) of the ``choice`` control ``action`` (e.g. the clicks that can be
        deleted, the candidate poses)."""
        return []

    def question(self, action: str, *args: Any) -> str:
        """What to ask the operator once more before ``action(*args)`` runs ("" to run at once): the
        control's fixed question, or one that depends on the state (an undo that discards later changes)."""
        c = self.control(action)
        return c.confirm if c is not None else ""

    def choice_value(self, action: str) -> Any:
        """The value the ``choice`` control ``action`` shows now (None: the operator's last choice)."""
        return None

    def weaknesses(self) -> list[str]:
        """Why the result about to be accepted is weak (empty when it is not): σ above a stated
        threshold, a residual above 3σ, a snap that moved more than 2 px, nothing redundant. The
        panel shows them and asks once more before Accept."""
        return []

    # ------------------------------------------------------------------ what to show

    def marks(self) -> Marks:
        """What to draw on the video now (pixels of the site's current camera)."""
        return Marks()

    def summary(self) -> dict[str, Any]:
        """Numbers to show the operator (RMS, residuals, σ ...), JSON-ready."""
        return {}

    def copy_text(self) -> str:
        """Text the operator copies from the panel (a designated target's coordinates), or ""."""
        return ""

    def perform(self, action: str, *args: Any, **kwargs: Any) -> Any:
        """Call an action by name (recorded scripts, the panel's controls); WorkflowError for an unknown one."""
        if action not in self.actions:
            raise WorkflowError(f"{self.title} has no action {action!r}; it has {', '.join(self.actions)}")
        return getattr(self, action)(*args, **kwargs)
