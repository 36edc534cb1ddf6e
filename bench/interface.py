"""Benchmark of the operator interface in a real browser (headless chromium + playwright).

Setup: the bundled scene's database plus extra boxes and cylinders on the table (50 objects in
all), the interface on 127.0.0.1, one headless chromium (swiftshader WebGL, the flags of
DESIGN.md), viewport 1200 × 700.

1. Video: a 640 × 480 source at 30 frames/s (the real ViSP cube sequence, ../shared/data; else
   frames of noise) with the database overlay live: the frames delivered to the browser over 10 s.
   Counted where viser writes each websocket message to the browser's socket (the write returns
   once the bytes are in the socket, so a browser that stops reading stalls it): each message is
   decoded (zstd + msgpack) and its /video frame updates counted.
2. Click → overlay: clicks on the canvas during "Designate target" (each one ray-casts the 50
   objects) and "Update pose" (points, segments, edge assignments). Measured in the server: from
   the click's arrival (the start of viser's callback) to the end of the redraw that sends that
   client's updated marks (the message queued to the websocket).

3. Scale table (also alone: ``--stall``, no chromium): browser-like clients (websocket readers in their
   own processes, reporting their camera as the page does, no rendering) record when each message
   arrives and what it holds (video frames, database overlay nodes), at 50, 500 and 2,000 objects:
   the full draw at start (one reader connected before the server starts), for a browser joining
   (5 joins, one after the other: the median and the worst), and after a new camera calibration (C's
   centre moved 5 mm): the time to the last overlay message received, the CPU seconds of the database
   thread's drawing (the overlay's, and with the 3D world's and the ray casters'), and each reader's longest
   video gap meanwhile, counted from its connection (a browser with no frame yet counts); then the longest
   gap while one object's pose is written every 2 s (as Accept writes it) over 12 s, and selection
   clicks at 2,000 objects (click → that client's marks sent). ``--before DIR`` runs the same on
   another checkout (its root) and prints it beside; bare viser's join (the video alone) is printed
   under it. Targets (issues 13, 27): at 2,000 objects the full overlay within 2 s, no video frozen
   more than 0.5 s, a watching browser's gap ≤ 150 ms when another joins, ≤ 100 ms and ≥ 28 frames/s
   while the database changes; click → overlay p95 ≤ 50 ms.

4. Undistortion table (also alone: ``--undistort``, no chromium): the frames/s the browser-like client
   receives from a 30 frames/s source at 640 × 480 and 1280 × 720, with the frames undistorted on
   arrival (``app.undistort.UndistortedSource``: OpenCV's 5-coefficient model, one ``cv2.remap``
   with precomputed maps) and without, in the same run, and the remap's own time per frame.
   Targets (issue 15): ≥ 28 frames/s at 640 × 480 and ≥ 25 at 1280 × 720 with undistortion on.

Run: ``.venv/bin/python bench/interface.py [--seconds 10] [--clicks 60] [--stall [--before DIR]] [--undistort]``.
Targets (issue 7): ≥ 25 frames/s; p95 click → overlay ≤ 100 ms.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
if os.environ.get("MCIT_BENCH_TREE"):  # measure another checkout's interface (``--before``) with this bench
    sys.path.insert(0, os.environ["MCIT_BENCH_TREE"])  # the browser harness lives with the e2e tests

from tests.e2e.harness import close_webgl_notice, free_port, launch, screen_of, wait_for_panel, wait_until  # noqa: E402

FRAMES = ROOT / ".." / "shared" / "data" / "visp-cube" / "frames"


def build(n_objects: int, fps: float, source=None, start: bool = True):
    from app.db import Database, seed_from_scene
    from app.scene import default_scene_path, load_scene
    from app.ui.server import InterfaceServer
    from app.video import FolderSource, FrameGrabber, StillSource
    from app.workflows import Site
    from core.brep import BRep
    from core.transforms import make_T, rot_z

    scene = load_scene(default_scene_path())
    db = Database.open(Path(tempfile.mkdtemp(prefix="mcit-bench-")) / "site.sqlite")
    seed_from_scene(db, scene)
    rng = np.random.default_rng(0)
    k = 0
    n = len(db.objects())
    with db.transaction():  # one commit (one fsync) for all the extra objects
        while n < n_objects:
            k += 1
            xy = rng.uniform([-0.4, -0.6], [0.4, 0.6])
            if k % 3:
                model = BRep.box(*rng.uniform(0.03, 0.08, 3))
            else:
                model = BRep.cylinder(rng.uniform(0.02, 0.04), rng.uniform(0.05, 0.12))
            db.add_object(
                f"extra_{k}",
                "box" if k % 3 else "cylinder",
                model,
                make_T(rot_z(rng.uniform(0, np.pi)), [xy[0], xy[1], 0.0]),
                status="known",
                method="bench",
            )
            n += 1
    if source is not None:
        video = source.description
    elif FRAMES.is_dir():
        source, video = FolderSource(FRAMES, fps=fps), f"ViSP cube sequence (218 real frames, 640×480) at {fps:.0f} fps"
    else:

        class NoiseVideo(StillSource):
            """A noise image moved a pixel each frame: a new image every frame, as a camera gives (the interface
            sends a still's same image once)."""

            def _read(self):
                return np.roll(self._image, self._index + 1, axis=1)

        source, video = (
            NoiseVideo(rng.integers(0, 255, (480, 640, 3), dtype=np.uint8), fps=fps),
            "a 640×480 noise image, moving",
        )
    site = Site(scene, db, clock=lambda: 0.0)
    server = InterfaceServer(site, FrameGrabber(source), port=free_port())
    return (server.start() if start else server), site, db, video


def open_page(browser, server):
    page = browser.new_page(viewport={"width": 1200, "height": 700})
    before = set(server.clients)
    page.goto(f"http://127.0.0.1:{server.port}/?fixedDpr=1")
    panel = wait_for_panel(server, before, timeout_s=30)
    close_webgl_notice(page)
    time.sleep(1.0)
    return page, panel


DELIVERED: list[tuple[float, int, int]] = []  # (time, /video updates, JPEG bytes) per message written to a browser


def count_deliveries() -> None:
    """Count the video frames viser writes to the browsers' websockets (the send returns once the
    bytes are in the socket: a browser that does not read blocks it, so this is the delivered rate)."""
    from websockets.asyncio.server import ServerConnection

    original = ServerConnection.send

    async def send(self, message, *args, **kwargs):
        result = await original(self, message, *args, **kwargs)
        DELIVERED.append((time.monotonic(), *video_updates(message)))
        return result

    ServerConnection.send = send


def measure_video(page, server, seconds: float) -> dict:
    """Frames delivered to one browser over ``seconds`` (after 5 s to settle), and the rate the
    server produced them over the same window."""
    time.sleep(5.0)
    sent0, t0 = server.frames_sent, time.monotonic()
    page.wait_for_timeout(seconds * 1000)
    t1, sent1 = time.monotonic(), server.frames_sent
    window = [(k, b) for t, k, b in DELIVERED if t0 <= t <= t1 and k]
    n = sum(k for k, _ in window)
    return {
        "delivered_fps": n / (t1 - t0),
        "sent_fps": (sent1 - sent0) / (t1 - t0),
        "kib": float(sum(b for _, b in window) / max(n, 1) / 1024),
    }


def video_updates(payload: bytes | list) -> tuple[int, int]:
    """(number of /video frame updates, their JPEG bytes) in one viser websocket message.

    viser's wire format: [8 bytes] msgpack size, [8 bytes] compressed size, zstd(msgpack), binary
    buffers; an image update is {"name": "/video", "updates": {"_data": <JPEG bytes>}}."""
    count = size = 0
    for m in payload if isinstance(payload, list) else _messages(payload):
        if isinstance(m, dict) and m.get("name") == "/video" and "_data" in (m.get("updates") or {}):
            count += 1
            data = m["updates"]["_data"]
            size += len(data) if isinstance(data, (bytes, bytearray)) else 0
    return count, size


def measure_clicks(page, server, panel, workflow: str, n: int, rng) -> np.ndarray:
    site = server.site
    cam = site.camera
    canvas = page.locator("canvas").nth(1)
    panel.click_latencies_s.clear()
    if workflow == "designate":
        page.get_by_role("button", name="Designate target").click()
        time.sleep(0.5)
        table = site.object("table")
        for _ in range(n):
            X = (
                table.T_world_obj[:3, :3] @ [rng.uniform(-0.4, 0.4), rng.uniform(-0.6, 0.6), 0.04]
                + table.T_world_obj[:3, 3]
            )
            x, y = screen_of(server, panel, cam.project(X))
            canvas.click(position={"x": x, "y": y})
            time.sleep(0.15)
    else:
        obj = site.object("parallelepiped")
        panel.session.select("parallelepiped")
        page.get_by_role("button", name="Update pose").click()
        time.sleep(0.5)
        drawn = cam.project(obj.model.edge_segments(obj.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
        done = 0
        while done < n:
            for k in range(len(drawn)):
                a, b = drawn[k]
                for uv in (
                    a + 0.3 * (b - a) + rng.normal(0, 2, 2),
                    a + 0.7 * (b - a) + rng.normal(0, 2, 2),
                    (a + b) / 2,
                ):
                    x, y = screen_of(server, panel, uv)
                    canvas.click(position={"x": x, "y": y})
                    time.sleep(0.15)
                    done += 1
                if done >= n:
                    break
            wf = panel.session.workflow
            if wf is not None and not wf.finished:  # start over: keep edges free for assignment
                wf.cancel()
                page.get_by_role("button", name="Update pose").click()
                time.sleep(0.5)
    time.sleep(0.5)
    return np.array(panel.click_latencies_s) * 1000.0


def ws_client(url: str, out: str) -> None:
    """A browser-like client: connects to viser's websocket like the page does, reads every message
    as it arrives (no rendering) and appends one line per message to ``out`` until killed: its
    wall-clock arrival time, the /video frames and the database overlay's node messages it holds. The
    first line, "<time> -1 -1", is when the connection opened (before the page's first message)."""
    import asyncio

    import msgspec
    import viser
    from websockets.asyncio.client import connect

    async def run() -> None:
        async with connect(url, subprotocols=[f"viser-v{viser.__version__}"], max_size=None, compression=None) as ws:
            with open(out, "a", buffering=1) as f:
                f.write(f"{time.time():.6f} -1 -1\n")
                # viser counts a client as connected once it reports its camera, as the page does
                await ws.send(
                    msgspec.msgpack.encode(
                        {
                            "type": "ViewerCameraMessage",
                            "wxyz": [1.0, 0.0, 0.0, 0.0],
                            "position": [3.2, 2.4, -5.0],
                            "fov": 0.9,
                            "near": 0.05,
                            "far": 2000.0,
                            "image_height": 700,
                            "image_width": 1200,
                            "look_at": [3.2, 2.4, 0.0],
                            "up_direction": [0.0, -1.0, 0.0],
                        }
                    )
                )
                while True:
                    message = await ws.recv()
                    t = time.time()
                    messages = _messages(message)
                    k, _ = video_updates(messages)
                    f.write(f"{t:.6f} {k} {overlay_messages(messages)}\n")

    asyncio.run(run())


def _messages(payload) -> list:
    """The messages of one viser websocket message (see ``video_updates``)."""
    import msgspec
    import zstandard

    if not isinstance(payload, (bytes, bytearray)) or len(payload) < 16:
        return []
    n_inner = int.from_bytes(payload[:8], "little")
    n_comp = int.from_bytes(payload[8:16], "little")
    inner = zstandard.ZstdDecompressor().decompress(bytes(payload[16 : 16 + n_comp]), max_output_size=n_inner)
    return msgspec.msgpack.decode(inner).get("messages", [])


def overlay_messages(messages: list) -> int:
    """How many of one websocket message's messages (``_messages``) create, update or remove a database
    overlay node."""
    n = 0
    for m in messages:
        name = m.get("name") if isinstance(m, dict) else None
        if isinstance(name, str) and name.startswith("/overlay/db"):
            n += 1
    return n


class Reader:
    """A browser-like client in its own process (``ws_client``) and what it received."""

    def __init__(self, port: int):
        import subprocess

        self.out = tempfile.mktemp(prefix="mcit-bench-frames-", suffix=".txt")
        Path(self.out).touch()
        self.process = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--ws-client", f"ws://127.0.0.1:{port}", self.out]
        )

    def rows(self) -> np.ndarray:
        """(N, 3): arrival time, video frames, overlay messages; the first row is the connection."""
        text = Path(self.out).read_text()
        rows = [r.split() for r in text.splitlines() if r.count(" ") == 2]
        return np.array(rows, float).reshape(-1, 3)

    @property
    def connected_at(self) -> float | None:
        r = self.rows()
        return float(r[0, 0]) if len(r) and r[0, 1] == -1 else None

    def wait_connected(self, timeout_s: float = 120.0) -> float:
        wait_until(lambda: self.connected_at is not None, timeout_s=timeout_s, what="the reader's connection")
        return float(self.connected_at)

    def frames(self, t0: float, t1: float) -> np.ndarray:
        r = self.rows()
        r = r[(r[:, 1] > 0) & (r[:, 0] >= t0) & (r[:, 0] <= t1)]
        return np.repeat(r[:, 0], r[:, 1].astype(int))

    def longest_gap_ms(self, t0: float, t1: float) -> float:
        """The longest time without a video frame within [t0, t1] (from t0: a browser that has none yet counts)."""
        return 1000.0 * float(np.diff(np.concatenate([[t0], self.frames(t0, t1), [t1]])).max())

    def last_overlay(self, t0: float) -> float | None:
        """When the last database overlay message after t0 arrived, or None."""
        r = self.rows()
        r = r[(r[:, 2] > 0) & (r[:, 0] >= t0)]
        return float(r[-1, 0]) if len(r) else None

    def stop(self) -> None:
        self.process.kill()
        self.process.wait()
        Path(self.out).unlink(missing_ok=True)


def click_event(server, uv):
    """What viser gives a scene click callback: a ray that meets the image plane at pixel uv."""
    from types import SimpleNamespace

    X = server.pixel_world.to_world(np.asarray(uv, float), 0.0)
    return SimpleNamespace(ray_origin=tuple(X - [0.0, 0.0, 5.0]), ray_direction=(0.0, 0.0, 1.0))


def _settled(server, reader: Reader, since: float, quiet_s: float = 1.5, timeout_s: float = 300.0) -> float:
    """Wait until the database thread has drawn the site as it is and ``reader`` has received no overlay
    message for ``quiet_s``; the time its last overlay message after ``since`` arrived."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        last = reader.last_overlay(since)
        if server.database_drawn and last is not None and time.time() - last > quiet_s:
            return last
        time.sleep(0.1)
    raise TimeoutError("the overlay never settled")


def _moved_camera(cam):
    """The camera recalibrated: its centre 5 mm aside (every object's projection moves)."""
    from core.camera import Camera

    K, T = cam.decompose()
    T = T.copy()
    T[0, 3] += 0.005
    return Camera(K @ T[:3], cam.width, cam.height)


JOINS = 5  # browsers joining one after the other, for the join figures


def measure_stall(n_objects: int, seconds: float, change_every_s: float, clicks: int, rng) -> dict:
    """At ``n_objects``: the full draw at start, for a joining browser and after a new camera calibration
    (time to the last overlay message received; each browser's longest video gap meanwhile, counted from
    its connection), then the video gaps while one object's pose is written every ``change_every_s``,
    then selection clicks (see the module docstring, 3)."""
    from core.transforms import make_T

    server, site, db, _ = build(n_objects, fps=30.0, start=False)
    draws: list[tuple[float, float, float]] = []  # per sync_database: (when it began, CPU s of the overlay, of all)
    sync, overlays = server.sync_database, [feed.overlay for feed in server.views.values()]
    overlay_cpu = [0.0]

    def timed(overlay):
        sync_overlay = overlay.sync

        def timed_overlay(*args):
            c = time.thread_time()
            try:
                return sync_overlay(*args)
            finally:
                overlay_cpu[0] += time.thread_time() - c

        return timed_overlay

    for overlay in overlays:
        overlay.sync = timed(overlay)

    def timed_sync() -> int:  # the draw's own CPU, on the database thread (not the video's or the sockets')
        t, c = time.time(), time.thread_time()
        overlay_cpu[0] = 0.0
        n = sync()
        draws.append((t, overlay_cpu[0], time.thread_time() - c))
        return n

    server.sync_database = timed_sync
    a = Reader(server.port)
    readers = [a]
    r: dict = {"objects": n_objects}
    try:
        a.wait_connected()
        wait_until(lambda: len(server.clients) >= 1, timeout_s=60, what="the first reader's panel")
        t0 = time.time()
        server.start()  # the first draw starts now, with a browser watching
        done = _settled(server, a, t0)
        r["start_s"], r["start_gap_ms"] = done - t0, a.longest_gap_ms(t0, done)
        r["start_cpu_s"] = sum(c for t, c, _ in draws if t0 <= t <= done)
        r["start_all_cpu_s"] = sum(c for t, _, c in draws if t0 <= t <= done)
        time.sleep(2.0)
        joins = []
        for k in range(JOINS):  # a browser joins (then leaves, but for the last one, which stays)
            b = Reader(server.port)
            readers.append(b)
            tb = b.wait_connected()
            done = _settled(server, b, tb)
            time.sleep(1.0)
            joins.append((done - tb, b.longest_gap_ms(tb, done), a.longest_gap_ms(tb - 0.5, done + 1.0)))
            if k < JOINS - 1:
                readers.pop().stop()
            time.sleep(1.0)
        # the median of the joins, and the worst (a loaded machine's single join is noise: 0.07-0.40 s)
        for key, values in zip(("join_s", "join_gap_ms", "join_other_gap_ms"), zip(*joins)):
            r[key], r[key + "_max"] = float(np.median(values)), float(np.max(values))
        tc = time.time()  # a new camera calibration: every object redrawn
        site.set_camera(_moved_camera(site.camera), rms_px=0.5, residuals_px=np.zeros(0), points={}, client="bench")
        done = max(_settled(server, x, tc) for x in readers)
        r["calib_s"] = done - tc
        r["calib_cpu_s"] = sum(c for t, c, _ in draws if tc <= t <= done)
        r["calib_all_cpu_s"] = sum(c for t, _, c in draws if tc <= t <= done)
        r["calib_gap_ms"] = max(x.longest_gap_ms(tc, done + 0.5) for x in readers)
        time.sleep(1.0)
        movable = [o for o in site.objects() if o.kind != "table"]
        t0 = time.time()
        changes = 0
        while time.time() < t0 + seconds:
            obj = site.object(movable[changes % len(movable)].name)
            T = obj.T_world_obj @ make_T(np.eye(3), [0.01, 0.0, 0.0])
            site.update_pose(obj, T, None, method="bench", client="bench")
            changes += 1
            time.sleep(max(0.0, t0 + changes * change_every_s - time.time()))
        t1 = time.time()
        r["gap_ms"] = max(x.longest_gap_ms(t0, t1) for x in readers)
        r["fps"] = min(len(x.frames(t0, t1)) for x in readers) / (t1 - t0)
        r["changes"], r["seconds"] = changes, t1 - t0
        latencies = []
        if clicks:
            panel = next(iter(server.clients.values()))
            cam = site.camera
            run_click = panel.guard(panel._on_click)
            boxes = [o for o in movable if len(o.model.edges)]
            for _ in range(clicks):
                obj = site.object(boxes[int(rng.integers(len(boxes)))].name)
                E = obj.model.edge_segments(obj.T_world_obj)
                uv = cam.project(E[int(rng.integers(len(E)))].mean(axis=0))
                n0 = len(panel.click_latencies_s)
                panel.click_worker.submit(run_click, click_event(server, uv))
                wait_until(lambda: len(panel.click_latencies_s) > n0, timeout_s=60, what="the click's redraw")
                latencies.append(panel.click_latencies_s[-1] * 1000.0)
                time.sleep(0.1)
        r["clicks_ms"] = np.array(latencies)
        overlay = server.db_overlay
        r["nodes"] = overlay.node_count if hasattr(overlay, "node_count") else 2 * len(overlay.drawn_ids)
    finally:
        for x in readers:
            x.stop()
        server.stop()
        db.close()
    return r


def measure_bare(seconds: float = 8.0) -> dict:
    """Bare viser: the same 30 frames/s video as an image node and nothing else; a second reader joins.
    The floor the interface's join figures stand beside."""
    import threading

    import viser

    from app.video import FolderSource, StillSource

    rng = np.random.default_rng(0)
    source = (
        FolderSource(FRAMES, fps=30.0)
        if FRAMES.is_dir()
        else StillSource(rng.integers(0, 255, (480, 640, 3), np.uint8))
    )
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    node = server.scene.add_image("/video", source.read().image, 6.4, 4.8, format="jpeg", jpeg_quality=80)
    stop = threading.Event()

    def pump() -> None:
        while not stop.is_set():
            t = time.monotonic()
            node.image = source.read().image
            stop.wait(max(0.0, 1 / 30 - (time.monotonic() - t)))

    threading.Thread(target=pump, daemon=True).start()
    a = Reader(server.get_port())
    b = None
    try:
        a.wait_connected()
        time.sleep(3.0)
        b = Reader(server.get_port())
        tb = b.wait_connected()
        time.sleep(seconds)
        first = b.frames(tb, tb + seconds)
        return {
            "join_first_frame_ms": 1000.0 * (first[0] - tb) if len(first) else float("inf"),
            "join_gap_ms": b.longest_gap_ms(tb, tb + seconds),
            "join_other_gap_ms": a.longest_gap_ms(tb - 0.5, tb + seconds),
        }
    finally:
        stop.set()
        for x in (a, b):
            if x is not None:
                x.stop()
        server.stop()


def stall_rows(sizes, seconds: float, change_every_s: float, clicks: int) -> list[dict]:
    rng = np.random.default_rng(2)
    rows = []
    for n in sizes:
        rows.append(measure_stall(n, seconds, change_every_s, clicks if n == max(sizes) else 0, rng))
        r = rows[-1]
        print(
            f"  {n} objects: start {r['start_s']:.2f} s (overlay {r['start_cpu_s']:.2f} s CPU, "
            f"all {r['start_all_cpu_s']:.2f}), "
            f"join {r['join_s']:.2f} s, calibration {r['calib_s']:.2f} s (overlay {r['calib_cpu_s']:.2f} s CPU, all "
            f"{r['calib_all_cpu_s']:.2f}), load {os.getloadavg()[0]:.1f}",
            file=sys.stderr,
            flush=True,
        )
    return rows


STALL_COLUMNS = (
    ("scene nodes of the overlay", "nodes", "{:.0f}", "—"),
    ("full draw at start, to the last overlay message (s)", "start_s", "{:.2f}", "≤ 2"),
    ("  its CPU: the database overlay's drawing (s)", "start_cpu_s", "{:.2f}", "—"),
    ("  its CPU with the 3D world's and the ray casters' (the database thread's, s)", "start_all_cpu_s", "{:.2f}", "—"),
    ("  its browser's longest video gap from the start (ms)", "start_gap_ms", "{:.0f}", "≤ 500"),
    ("full draw for a joining browser, from its connection (s), median of 5", "join_s", "{:.2f}", "≤ 2"),
    ("  the same, the slowest of the 5 joins", "join_s_max", "{:.2f}", "≤ 2"),
    ("  the joining browser's longest video gap from its connection (ms), median", "join_gap_ms", "{:.0f}", "≤ 500"),
    ("  the same, the worst of the 5 joins", "join_gap_ms_max", "{:.0f}", "≤ 500"),
    ("  the watching browser's longest video gap meanwhile (ms), median", "join_other_gap_ms", "{:.0f}", "≤ 150"),
    ("  the same, the worst of the 5 joins", "join_other_gap_ms_max", "{:.0f}", "≤ 150"),
    ("full draw after a new camera calibration (s)", "calib_s", "{:.2f}", "≤ 2"),
    ("  its CPU: the database overlay's drawing (s)", "calib_cpu_s", "{:.2f}", "—"),
    ("  its CPU with the 3D world's and the ray casters' (the database thread's, s)", "calib_all_cpu_s", "{:.2f}", "—"),
    ("  the browsers' longest video gap meanwhile (ms)", "calib_gap_ms", "{:.0f}", "≤ 500 (watching: ≤ 150)"),
    ("longest video gap, a pose written every 2 s (ms)", "gap_ms", "{:.0f}", "≤ 100"),
    ("frames/s delivered meanwhile (the slower browser)", "fps", "{:.1f}", "≥ 28"),
)


def stall_table(sizes, seconds: float, change_every_s: float, clicks: int, before: str | None = None) -> None:
    """The stall table of this tree, beside the same run on ``before`` (another checkout's root) and bare viser."""
    import json
    import subprocess

    rows = stall_rows(sizes, seconds, change_every_s, clicks)
    old = None
    if before:
        cmd = [
            sys.executable,
            str(Path(__file__).resolve()),
            "--stall-json",
            "--stall-sizes",
            ",".join(map(str, sizes)),
        ]
        cmd += ["--stall-seconds", str(seconds), "--change-every", str(change_every_s), "--stall-clicks", str(clicks)]
        env = dict(os.environ, MCIT_BENCH_TREE=str(Path(before).resolve()))
        out = subprocess.run(cmd, env=env, capture_output=True, text=True, check=True).stdout
        old = json.loads(out.strip().splitlines()[-1])
    bare = measure_bare()
    load = os.getloadavg()[0]
    print(
        f"mcit interface at scale — video 30 frames/s (640×480), browser-like clients (websocket readers, no "
        f"rendering, each its own process); a pose moved 1 cm every {change_every_s:.0f} s over {seconds:.0f} s; "
        f"machine: {os.cpu_count()} cores, load average {load:.1f}" + (f"; before = {before}" if before else "")
    )
    print()
    head = "| metric | " + " | ".join(
        (f"{r['objects']} before | {r['objects']} after" if old else f"{r['objects']} objects") for r in rows
    )
    print(head + " | target at 2,000 |")
    print("|---|" + "---|" * (len(rows) * (2 if old else 1)) + "---|")
    for label, key, fmt, target in STALL_COLUMNS:
        cells = []
        for i, r in enumerate(rows):
            if old:
                cells.append(fmt.format(old[i][key]) if key in old[i] else "—")
            cells.append(fmt.format(r[key]))
        print(f"| {label} | " + " | ".join(cells) + f" | {target} |")
    lat = rows[-1]["clicks_ms"]
    if len(lat):
        cell = f"{np.percentile(lat, 50):.1f} / {np.percentile(lat, 95):.1f} / {lat.max():.1f}"
        olds = ""
        if old and old[-1].get("clicks_ms"):
            o = np.array(old[-1]["clicks_ms"])
            olds = f"before {np.percentile(o, 50):.1f} / {np.percentile(o, 95):.1f} / {o.max():.1f}; "
        print(
            f"| click → overlay, {rows[-1]['objects']} objects, p50 / p95 / max ms (n = {len(lat)}) | "
            f"{olds}after {cell} | p95 ≤ 50 ms |"
        )
    print(
        f"| bare viser (the video alone), a browser joining: its first frame {bare['join_first_frame_ms']:.0f} ms "
        f"after connecting, its longest gap {bare['join_gap_ms']:.0f} ms, the watching browser's "
        f"{bare['join_other_gap_ms']:.0f} ms | | |"
    )


def bench_lens(width: int, height: int):
    """A wide-angle lens for ``width`` × ``height`` frames (OpenCV's 5 coefficients, tens of pixels at the corners)."""
    from app.undistort import LensDistortion

    f = 0.8 * width
    K = np.array([[f, 0.0, (width - 1) / 2], [0.0, f, (height - 1) / 2], [0.0, 0.0, 1.0]])
    return LensDistortion(K, [-0.3, 0.1, 0.001, -0.001, -0.02], "opencv", width, height)


def smooth_video(width: int, height: int):
    """A 30 frames/s video of 8 smooth-noise images in turn (JPEG-friendly, like a camera's images rather than
    pixel noise; viser sends nothing for an image that did not change, so not a still)."""
    import cv2

    from app.video import VideoSource

    rng = np.random.default_rng(3)
    images = [
        cv2.resize(
            rng.integers(0, 255, (height // 8, width // 8, 3), dtype=np.uint8),
            (width, height),
            interpolation=cv2.INTER_CUBIC,
        )
        for _ in range(8)
    ]

    class Cycle(VideoSource):
        def __init__(self):
            super().__init__()
            self.width, self.height, self.fps, self.frame_count = width, height, 30.0, len(images)
            self.description = f"{width}×{height} smooth noise at 30 fps"

        def _read(self):
            if self._position + 1 >= len(images):
                self._position = -1
            return images[self._position + 1]

    return Cycle()


def measure_rate(source, seconds: float) -> dict:
    """Frames/s a browser-like client receives (and the server sends) from ``source`` over ``seconds``."""
    server, site, db, _ = build(50, fps=30.0, source=source)
    before = set(server.clients)
    reader = Reader(server.port)
    try:
        wait_for_panel(server, before, timeout_s=120)
        deadline = time.monotonic() + 300
        while not server.database_drawn and time.monotonic() < deadline:  # the first full draw
            time.sleep(0.2)
        time.sleep(3.0)
        t0, sent0 = time.time(), server.frames_sent
        time.sleep(seconds)
        t1, sent1 = time.time(), server.frames_sent
        window = reader.frames(t0, t1)
    finally:
        reader.stop()
        server.stop()
        db.close()
    return {"fps": len(window) / (t1 - t0), "sent_fps": (sent1 - sent0) / (t1 - t0)}


def undistort_table(seconds: float) -> None:
    """Frames/s with and without undistortion, same run (see the module docstring, 4)."""
    from app.undistort import UndistortedSource

    rows = []
    for w, h in ((640, 480), (1280, 720)):
        lens = bench_lens(w, h)
        img = smooth_video(w, h).read().image
        lens.undistort_image(img)
        t = time.perf_counter()
        for _ in range(50):
            lens.undistort_image(img)
        remap_ms = (time.perf_counter() - t) / 50 * 1000.0
        plain = measure_rate(smooth_video(w, h), seconds)
        und = measure_rate(UndistortedSource(smooth_video(w, h), lens), seconds)
        rows.append((w, h, lens.describe(), remap_ms, plain, und))
        print(
            f"  {w}×{h}: {plain['fps']:.1f} frames/s plain, {und['fps']:.1f} undistorted", file=sys.stderr, flush=True
        )
    load = os.getloadavg()[0]
    print(
        "mcit interface with lens distortion — a 30 frames/s video (8 smooth-noise images in "
        "turn), 50 objects, one browser-like client (a websocket reader, its own process), "
        f"{seconds:.0f} s each; machine: {os.cpu_count()} cores, load average {load:.1f}"
    )
    print()
    print(
        "| frames | lens | remap per frame (ms) | frames/s received, undistortion off | frames/s received, "
        "undistortion on | target (on) |"
    )
    print("|---|---|---|---|---|---|")
    for w, h, lens, ms, plain, und in rows:
        target = "≥ 28" if w == 640 else "≥ 25"
        print(f"| {w}×{h} | {lens} | {ms:.1f} | {plain['fps']:.1f} | {und['fps']:.1f} | {target} |")


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "--ws-client":
        ws_client(sys.argv[2], sys.argv[3])
        return 0
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seconds", type=float, default=10.0)
    ap.add_argument("--clicks", type=int, default=60)
    ap.add_argument("--objects", type=int, default=50)
    ap.add_argument("--stall", action="store_true", help="only the stall table (no chromium)")
    ap.add_argument("--stall-sizes", default="50,500,2000")
    ap.add_argument("--stall-seconds", type=float, default=12.0)
    ap.add_argument("--change-every", type=float, default=2.0)
    ap.add_argument("--stall-clicks", type=int, default=30)
    ap.add_argument("--before", help="the stall table beside the same run on another checkout (its root)")
    ap.add_argument("--stall-json", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--undistort", action="store_true", help="only the undistortion table (no chromium)")
    ap.add_argument("--undistort-seconds", type=float, default=10.0)
    args = ap.parse_args()
    if args.undistort:
        undistort_table(args.undistort_seconds)
        return 0
    sizes = [int(n) for n in args.stall_sizes.split(",")]
    if args.stall_json:  # one tree's rows, for another run's table (--before)
        import json

        rows = stall_rows(sizes, args.stall_seconds, args.change_every, args.stall_clicks)
        print(json.dumps([{k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in r.items()} for r in rows]))
        return 0
    if args.stall:
        stall_table(sizes, args.stall_seconds, args.change_every, args.stall_clicks, args.before)
        return 0
    from playwright.sync_api import sync_playwright

    count_deliveries()
    server, site, db, video = build(args.objects, fps=30.0)
    rng = np.random.default_rng(1)
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page, panel = open_page(browser, server)
            v = measure_video(page, server, args.seconds)
            page.close()
            page, panel = open_page(browser, server)
            lat_d = measure_clicks(page, server, panel, "designate", args.clicks, rng)
            lat_u = measure_clicks(page, server, panel, "update_pose", args.clicks, rng)
            browser.close()
    finally:
        server.stop()
        db.close()
    load = os.getloadavg()[0]
    print(
        f"mcit interface benchmark — {len(site.objects())} objects in "
        f"the database, video: {video}, JPEG q{server.jpeg_quality}"
    )
    print(
        "one headless chromium (swiftshader), viewport 1200×700; "
        f"machine: {os.cpu_count()} cores, load average {load:.1f}"
    )
    print()
    print("| metric | measured | target |")
    print("|---|---|---|")
    print(f"| video frames/s delivered to the browser (640×480, overlay live) | {v['delivered_fps']:.1f} | ≥ 25 |")
    print(f"| video frames/s produced by the server's redraw loop | {v['sent_fps']:.1f} | (source: 30) |")
    print(f"| mean video frame size (JPEG) | {v['kib']:.1f} KiB | — |")
    for name, lat in (
        ("designate target (ray cast on 50 objects)", lat_d),
        ("update pose (points, segments, edges)", lat_u),
    ):
        if len(lat):
            print(
                f"| click → overlay sent, {name}: p50 / p95 / max (n = {len(lat)}) | "
                f"{np.percentile(lat, 50):.1f} / {np.percentile(lat, 95):.1f} / {lat.max():.1f} ms | p95 ≤ 100 ms |"
            )
        else:
            print(f"| click → overlay sent, {name} | no click reached the server | p95 ≤ 100 ms |")
    print()
    stall_table([int(n) for n in args.stall_sizes.split(",")], args.stall_seconds, args.change_every, args.stall_clicks)
    print()
    undistort_table(args.undistort_seconds)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
