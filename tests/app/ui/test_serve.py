"""mcit serve: defaults (loopback), and everything it opens on a temporary database and video folder."""

from __future__ import annotations

import cv2
import numpy as np

from app.cli import build_parser
from app.scene import default_scene_path
from app.ui.serve import build_interface
from tests.e2e.harness import free_port


def test_defaults_listen_on_loopback_with_emulated_devices():
    args = build_parser().parse_args(["serve"])
    assert args.host == "127.0.0.1" and args.port is None  # 8080, or the next free one
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


def _serve_args(tmp_path, *extra):
    return build_parser().parse_args(
        ["serve", "--db", str(tmp_path / "site.sqlite"), "--no-devices", "--port", str(free_port()), *extra]
    )


def _sources(server) -> dict:
    return {name: feed.grabber.source for name, feed in server.views.items()}


def test_the_default_is_the_site_rendered_live_on_every_camera(tmp_path):
    import time

    from app.render.live import LiveRenderError, LiveSource

    try:
        server, closers = build_interface(_serve_args(tmp_path))
    except LiveRenderError as exc:  # pragma: no cover - only where OpenGL cannot start
        import pytest

        pytest.skip(f"no live rendering here: {exc}")
    try:
        sources = _sources(server)
        assert set(sources) == {"front", "side"}
        assert all(isinstance(s, LiveSource) for s in sources.values())
        assert [s.view_name for s in sources.values()] == ["front", "side"]
        assert all(s.fps == 12.0 and s.frame_count == 343 for s in sources.values())  # the recordings' timing
        deadline = time.monotonic() + 20
        while any(f.grabber.latest() is None for f in server.views.values()) and time.monotonic() < deadline:
            time.sleep(0.05)
        front = server.views["front"].grabber.latest()
        assert front is not None and front.image.shape == (256, 512, 3)
        assert "the emulated site, rendered live" in str(server._video_status(server.views["front"]))
    finally:
        server.server.stop()
        for close in closers:
            close()


def test_recorded_plays_the_scenes_videos_and_a_missing_opengl_falls_back_to_them(tmp_path, monkeypatch, caplog):
    import logging

    import app.render.live as live
    from app.video import CaptureSource

    server, closers = build_interface(_serve_args(tmp_path, "--recorded"))
    try:
        sources = _sources(server)
        assert all(isinstance(s, CaptureSource) for s in sources.values())
        assert [s.description for s in sources.values()] == [
            f"file {p}" for p in (default_scene_path() / "video.avi", default_scene_path() / "side.avi")
        ]
    finally:
        server.server.stop()
        for close in closers:
            close()

    def no_gl(*args, **kwargs):
        raise live.LiveRenderError("no OpenGL 4.5 through EGL here (libEGL.so.1 missing)")

    monkeypatch.setattr(live, "LiveSource", no_gl)
    with caplog.at_level(logging.WARNING, logger="mcit.serve"):
        server, closers = build_interface(_serve_args(tmp_path))
    try:
        assert all(isinstance(s, CaptureSource) for s in _sources(server).values())
        said = [r.getMessage() for r in caplog.records if "rendered live" in r.getMessage()]
        assert len(said) == 1 and "libEGL.so.1 missing" in said[0] and "recordings" in said[0]
    finally:
        server.server.stop()
        for close in closers:
            close()
