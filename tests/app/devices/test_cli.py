"""`mcit emulate`: emulators on pseudo-terminals behind stable links, driven like real devices."""

import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from app.devices.cli import parse_fault_rates
from app.devices.drivers.rangefinder import RangeFinder
from app.devices.drivers.turret import Turret

ROOT = Path(__file__).resolve().parents[3]


def test_mcit_emulate_serves_ptys_that_drivers_open_by_their_links(tmp_path):
    rf_link, tu_link = tmp_path / "rangefinder", tmp_path / "turret"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "app.cli",
            "emulate",
            "--rangefinder-link",
            str(rf_link),
            "--turret-link",
            str(tu_link),
            "--measure-delay-ms",
            "5",
            "--static",
            "--duration",
            "60",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        lines = []
        deadline = time.monotonic() + 30
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line.rstrip())
            if line.startswith("Ctrl-C"):
                break
        text = "\n".join(lines)
        assert f"mcit serve --rangefinder {rf_link} --turret {tu_link}" in text, (
            text + proc.stderr.read() if proc.poll() is not None else text
        )
        assert rf_link.is_symlink() and tu_link.is_symlink()
        with RangeFinder(str(rf_link), attempt_timeout_s=1.0) as rf, Turret(str(tu_link), attempt_timeout_s=1.0) as tu:
            assert tu.move_to_steps(380, -450) == (380, -450)
            assert 0.6 < rf.measure() < 10.0
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=10) == 0
        assert "emulators stopped." in proc.stdout.read()
        assert not rf_link.exists() and not tu_link.exists()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_fault_rate_options():
    rates = parse_fault_rates(None, 0.08)
    assert (
        "unplug" not in rates and sum(rates.values()) == pytest.approx(0.08) and len(rates) == 9
    )  # every kind but unplug
    assert parse_fault_rates("drop=0.05,unplug=0.001", 0.0) == {"drop": 0.05, "unplug": 0.001}
    assert parse_fault_rates(None, 0.0) == {}
    with pytest.raises(ValueError, match="kind=probability"):
        parse_fault_rates("drop", 0.0)
    with pytest.raises(ValueError, match="within"):
        parse_fault_rates(None, 2.0)


def test_mcit_emulate_reports_bad_options():
    out = subprocess.run(
        [sys.executable, "-m", "app.cli", "emulate", "--faults", "explode=0.5", "--duration", "0"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert out.returncode == 2 and "unknown fault kind" in out.stderr
