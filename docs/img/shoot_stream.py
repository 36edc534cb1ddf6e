"""Take docs/img/stream_lost.png: mcit serve on a stream that is lost, in a real headless browser.

Debian's ffmpeg serves the bundled scene's video as Motion-JPEG over HTTP (as an IP camera's
``/video.mjpg``); the interface is built exactly as ``mcit serve --video URL`` builds it; once the
page shows the live video, ffmpeg is killed and the page is taken while mcit reconnects.

Run from the project root: ``.venv/bin/python docs/img/shoot_stream.py`` (needs ffmpeg and /usr/bin/chromium).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tests.e2e.harness import close_webgl_notice, free_port, launch, wait_for_panel, wait_until  # noqa: E402

OUT = ROOT / "docs" / "img" / "stream_lost.png"


def main() -> int:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    from app.cli import build_parser
    from app.ui.serve import build_interface

    port = free_port()
    url = f"http://127.0.0.1:{port}/video.mjpg"
    ffmpeg = subprocess.Popen(
        [
            "ffmpeg",
            "-hide_banner",
            "-nostdin",
            "-loglevel",
            "error",
            "-re",
            "-stream_loop",
            "-1",
            "-i",
            str(ROOT / "scenes" / "workcell" / "video.avi"),
            "-f",
            "mpjpeg",
            "-q:v",
            "3",
            "-listen",
            "1",
            url,
        ]
    )
    time.sleep(1.0)
    db = Path(tempfile.mkdtemp(prefix="mcit-stream-")) / "site.sqlite"
    args = build_parser().parse_args(
        ["serve", "--video", url, "--db", str(db), "--no-devices", "--port", str(free_port())]
    )
    server, closers = build_interface(args)
    server.start()
    try:
        with sync_playwright() as p:
            browser = launch(p)
            page = browser.new_page(viewport={"width": 1280, "height": 720})
            before = set(server.clients)
            page.goto(server.url + "/?fixedDpr=1")
            wait_for_panel(server, before)
            wait_until(lambda: server.database_drawn, 20.0, "the database overlay")
            close_webgl_notice(page)
            time.sleep(2.0)
            ffmpeg.kill()
            wait_until(lambda: server._video_stamp is not None, 10.0, "the video to be marked not live")
            time.sleep(2.5)
            close_webgl_notice(page)  # in case it came late
            time.sleep(0.5)
            page.screenshot(path=str(OUT))
            browser.close()
    finally:
        ffmpeg.kill()
        server.stop()
        for close in closers:
            close()
    img = Image.open(OUT).convert("RGB")
    img.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(OUT, optimize=True)
    print(f"{OUT.relative_to(ROOT)}: {OUT.stat().st_size // 1024} KiB")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
