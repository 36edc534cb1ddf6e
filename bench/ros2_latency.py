"""Latency of the ROS 2 bridge beside the feed socket's, in one run (issue 26).

Setup: ``mcit serve``'s own interface (build_interface) on the bundled scene with ``--video ros2:/cam/image_raw
--ros2 --feed-socket``, no browser; a peer node in its own rclpy context (``app.ros2.peer.RosPeer``: the messages
cross Fast DDS as another program's would) publishes the first camera's image (512 × 256, rgb8) at 10 per second.

1. Image published → frame sent: from the peer's publish to the moment the interface's frame loop hands that image
   (found by its header stamp) to viser for the browsers (the overlay is drawn over it there).
2. Pose written → received: an object's pose written through the site (as Accept writes it), every 0.2 s; from the
   write's start to (a) the PoseStamped at the peer, (b) the feed socket's JSON line at a socket reader.

Run: ``.venv/bin/python bench/ros2_latency.py [--n 100] [--domain 42]``. Prints p50 / p95 / max in ms per path.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def _stats(ms: list[float]) -> str:
    a = np.asarray(ms, float)
    if not len(a):
        return "| — | — | — | 0 |"
    return f"| {np.percentile(a, 50):.1f} | {np.percentile(a, 95):.1f} | {a.max():.1f} | {len(a)} |"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=100, help="images and poses measured (default 100)")
    ap.add_argument("--domain", type=int, default=42, help="DDS domain id (default 42)")
    opts = ap.parse_args()

    from app.ros2.peer import RosPeer
    from app.scene import default_scene_path, load_scene
    from app.ui.serve import add_serve_parser, build_interface
    from tests.e2e.harness import free_port, site_frame

    print(f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    scene = load_scene(default_scene_path())
    image = site_frame(scene)
    K, _ = scene.camera.decompose()
    tmp = Path(tempfile.mkdtemp(prefix="mcit-ros2-bench-"))
    sock = tmp / "feed.sock"
    peer = RosPeer(opts.domain)
    parser = argparse.ArgumentParser()
    add_serve_parser(parser.add_subparsers(dest="command"))
    args = parser.parse_args(
        ["serve", "--port", str(free_port()), "--db", str(tmp / "site.sqlite"), "--no-devices", "--recorded"]
        + ["--video", "ros2:/cam/image_raw", "--ros2", "--ros2-domain", str(opts.domain), "--feed-socket", str(sock)]
    )
    published: dict[float, float] = {}  # stamp → wall time of the publish
    sent: dict[float, float] = {}  # stamp → wall time the frame loop handed it to viser
    stop = threading.Event()

    def camera():
        k = 0
        while not stop.wait(0.1):
            t = 1_733_400_000.0 + 0.1 * k
            k += 1
            published[round(t, 6)] = time.time()
            peer.publish_image(image, t, "/cam/image_raw")

    threading.Thread(target=camera, daemon=True).start()
    server, closers = build_interface(args)
    view = server.views[scene.views[0].name]
    send = server._send_frame

    def timed_send(feed):  # the frame loop's hand-over of a new frame, by its stamp
        before = feed.frame_index
        out = send(feed)
        frame = feed.grabber.latest()
        if feed is view and frame is not None and feed.frame_index != before and frame.stamp is not None:
            sent.setdefault(round(frame.stamp, 6), time.time())
        return out

    server._send_frame = timed_send
    server.start()
    try:
        deadline = time.monotonic() + 0.1 * opts.n + 30
        while len(sent) < opts.n + 5 and time.monotonic() < deadline:
            time.sleep(0.1)
        image_ms = [1000 * (sent[s] - published[s]) for s in sorted(sent)[5:] if s in published][: opts.n]

        # poses: the PoseStamped at the peer beside the feed socket's line
        topic = peer.watch_pose("parallelepiped")
        lines: list[tuple[float, dict]] = []  # (arrival, line) of the feed socket's reader

        def read():
            from app.feed import follow

            for line in follow(sock):  # ends when the publisher closes the socket
                lines.append((time.time(), line))

        threading.Thread(target=read, daemon=True).start()
        time.sleep(1.0)
        site = server.site
        ros_ms, feed_ms = [], []
        for k in range(opts.n):
            obj = site.object("parallelepiped")
            T = obj.T_world_obj.copy()
            T[0, 3] += 0.001 if k % 2 == 0 else -0.001
            n_ros, n_feed = len(peer.poses[topic]), len(lines)
            t0 = time.time()
            site.update_pose(obj, T, None, method="bench", client="bench", seen_at=t0)
            if peer.wait(lambda: len(peer.poses[topic]) > n_ros, 5.0):
                ros_ms.append(1000 * (peer.poses[topic][n_ros][0] - t0))
            end = time.monotonic() + 5.0
            while len(lines) <= n_feed and time.monotonic() < end:
                time.sleep(0.0005)
            if len(lines) > n_feed:
                feed_ms.append(1000 * (lines[n_feed][0] - t0))
            time.sleep(0.2)
    finally:
        stop.set()
        server.stop()
        for close in closers:
            close()
        peer.close()

    print(f"\nROS 2 bridge latency, {os.cpu_count()} cores, Fast DDS on one machine (ms)\n")
    print("| path | p50 | p95 | max | n |")
    print("|---|---|---|---|---|")
    print("| image published (ROS 2) → frame sent to the browsers " + _stats(image_ms))
    print("| pose written → PoseStamped received (ROS 2) " + _stats(ros_ms))
    print("| pose written → feed socket line received (anchor) " + _stats(feed_ms))
    return 0


if __name__ == "__main__":
    sys.exit(main())
