"""open_devices and EmulatedSite: emulated or real URLs, the shared mount, the scene clock."""

import time
from dataclasses import replace

import numpy as np
import pytest
import serial

from app.devices.drivers.errors import NoTargetError
from app.devices.site import EmulatedSite, open_devices, scene_clock, video_duration_s
from app.scene import Body
from core.brep import BRep
from core.rangefinder import aim
from core.transforms import make_T

from .conftest import FAST_DRIVER, FAST_SITE, exact_scene, facing_face


def test_open_devices_emulates_both_when_no_url_is_given(workcell):
    scene = exact_scene(workcell)
    with open_devices(
        scene, clock=lambda: 0.0, site_options=FAST_SITE, rangefinder_options=FAST_DRIVER, turret_options=FAST_DRIVER
    ) as dev:
        assert dev.emulated and all(u.startswith("mcit://") for u in dev.urls)
        assert np.allclose(dev.T_world_turret, scene.turret.T_world_turret)
        C, _, rho = facing_face(scene)
        pan, tilt, _ = aim(dev.T_world_turret, C)
        dev.turret.move_to(float(pan), float(tilt))
        assert dev.rangefinder.measure() == pytest.approx(rho, abs=0.002)  # one step off the centroid at most
        url = dev.urls[0]
    with pytest.raises(serial.SerialException):  # closed with the devices
        serial.serial_for_url(url, timeout=0.1)


def test_emulated_lines_tell_the_drivers_their_rate(workcell):
    """The drivers time their listening by the line's rate (a second reply within one reply's line time): on an
    emulated in-process line they take the emulator's (0: an instant line; a driver that took it for 19 200 baud
    listened 10 ms after every shot); a rate given for a driver is kept."""
    instant = dict(FAST_SITE, rangefinder_baud=0, turret_baud=0)
    with open_devices(workcell, clock=lambda: 0.0, site_options=instant) as dev:
        assert (dev.rangefinder._line.baudrate, dev.turret._line.baudrate) == (0, 0)
    real = dict(FAST_SITE, rangefinder_baud=19200, turret_baud=9600)
    with open_devices(workcell, clock=lambda: 0.0, site_options=real, turret_options={"baudrate": 4800}) as dev:
        assert (dev.rangefinder._line.baudrate, dev.turret._line.baudrate) == (19200, 4800)


def test_open_devices_on_real_paths_and_over_ptys(workcell, tmp_path):
    scene = exact_scene(workcell)
    with EmulatedSite(scene, **FAST_SITE) as site:
        rf_path, tu_path = site.serve_pty(tmp_path / "rf", tmp_path / "tu")
        with open_devices(scene, rf_path, tu_path, rangefinder_options=FAST_DRIVER, turret_options=FAST_DRIVER) as dev:
            assert not dev.emulated and dev.urls == (rf_path, tu_path)
            assert dev.turret.move_to_steps(50, -50) == (50, -50)
            assert site.mount.steps_at() == (50, -50)
    with open_devices(
        scene,
        clock=lambda: 0.0,
        transport="pty",
        site_options=FAST_SITE,
        rangefinder_options=FAST_DRIVER,
        turret_options=FAST_DRIVER,
    ) as dev:
        assert dev.urls[0].startswith("/dev/") and dev.rangefinder.temperature_c() == pytest.approx(24.0)


def test_open_devices_refuses_half_a_pair(workcell):
    with pytest.raises(ValueError, match="both"):
        open_devices(workcell, rangefinder_url="/dev/ttyUSB0")
    with pytest.raises(ValueError, match="transport"):
        open_devices(workcell, transport="carrier-pigeon")


def test_the_clock_decides_where_moving_bodies_are(workcell):
    crate = Body(
        "crate",
        "box",
        "known",
        BRep.box(0.3, 0.3, 0.3),
        make_T(np.eye(3), [0.0, 0.0, 0.0]),
        ((1.0, make_T(np.eye(3), [0.0, 0.0, 0.0])), (2.0, make_T(np.eye(3), [2.0, 0.0, 0.0]))),
    )
    scene = replace(exact_scene(workcell), bodies=(crate,))
    now = {"t": 0.0}
    with open_devices(
        scene,
        clock=lambda: now["t"],
        site_options=FAST_SITE,
        rangefinder_options=FAST_DRIVER,
        turret_options=FAST_DRIVER,
    ) as dev:
        pan, tilt, rho = aim(dev.T_world_turret, np.array([0.0, 0.0, 0.15]))
        dev.turret.move_to(float(pan), float(tilt))
        assert dev.rangefinder.measure() < float(rho)  # the crate's near face, in front of its centre
        now["t"] = 5.0  # the crate has gone 2 m to the side
        with pytest.raises(NoTargetError):
            dev.rangefinder.measure()


def test_scene_clock_counts_and_loops_with_the_video(tmp_path):
    import cv2

    plain = scene_clock()
    looped = scene_clock(loop_s=0.05)
    time.sleep(0.12)
    assert plain() >= 0.12 and 0.0 <= looped() < 0.05
    video = tmp_path / "v.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (32, 24))
    for i in range(25):
        writer.write(np.full((24, 32, 3), 10 * i, np.uint8))
    writer.release()
    assert video_duration_s(video) == pytest.approx(2.5, abs=0.11)
    assert video_duration_s(tmp_path / "missing.mp4") is None and video_duration_s(None) is None
