"""The project's promises to a new user: the README's commands, the layout, the CI entry point."""

import re
import subprocess
import sys
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def readme_commands() -> list[str]:
    block = re.search(r"## Quick start.*?```(?:bash|sh)?\n(.*?)```", (ROOT / "README.md").read_text(), re.S)
    assert block, "README.md must have a '## Quick start' section with a code block"
    return [line.strip() for line in block.group(1).splitlines() if line.strip() and not line.strip().startswith("#")]


def test_readme_has_exactly_two_setup_commands():
    cmds = readme_commands()
    assert len(cmds) == 2, cmds
    run, test = cmds
    assert re.search(r"pip install (-p \.venv )?-e \.", run) and "mcit" in run.split("&&")[-1]
    assert "'.[test,ros2]'" in test and "pytest" in test  # the ROS 2 bridge's tests run against a real rclpy node


def test_ci_runs_the_readme_test_command_verbatim():
    test_cmd = readme_commands()[1]
    ci = (ROOT / ".ci" / "run").read_text()
    assert test_cmd in ci.splitlines(), f"{test_cmd!r} not found as a line of .ci/run"
    assert "set -euo pipefail" in ci


def test_layout_and_entry_point():
    for folder in ("core", "app", "static", "tests", "scenes", "bench"):
        assert (ROOT / folder).is_dir(), folder
    meta = tomllib.loads((ROOT / "pyproject.toml").read_text())
    assert meta["project"]["name"] == "mcit"
    assert meta["project"]["scripts"]["mcit"] == "app.cli:main"
    for dep in ("viser", "numpy", "scipy", "opencv-python-headless", "trimesh", "pyserial"):
        assert any(d.startswith(dep) for d in meta["project"]["dependencies"]), dep
    for dep in ("pytest", "hypothesis", "playwright", "poselib"):
        assert any(d.startswith(dep) for d in meta["project"]["optional-dependencies"]["test"]), dep


def test_core_never_imports_app_or_io_libraries():
    forbidden = re.compile(r"^\s*(?:from|import)\s+(app\b|viser|serial|sqlite3|cv2|trimesh|threading|socket)", re.M)
    offenders = [str(p.relative_to(ROOT)) for p in (ROOT / "core").rglob("*.py") if forbidden.search(p.read_text())]
    assert not offenders, f"core/ must stay pure geometry (numpy/scipy): {offenders}"


def test_console_script_answers_help():
    out = subprocess.run(
        [sys.executable, "-m", "app.cli", "--help"], capture_output=True, text=True, cwd=ROOT, timeout=60
    )
    assert out.returncode == 0 and "usage: mcit" in out.stdout


def test_every_test_folder_is_a_package():
    """With tests/ and each sub-folder a package, pytest imports tests as ``tests.<path>`` from the
    project root, so a folder such as tests/core can never shadow the real ``core`` package."""
    missing = [
        str(d.relative_to(ROOT))
        for d in [ROOT / "tests", *(ROOT / "tests").rglob("*")]
        if d.is_dir() and d.name != "__pycache__" and any(d.glob("*.py")) and not (d / "__init__.py").exists()
    ]
    assert not missing, f"add an __init__.py to: {missing}"
