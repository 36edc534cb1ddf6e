"""ROS 2 in the browser: ``mcit serve --video ros2:/cam/image_raw --ros2`` fed by a real rclpy node (another
context: the images cross Fast DDS). The page shows the published images with the database drawn over them; the
operator updates the moved box's pose by one double click on them; the PoseStamped mcit publishes carries the
stamp of the very image the click was made on, and the pose is the scene's truth."""

from __future__ import annotations

import os
import threading

import numpy as np
import pytest

from core.transforms import pose_error

from .flows import Operator, projected_edges
from .harness import FRAME_T_S, ServedInterface, site_frame, wait_until
from .test_workflows_pose import _start_update_pose

pytestmark = pytest.mark.e2e
pytest.importorskip("rclpy", reason="the ROS 2 extra is not installed: pip install '.[ros2]'")

BOX = "parallelepiped"
T0 = 1_733_400_000.0  # the images' stamps: far from the clock's, so that a clock's stamp would show


class RosCameraSite(ServedInterface):
    """``mcit serve``'s own interface (build_interface) with its first camera's video from ROS 2."""

    def __init__(self, tmp_path, domain: int):
        super().__init__(
            ["--db", str(tmp_path / "site.sqlite"), "--no-devices", "--recorded"]
            + ["--video", "ros2:/cam/image_raw", "--ros2", "--ros2-domain", str(domain)]
        )


def test_the_video_from_ros2_is_worked_on_and_the_pose_goes_out_stamped_with_its_image(browser, scene, tmp_path):
    from app.ros2.peer import RosPeer

    domain = 60 + int(os.environ.get("PYTEST_XDIST_WORKER", "gw0")[2:] or 0)
    peer = RosPeer(domain)
    image = site_frame(scene)  # the site at FRAME_T_S: the box has moved since the database's pose
    K, _ = scene.camera.decompose()
    stamps: list[float] = []
    stop = threading.Event()

    def camera():  # the robot's camera driver: 4 images a second, each with its own stamp (each image the page
        k = 0  # draws again: at 10 a second, the page's software WebGL took 9.6 s of CPU at this test's dpr 1)
        while not stop.wait(0.25):
            t = T0 + 0.25 * k
            k += 1
            stamps.append(t)
            peer.publish_image(image, t, "/cam/image_raw", "bgr8")
            peer.publish_camera_info(K, image.shape[1], image.shape[0], t, "/cam/camera_info")

    threading.Thread(target=camera, daemon=True).start()
    ui = RosCameraSite(tmp_path, domain)
    try:
        topic = peer.watch_pose(BOX)
        page = ui.open(browser, viewport={"width": 1280, "height": 720}, dpr=1)  # its pixels are read
        page.get_by_text("ROS 2 /cam/image_raw").first.wait_for(timeout=60_000)  # the panel names the source
        # the published image is what the page shows (local means: JPEG transport decorrelates single pixels)
        import cv2

        smooth = cv2.blur(image.mean(axis=2).astype(np.float32), (5, 5))
        uv = np.random.default_rng(0).uniform([8, 8], [503, 232], size=(300, 2))
        truth = np.array([smooth[int(round(v)), int(round(u))] for u, v in uv])

        def shown_is_the_image() -> bool:
            shot = ui.screenshot(page)
            at = [ui.screen_of(page, p) for p in uv]
            shown = np.array([shot[int(y) - 3 : int(y) + 4, int(x) - 3 : int(x) + 4].mean() for x, y in at])
            return float(np.corrcoef(shown, truth)[0, 1]) > 0.9

        wait_until(shown_is_the_image, what="the ROS 2 image on the page")
        # the database drawn over it: the table's long edges in green where C projects them
        from .test_interface import _drawn_along

        table = ui.site.object("table")
        segs = ui.site.camera.project(table.model.edge_segments(table.T_world_obj).reshape(-1, 3)).reshape(-1, 2, 2)
        wire = table.model.wireframe(ui.site.camera.center, table.T_world_obj)
        long_edges = [
            int(k)
            for k, v in zip(wire.edge_index, wire.visible)
            if v and k >= 0 and np.linalg.norm(segs[k, 1] - segs[k, 0]) > 100
        ]
        assert long_edges
        wait_until(
            lambda: min(_drawn_along(ui, page, ui.screenshot(page), segs[k]) for k in long_edges) >= 0.7,
            what="the table's edges drawn over the ROS 2 image",
        )

        # one double click on the box where the image shows it, Accept
        op = Operator(ui, page)
        obj = ui.site.object(BOX)
        T_true = scene.body(BOX).pose_at(FRAME_T_S)
        assert pose_error(T_true, obj.T_world_obj)[0] > 50.0  # the database is stale
        wf = _start_update_pose(op, page, obj, ui.site.camera)
        op.double_click(ui.site.camera.project_obj(T_true, obj.model.vertices).mean(axis=0))
        wait_until(lambda: wf.found is not None, timeout_s=60, what="the found poses", panel=page.panel)
        op.accept(wf)
        wait_until(lambda: ui.db.get(BOX).version == obj.version + 1, what="the pose written")
        entry = ui.db.history(BOX)[-1]
        # the frame clicked on: one of the published images, by its header stamp, to the nanosecond the header holds
        # (T0 + 0.25 k read back from its seconds and nanoseconds can differ from the float sent in its last place)
        assert min(abs(entry.seen_at - t) for t in stamps) < 1e-6, (entry.seen_at, stamps[:3])
        assert entry.clicks["frame"]["stamp"] == pytest.approx(entry.seen_at)

        # ROS 2: the PoseStamped of the box, stamped with that image's time, at the truth
        def stamped():
            return [m for _, m in peer.poses[topic] if abs(peer.stamp_of(m) - entry.seen_at) < 1e-6]

        assert peer.wait(lambda: bool(stamped()), 60.0), "no PoseStamped with the image's stamp"
        msg = stamped()[-1]
        from scipy.spatial.transform import Rotation

        q = msg.pose.orientation
        T = np.eye(4)
        T[:3, :3] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
        T[:3, 3] = [msg.pose.position.x, msg.pose.position.y, msg.pose.position.z]
        deg, m = pose_error(T, T_true)
        print(f"PoseStamped {deg:.3f}° / {1000 * m:.2f} mm from the truth, stamp {peer.stamp_of(msg):.1f}")
        assert msg.header.frame_id == "world" and deg < 1.0 and m < 0.005
        assert projected_edges(ui.site.camera, obj.model, T).shape[0] == len(obj.model.edges)
    finally:
        stop.set()
        ui.close()
        peer.close()
