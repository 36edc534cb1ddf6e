"""The workflow's controls on a page, as the workflow declares them (``Workflow.controls`` and
``Workflow.current_step()``): one button or chooser per control, hidden while it does not apply, and a
keyboard shortcut per button (viser commands). A shortcut stays live when its control is hidden, so that
pressing it says why it does not apply; the keys of other workflows say they do nothing here."""

from __future__ import annotations

import functools
from typing import TYPE_CHECKING, Any

from app.workflows import WorkflowError
from app.workflows.base import KEY_TEXT
from app.workflows.session import WORKFLOWS

if TYPE_CHECKING:  # pragma: no cover
    from .client import ClientPanel

__all__ = ["WorkflowControls", "GLOBAL_KEYS", "NO_CHOICE", "button_label", "on_key"]

NO_CHOICE = "—"
GLOBAL_KEYS = {"f", "l", "h", "n"}  # the panel's own shortcuts (Freeze, Show live, Fit view, Next camera), always live


class WorkflowControls:
    """The controls of the workflow ``built_for`` on the page of ``panel``: ``handles`` (action → button or
    dropdown), the choosers' values (``choice_values``: action → the value chosen)."""

    def __init__(self, panel: ClientPanel):
        self.panel = panel
        self.built_for: Any = None  # the workflow whose controls are on screen
        self.handles: dict[str, Any] = {}
        self.commands: list[Any] = []  # keyboard shortcuts (viser commands), the other workflows' keys too
        self._command_of: dict[str, Any] = {}  # action → its shortcut
        self.choice_values: dict[str, Any] = {}
        self._options: dict[str, dict[str, Any]] = {}  # choice action → option text → value
        self.foreign_keys(None)

    def rebuild(self, wf) -> None:
        """The controls of ``wf`` (None or finished: none), as it declares them."""
        for handle in list(self.handles.values()) + self.commands:
            handle.remove()
        self.handles, self.commands, self._command_of = {}, [], {}
        self.choice_values, self._options = {}, {}
        self.built_for = wf
        self.foreign_keys(None if wf is None or wf.finished else wf)
        if wf is None or wf.finished:
            return
        panel, gui = self.panel, self.panel.client.gui
        live_keys = _live_shortcuts(wf.controls, wf.current_step().enabled)  # live from the start, no gap
        # Buttons made as they are to be shown: one made hidden and shown in the same redraw left its update queued
        # after viser had dropped the making (the workflow ended before the page took it), and the page logged
        # "Tried to update non-existent component" (a new operator's console).
        applies = _applies(wf, wf.current_step(), panel.busy)
        # The shortcuts first: the page takes the server's messages in order, so a button it shows has its key live
        # (a key pressed as the buttons appeared went nowhere when the page had taken a button but not yet its key).
        for c in wf.controls:
            if c.kind != "choice" and c.key is not None:
                cmd = gui.add_command(
                    f"{wf.title}: {c.label}",
                    hotkey=c.key,
                    description=c.hint or None,
                    disabled=live_keys.get(c.key) != c.action,
                )
                cmd.on_trigger(on_key(panel, functools.partial(panel.press_event, c.action)))
                self.commands.append(cmd)
                self._command_of[c.action] = cmd
        with panel.gui_actions:
            for c in wf.controls:
                if c.kind == "choice":
                    handle = gui.add_dropdown(
                        c.label, (NO_CHOICE,), initial_value=NO_CHOICE, hint=c.hint or None, visible=False
                    )
                    handle.on_update(panel.guard(functools.partial(self.on_choice, c.action)))
                else:
                    label, shown = button_label(c, panel.asking), c.action in applies
                    handle = gui.add_button(label, color=c.color, hint=c.hint or None, visible=shown)
                    handle.on_click(panel.guard(functools.partial(panel.press_event, c.action)))
                self.handles[c.action] = handle

    def foreign_keys(self, wf) -> None:
        """The keys of other workflows' controls, live here so that pressing one says it does nothing now
        and which keys do (a new operator pressed P, Solve in Update pose, in Designate: nothing said)."""
        own = {c.key.lower() for c in (wf.controls if wf is not None else ()) if c.key}
        by_label: dict[str, dict[str, list[str]]] = {}  # key → its label → the workflows it is that in
        for cls in WORKFLOWS.values():
            for c in cls.controls:
                if c.key and c.key.lower() not in own | GLOBAL_KEYS and (wf is not None or c.key != "escape"):
                    titles = by_label.setdefault(c.key, {}).setdefault(c.label, [])
                    if cls.title not in titles:
                        titles.append(cls.title)
        # every use said, grouped: "Solve in Calibrate camera, Model object; Refine in Update pose" (two of them
        # only left a new operator looking for the others)
        uses = {k: "; ".join(f"{label} in {', '.join(t)}" for label, t in d.items()) for k, d in by_label.items()}
        here = (
            f"{wf.title}'s keys: " + ", ".join(f"{c.key_text} {c.label}" for c in wf.controls if c.key)
            if wf is not None
            else "start a workflow first"
        )
        for key, where in sorted(uses.items()):
            name = KEY_TEXT.get(key, key.upper())

            def said(_event, name=name, where=where) -> None:
                raise WorkflowError(
                    f"{name} does nothing {'in ' + wf.title if wf is not None else 'now'} (it is {where}): {here}"
                )

            cmd = self.panel.client.gui.add_command(f"{name}: {where}", hotkey=key)
            cmd.on_trigger(on_key(self.panel, said))
            self.commands.append(cmd)

    def on_choice(self, action: str, _event=None) -> None:
        """The operator chose in the chooser of ``action``: remembered for the button that takes it, or
        acted on at once by a chooser that acts (candidate, method). The panel's own setting of a chooser
        (``_show_choices``: to what the workflow holds; viser calls this for it too) is not a choice."""
        if _event is not None and _event.client_id is None:
            return
        panel, handle = self.panel, self.handles.get(action)
        wf = panel.session.workflow
        if handle is None or wf is None or wf.finished:
            return
        options = self._options.get(action, {})
        if handle.value not in options:
            return
        value = options[handle.value]
        self.choice_values[action] = value
        if panel.confirm_pending is not None:  # a question about the item chosen before: it no longer applies
            asked = wf.control(panel.confirm_pending[0])
            if asked is not None and asked.arg == action and panel.confirm_pending[1] != (value,):
                panel.confirm_pending, panel.warning = None, ""
        if action in wf.actions and value != wf.choice_value(action):
            wf.message = ""
            wf.perform(action, value)

    def update(self, wf, step, busy: bool) -> None:
        """Show the controls that apply now (the others hidden), the choosers' options, shortcuts on/off."""
        if wf is None or step is None or wf is not self.built_for:
            return
        applies = _applies(wf, step, busy)
        keyed = _live_shortcuts(wf.controls, applies)
        asking = self.panel.asking
        for c in wf.controls:
            handle = self.handles.get(c.action)
            if handle is None:
                continue
            on = c.action in applies
            if handle.visible != on:
                handle.visible = on
            # of controls sharing a key (Pause/Resume) only the one that applies
            cmd, live = self._command_of.get(c.action), keyed.get(c.key) == c.action
            if cmd is not None and cmd.disabled == live:
                cmd.disabled = not live
            if c.kind == "choice" and on:
                self._show_choices(wf, c.action, handle)
            elif c.kind != "choice":
                label = button_label(c, asking)
                if handle.label != label:
                    handle.label = label

    def _show_choices(self, wf, action: str, handle) -> None:
        texts = {text: value for text, value in wf.choices(action)}
        options = tuple(texts) if texts else (NO_CHOICE,)
        if tuple(handle.options) != options:
            # viser sets the value to the first option when the old one is gone, and calls on_choice: known only
            # after this, the new options do not act on that (it chose a 5 mm standoff over the workflow's 20 mm)
            handle.options = options
        self._options[action] = texts
        current = wf.choice_value(action)
        if current is None:
            current = self.choice_values.get(action)
        shown = next((t for t, v in texts.items() if v == current), options[0])
        # what a button taking it uses: the value shown (the workflow's own choice too: Remove edge was refused with
        # "choose the edge first" while the chooser showed the one the workflow had chosen)
        if texts:
            self.choice_values[action] = texts[shown]
        else:
            self.choice_values.pop(action, None)
        if handle.value != shown:
            handle.value = shown


def _applies(wf, step, busy: bool) -> set[str]:
    """The actions of ``wf``'s controls that apply at ``step`` (only Cancel while a long action runs)."""
    return {c.action for c in wf.controls if c.action in step.enabled and not (busy and c.action != "cancel")}


def on_key(panel: ClientPanel, fn):
    """``fn`` as a shortcut's callback on ``panel``: guarded, and counted in ``panel.keys_received``."""
    guarded = panel.guard(fn)

    def triggered(*args, **kwargs):
        panel.keys_received += 1
        return guarded(*args, **kwargs)

    return triggered


def button_label(c, asking: str | None) -> str:
    """The label of control ``c``'s button: what pressing it does now. Asking once more about it (``asking``, the
    panel's question): "Accept anyway" for Accept, "<label>: confirm" for the others; else its own label."""
    if asking != c.action:
        return c.button_label
    label = "Accept anyway" if c.action == "accept" else f"{c.label}: confirm"
    return f"{label} ({c.key_text})" if c.key else label


def _live_shortcuts(controls, applies) -> dict[str, str]:
    """key → the action its shortcut triggers now: of the controls sharing a key (Pause/Resume), the
    first that applies; a key whose controls all are hidden stays live on the first of them, so that
    pressing it says why it does not apply (feedback)."""
    live: dict[str, str] = {}
    for c in controls:
        if c.key is not None and c.action in applies:
            live.setdefault(c.key, c.action)
    for c in controls:
        if c.key is not None:
            live.setdefault(c.key, c.action)
    return live
