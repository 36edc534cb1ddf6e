"""A still image as the video (an image file, a scene without a video file: ``mcit serve`` shows a rendered still)
is sent to the browsers once, not again at its frame rate: each browser decoded and drew the same image 10 to 20
times a second. A recording is sent frame by frame."""

from __future__ import annotations

import numpy as np

from app.ui.server import InterfaceServer
from app.video import FrameGrabber, StillSource
from tests.e2e.harness import free_port, wait_until


def test_a_still_is_sent_once_while_its_frames_go_on(site):
    image = np.full((site.camera.height, site.camera.width, 3), 90, np.uint8)
    grabber = FrameGrabber(StillSource(image, fps=50))
    server = InterfaceServer(site, grabber, port=free_port()).start()
    try:
        wait_until(lambda: grabber.latest() is not None and grabber.latest().index >= 20, 20.0, "20 frames read")
        wait_until(lambda: server.redraws >= 10, 20.0, "the frame loop running")
        assert server.views[site.views[0]].frames_sent == 1
        assert server.video.image.shape == image.shape
    finally:
        server.stop()
