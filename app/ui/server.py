"""The operator interface's server: viser, the video plane, the shared overlay and the redraw loop.

Layout of the viser scene (DESIGN.md §"The operator interface"):

* ``/video``: the frame as a textured plane in the pixel world (pixel (u, v) ↔ (u·k, v·k, 0));
* ``/overlay/db/group_<k>`` and ``/overlay/db_labels/<object id>``: the database objects projected
  through C, up to 64 a node, and each one's name (shared by all clients; ``app.ui.db_overlay``);
  ``/overlay/beam``: the range finder's last spot;
* ``/overlay/marks`` and ``/overlay/marks_labels/*``: one client's workflow marks (client-scoped);
* ``/world3d/...``: the virtual world in metres (objects, camera frustum, turret, beam), placed
  away from the image plane; a client's "3D world" view orbits it.

Threads: viser runs callbacks on its pool (they only change state). The frame loop
(``mcit-redraw``), woken by each new video frame or by a callback, sends the frame, then each
client's marks inside ``server.atomic()``. The database thread (``mcit-database``) polls the
database each second and, when the site changed, redraws only the objects whose version or status
moved (every object only when C changed), the 3D world likewise, and builds the changed objects' ray
casters: the video never waits for the database.
"""

from __future__ import annotations

import logging
import threading
import time
import warnings
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import viser

from app.markup import Md
from app.overlay import LineBatch, PixelWorld
from app.video import FrameGrabber, stamp_not_live, stamp_replay_time
from app.workflows.frames import GrabberFrames
from app.workflows.site import Site

from .access import AccessPolicy, open_viser_server
from .client import ClientPanel
from .db_overlay import DatabaseOverlay
from .inbound import guard_inbound_messages
from .recent import RecentFrames
from .robot_overlay import RobotOverlay
from .viser_hints import plain_pose_setter, share_prop_hints
from .world3d import World3D
from .wslog import quiet_malformed_messages

# A page that leaves while its marks or frozen image are on their way: viser drops them and warns. That a
# departed page gets nothing is expected; the warning would reach the operator's terminal as noise.
warnings.filterwarnings("ignore", message=r"Queued a \w+ on a closed connection", category=UserWarning)

__all__ = ["InterfaceServer"]

log = logging.getLogger("mcit.ui")

Z_DB = -0.001  # overlay planes just in front of the image (world units; the viewer looks along +z)
Z_MARKS = -0.002
LINE_PX = 2.0


VIEW_GAP_PX = 40  # between two cameras' images, side by side in the pixel world


@dataclass
class ViewFeed:
    """One camera's video in the interface: its grabber, where its image lies in the pixel world, its
    database overlay and its recent frames; ``video`` its image node once the scene is set up."""

    name: str
    grabber: FrameGrabber
    pixel_world: PixelWorld
    overlay: DatabaseOverlay
    recent: RecentFrames
    video: Any = None
    frame_index: int = -1
    stamp: str | None = None  # the not-live text stamped on the shown frame, or None
    frames_sent: int = 0
    sent_image: Any = None  # the image last sent: a still source gives the same array every frame


class InterfaceServer:
    """The operator interface on one site and its cameras' video sources.

    Parameters
    ----------
    site : Site
    grabber : FrameGrabber of the site's first camera, or {camera name: FrameGrabber} for several (in the
        site's order; started here). Each camera's image lies beside the previous one's.
    host, port : where to listen (127.0.0.1 by default)
    allow_origins : page origins admitted besides the interface's own (a reverse proxy's public address)
    token : access token every request must carry (``?token=`` or its cookie), or None (app/ui/access.py)
    k : world units per video pixel.
    jpeg_quality : quality of the video frames sent to the browsers.
    """

    def __init__(
        self,
        site: Site,
        grabber: FrameGrabber,
        *,
        host: str = "127.0.0.1",
        port: int = 8080,
        k: float = 0.01,
        jpeg_quality: int = 80,
        verbose: bool = False,
        allow_origins: tuple[str, ...] = (),
        token: str | None = None,
    ):
        self.site = site
        grabbers = grabber if isinstance(grabber, Mapping) else {site.views[0]: grabber}
        unknown = [name for name in grabbers if name not in site.views]
        if unknown or site.views[0] not in grabbers:
            raise ValueError(
                f"video for camera(s) {unknown or [site.views[0]]} but the site's cameras are {list(site.views)}: "
                "give the first camera's video and name each other one as the scene does"
            )
        self.jpeg_quality = int(jpeg_quality)
        share_prop_hints()  # a full draw builds thousands of handles (app/ui/viser_hints.py)
        plain_pose_setter()  # ... and moves their labels
        self.access = AccessPolicy(host=host, allow_origins=tuple(allow_origins), token=token)
        quiet_malformed_messages()  # a message a browser sent that cannot be read: one log line, not a traceback
        self.server = open_viser_server(self.access, host=host, port=port, label="mcit", verbose=verbose)
        # each browser message checked against its type before viser dispatches it; a bad one dropped, one log line
        self.inbound = guard_inbound_messages(
            self.server, name_of=lambda cid: f"browser-{cid + self.client_number_offset}"
        )
        # no Share button: it would open a tunnel to the interface through viser's public relay; no viser logo: an
        # operator took its axes icon for the view's axes, and it opens viser's credits
        self.server.gui.configure_theme(show_share_button=False, show_logo=False)
        self.host = host
        self.clients: dict[int, ClientPanel] = {}
        self.clients_lock = threading.RLock()
        # Browsers are named browser-N in the history; N goes on from the last run's (viser counts
        # from 0 again when the server restarts, and 'browser-1' then named two different pages).
        self.client_number_offset = _last_browser_number(site.db) + 1
        self._wake = threading.Event()
        self._stop = threading.Event()
        self._db_revision = -1
        self._beam_key: Any = None
        self._frame_index = -1
        self._panels_revision = -1  # the site revision the clients' panels last saw
        self.views: dict[str, ViewFeed] = {}
        x0 = 0.0
        for name in (v for v in site.views if v in grabbers):
            g = grabbers[name]
            pw = PixelWorld(g.source.width, g.source.height, k, x0)
            first = not self.views
            prefix = "/overlay" if first else f"/views/{name}/overlay"
            overlay = DatabaseOverlay(self.server.scene, pw, Z_DB, LINE_PX, prefix=prefix)
            # the recent frames, for each operator's frozen frame and its scrubber (app/ui/recent.py)
            self.views[name] = ViewFeed(name, g, pw, overlay, RecentFrames(g, seconds=12.0, max_frames=120))
            x0 += (g.source.width + VIEW_GAP_PX) * k
        # every camera's image together (zoomed out that far, the operator sees them side by side)
        self.all_images = PixelWorld(
            int(round(x0 / k)) - VIEW_GAP_PX, max(f.pixel_world.height for f in self.views.values()), k
        )
        first = self.views[site.views[0]]  # the first camera's, by their old names
        self.grabber, self.pixel_world, self.db_overlay, self.recent = (
            first.grabber,
            first.pixel_world,
            first.overlay,
            first.recent,
        )
        self._db_wake = threading.Event()
        self._db_thread = threading.Thread(target=self._db_loop, name="mcit-database", daemon=True)
        self.frames_sent = 0
        self.redraws = 0
        self._last_status_t = 0.0
        # what every operator must know now, at the panel's top (key → callable giving the text, "" when none):
        # e.g. the pose solvers being prepared at start (app/ui/serve.py)
        self.notices: dict[str, Any] = {}
        self.bridge_note = ""  # what the status says of the ROS 2 bridge (app/ui/serve.py), "" without one
        self.world3d = World3D(self.server.scene, offset=np.array([-60.0, 0.0, 0.0]))
        self.robot_overlay = RobotOverlay(
            self.server.scene,
            self._send_lines,
            {name: (f.pixel_world, f.overlay.prefix) for name, f in self.views.items()},
            Z_DB,
            self.world3d,
        )
        self._setup_scene()
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)
        self._thread = threading.Thread(target=self._loop, name="mcit-redraw", daemon=True)
        for feed in self.views.values():
            feed.grabber.add_listener(lambda _frame: self._wake.set())  # a new frame: redraw now
            # Snapping, matching and tracking work on what the operator sees: the grabber's latest frame.
            site.set_frames(GrabberFrames(feed.grabber), view=feed.name)
            if self.camera_doubt(feed.name):
                log.warning("camera %s: %s", feed.name, self.camera_doubt(feed.name))

    # ------------------------------------------------------------------ life cycle
    @property
    def port(self) -> int:
        return int(self.server.get_port())

    @property
    def url(self) -> str:
        host = "127.0.0.1" if self.host in ("0.0.0.0", "::", "") else self.host
        if ":" in host:
            host = f"[{host}]"
        token = "" if self.access.token is None else f"/?token={self.access.token}"
        return f"http://{host}:{self.port}{token}"

    def camera_doubt(self, view: str) -> str:
        """ "" when the camera ``view`` is calibrated for its video's size and sees the database in front of it,
        else a sentence saying what is wrong."""
        cam, pw = self.site.camera_of(view), self.views[view].pixel_world
        if (cam.width, cam.height) != (pw.width, pw.height):
            return (
                f"the video is {pw.width}×{pw.height} but the camera is calibrated for {cam.width}×{cam.height}: "
                "run Calibrate camera"
            )
        V = [o.vertices_world() for o in self.site.objects()]
        V = np.vstack([v for v in V if len(v)]) if any(len(v) for v in V) else np.zeros((0, 3))
        if len(V) and not np.any(cam.depth(V) > 0):  # nothing would be drawn, and nothing said (a new user's)
            return (
                "the camera's C puts every database object behind it, so none is drawn: check C's sign, or "
                "whether the world is mirrored (a reconstruction's often is: negate one world axis of the "
                "objects and of C)"
            )
        return ""

    def view_at(self, origin: np.ndarray, direction: np.ndarray) -> tuple[str, np.ndarray] | None:
        """(camera name, pixel) of the image a viewer ray meets, or None when it meets none."""
        for feed in self.views.values():
            uv = feed.pixel_world.pixel_from_ray(origin, direction)
            if feed.pixel_world.holds(uv):
                return feed.name, uv
        return None

    def start(self) -> InterfaceServer:
        for feed in self.views.values():
            feed.grabber.start()
        self._thread.start()
        self._db_thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._wake.set()
        self._db_wake.set()
        for thread in (self._thread, self._db_thread):
            if thread.is_alive():
                thread.join(timeout=3.0)
        for feed in self.views.values():
            feed.grabber.stop()
        self.server.stop()

    def wake(self) -> None:
        """Ask the loops to redraw now (called by callbacks after they change state)."""
        self._wake.set()
        self._db_wake.set()

    def object_at(self, uv: np.ndarray, radius_px: float, view: str | None = None) -> str | None:
        """The object whose drawn wireframe passes nearest to pixel ``uv`` (2,) of camera ``view`` (the
        first for None), within ``radius_px`` pixels, or None: picked on the projections the database
        overlay keeps (no projection here)."""
        return self.views[view or self.site.views[0]].overlay.object_at(uv, radius_px)

    # ------------------------------------------------------------------ clients
    def _on_connect(self, client: viser.ClientHandle) -> None:
        try:
            panel = ClientPanel(self, client)
        except Exception:  # noqa: BLE001
            log.exception("could not build the panel of client %s", client.client_id)
            return
        with self.clients_lock:
            self.clients[client.client_id] = panel
        for name in self.views:
            if self.camera_doubt(name):
                said = self.camera_doubt(name)
                where = f"Camera {name}: t" if len(self.views) > 1 else "T"
                panel.notify(
                    "Camera and video differ" if "video" in said else "Nothing in front of the camera",
                    f"{where}{said[1:]}.",
                    "yellow",
                )
        self.wake()

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self.clients_lock:
            panel = self.clients.pop(client.client_id, None)
        if panel is not None:
            panel.close()

    # ------------------------------------------------------------------ scene
    def _setup_scene(self) -> None:
        for i, feed in enumerate(self.views.values()):
            pw = feed.pixel_world
            frame = feed.grabber.latest()
            image = frame.image if frame is not None else np.zeros((pw.height, pw.width, 3), np.uint8)
            rw, rh = pw.render_size
            feed.video = self.server.scene.add_image(
                "/video" if i == 0 else f"/views/{feed.name}/video",
                image,
                rw,
                rh,
                format="jpeg",
                jpeg_quality=self.jpeg_quality,
                position=tuple(pw.image_center),
                cast_shadow=False,
                receive_shadow=False,
            )
        self.video = self.views[self.site.views[0]].video
        self.server.scene.world_axes.visible = False

    def _send_lines(self, scene_api, name: str, batch: LineBatch, z: float, pw: PixelWorld | None = None) -> None:
        if len(batch) == 0:
            # Per-vertex colours even when empty: a node first sent with one colour keeps ignoring
            # the per-vertex colours it gets later (they render white in viser 1.1.1).
            scene_api.add_line_segments(
                name,
                np.zeros((1, 2, 3), np.float32),
                np.zeros((1, 2, 3), np.uint8),
                thickness=LINE_PX,
                thickness_units="screen",
                visible=False,
            )
            return
        points, colors = batch.world(pw or self.pixel_world, z)
        scene_api.add_line_segments(
            name, points.astype(np.float32), colors, thickness=LINE_PX, thickness_units="screen"
        )

    def send_client_overlay(
        self, client: viser.ClientHandle, batch: LineBatch, labels: list, sent: dict, pw: PixelWorld | None = None
    ) -> dict:
        """Draw one client's marks (client-scoped nodes) on the image ``pw`` (default: the first camera's);
        each label's bottom-left corner at its uv (``drawing.spread_labels``). ``sent`` holds the labels this
        client was sent last (name → (text, position)); only changed ones are sent again. Returns the new dict."""
        pw = pw or self.pixel_world
        self._send_lines(client.scene, "/overlay/marks", batch, Z_MARKS, pw)
        new: dict = {}
        for i, (uv, text) in enumerate(labels):
            name = f"/overlay/marks_labels/{i}"
            position = tuple(float(v) for v in pw.to_world(np.asarray(uv, float), Z_MARKS))  # spread_labels' corner
            new[name] = (text, position)
            if sent.get(name) != new[name]:
                client.scene.add_label(name, text, position=position, anchor="bottom-left", font_screen_scale=0.8)
        for name in set(sent) - set(new):
            client.scene.remove_by_name(name)
        return new

    @property
    def database_drawn(self) -> bool:
        """True once the overlay shows the database as it is now (the database thread caught up)."""
        return self._db_revision == self.site.revision

    def sync_database(self) -> int:
        """Bring the database overlay and the 3D world up to date (only what changed) and build the
        changed objects' ray casters; the database thread's work. Returns how many objects were redrawn."""
        site = self.site
        revision = site.revision
        objects = site.objects()
        n = 0
        for feed in self.views.values():
            n = max(n, feed.overlay.sync(site.camera_of(feed.name), objects))
        self.world3d.sync(site, objects)
        # the ray casters of the objects that changed built now, not on the operator's next click (one ray cast:
        # 0.03 s at 2,000 objects). Not site.surfaces() (its one trimesh of every object, which the ray casts no
        # longer use, was built again at each change; each old one became cyclic garbage that only a full
        # collection frees: 10 changes at 500 objects left 13 MB of arrays, bench/soak.py's growth)
        cam = site.camera
        origin, dirs = cam.rays(np.array([[cam.width / 2.0, cam.height / 2.0]]))
        site.raycast(np.asarray(origin).reshape(-1, 3)[0], dirs[0])
        self._db_revision = revision
        return n

    def _draw_beam(self, panels: list) -> None:
        """The range finder's spot moved: each client draws it among its marks (so that it keeps its
        size on the screen when zoomed), and the 3D world's beam follows."""
        X = self.site.beam_X_world
        key = None if X is None else tuple(np.round(X, 6))
        if key == self._beam_key:
            return
        self._beam_key = key
        for panel in panels:
            panel.dirty = True
        self.world3d.draw_beam(self.site)

    def world3d_view(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A viewer pose (position, look_at, up) overlooking the virtual world."""
        return self.world3d.default_view(self.site)

    # ------------------------------------------------------------------ the loop
    def _loop(self) -> None:
        # Woken by each new frame and by every callback; the timeout only keeps a stalled video
        # from freezing the rest (status, polling the database).
        period = 1.0 / max(1.0, min(60.0, max(f.grabber.source.fps for f in self.views.values())))
        while not self._stop.is_set():
            self._wake.wait(max(period, 0.1))
            self._wake.clear()
            if self._stop.is_set():
                break
            try:
                self.redraw()
            except Exception:  # noqa: BLE001 - keep serving; the next pass retries
                log.exception("redraw failed")
                time.sleep(0.2)

    def _db_loop(self) -> None:
        # Woken by callbacks (a write is usually what they did); polls the database each second for
        # other writers. Never blocks the frame loop: the overlay's nodes are sent outside viser's atomic().
        while not self._stop.is_set():
            self._db_wake.wait(0.25)
            self._db_wake.clear()
            if self._stop.is_set():
                break
            try:
                now = time.monotonic()
                if now - self._last_status_t > 1.0:
                    self._last_status_t = now
                    try:
                        self.site.poll()
                    except Exception:  # noqa: BLE001
                        log.exception("database poll failed")
                    self._update_status()
                if self.site.revision != self._db_revision:
                    self.sync_database()
                    self._wake.set()  # the panels redraw what depends on the objects
            except Exception:  # noqa: BLE001 - keep serving; the next pass retries
                log.exception("database overlay redraw failed")
                time.sleep(0.2)

    def redraw(self) -> None:
        """One pass of the frame loop: each camera's new video frame (sent at once, on its own), then each
        client's marks. The database overlay is the database thread's (``sync_database``)."""
        video_changed = False
        for feed in self.views.values():
            video_changed |= self._send_frame(feed)
        if video_changed:
            self._update_status()
        revision = self.site.revision
        site_changed = revision != self._panels_revision or video_changed
        self._panels_revision = revision
        with self.clients_lock:
            panels = list(self.clients.values())
        with self.server.atomic():
            self._draw_beam(panels)
            self.robot_overlay.sync(self.site)
            for panel in panels:
                try:
                    panel.redraw(site_changed)
                except Exception:  # noqa: BLE001 - one client's failure must not stop the others
                    log.exception("redraw of client %s failed", panel.client.client_id)
        self.redraws += 1

    def _send_frame(self, feed: ViewFeed) -> bool:
        """Send one camera's newest frame if it is new; True when its video was lost or came back."""
        frame = feed.grabber.latest()
        status = feed.grabber.status()
        was_stamped = feed.stamp is not None
        if not status.live and frame is not None:
            # The video is lost: its last frame stays, but greyed with what happened stamped on it
            # (never a frozen image that looks live); the panels say it too, at once.
            if feed.stamp != status.text:
                feed.video.image = stamp_not_live(frame.image, status.text)
                feed.stamp = status.text
        elif frame is not None and (frame.index != feed.frame_index or was_stamped):
            feed.stamp = None
            feed.frame_index = frame.index
            if frame.image is feed.sent_image and not was_stamped:
                # a still's same image again: the page has it (sent at the still's rate, each browser decoded and
                # drew it again, 20 times a second for the browser tests' stills)
                return False
            feed.sent_image = frame.image
            src = feed.grabber.source
            loop = None if src.live or (src.frame_count or 0) <= 1 else src.duration_s
            # a looping recording says where it is on the video itself: what moved in it jumps back at each restart
            # (a live site's scripted motions loop the same way)
            label = "SCRIPT" if getattr(src, "rendered_live", False) else "REPLAY"
            image = frame.image if not loop else stamp_replay_time(frame.image, float(frame.t_s), loop, label)
            feed.video.image = image
            feed.frames_sent += 1
            self.frames_sent += 1
        return was_stamped != (feed.stamp is not None)  # lost, or live again

    def _update_status(self) -> None:
        parts = [self._video_status(feed) for feed in self.views.values()]
        n = len(self.site.objects())
        text = Md("\n\n").join(parts) + Md("\n\n{} object{}").format(n, "" if n == 1 else "s")
        if self.bridge_note:
            text += Md("\n\n{}").format(self.bridge_note)
        with self.clients_lock:
            panels = list(self.clients.values())
        notice = Md("\n\n").join(Md(t) for t in (fn() for fn in list(self.notices.values())) if t)
        for panel in panels:
            panel.set_status(text)
            panel.set_notice(notice)

    def _video_status(self, feed: ViewFeed) -> Md:
        """What the panel says of one camera's video and calibration."""
        src, status = feed.grabber.source, feed.grabber.status()
        video = Md("**Video** {} · {}×{} · {:.1f} fps (shown {:.1f})").format(
            src.description, src.width, src.height, src.fps, feed.grabber.measured_fps
        )
        if len(self.views) > 1:
            video = Md("**Camera {}** · ").format(feed.name) + video
        if status.live:
            loop = src.duration_s if not src.live else None
            if src.live:
                video += Md(" · **live**")
            elif getattr(src, "rendered_live", False):  # the emulated site: live, its scripted motions looping
                video += Md(" · **the emulated site, rendered live**")
                if loop and (src.frame_count or 0) > 1:
                    video += Md("; its scripted motions restart every {:.1f} s (objects jump back then)").format(loop)
            elif loop and (src.frame_count or 0) > 1:  # say it: what moved in it jumps back at every loop
                video += Md(
                    " · **a recording, replayed every {:.1f} s** (not live: objects jump back when it restarts)"
                ).format(loop)
        elif feed.grabber.error is not None:
            video += Md("\n\n**Video stopped:** {}").format(feed.grabber.error)
        else:  # lost (reconnecting) or waiting: the image shown is not live
            video += Md("\n\n**⚠ Not live: {}.** The image shown is the last frame, greyed{}.").format(
                status.text, f" (last try: {status.reason})" if status.reason else ""
            )
        said = getattr(src, "warning", "")  # what the source found wrong while it plays on (a ROS 2 camera's)
        if said:
            video += Md("\n\n**⚠ {}**").format(said)
        cam = self.site.camera_of(feed.name)
        return video + Md(" · calibrated for {}×{}").format(cam.width, cam.height)


def _last_browser_number(db) -> int:
    """The largest N of the 'browser-N' names in the database's recent history (-1: none)."""
    import re

    try:
        changes = db.history(limit=5000)
    except Exception:  # noqa: BLE001 - a name is not worth failing the start for
        log.debug("could not read the history for the browsers' names", exc_info=True)
        return -1
    numbers = [int(m[1]) for c in changes if (m := re.fullmatch(r"browser-(\d+)", str(c.client or "")))]
    return max(numbers, default=-1)
