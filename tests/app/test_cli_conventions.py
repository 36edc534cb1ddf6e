"""The command line as robotics tools behave (issue 26.3): ``--version``; a warning is one line in the user's
words; the exit statuses are one documented scheme; ``mcit serve --port`` says which port it took."""

from __future__ import annotations

import errno
import re
import signal
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

from app import cli, exit_status

ROOT = Path(__file__).resolve().parents[2]

# A .cao whose one circle has its centre and two rim points on one line: ViSP parses it, mcit leaves it out and warns.
FLAT_CIRCLE_CAO = """V1
# 3D Points
4
0 0 0
1 0 0
2 0 0
0 1 0
# 3D Lines
1
0 3
# Faces from 3D lines
0
# Faces from 3D points
0
# 3D cylinders
0
# 3D circles
1
0.5 0 1 2
"""


def _mcit(*argv, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "app.cli", *map(str, argv)],
        capture_output=True,
        text=True,
        cwd=ROOT,
        timeout=300,
        **kwargs,
    )


def test_version():
    from importlib.metadata import version

    run = _mcit("--version")
    assert run.returncode == 0 and run.stdout == f"mcit {version('mcit')}\n" and run.stderr == ""


def test_a_cao_warning_is_one_line_without_mcits_source(tmp_path):
    cao = tmp_path / "flat.cao"
    cao.write_text(FLAT_CIRCLE_CAO)
    run = _mcit("db", "import", cao, "--db", tmp_path / "site.sqlite")
    assert run.returncode == 0 and "added #1 'flat'" in run.stdout, run.stderr
    assert run.stderr == (
        f"mcit db import: warning: {cao}:19: circle 0 is left out: its centre and two points are on one line, "
        "so its plane is unknown\n"
    )
    # Python's own form named mcit's source file and line (".../app/models_io/cao.py:494: CaoWarning: ...")
    assert ".py" not in run.stderr and "CaoWarning" not in run.stderr and str(ROOT) not in run.stderr


def test_another_librarys_warning_is_one_line_naming_its_kind(monkeypatch, capsys):
    def func(args):
        np.log(np.zeros(1))  # numpy: RuntimeWarning, divide by zero
        return 0

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    sub.choices["script"].set_defaults(func=func)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    showwarning = warnings.showwarning
    assert cli.main(["script"]) == 0
    assert capsys.readouterr().err == "mcit script: warning: RuntimeWarning: divide by zero encountered in log\n"
    assert warnings.showwarning is showwarning  # Python's own form is back once the command is done


def _readme_exit_statuses() -> dict[int, str]:
    text = (ROOT / "README.md").read_text()
    section = text[text.index("## Exit status") :]
    section = section[: section.index("\n## ", 4)]
    return {int(m.group(1)): m.group(2) for m in re.finditer(r"^\| (\d+) \| (.+?) \|$", section, re.M)}


def test_the_exit_statuses_are_documented_once_for_all():
    codes = {v for k, v in vars(exit_status).items() if k.isupper()}
    assert set(_readme_exit_statuses()) == codes == {0, 1, 2, 3, 70, 130, 141}
    for code in codes:  # and the command line's docstring lists the same
        assert re.search(rf"^    {code} ", cli.__doc__, re.M), code


@pytest.mark.parametrize(
    "exc, status",
    [
        (exit_status.UsageError("--a and --b go together"), 2),
        (ValueError("no such scene"), 1),
        (FileNotFoundError(2, "No such file or directory", "x.cao"), 1),
        (RuntimeError("a bug"), 70),
        (KeyboardInterrupt(), 130),
    ],
)
def test_each_kind_of_error_has_its_status(monkeypatch, capsys, exc, status):
    """(141, a reader that left: tests/app/test_cli_errors.py; 3, a lost object: tests/app/vision/test_sequence.py)"""

    def func(args):
        raise exc

    parser = cli.build_parser()
    sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
    sub.choices["script"].set_defaults(func=func)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    assert cli.main(["script"]) == status
    err = capsys.readouterr().err
    if status == 2:
        assert err == "mcit script: error: --a and --b go together (see mcit script --help)\n"


# ------------------------------------------------------------------------------------------------ serve --port
def test_a_taken_port_gives_the_next_free_one():
    from app.ui.serve import free_port

    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        got = free_port("127.0.0.1", port)
        assert port < got < port + 100
        with socket.socket() as probe:  # and it is free indeed
            probe.bind(("127.0.0.1", got))
    assert free_port("127.0.0.1", 0) == 0  # the system chooses


def test_a_port_that_cannot_be_had_is_one_line(monkeypatch):
    from app.ui import serve

    with socket.socket() as taken:
        try:
            taken.bind(("127.0.0.1", 65535))
            taken.listen()
        except OSError:
            pass  # taken by another program: as good
        with pytest.raises(ValueError) as info:
            serve.free_port("127.0.0.1", 65535)
    assert str(info.value) == (
        "--port 65535: port 65535 is in use on 127.0.0.1; give another --port, or 0 for any free port"
    )
    monkeypatch.setattr(serve, "_bind_error", lambda host, port: OSError(errno.EACCES, "Permission denied"))
    with pytest.raises(
        ValueError,
        match=r"--port 80: cannot listen on 127.0.0.1:80: Permission denied \(a port "
        r"below 1024 needs root or CAP_NET_BIND_SERVICE\); give another --port",
    ):
        serve.free_port("127.0.0.1", 80)


def _serve(tmp_path, *extra: str) -> tuple[subprocess.Popen, str]:
    """``mcit serve`` on a still folder, started: (the process, the address line it printed, "" if none)."""
    import cv2

    (tmp_path / "frames").mkdir(exist_ok=True)
    cv2.imwrite(str(tmp_path / "frames" / "f0.png"), np.full((256, 512), 90, np.uint8))
    argv = ["serve", "--video", tmp_path / "frames", "--no-devices", "--recorded", "--db", tmp_path / "s.sqlite"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", *map(str, argv), *extra],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    return proc, next((line for line in proc.stdout if line.startswith("mcit: open ")), "")


def test_serve_on_the_default_port_taken_says_which_it_took(tmp_path):
    from app.ui.serve import DEFAULT_PORT

    with socket.socket() as taken:
        try:
            taken.bind(("127.0.0.1", DEFAULT_PORT))
            taken.listen()
        except OSError:
            pass  # taken by another program: as good
        proc, url = _serve(tmp_path)
        try:
            assert url, "no address printed"
        finally:
            proc.send_signal(signal.SIGTERM)
            _, err = proc.communicate(timeout=120)
    got = int(re.search(r":(\d+) in a browser", url).group(1))
    assert got != DEFAULT_PORT and proc.returncode == 0, err
    said = [line for line in err.splitlines() if "in use" in line]
    assert said == [f"mcit serve: port {DEFAULT_PORT} is in use: listening on port {got} instead"], err


def test_serve_on_a_given_port_taken_refuses_to_start(tmp_path):
    """A port given is the one listened on: a proxy, a tunnel or a script set up for it would reach another."""
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc, url = _serve(tmp_path, "--port", str(port))
        _, err = proc.communicate(timeout=120)
    assert url == "" and proc.returncode == 1, err
    assert err == (
        f"mcit serve: error: --port {port}: port {port} is in use on 127.0.0.1; give another --port, or 0 for any "
        "free port\n"
    )
    assert not (tmp_path / "s.sqlite").exists()  # nothing opened, nothing written


@pytest.mark.parametrize(
    "argv, prog", [(["serve", "--bogus"], "mcit serve"), (["db", "list", "--bogus"], "mcit db list")]
)
def test_an_unknown_option_is_refused_by_the_commands_own_name(argv, prog, capsys):
    from app.cli import main

    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err == f"{prog}: error: unrecognized arguments: --bogus (see {prog} --help)\n"
