"""Feeding a Track workflow the live video, on its own thread (never the redraw loop's).

One ``TrackFeeder`` per tracked object (per Track workflow): woken by each new frame of the
grabber, it hands the latest frame to ``TrackObject.step`` (frames that arrive while a step runs
are skipped: the tracker always works on the newest one), marks the client's overlay dirty and
wakes the redraw loop. It notifies the operator when the track is lost (and once more on an
unexpected failure, which stops it), and ends when the workflow is accepted or cancelled.
"""

from __future__ import annotations

import logging
import threading
from typing import Any

from app.workflows import WorkflowError

__all__ = ["TrackFeeder"]

log = logging.getLogger("mcit.ui")


class TrackFeeder:
    """Runs ``wf.step(frame)`` for every new frame of ``grabber`` while the workflow follows.

    panel : the client's panel (``notify``, ``dirty``, ``app.wake``). wf : a TrackObject.
    grabber : app.video.FrameGrabber.
    recent : the frames kept of that video (``app.ui.recent.RecentFrames``), None: none. start : the frame whose
    pose the workflow holds (image, t_s, index, stamp: a frame frozen when Track started, the database's pose right
    there): tracked first, then the frames kept after it, in order, until the newest (also after a
    re-initialisation's frame, ``wf.resume_index``); None: from the newest.
    """

    def __init__(self, panel: Any, wf: Any, grabber: Any, recent: Any = None, start: Any = None):
        self.panel = panel
        self.wf = wf
        self.grabber = grabber
        self.recent = recent
        self._first = start
        self._catch_up: int | None = None  # the frames kept after this one are tracked next, in order (None: newest)
        self._from_kept = False  # the last frame tracked was one of the frames kept
        self.steps = 0
        self._event = threading.Event()
        self._stop = threading.Event()
        grabber.add_listener(self._on_frame)
        self.thread = threading.Thread(target=self._run, name=f"mcit-track-{wf.object_name}", daemon=True)
        self.thread.start()

    def _on_frame(self, _frame) -> None:
        self._event.set()

    def stop(self) -> None:
        self._stop.set()
        self._event.set()

    @property
    def alive(self) -> bool:
        return self.thread.is_alive()

    def _run(self) -> None:
        wf, last, lost_seen = self.wf, -1, self.wf.lost_count
        lost_note = None  # the "Tracking lost" notification on screen
        self._event.set()  # the frame on screen now is the first to track
        try:
            while not self._stop.is_set() and not wf.finished:
                self._event.wait(0.5)
                self._event.clear()
                if wf.resume_index is not None:  # re-initialised on a frozen frame: on from there
                    self._catch_up, self._from_kept, wf.resume_index = wf.resume_index, False, None
                frame = self._next()
                if self._stop.is_set() or wf.finished or frame is None or frame.index == last or not wf.following:
                    continue
                last = frame.index
                try:
                    wf.step(frame=frame.image, t_s=frame.t_s, stamp=frame.stamp, ref=frame)
                    self.steps += 1
                except WorkflowError as exc:
                    if wf.following:  # a frame it cannot use (size, no video): stop following, say why
                        try:
                            wf.pause()
                        except WorkflowError:
                            pass
                        self.panel.error = f"Tracking paused: {exc}"  # said in the panel (no toast over the video)
                if wf.lost_count != lost_seen:  # also at the top of the panel; this one stays until closed
                    lost_seen = wf.lost_count  # (an auto-closing toast vanished under the cursor aiming at it)
                    # short: the panel's instruction says why and what to do (said once, not three times)
                    lost_note = self.panel.notify(
                        "Tracking lost",
                        f"{wf.object_name}: the track stopped on the last "
                        "frame it fitted. The panel says why; Re-initialise or Restart there.",
                        "orange",
                        stays=True,
                    )
                elif lost_note is not None and not wf.lost:  # following again: the old news goes
                    _remove(lost_note)
                    lost_note = None
                self.panel.dirty = True
                self.panel.app.wake()
                if self._catch_up is not None:
                    self._event.set()  # frames kept are waiting: no need to wait for a new one
        except Exception as exc:  # noqa: BLE001 - say so, keep the server running
            log.exception("tracking %s failed", wf.object_name)
            self.panel.notify(
                "Tracking failed", f"{type(exc).__name__}: {exc}. Nothing was written; Cancel and Track again.", "red"
            )
        finally:
            self.grabber.remove_listener(self._on_frame)
            if lost_note is not None:  # the track is over (finished, or another workflow started): its news goes
                _remove(lost_note)  # (a new operator had "Tracking lost" notes stacked 15 minutes on)

    def _next(self) -> Any:
        """The frame to track now: the start frame, then while catching up the oldest frame kept after the last
        tracked (the frames kept are some 0.1 s apart), else the newest. A tracker slower than the frames kept are
        dropped falls off them: it goes on from the newest (never tracking ever further behind the live video)."""
        if self._first is not None:
            first, self._first = self._first, None
            self._catch_up = first.index
            return first
        if self._catch_up is not None and self.recent is not None:
            kept = self.recent.frames()
            after = [f for f in kept if f.index > self._catch_up]
            behind = self._from_kept and all(f.index != self._catch_up for f in kept)  # the last tracked was dropped
            if after and not behind:
                self._catch_up, self._from_kept = after[0].index, True
                return after[0]
        self._catch_up = None
        return self.grabber.latest()


def _remove(note) -> None:
    """Take a notification off the page (the client may have gone)."""
    try:
        note.remove()
    except Exception:  # noqa: BLE001
        log.debug("could not remove a notification", exc_info=True)
