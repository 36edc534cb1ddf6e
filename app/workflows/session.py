"""One operator's session: the selected object and the workflow under way.

The viser interface keeps one ``Session`` per browser tab; the headless demo keeps one for its
script. Both start workflows by name and call their actions::

    session = Session(site, client="alice")
    wf = session.start("calibrate_camera")
    session.perform("click", uv=[120.0, 80.5])      # == wf.click([120.0, 80.5])
    session.perform("solve"); session.perform("accept")

A script action is ``{"workflow": name, "action": name, **arguments}``: ``run_action`` starts the
workflow when it is not the current one (an action named "start" passes its arguments to it).
"""

from __future__ import annotations

import threading
from typing import Any

from .base import Workflow, WorkflowError
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
        self.workflow: Workflow | None = None
        self.snap = True  # snap clicks to the image (the panel's "Snap clicks"); passed to workflows that snap
        self.lock = threading.RLock()

    def select(self, name: str | None) -> None:
        """Select an object by name (None clears); WorkflowError if there is no such object."""
        with self.lock:
            if name is not None:
                try:
                    self.site.object(name)
                except KeyError as exc:
                    raise WorkflowError(str(exc.args[0])) from None
            self.selected = name

    def start(self, name: str, **options: Any) -> Workflow:
        """Start workflow ``name`` (cancelling an unfinished one); options go to its constructor."""
        cls = WORKFLOWS.get(name)
        if cls is None:
            raise WorkflowError(f"no workflow {name!r}; there are {', '.join(sorted(WORKFLOWS))}")
        with self.lock:
            if self.workflow is not None and not self.workflow.finished:
                self.workflow.cancel()
            if "object_name" in getattr(cls, "options", ()) and "object_name" not in options:
                if self.selected is None:
                    raise WorkflowError(f"{cls.title}: select an object first")
                options["object_name"] = self.selected
            if cls.snapping and "snap" not in options:
                options["snap"] = self.snap
            try:
                self.workflow = cls(self.site, client=self.client, **options)
            except TypeError as exc:
                raise WorkflowError(f"{cls.title}: bad options {sorted(options)}: {exc}") from None
            return self.workflow

    def set_snap(self, on: bool) -> None:
        """Snap clicks to the image (on) or not, from now on: in the workflow under way too."""
        with self.lock:
            self.snap = bool(on)
            wf = self.workflow
        if wf is not None and not wf.finished and wf.snapping:
            wf.set_snap(self.snap)

    def perform(self, action: str, **kwargs: Any) -> Any:
        """Call an action of the current workflow by name."""
        wf = self.workflow
        if wf is None:
            raise WorkflowError(f"no workflow is under way; start one before {action!r}")
        return wf.perform(action, **kwargs)

    def cancel(self) -> None:
        """Cancel the workflow under way, if any."""
        wf = self.workflow
        if wf is not None and not wf.finished:
            wf.cancel()

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
