"""One operator's session: the selected object and the workflow under way.

The viser interface keeps one ``Session`` per browser tab; the headless demo keeps one for its
script. Both start workflows by name and call their actions::

    session = Session(site, client="alice")
    wf = session.start("calibrate_camera")
    session.perform("click", uv=[120.0, 80.5])      # == wf.click([120.0, 80.5])
    session.perform("solve"); session.perform("accept")

The interface sends the operator's intents and the session decides what they mean: ``click`` and
``double_click`` (a click in a named camera: the workflow's, or a selection; a double click with no
workflow under way starts Update pose on the object and finds its pose from that point), ``start``.
An action may return a ``Detour`` (``act``): the workflow it names runs while the asking one waits
(``waiting``) with its work kept, and is back once the detour is accepted or cancelled (``Detour.returned``).

A script action is ``{"workflow": name, "action": name, **arguments}``: ``run_action`` starts the
workflow when it is not the current one (an action named "start" passes its arguments to it).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from .base import AS_CLICK, Detour, Workflow, WorkflowError
from .site import Site

__all__ = ["WORKFLOWS", "register", "Session"]

WORKFLOWS: dict[str, type[Workflow]] = {}


def register(cls: type[Workflow]) -> type[Workflow]:
    """Make a workflow class startable by its ``name``."""
    WORKFLOWS[cls.name] = cls
    return cls


class Session:
    """An operator's state: ``client`` (who, for the history), ``selected`` object, ``workflow``."""

    def __init__(self, site: Site, client: str = "operator"):
        self.site = site
        self.client = client
        self.selected: str | None = None
        self._workflow: Workflow | None = None
        self.waiting: Workflow | None = None  # set aside while a detour it asked for runs (``act``)
        self._returned: Callable[[Workflow], None] | None = None  # the waiting one's ``Detour.returned``
        self.snap = True  # snap clicks to the image (the panel's "Snap clicks"); passed to workflows that snap
        self.lock = threading.RLock()
        # called with each workflow started and the frame it is to work on (None: the interface's choice)
        self.on_start: Callable[[Workflow, Any], None] | None = None

    @property
    def workflow(self) -> Workflow | None:
        """The workflow under way (or the last one, finished); a detour accepted or cancelled gives the workflow
        that waited on it back (``Detour.returned`` told)."""
        wf = self._workflow
        if wf is not None and wf.finished and self.waiting is not None:
            with self.lock:
                if self._workflow is wf and self.waiting is not None:
                    back, self.waiting = self.waiting, None
                    self._workflow = back
                    returned, self._returned = self._returned, None
                    if returned is not None:
                        returned(wf)
                    else:
                        back.message = f"Back in {back.title} ({wf.state} in {wf.title}): your work here is kept."
        return self._workflow

    def select(self, name: str | None) -> None:
        """Select an object by name (None clears); WorkflowError if there is no such object."""
        with self.lock:
            if name is not None:
                try:
                    self.site.object(name)
                except KeyError as exc:
                    raise WorkflowError(str(exc.args[0])) from None
            self.selected = name

    def start(
        self, name: str, frame: Any = None, form: dict | None = None, *, detour: bool = False, **options: Any
    ) -> Workflow:
        """Start workflow ``name`` (cancelling an unfinished one, and one waiting on it; ``detour``: the one under
        way waits instead, ``act``); options go to its constructor, with those of the Start ``form`` it takes
        (``Workflow.form``); ``frame`` (the frame shown when the operator asked) goes to ``on_start``. A model
        object of a polyhedral shape (wedge, pyramid) is its own workflow, faces identified and sides assigned to
        edges."""
        form = form or {}
        if name == "model_object" and (form.get("shape") or options.get("shape")) in ("wedge", "pyramid"):
            name = "model_polyhedron"
            options.pop("vertical", None)
        cls = WORKFLOWS.get(name)
        if cls is not None:
            options = {**{k: v for k, v in form.items() if k in cls.form}, **options}
        if cls is None:
            raise WorkflowError(f"no workflow {name!r}; there are {', '.join(sorted(WORKFLOWS))}")
        why = cls.available(self.site)
        if why:  # the panel does not offer it; a script or a key might still ask
            raise WorkflowError(f"{cls.title}: {why}")
        with self.lock:
            current = self.workflow
            if detour and self.waiting is not None:
                raise WorkflowError(f"{cls.title}: finish {current.title} first (it is itself a detour)")
            if "object_name" in getattr(cls, "options", ()) and "object_name" not in options:
                if self.selected is None:
                    raise WorkflowError(f"{cls.title}: select an object first")
                options["object_name"] = self.selected
            if cls.snapping and "snap" not in options:
                options["snap"] = self.snap
            if not detour:
                self.cancel()
            try:
                wf = cls(self.site, client=self.client, **options)
            except TypeError as exc:
                raise WorkflowError(f"{cls.title}: bad options {sorted(options)}: {exc}") from None
            if detour and current is not None and not current.finished:
                self.waiting = current
                wf.message = f"{current.title} waits with your work kept: Accept or Cancel here goes back to it."
                if current.frame is not None:  # on the frame the waiting one found the object moved in
                    wf.use_frame(current.frame)
            self._workflow = wf
        if self.on_start is not None:
            self.on_start(wf, frame)
        return wf

    def click(
        self,
        view: str,
        uv: np.ndarray,
        *,
        on: str | None = None,
        live_shown: bool = False,
        px_per_screen_px: float = 1.0,
    ) -> None:
        """A click at pixel uv of camera ``view``: the workflow's while it takes clicks, else it selects ``on``
        (the object drawn there, or None). ``live_shown``: the operator looks at the live video over a frozen
        frame, where the workflow's clicks would not land on what they see. ``px_per_screen_px``: video pixels
        per screen pixel in the page's view, for the workflows that pick what lies within a few screen pixels of a
        click (``Workflow.click_px_per_screen_px``)."""
        wf = self.workflow
        if wf is not None and not wf.finished and "click" in wf.actions:
            if wf.current_step().clicks:
                if live_shown:
                    raise WorkflowError(
                        "you are looking at the live video: clicks go to the frozen frame. Press Show "
                        "frozen (L) to see it, then click"
                    )
                wf.message = ""
                scale = float(px_per_screen_px)
                wf.click_px_per_screen_px = scale if np.isfinite(scale) and scale > 0 else 1.0
                wf.click_in(view, uv)  # the workflow says whether it takes clicks in this camera
                return
            if not wf.follows_live():
                raise WorkflowError(f"clicks are not taken now. {wf.prompt_text(markdown=False)}")
        self.select(on)

    def double_click(
        self, view: str, uv: np.ndarray, *, before: str | None, on: str | None, frame: Any = None, live_shown=False
    ) -> str | None:
        """The second click of a double click at pixel uv of camera ``view`` (its first came as a click):
        the action it presses (Find), or None. ``before``: the object selected before its first click;
        ``on``: the object drawn at uv; ``frame``: the frame shown at its first click.

        With no workflow under way it finds the selected object's pose from that point: Update pose starts
        on ``frame`` and Find is pressed. The object is the one selected before the double click, even
        when its first click selected another whose wireframe runs there (the table's edge across the
        moved box); with none selected before, the one its first click selected; the table selected and
        the double click on another object, that object."""
        wf = self.workflow
        if wf is None or wf.finished:
            name = before if before is not None else self.selected
            if name is not None and on not in (None, name) and self.is_table(name):
                name = on
            if name is None:
                raise WorkflowError(
                    "a double click finds the pose of the selected object: select it by a click where the "
                    "database draws it, then double-click where it is in the video"
                )
            self.select(name)
            self.start("update_pose", frame=frame, view=view).click(uv)
            return "find"
        if "click" not in wf.actions:
            self.select(on)
            return None
        press = wf.on_double_click(view, uv)
        if press == AS_CLICK:
            self.click(view, uv, on=on, live_shown=live_shown)
            return None
        return press

    def is_table(self, name: str) -> bool:
        """The object ``name`` is the site's table (what the others stand on)."""
        try:
            return self.site.object(name).kind == "table"
        except (KeyError, ValueError):  # gone from the database meanwhile
            return False

    def set_snap(self, on: bool) -> None:
        """Snap clicks to the image (on) or not, from now on: in the workflow under way too."""
        with self.lock:
            self.snap = bool(on)
            wf = self.workflow
        if wf is not None and not wf.finished and wf.snapping:
            wf.set_snap(self.snap)

    def perform(self, action: str, **kwargs: Any) -> Any:
        """Call an action of the current workflow by name (``act``)."""
        wf = self.workflow
        if wf is None:
            raise WorkflowError(f"no workflow is under way; start one before {action!r}")
        return self.act(wf, action, **kwargs)

    def act(self, wf: Workflow, action: str, *args: Any, **kwargs: Any) -> Any:
        """``wf.perform(action, ...)``; a ``Detour`` it returns starts that workflow on the same frame while
        ``wf`` waits (returned: the detour)."""
        out = wf.perform(action, *args, **kwargs)
        if isinstance(out, Detour):
            with self.lock:
                if self.waiting is not None:
                    raise WorkflowError(f"finish {self._workflow.title} first: {self.waiting.title} waits on it")
                self._returned = out.returned
            try:  # (outside the lock: ``start`` calls the interface's ``on_start``)
                return self.start(out.workflow, detour=True, **{"view": wf.view, **out.options})
            except BaseException:
                with self.lock:
                    if self.waiting is None:
                        self._returned = None
                raise
        return out

    def cancel(self) -> None:
        """Cancel the workflow under way and one waiting on it, if any."""
        with self.lock:
            waiting, self.waiting = self.waiting, None
            wf = self._workflow
        for w in (wf, waiting):
            if w is not None and not w.finished:
                w.cancel()

    def run_action(self, step: dict[str, Any]) -> Any:
        """Replay one recorded action ``{"workflow", "action", **arguments}`` (extra keys such as
        ``"t"`` are ignored)."""
        step = dict(step)
        step.pop("t", None)
        name = step.pop("workflow", None)
        action = step.pop("action", None)
        if not name or not action:
            raise WorkflowError(f"a recorded action needs 'workflow' and 'action', got {sorted(step)}")
        if action == "start" or self.workflow is None or self.workflow.name != name or self.workflow.finished:
            options = step if action == "start" else {}
            self.start(name, **options)
            if action == "start":
                return self.workflow
        return self.perform(action, **step)
