"""What a page's panel says: the workflow under way (its title, camera, instruction, last outcome, a weak
result's reasons, a refused action), its result, the frame shown, and what to do with none under way.
Every text from the database or the workflow is escaped on its way to Markdown (app.markup)."""

from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

from app.markup import Md, as_markdown

from .controls import report_markdown, result_headline

if TYPE_CHECKING:  # pragma: no cover
    from .client import ClientPanel

__all__ = ["PanelText", "show", "idle_text"]

log = logging.getLogger("mcit.ui")


class PanelText:
    """The texts of ``panel``; ``finished_at``: (the finished workflow, when this page saw it finish, the
    selection then), so that its text goes once the operator selects another object."""

    def __init__(self, panel: ClientPanel):
        self.panel = panel
        self.finished_at: tuple | None = None
        self._weak_key: tuple | None = None
        self._weak: list[str] = []

    def moved_on(self, wf) -> None:
        """The operator moved on (froze a frame): a finished workflow's text goes."""
        if wf is not None and wf.finished and self.finished_at is not None and self.finished_at[0] is wf:
            self.finished_at = (wf, self.finished_at[1], object())

    def update(self, wf, busy: bool) -> None:
        """Draw the texts and the workflow's controls (``busy``: a long action runs, as the redraw read it)."""
        panel = self.panel
        selected = panel.session.selected
        if wf is not None and wf.finished and self.finished_at is not None and self.finished_at[0] is wf:
            if self.finished_at[2] != selected:
                # a finished workflow's text goes once the operator selects another object, and does not
                # come back with the selection it finished with (a new operator's Designate "closed" text did)
                self.finished_at = (wf, self.finished_at[1], object())
                wf = None
        step = None if wf is None else wf.current_step()
        if wf is None:
            title, report, headline = Md("**No workflow.** ") + idle_text(selected), "", ""
            base = panel.app.site.robot_base_warning()
            if base:  # said while nothing is under way: a Move would be asked about it once more
                title += Md("\n\n⚠ {} (Calibrate robot).").format(base.rsplit(".", 1)[0])
        else:
            title, report, headline = self._workflow_text(wf, step)
        if panel.error:
            title += Md("\n\n⚠ {}").format(panel.error)
        show(panel.gui_title, title)
        show(panel.gui_report, report)
        panel.gui_headline.visible = bool(headline)
        show(panel.gui_headline, headline)
        panel.gui_warning.visible = bool(panel.warning)
        show(panel.gui_warning, panel.warning)
        panel.workflow_controls.update(wf, step, busy)
        text = wf.copy_text() if wf is not None and not wf.finished else ""
        panel.gui_copy.visible = bool(text)
        if text and panel.gui_copy.value != text:
            panel.gui_copy.value = text
        frozen = panel.frozen_frames
        show(panel.gui_frame, frozen.text(panel.feed.grabber.status().live))
        panel.gui_live.visible = frozen.frame is not None  # nothing frozen: the live video is what is shown
        if frozen.frame is not None and frozen.by is None:  # frozen to look at, no workflow's: L goes back to live
            live_label = "Back to live (L)"
        else:
            live_label = "Show frozen (L)" if frozen.show_live and frozen.frame is not None else "Show live (L)"
        if panel.gui_live.label != live_label:  # says what it does now
            panel.gui_live.label = live_label

    def _workflow_text(self, wf, step) -> tuple[Md, str, str]:
        panel = self.panel
        closes = wf.control("accept")  # History's Close, Designate's Done: nothing is accepted
        done = "accepted" if closes is None or closes.label == "Accept" else "closed"
        if wf.finished and (self.finished_at is None or self.finished_at[0] is not wf):
            if wf.accepted and wf.selects_result and wf.object_name:
                try:  # the object just made is selected: Update pose, Track … apply to it next
                    panel.session.select(wf.object_name)
                except ValueError:
                    pass
            self.finished_at = (wf, time.strftime("%H:%M:%S"), panel.session.selected)  # when this page saw it
        at = f" at {self.finished_at[1]}" if wf.finished else ""  # a finished workflow's text says when
        state = f" ({done}{at})" if wf.accepted else (f" (cancelled{at})" if wf.cancelled else "")
        subject = wf.object_name
        title = Md("**{}**{}").format(f"{wf.title}: {subject}" if subject else wf.title, state)
        waiting = panel.session.waiting  # a detour's: Accept or Cancel goes back to it
        if waiting is not None and waiting is not wf and not wf.finished:
            title += Md(" · then back to **{}**, which waits with your work kept").format(waiting.title)
        if len(panel.app.views) > 1:  # which camera it works in, and which is shown
            title += Md(" · in camera **{}**").format(wf.view)
            if wf.view != panel.camera_view:
                title += Md(" (camera {} shown)").format(panel.camera_view)
        title += Md("\n\n") + wf.prompt_text()
        said = wf.prompt_text(markdown=False)
        if wf.message and not wf.finished and not panel.warning and wf.message[:40] not in said:
            title += Md("\n\n_{}_").format(
                wf.message.strip()
            )  # (a space before the closing _ showed the _ raw)  # not said twice, nor above a question being asked
        weak = [w for w in self.weaknesses(wf, step) if w not in wf.message]  # not said twice
        if weak and not panel.warning:  # said with the result, not first at Accept (a new operator's)
            title += Md("\n\n⚠ **Check before accepting:** {}.").format("; ".join(weak))
        if wf.finished:
            title += Md("\n\n") + idle_text(panel.session.selected)
        # a cancelled result is gone; a closed one (History, Designate: nothing accepted) too
        summary = {} if wf.cancelled or (wf.finished and done == "closed") else wf.summary()
        if panel.error and panel.error_step is not None and step.name != panel.error_step:
            panel.error = ""  # said in a step the workflow has left
        return title, report_markdown(summary), result_headline(summary)

    def weaknesses(self, wf, step) -> list[str]:
        """The result's weaknesses while Accept applies (``Workflow.weaknesses``), read again only when the
        workflow's step, message or choices changed."""
        if wf.finished or "accept" not in step.enabled:
            return []
        choices = tuple(repr(wf.choice_value(c.action)) for c in wf.controls if c.kind == "choice")
        key = (id(wf), step.name, wf.message, choices)
        if self._weak_key != key:
            self._weak_key = key
            try:
                self._weak = list(wf.weaknesses())
            except Exception:  # noqa: BLE001 - Accept asks again anyway
                log.exception("weaknesses of %s failed", wf.title)
                self._weak = []
        return self._weak


def show(handle, content) -> None:
    """Set a Markdown element's content: ``Md`` as written, any other text escaped (app.markup)."""
    text = as_markdown(content)
    if handle.content != text:
        handle.content = text


def idle_text(selected: str | None) -> str:
    """What the panel says with no workflow under way."""
    if selected is None:
        return Md("Click an object to select it, or start a workflow below.")
    return Md(
        "**{}** is selected: double-click where it is in the video to find its pose, start a workflow below "
        "(Update pose, Track, …), or click another object."
    ).format(selected)
