"""Take docs/img/own_site.png: ``mcit serve --site`` on the ViSP tea box made by docs/own-site.md's three
commands, in headless chromium at 1280×720, frame 0 of teabox.mp4 shown (the frame the corners were
clicked on). Run from the project root: ``.venv/bin/python docs/img/shoot_own_site.py`` (needs
/usr/bin/chromium and ../shared/data/visp-teabox)."""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2

ROOT = Path(__file__).resolve().parents[2]
DATA = ROOT.parent / "shared" / "data" / "visp-teabox"
CLICKS = ((192, 84.5), (349.5, 205.5), (324, 376), (458.5, 351))  # tests/app/vision/test_track.py
PORT = 8765


def mcit(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "app.cli", *args], cwd=ROOT, check=True, capture_output=True)


def main() -> None:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory() as tmp:
        site, init, frame0 = Path(tmp) / "teabox", Path(tmp) / "teabox.init", Path(tmp) / "frame0.png"
        init.write_text((DATA / "teabox.init").read_text() + "4\n" + "".join(f"{v} {u}\n" for u, v in CLICKS))
        cv2.imwrite(str(frame0), cv2.VideoCapture(str(DATA / "teabox.mp4")).read()[1])
        mcit("site", "new", str(site), "--camera", str(DATA / "teabox.xml"), "--video", str(DATA / "teabox.mp4"))
        mcit("db", "import", str(DATA / "teabox.cao"), "--site", str(site), "--pose", str(init))
        argv = ["serve", "--site", str(site), "--video", str(frame0), "--port", str(PORT)]
        serve = subprocess.Popen(
            [sys.executable, "-m", "app.cli", *argv],
            cwd=ROOT,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
        )
        try:
            for line in serve.stdout:
                if "open http" in line:
                    break
            with sync_playwright() as pw:
                browser = pw.chromium.launch(
                    executable_path="/usr/bin/chromium",
                    args=["--no-sandbox", "--use-angle=swiftshader", "--enable-unsafe-swiftshader"],
                )
                page = browser.new_page(viewport={"width": 1280, "height": 720})
                page.goto(f"http://127.0.0.1:{PORT}/?fixedDpr=1")
                notice = page.locator(".mantine-Notification-root", has_text="Software WebGL")
                notice.locator("button").click(timeout=30_000)
                time.sleep(3)
                out = ROOT / "docs" / "img" / "own_site.png"
                page.screenshot(path=str(out))
                browser.close()
            img = Image.open(out).convert("RGB")
            img.quantize(colors=256, method=Image.Quantize.FASTOCTREE).save(out, optimize=True)
            print(f"{out.relative_to(ROOT)}: {out.stat().st_size // 1024} KiB")
        finally:
            serve.terminate()
            serve.wait()


if __name__ == "__main__":
    main()
