"""A page's frozen frame: the video frame a workflow's clicks, snapping and solving use.

The newest frame is frozen when a workflow that takes a frozen frame starts (or by Freeze, or by the
scrubber over the recent frames), together with every other camera's frame shown at that moment, and each
is shown over its camera's live video, sharp (nearest-neighbour upscaled PNG) so that zooming shows
pixels; "Show live" looks at the live video meanwhile. A frame frozen with no workflow under way is there
to look at: it stays until Show live, until a workflow adopts it, or until another camera is shown.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any

import numpy as np

from app.markup import Md
from app.video import stamp_corner
from app.workflows import WorkflowError
from app.workflows.base import MOTION_GAP_S, FrameRef

if TYPE_CHECKING:  # pragma: no cover
    from .client import ClientPanel

__all__ = ["FrozenFrames", "past_kept"]

Z_FROZEN = -0.0005  # the frozen frame: in front of the live video, behind the overlays
FROZEN_MAX_SIDE = 2048  # the frozen frame is upscaled (nearest neighbour) up to this many pixels a side


class FrozenFrames:
    """The frozen frame of one page (``ClientPanel``): ``frame`` (None: live), the workflow it is for
    (``by``; None: frozen to look at it) and whether the live video is shown over it."""

    def __init__(self, panel: ClientPanel):
        self.panel = panel
        self.frame: FrameRef | None = None
        self.by: Any = None
        self.show_live = False
        self._sent: dict[str, Any] = {}  # camera → the frame shown over its video (its id)
        self.at: float | None = None  # when the frozen frame arrived (time.monotonic)
        # Seconds back counts from the frame on screen when the scrubber left 0 (when it arrived), not from the
        # live video (a new operator on a frame frozen a while before reached one far earlier than asked)
        self._scrub_from: float | None = None
        self.scrubbed_s = 0.0  # what the scrubber says of the frame on screen (a refused value goes back to it)
        self.note = ""  # said under the frame: a Seconds back that reached past the kept frames

    @property
    def looked_at(self) -> bool:
        """A frame frozen to look at (no workflow) is on screen."""
        return self.frame is not None and self.by is None and not self.show_live

    def looked_at_frame(self) -> FrameRef | None:
        """The frame frozen to look at on screen, when it is the shown camera's."""
        return self.frame if self.looked_at and self.frame.view in ("", self.panel.camera_view) else None

    def freeze(self, frame: Any, source: str) -> None:
        """Freeze ``frame`` (a grabbed frame of the shown camera) and the other cameras' of that moment."""
        panel = self.panel
        self._scrub_from, self.note = None, ""
        if frame is None:
            self.frame = None
            return
        feed = panel.feed
        earlier = feed.recent.before(frame, MOTION_GAP_S)  # to see whether what is clicked on was moving
        at = feed.recent.arrival(frame)
        at = time.monotonic() if at is None else at
        if earlier is None:  # a frame the ring did not keep (it keeps one every 0.1 s): the one kept before it
            hit = feed.recent.back_from(at, MOTION_GAP_S)
            earlier = hit[0] if hit is not None and hit[1] >= 0.5 * MOTION_GAP_S else None
        self.at = at
        others = {}
        for name, other in panel.app.views.items():
            hit = None if name == panel.camera_view else other.recent.nearest(at)
            if hit is not None:
                f, arrived = hit
                others[name] = FrameRef(
                    f.image, float(f.t_s), int(f.index), source, view=name, gap_s=arrived - at, stamp=f.stamp
                )
        self.frame = FrameRef(
            frame.image,
            float(frame.t_s),
            int(frame.index),
            source,
            previous=None if earlier is None else earlier.image,
            view=panel.camera_view,
            others=others,
            stamp=getattr(frame, "stamp", None),
        )
        self.show_live = False
        self.adopt(panel.session.workflow)

    def adopt(self, wf) -> None:
        """The frozen frame becomes ``wf``'s (None or finished: frozen to look at it)."""
        self.by = wf if wf is not None and not wf.finished else None
        if self.by is not None:
            wf.use_frame(self.frame)

    def unfreeze(self) -> None:
        self.frame, self.by, self.show_live = None, None, False
        self._scrub_from, self.note = None, ""

    def started(self, wf, frame: Any) -> None:
        """A workflow started: on the live video if it follows it, else on the frame the operator froze to
        look at, else on ``frame`` (the frame shown when it was asked for), else on the newest."""
        panel = self.panel
        if wf.follows_live():
            self.unfreeze()
        elif self.frame is not None and self.by is not None and self.by is panel.session.waiting:
            self.adopt(wf)  # a detour (Update pose of what Calibrate turret found moved): on the waiting one's frame
            return
        elif self.looked_at:
            # a frame the operator froze (F, Seconds back) before starting, or double-clicked on: the workflow's
            # clicks use it (a new operator froze t = 3.4 s, started a workflow, and found the newest frozen)
            self.adopt(wf)
            return
        else:
            self.freeze(frame if frame is not None else panel.feed.grabber.latest(), "live")
        self._scrubber_at_zero()

    def _scrubber_at_zero(self) -> None:
        self.scrubbed_s = 0.0
        self.panel.reset_scrubber()

    def _may_freeze(self) -> None:
        """WorkflowError when another frame may not be frozen now (the workflow follows the live video, or
        its clicks were made on the frozen frame)."""
        panel = self.panel
        wf = panel.session.workflow
        if wf is not None and not wf.finished and wf.follows_live():
            raise WorkflowError(wf.follows_live())
        panel.texts.moved_on(wf)  # a finished workflow's text goes
        if wf is not None and not wf.finished and "remove_last" in wf.current_step().enabled:
            raise WorkflowError(
                "your clicks were made on the frozen frame: every click of a workflow uses one frame. "
                "Remove them (Remove last) or Cancel before freezing another frame"
            )

    def freeze_back(self, seconds: float) -> None:
        """Freeze the newest frame (``seconds`` 0: Freeze), or the one ``seconds`` before the frame on screen
        (``scrub``)."""
        if seconds > 0:
            self.scrub(seconds)
            return
        self._may_freeze()
        frame = self.panel.feed.grabber.latest()
        if frame is None:
            raise WorkflowError("no video frame has arrived yet: check the video source")
        self.freeze(frame, "live")
        self._scrubber_at_zero()  # the scrubber counts from this frame now
        self.panel.error = ""

    def scrub(self, seconds: float) -> None:
        """Freeze the frame ``seconds`` before the frame on screen when the scrubber left 0 (the frozen frame, or
        the live video's newest), and say when the kept frames do not reach that far back. Refused, the scrubber
        goes back to what it said of the frame on screen (a new operator's box kept the refused 12)."""
        try:
            self._may_freeze()
        except WorkflowError:
            self.panel.gui_scrub.value = self.scrubbed_s
            raise
        feed = self.panel.feed
        origin = self._scrub_from
        if origin is None:
            shown = self.frame is not None and not self.show_live and self.at is not None
            newest = feed.grabber.latest()
            arrived = None if newest is None else feed.recent.arrival(newest)
            origin = self.at if shown else (time.monotonic() if arrived is None else arrived)
        hit = feed.recent.back_from(origin, seconds)
        if hit is None:
            raise WorkflowError("no video frame has arrived yet: check the video source")
        frame, back_s = hit
        self.freeze(frame, "scrubbed" if back_s > 0 else "live")
        self._scrub_from, self.scrubbed_s = origin, float(seconds)
        self.note = past_kept(float(seconds), back_s, feed.recent.seconds)
        self.panel.error = ""

    def follow(self, wf) -> bool:
        """A finished workflow's frozen frame goes (back to the live video); a workflow that follows the live
        video now lets its frame go, and one that takes a frozen frame (Track paused or lost) freezes the
        newest. True when that changed what is shown."""
        if wf is None or wf.finished:
            if self.frame is not None and self.by is not None:
                self.unfreeze()
                self._scrubber_at_zero()  # back to the live video: the scrubber says so (it kept "4")
                return True
            return False
        live = bool(wf.follows_live())
        if not live and self.frame is not None and self.by is not wf and self.by is not None and self.by.finished:
            self.adopt(wf)  # back from a detour: the frame on screen is the workflow's that waited
            return False
        if live and self.frame is not None:
            wf.use_frame(None)
            self.unfreeze()
            return True
        if not live and self.frame is None:  # the frame it stopped on (the video has moved on since)
            at = wf.stepped_on  # Track's last frame, when of the camera shown
            stopped = (
                at if at is not None and wf.view in ("", self.panel.camera_view) else self.panel.feed.grabber.latest()
            )
            self.freeze(stopped, "live")
            return self.frame is not None
        return False

    def toggle_live(self) -> None:
        """Show the live video over the frozen frame, or the frozen frame again; a frame frozen only to look at
        (no workflow's) is let go: back to the live video (a new operator found no way back but a workflow)."""
        if self.frame is None:
            raise WorkflowError("no frame is frozen: the live video is shown")
        if self.by is None:
            self.unfreeze()
            self._scrubber_at_zero()
            return
        self.show_live = not self.show_live

    def send(self) -> None:
        """Show each camera's frozen frame over its live video (the shown camera's and those frozen with
        it, seen beside it when zoomed out), or hide them."""
        panel = self.panel
        refs = {}
        if self.frame is not None and not self.show_live and panel.viewport.view == "video":
            refs = {self.frame.view or panel.camera_view: self.frame, **self.frame.others}
        for name in panel.app.views:
            ref = refs.get(name)
            key = None if ref is None else id(ref)
            if key == self._sent.get(name):
                continue
            self._sent[name] = key
            node = f"/frozen/{name}"
            if ref is None:
                panel.client.scene.remove_by_name(node)
            else:
                # marked on the video itself: the panel's text alone left a new operator unsure what was shown
                shown = stamp_corner(ref.image, f"FROZEN t = {ref.t_s:.2f} s")
                _add_image(panel.client.scene, node, shown, panel.app.views[name].pixel_world)

    def text(self, live: bool) -> Md:
        """What the panel says of the frame shown (``live``: the video is live, not lost)."""
        if self.frame is None:
            head = Md(
                "Live video (no frame frozen)"
                if live
                else "**Not live**: the video is lost and the image is its last frame, greyed; no frame frozen "
                "(the status below says more)"
            )
            return head + Md(". *Seconds back* freezes an earlier frame (counted from the newest).")
        others = Md("").join(Md(" · {} t = {:.2f} s").format(name, f.t_s) for name, f in self.frame.others.items())
        src = self.panel.feed.grabber.source
        number = (  # a recording's frame number (a video's frame, an image folder's file in name order, from 0)
            Md(" (frame {})").format(int(round(self.frame.t_s * src.fps)))
            if not src.live and not getattr(src, "rendered_live", False) and (src.frame_count or 0) > 1
            else Md("")
        )
        return (
            Md("Frozen frame: t = {:.2f} s").format(self.frame.t_s)
            + number
            + others
            + Md(" · **live shown**" if self.show_live else "")
            + (Md(". **{}**").format(self.note) if self.note else Md(""))
            + Md(". *Seconds back*: a frame that long before the frame on screen.")
        )


def _add_image(scene, node: str, image: np.ndarray, pw) -> None:
    """``image`` over its camera's image in the pixel world ``pw``, upscaled (nearest neighbour: zoomed in, the
    operator sees pixels, not blur)."""
    import cv2

    if image.ndim == 2:
        image = np.repeat(image[:, :, None], 3, axis=2)
    up = max(1, min(4, FROZEN_MAX_SIDE // max(image.shape[:2])))
    if up > 1:
        image = cv2.resize(image, None, fx=up, fy=up, interpolation=cv2.INTER_NEAREST)
    rw, rh = pw.render_size
    cx, cy, _ = pw.image_center
    scene.add_image(
        node,
        image,
        rw,
        rh,
        format="png",
        position=(float(cx), float(cy), Z_FROZEN),
        cast_shadow=False,
        receive_shadow=False,
    )


def past_kept(seconds: float, back_s: float, kept_s: float) -> str:
    """What to say of a Seconds back ``seconds`` that froze a frame ``back_s`` before the frame scrubbed from, the
    video's last ``kept_s`` seconds being kept ("" when it is the frame asked for; the scrubber's step is 0.5 s)."""
    if back_s >= seconds - 0.25:
        return ""
    if back_s < 0.0:  # the frame scrubbed from has itself left the kept frames: the oldest kept is newer
        return (
            f"Seconds back {seconds:g}: the frame you scrubbed from is older than the video's last {kept_s:g} s, "
            f"which are kept; this is the oldest kept, {-back_s:.1f} s after it"
        )
    return (
        f"Seconds back {seconds:g} reaches past the frames kept: this is the oldest kept, "
        f"{back_s:.1f} s before the frame you scrubbed from"
    )
