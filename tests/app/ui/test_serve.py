"""mcit serve: defaults (loopback), and everything it opens on a temporary database and video folder."""

from __future__ import annotations

import cv2
import numpy as np

from app.cli import build_parser
from app.ui.serve import build_interface
from tests.e2e.harness import free_port


def test_defaults_listen_on_loopback_with_emulated_devices():
    args = build_parser().parse_args(["serve"])
    assert args.host == "127.0.0.1" and args.port == 8080
    assert args.video == [] and args.db is None and args.rangefinder is None and not args.no_devices


def test_build_interface_seeds_a_new_database_and_serves(tmp_path):
    for i in range(3):
        cv2.imwrite(str(tmp_path / f"f{i}.png"), np.full((256, 512), 60 * i, np.uint8))
    args = build_parser().parse_args(
        [
            "serve",
            "--video",
            str(tmp_path),
            "--db",
            str(tmp_path / "site.sqlite"),
            "--no-devices",
            "--port",
            str(free_port()),
        ]
    )
    server, closers = build_interface(args)
    try:
        server.start()
        assert server.url.startswith("http://127.0.0.1:")
        assert {o.name for o in server.site.objects()} >= {"table", "parallelepiped"}
        assert server.site.devices is None
        assert (server.pixel_world.width, server.pixel_world.height) == (512, 256)
    finally:
        server.stop()
        for close in closers:
            close()
    # a second start on the same file keeps the site (no second seeding)
    server, closers = build_interface(args)
    try:
        assert len(server.site.db.history()) == len(
            [c for c in server.site.db.history() if c.method.startswith("seed")]
        )
    finally:
        server.server.stop()
        for close in closers:
            close()
