"""``mcit serve``: the operator interface on a scene, a video, a database and the devices.

With no arguments: the bundled scene as a live emulated site — every camera's video rendered live from
the site's state (``app.render.live.LiveSource``: the scene's scripted motions, looping with its
recording, on one clock with the emulated devices) —, emulated devices in-process and the database at
the default location (seeded from the scene when new), on 127.0.0.1. ``--video`` feeds a camera from a
file, a camera or a stream instead; ``--recorded`` plays the scene's prerecorded videos (as ``mcit demo``
does); where OpenGL cannot start (no libEGL), the recordings play and the log says why.
"""

from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
import threading
import time
from pathlib import Path

from app.exit_status import UsageError

__all__ = ["add_serve_parser", "run_serve", "build_interface", "free_port", "scene_with_intrinsics", "video_specs"]

log = logging.getLogger("mcit.serve")

LOOPBACK = ("127.0.0.1", "localhost", "::1")


def add_serve_parser(sub: argparse._SubParsersAction) -> argparse.ArgumentParser:
    from app.argtypes import frame_rate, percent, port_number

    p = sub.add_parser(
        "serve",
        help="open the operator interface in a browser (viser)",
        description="Serve the operator interface: the live video with the database overlaid, and the workflows. "
        "Listens on 127.0.0.1 by default and answers only its own pages (other web pages open in the browser "
        "cannot drive it). With --host other than loopback an access token is generated and printed in the URL; "
        "see README 'Security'.",
    )
    p.add_argument("--scene", type=Path, default=None, help="scene folder (default: the bundled workcell)")
    p.add_argument(
        "--site",
        type=Path,
        default=None,
        metavar="DIR",
        help="a site folder made by mcit site new: its scene, database, video and frame rate (--video and --fps "
        "given here replace its own; docs/own-site.md)",
    )
    p.add_argument(
        "--host",
        default="127.0.0.1",
        help="address to listen on (default 127.0.0.1; any other address needs an access token, generated "
        "unless --token gives one)",
    )
    p.add_argument(
        "--allow-origin",
        action="append",
        default=[],
        metavar="URL",
        help="also admit pages served from URL (a reverse proxy's public address, e.g. "
        "https://mcit.example.org); repeatable",
    )
    p.add_argument(
        "--token",
        default=None,
        help="access token required to open the interface (open the printed URL, which carries it); "
        "default: none on loopback, a generated one otherwise",
    )
    p.add_argument(
        "--port",
        type=port_number,
        default=None,
        help=f"port, 1 to 65535 (default {DEFAULT_PORT}, or the next free one when it is taken, said on stderr); a "
        "port given here is the one listened on, the start refused when it is taken; 0: any free port",
    )
    p.add_argument(
        "--video",
        action="append",
        default=[],
        metavar="[NAME=]SOURCE",
        help="video source: camera index (0), video file, image folder, image file or stream URL (default: the "
        "site rendered live from the scene). NAME=SOURCE feeds the scene's camera NAME (repeat for each camera); "
        "SOURCE alone feeds the first camera",
    )
    p.add_argument(
        "--recorded",
        action="store_true",
        help="play the scene's prerecorded videos (looped) instead of rendering the site live",
    )
    p.add_argument(
        "--fps",
        type=frame_rate,
        default=None,
        help="frame rate for image folders and stills, or to override a file's (above 0, at most 240)",
    )
    p.add_argument(
        "--intrinsics",
        type=Path,
        default=None,
        metavar="FILE",
        help="the camera's intrinsics (K and lens distortion) from this calibration file (mcit "
        "calibrate-intrinsics' output, OpenCV .yml, ROS .yaml, ViSP .xml), instead of the scene's: frames are "
        "undistorted with its lens, and Calibrate camera can solve the camera's pose alone from 4 points (PnP)",
    )
    p.add_argument(
        "--camera-name",
        default=None,
        help="with --intrinsics: the camera to read in a file that holds several (ViSP <name>, or a YAML "
        "file's camera key or camera_name)",
    )
    p.add_argument("--db", type=Path, default=None, help="database file (default: ~/.local/share/mcit/mcit.sqlite)")
    p.add_argument(
        "--rangefinder", default=None, help="range finder device path or URL (with --turret); default: emulated"
    )
    p.add_argument("--turret", default=None, help="turret device path or URL (with --rangefinder); default: emulated")
    p.add_argument("--no-devices", action="store_true", help="run without range finder and turret")
    p.add_argument(
        "--jpeg-quality", type=percent, default=80, help="JPEG quality of the frames sent to browsers (default 80)"
    )
    p.add_argument(
        "--feed-socket",
        type=Path,
        default=None,
        metavar="PATH",
        help="publish accepted pose changes and designated targets as JSON lines on this Unix socket, for a "
        "robot controller (docs/exchange.md)",
    )
    p.add_argument(
        "--feed-file", type=Path, default=None, metavar="PATH", help="append the same JSON lines to this file"
    )
    from app.ros2.bridge import add_ros2_arguments  # argparse only: rclpy loads when --ros2 is given

    add_ros2_arguments(p)
    p.set_defaults(func=run_serve)
    return p


def video_specs(values, scene) -> dict[str, str]:
    """{camera name: source} of the --video values: NAME=SOURCE for the scene's camera NAME, SOURCE alone
    for the first camera. ValueError for a camera the scene does not have or one given twice."""
    from app.scene import VIEW_NAME

    out: dict[str, str] = {}
    for value in values or ():
        name, sep, rest = str(value).partition("=")
        if sep and name in scene.view_names:
            camera, source = name, rest
        elif sep and VIEW_NAME.fullmatch(name) and not Path(value).exists() and "://" not in value:
            raise ValueError(
                f"--video {value}: the scene has no camera named {name!r}; its cameras: {', '.join(scene.view_names)}"
            )
        else:
            camera, source = scene.view_names[0], str(value)
        if camera in out:
            raise ValueError(f"--video: camera {camera!r} is given two sources; give one --video per camera")
        if not source:
            raise ValueError(f"--video {value}: no source after '='; give NAME=SOURCE")
        out[camera] = source
    return out


def _video_source(spec, scene, fps, view=None, live: bool = False, bodies_at=None, bridge=None):
    """The video source of one camera (the first for None): ``spec`` when given; else, with ``live``, the site
    rendered live through that camera (``LiveSource`` drawing ``bodies_at(t)``, default the scene's bodies;
    ``app.render.live.LiveRenderError`` when OpenGL cannot start); else the scene's video of that camera;
    else (the first camera only: no recording yet) one frame rendered from the scene's truth at t = 0 (a
    still); None for another camera with no video."""
    from app.video import StillSource, open_video

    v = scene.view(view)
    topic = None if spec is None else _ros2_topic(spec)
    if topic is not None:
        return bridge.video(topic, v.camera, v.lens, fps)
    if spec is not None:
        return open_video(spec, fps)
    if live:
        from app.render.live import LiveSource

        return LiveSource(scene, v.name, bodies_at=bodies_at, fps=fps)
    if v.video is not None and Path(v.video.path).is_file():
        return open_video(str(v.video.path), fps)
    if v is not scene.views[0]:
        return None
    from app.render.renderer import render_frame

    log.warning("scene %s has no video file: showing a frame rendered from the scene", scene.name)
    return StillSource(render_frame(scene, 0.0), fps or 10.0, description=f"rendered still of {scene.name}")


def _ros2_topic(spec) -> str | None:
    from app.ros2.bridge import ros2_topic

    return ros2_topic(spec)


def scene_with_intrinsics(scene, path, camera_name: str | None = None):
    """``scene`` with its camera's intrinsics read from ``path`` (``mcit serve --intrinsics``): K and
    lens from the file, the camera's pose and image size the scene's, as if the scene's camera block
    named the file as its ``intrinsics_file`` (so Calibrate camera knows the lens: PnP). ValueError,
    naming the file, when it cannot be read or was calibrated for another image size."""
    import dataclasses

    from app.camera_io import read_intrinsics
    from app.scene import pose_to_json
    from app.undistort import lens_of
    from core.camera import Camera
    from core.transforms import invert_T

    cam = scene.camera
    w, h = cam.width, cam.height
    path = Path(path).expanduser().resolve()
    intr = read_intrinsics(path, camera_name=camera_name, image_size=(w, h))
    if intr.width is not None and (intr.width, intr.height) != (w, h):
        raise ValueError(
            f"--intrinsics {path}: the camera was calibrated on {intr.width}×{intr.height} images but the "
            f"scene's camera is {w}×{h}; give the intrinsics for this size"
        )
    _, T_cam_world = cam.decompose()
    camera = Camera.from_intrinsics(intr.K, T_cam_world, w, h)
    block = {"width": w, "height": h, "intrinsics_file": str(path), "T_world_cam": pose_to_json(invert_T(T_cam_world))}
    if camera_name is not None:
        block["camera_name"] = camera_name
    raw = dict(scene.raw or {})
    if "cameras" in raw:  # the first camera's block, its name and video kept
        first = raw["cameras"][0]
        block.update({k: first[k] for k in ("name", "video") if k in first})
        raw["cameras"] = [block, *raw["cameras"][1:]]
    else:
        raw["camera"] = block
    return dataclasses.replace(scene, camera=camera, lens=lens_of(intr, w, h), raw=raw)


def _access_policy(args: argparse.Namespace):
    """The AccessPolicy of --host, --allow-origin and --token (a token generated, and kept in ``args.token``,
    when the interface listens beyond this machine); ValueError on a malformed origin or token."""
    from app.ui.access import AccessPolicy, generate_token, is_loopback

    if getattr(args, "token", None) is None and not is_loopback(args.host):
        args.token = generate_token()
    return AccessPolicy(
        host=args.host,
        allow_origins=tuple(getattr(args, "allow_origin", None) or ()),
        token=getattr(args, "token", None),
    )


def _check_host(host: str, port: int) -> None:
    """ValueError when ``host`` is no address of this machine that a server could listen on (viser's
    server thread would fail to bind and the start would wait for it for ever)."""
    import errno
    import socket

    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except (socket.gaierror, UnicodeError) as exc:
        raise ValueError(
            f"--host {host}: not an address or a name this machine can resolve ({exc}); give one of its "
            "addresses, e.g. 127.0.0.1 (this machine only) or 0.0.0.0 (every network)"
        ) from None
    family, kind, proto, _, addr = infos[0]
    with socket.socket(family, kind, proto) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            probe.bind((addr[0], 0))  # the address only: a port in use is viser's to handle
        except OSError as exc:
            if exc.errno in (errno.EADDRNOTAVAIL, errno.EAFNOSUPPORT):
                raise ValueError(
                    f"--host {host}: not an address of this machine ({exc.strerror}); give one of its "
                    "addresses, e.g. 127.0.0.1 (this machine only) or 0.0.0.0 (every network)"
                ) from None
            raise


DEFAULT_PORT = 8080
PORT_TRIES = 100  # the default port taken: the 99 after it are tried, then the start is refused


def _bind_error(host: str, port: int) -> OSError | None:
    """Why a server could not listen on ``host:port`` now (None: it could), bound as asyncio's
    ``create_server`` (viser's) binds: every address of the host, SO_REUSEADDR, IPv6 sockets v6-only."""
    import socket

    for family, kind, proto, _, addr in socket.getaddrinfo(
        host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    ):
        with socket.socket(family, kind, proto) as probe:
            probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            if family == socket.AF_INET6:
                probe.setsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY, 1)
            try:
                probe.bind(addr)
            except OSError as exc:
                return exc
    return None


def free_port(host: str, port: int, tries: int = PORT_TRIES) -> int:
    """The port ``mcit serve --port PORT`` listens on: PORT when it is free on ``host``, else the next free
    one of the ``tries`` from PORT on (0 stays 0: the system chooses). ValueError, one line, when none can
    be had: each taken, or refused (a port below 1024 without the right to it)."""
    import errno

    if port == 0:
        return 0
    last = min(65535, port + tries - 1)
    for candidate in range(port, last + 1):
        exc = _bind_error(host, candidate)
        if exc is None:
            return candidate
        if exc.errno != errno.EADDRINUSE:
            why = exc.strerror or str(exc)
            if exc.errno == errno.EACCES and candidate < 1024:
                why += " (a port below 1024 needs root or CAP_NET_BIND_SERVICE)"
            raise ValueError(
                f"--port {port}: cannot listen on {host}:{candidate}: {why}; "
                "give another --port (1024 to 65535, 0: any free port)"
            )
    taken = f"port {port} is in use" if last == port else f"ports {port} to {last} are all in use"
    raise ValueError(f"--port {port}: {taken} on {host}; give another --port, or 0 for any free port")


def build_interface(args: argparse.Namespace, bodies_at=None):
    """Open everything ``mcit serve`` needs; returns (InterfaceServer, closers).

    bodies_at : scene time (s) → list of ``app.render.live.RenderBody``, what the live site's cameras draw
    (default ``scene_bodies(scene, t)``: the scene's bodies and scripted motions); each camera's
    ``LiveSource.bodies_at`` can also be replaced while it runs.
    """
    from app.db import Database, default_db_path, seed_from_scene
    from app.render.live import LiveRenderError
    from app.scene import default_scene_path, load_scene
    from app.ui.server import InterfaceServer
    from app.video import FrameGrabber
    from app.workflows import Site

    access = _access_policy(args)  # before anything opens: a bad --token or --allow-origin stops here
    _check_host(args.host, DEFAULT_PORT if args.port is None else args.port)  # an address this machine does not have
    # the default port, or the next free one when it is taken (run_serve says so); a port given is that one or none:
    # a proxy, a tunnel or a script set up for it would reach another program, or nothing
    port = free_port(args.host, DEFAULT_PORT) if args.port is None else free_port(args.host, args.port, tries=1)
    if getattr(args, "site", None) is not None:  # a site folder (mcit site new): its scene, database and video
        from app.site_folder import serve_site_args

        serve_site_args(args)
    scene = load_scene(args.scene or default_scene_path())
    if scene.turret is None and (args.rangefinder is not None or args.turret is not None):
        raise ValueError(
            f"scene {scene.name} is camera-only (no turret block): --rangefinder and --turret need a scene with a "
            "turret (docs/scene-format.md)"
        )
    if getattr(args, "camera_name", None) and not getattr(args, "intrinsics", None):
        raise ValueError("--camera-name chooses a camera in the --intrinsics file; give --intrinsics FILE")
    if getattr(args, "intrinsics", None):
        scene = scene_with_intrinsics(scene, args.intrinsics, args.camera_name)
        log.info("camera intrinsics from %s: Calibrate camera can solve the pose alone (PnP)", args.intrinsics)
    videos = args.video if isinstance(args.video, list) else [args.video] if args.video else []
    specs = video_specs(videos, scene)
    grabbers: dict = {}
    start_at = time.monotonic()  # one clock for every camera's recording: their frames show one moment
    closers = []
    from app.ros2.bridge import Ros2Bridge

    Ros2Bridge.wanted(args, specs)  # --ros2 without ROS 2 installed: said before anything opens
    # the database first: a file that is not one is said before any video or OpenGL starts (their threads
    # torn down by the exit printed C++ runtime lines after the one-line error)
    db_path = args.db or default_db_path()
    db_path.parent.mkdir(parents=True, exist_ok=True)
    db = Database.open(db_path, client="mcit-serve")
    closers.append(db.close)
    seeded = not db.objects() and not db.calibrations()
    if seeded:
        seed_from_scene(db, scene)
    live = not getattr(args, "recorded", False)
    try:
        bridge = Ros2Bridge.open(args, specs)  # None without --ros2 or a ros2: video
    except BaseException:
        db.close()
        raise
    if bridge is not None:
        closers.append(bridge.close)
    holder: dict = {}  # the site and the clock, made below: the robot's feed lines and grasps use them
    try:
        robot = _open_robot(scene, holder, bridge)
    except BaseException:
        for close in closers:
            close()
        raise
    if robot is not None:
        closers.insert(0, robot.close)  # before the bridge's node, which its controller may use
        bodies_at = bodies_at or robot.world.bodies_at
    try:
        for view in scene.views:
            try:
                source = _video_source(specs.get(view.name), scene, args.fps, view.name, live, bodies_at, bridge)
            except LiveRenderError as exc:  # no OpenGL here: the recordings instead, said once
                log.warning("the site cannot be rendered live (%s): playing the scene's recordings", exc)
                live = False
                source = _video_source(specs.get(view.name), scene, args.fps, view.name)
            if source is None:
                log.info("camera %s has no video: give --video %s=SOURCE to see it", view.name, view.name)
                continue
            if view.lens is not None:  # every frame undistorted once on arrival: C, clicks and the overlay hold in it
                from app.undistort import UndistortedSource

                source = UndistortedSource(source, view.lens)
                log.info("camera %s: frames undistorted: %s", view.name, view.lens.describe())
            grabbers[view.name] = FrameGrabber(source, start_at=start_at).start()
            closers.append(grabbers[view.name].stop)
    except Exception:
        for close in closers:
            close()
        raise
    live_views = [name for name, g in grabbers.items() if getattr(g.source, "rendered_live", False)]
    notes = []  # said once everything opened: a start that fails says one line, its reason
    if seeded:
        notes.append(f"new database {db_path} seeded from scene {scene.name}")
    if live_views:
        from app.render.live import gl_description

        notes.append(f"cameras {', '.join(live_views)}: the site rendered live ({gl_description()})")
    if robot is not None:
        cell = robot.cell
        by = "emulated controller" if bridge is None else f"joint states on {args.ros2_joint_states} (ROS 2)"
        notes.append(
            f"robot {cell.model.name}: {cell.model.n} joints, base at "
            f"{[round(float(v), 3) for v in cell.T_world_base[:3, 3]]} ({by})"
        )
    grabber = grabbers[scene.views[0].name]

    def clock() -> float:
        frame = grabber.latest()
        return 0.0 if frame is None else frame.t_s

    holder["clock"] = clock
    if robot is not None and not live:
        notes.append("the robot moves unseen on the recorded video: its overlay follows its joint states")

    devices = None
    if scene.turret is None:  # a camera-only site: the workflows that need the devices say so
        notes.append(f"scene {scene.name} is camera-only: no range finder and turret")
    elif not args.no_devices:
        from app.devices import open_devices

        try:
            # the emulated range finder sees the robot's links and the bodies where the robot left them
            options = {"bodies": robot.world.beam_bodies()} if robot is not None else None
            devices = open_devices(scene, args.rangefinder, args.turret, clock=clock, site_options=options)
            closers.insert(0, devices.close)
        except Exception as exc:  # noqa: BLE001 - the interface works without devices; say so
            if args.rangefinder is not None:
                raise
            log.error("emulated devices failed to start (%s): continuing without range finder and turret", exc)
    site = Site(scene, db, devices=devices, clock=clock, robot=None if robot is None else robot.cell)
    holder["site"] = site
    if getattr(args, "feed_socket", None) or getattr(args, "feed_file", None):
        from app.feed import FeedPublisher

        try:
            feed = FeedPublisher(file=args.feed_file, socket_path=args.feed_socket, snapshot=site.feed_snapshot)
        except ValueError:
            for close in closers:
                close()
            raise
        site.attach_feed(feed)
        closers.insert(0, feed.close)
        log.info(
            "live feed of poses and targets on %s",
            " and ".join(str(x) for x in (args.feed_socket, args.feed_file) if x),
        )
    if bridge is not None:
        bridge.attach(site)
        notes.append(
            f"ROS 2 (domain {bridge.node.domain}): object poses, markers and targets on {args.ros2_namespace}, "
            f"frame {args.ros2_frame}"
        )
    server = InterfaceServer(
        site,
        grabbers,
        host=args.host,
        port=port,
        jpeg_quality=args.jpeg_quality,
        allow_origins=access.allow_origins,
        token=access.token,
    )
    server.emulated_world = None if robot is None else robot.world  # the emulated site's truth (tests, benches)
    if bridge is not None:
        server.bridge_note = (
            f"**ROS 2** on domain {bridge.node.domain}: poses, markers and targets out on {args.ros2_namespace}"
            + (f"; the robot from {args.ros2_joint_states}" if robot is not None else "")
        )
    for note in notes:
        log.info(note)
    return server, closers


def _open_robot(scene, holder: dict, bridge=None):
    """The scene's robot (app.robot.setup.RobotSetup), emulated (or through ROS 2 with a ``bridge``), or None; its
    joint states go out on the site's live feed and its grasps read the scene time, both found in ``holder`` once
    made."""
    if scene.robot is None:
        return None
    from app.robot.setup import open_robot

    def publish(event: dict) -> None:
        site = holder.get("site")
        if site is not None:
            site.publish(event)

    return open_robot(
        scene,
        clock=lambda: holder["clock"]() if "clock" in holder else 0.0,
        publish=publish,
        make_controller=None if bridge is None else bridge.controller,
    )


SOLVERS_COLD_S = 40.0  # compiling every kernel on a new machine: 36.5 s measured on 2 cores at load 3


def _kernels_compiled() -> bool:
    """Whether numba's cache holds the pose kernels already (then loading them takes a second or two)."""
    import core.pose

    name = "_kernels.*.nbi"
    if any((Path(core.pose.__file__).parent / "__pycache__").glob(name)):
        return True
    cache = os.environ.get("NUMBA_CACHE_DIR")
    return bool(cache) and any(Path(cache).rglob(name))


def warm_solvers(server, warm=None) -> threading.Thread:
    """Load the pose solvers' compiled kernels on a thread (the first time on a machine: compile them, about
    ``SOLVERS_COLD_S``), every operator told at the panel's top meanwhile, and how long it takes."""
    warm = warm or _warm_pose_kernels
    cold = not _kernels_compiled()
    t0 = time.monotonic()

    def notice() -> str:
        so_far = time.monotonic() - t0
        how = (
            f"compiling them once for this machine: about {SOLVERS_COLD_S:.0f} s on an idle machine, "
            f"{so_far:.0f} s so far"
            if cold
            else f"{so_far:.0f} s so far"
        )
        return (
            f"**Preparing the pose solvers** ({how}): until they are ready, an Auto match, a Refine or a one-click "
            "search may wait for them."
        )

    server.notices["solvers"] = notice

    def run() -> None:
        try:
            warm()
        finally:
            server.notices.pop("solvers", None)
            log.info("pose solvers ready in %.1f s%s", time.monotonic() - t0, " (compiled)" if cold else "")

    thread = threading.Thread(target=run, name="pose-kernels", daemon=True)
    thread.start()
    return thread


def _warm_pose_kernels() -> None:
    try:
        from app.vision.matching import warm_up as warm_up_matching
        from core.pose import warm_up

        warm_up()
        warm_up_matching()
    except Exception:  # noqa: BLE001 - a first click then compiles them instead
        log.warning("loading the pose kernels failed", exc_info=True)


def run_serve(args: argparse.Namespace) -> int:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    try:
        _access_policy(args)
    except ValueError as exc:  # --token, --allow-origin
        raise UsageError(str(exc)) from None
    try:
        server, closers = build_interface(args)
    except BaseException:  # said by app.cli in one line (a database that is not one, ...): OpenGL released first
        _release_gl()
        raise
    if args.port is None and server.port != DEFAULT_PORT:
        print(f"mcit serve: port {DEFAULT_PORT} is in use: listening on port {server.port} instead", file=sys.stderr)
    # SIGTERM stops the interface from before its address is printed: a supervisor may stop it as soon as it reads it
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    server.start()
    # The pose solvers' compiled kernels load (the first time on a machine: compile) while the page opens.
    warm_solvers(server)
    from app.ui.access import is_loopback

    if not is_loopback(args.host):
        print(
            f"mcit: listening on {args.host}: only browsers given the token in the address below can open the "
            "interface, over plain HTTP (use a reverse proxy with HTTPS beyond a trusted network).",
            flush=True,
        )
    print(f"mcit: open {server.url} in a browser (Ctrl-C to stop)", flush=True)
    try:
        while not stop.wait(0.5):
            pass
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
        for close in closers:
            try:
                close()
            except Exception:  # noqa: BLE001 - best effort at exit
                log.debug("close failed", exc_info=True)
        _release_gl()
    return 0


def _release_gl() -> None:
    """The live renderer's OpenGL released before the process exits (when it was started)."""
    if "app.render.live" in sys.modules:
        sys.modules["app.render.live"].shutdown_gl()
