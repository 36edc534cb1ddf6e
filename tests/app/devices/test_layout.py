"""app/devices is split by concern (drivers, emulators, faults) and its public names still import."""

import subprocess
import sys

import app.devices


def test_every_public_name_of_app_devices_imports():
    for name in app.devices.__all__:
        assert getattr(app.devices, name) is not None, name
    from app.devices import DeviceError, Fault, RangeFinder, Turret, TurretEmulator, open_devices  # noqa: F401

    assert app.devices.RangeFinder.__module__ == "app.devices.drivers.rangefinder"
    assert app.devices.TurretEmulator.__module__ == "app.devices.emulators.turret"


def test_the_drivers_load_no_emulator_and_no_fault_injection():
    """A host that drives real devices imports no emulator, port or fault code."""
    code = (
        "import sys; import app.devices.drivers.rangefinder, app.devices.drivers.turret; "
        "print(sorted(m for m in sys.modules if m.startswith('app.devices.') "
        "and not m.startswith('app.devices.drivers')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]", out
