"""Every ``mcit`` command's failures (app/cli.py): one line on stderr saying what happened and what to
do, a non-zero exit, no traceback. A sweep runs each sub-command (every one ``mcit --help`` lists:
a new command without a case here fails the sweep) with bad input in a process of its own
(forked from one that has imported the CLI: tests/forked_cli.py)."""

from __future__ import annotations

import argparse
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from app import cli

ROOT = Path(__file__).resolve().parents[2]


def _commands() -> set[str]:
    """Every command and db sub-command of the parser ("db list", "serve", ...)."""
    out = set()

    def walk(parser: argparse.ArgumentParser, prefix: str) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    has_sub = any(isinstance(a, argparse._SubParsersAction) for a in sub._actions)
                    if has_sub:
                        walk(sub, f"{prefix}{name} ")
                    else:
                        out.add(f"{prefix}{name}")

    walk(cli.build_parser(), "")
    return out


# (command, arguments after it, exit status); {tmp} is a fresh folder, {notes} a text file, {db} a seeded database.
# Status 1: the command could not do its job (a file, the database, a port); 2: the command line is wrong
# (app/exit_status.py).
CASES = [
    ("db init", "--scene {tmp}/no-scene --db {tmp}/new.sqlite", 1),
    ("db import", "{tmp}/no-model.cao --db {db}", 1),
    ("db import", "{notes} --db {db}", 1),
    ("db list", "--db {notes}", 1),
    ("db list", "--db {tmp}/no.sqlite", 1),
    ("db show", "ghost --db {db}", 1),
    ("db show", "99999999999999999999999 --db {db}", 1),
    ("db export", "parallelepiped {tmp}/no-folder/out.cao --db {db}", 1),
    ("db export", "parallelepiped {tmp}/out.xyz --db {db}", 1),
    ("db history", "ghost --db {db}", 1),
    ("db undo", "99999999999999999999999 --db {db}", 1),
    ("db undo", "42 --db {db} --wait-s -1", 2),
    ("db export-poses", "{tmp}/poses.json --db {notes}", 1),
    ("db feed", "--file {tmp}/feed.jsonl --db {notes}", 1),
    ("emulate", "--scene {tmp}/no-scene", 1),
    ("serve", "--scene {tmp}/no-scene", 1),
    ("serve", "--video {tmp}/no-video.mp4 --no-devices --db {db} --port 0", 1),
    ("serve", "--no-devices --db {notes} --port 0", 1),
    (
        "serve",
        "--host 999.1.1.1 --no-devices --db {tmp}/unwritten.sqlite --port 0",
        1,
    ),  # hung before: viser waits for a thread that failed to bind
    (
        "serve",
        "--host 192.0.2.1 --no-devices --db {tmp}/unwritten.sqlite --port 0",
        1,
    ),  # TEST-NET-1: no address of this machine
    ("render", "--scene {tmp}/no-scene", 1),
    ("script", "--scene {tmp}/no-scene", 1),
    ("track", "{tmp}/no-video.mp4 --scene scenes/workcell --body parallelepiped", 1),
    ("track", "{notes} --scene scenes/workcell --body parallelepiped", 1),
    ("track", "--scene scenes/workcell --body nosuch", 1),
    ("calibrate-intrinsics", "{tmp}/no-frames --cols 9 --rows 6 --square-mm 25 --out {tmp}/cam.yml", 1),
    ("calibrate-intrinsics", "{notes} --cols 9 --rows 6 --square-mm 25 --out {tmp}/cam.yml", 1),
    ("demo", "--scene {tmp}/no-scene", 1),
    ("robot urdf", "--out {tmp}/no-folder/arm.urdf", 1),
    ("db show-calibration", "turret --db {tmp}/no.sqlite", 1),
    ("db show-calibration", "nosuch --db {db}", 1),
    ("db show-calibration", "99 --db {db}", 1),
    ("site new", "{tmp}/new-site --camera {notes} --video {notes}", 1),
    ("site new", "{tmp}/new-site --camera {tmp}/no-camera.xml --video {tmp}/no-video.mp4", 1),
    ("serve", "--site {tmp} --port 0", 1),
    ("serve", "--port {busy} --host 127.0.0.1 --no-devices --db {tmp}/unwritten.sqlite", 1),
    # the command line is wrong in a way argparse cannot see: status 2, as argparse's own refusals
    ("nosuch", "", 2),
    ("db feed", "--db {db}", 2),
    ("serve", "--allow-origin not-a-url --no-devices --db {tmp}/unwritten.sqlite --port 0", 2),
    ("track", "{notes} --scene scenes/workcell --body parallelepiped --init-points {notes}", 2),
    ("track", "{notes} --intrinsics {notes} --body parallelepiped", 2),
    ("calibrate-intrinsics", "{notes} --cols 9 --rows 6 --square-mm 25 --every 0 --out {tmp}/cam.yml", 2),
    ("calibrate-intrinsics", "{notes} --cols 9 --rows 6 --square-mm 25 --out {tmp}/cam.txt", 2),
    ("emulate", "--faults explode=0.5", 2),
    ("demo", "--sim-trials -1", 2),
    ("render", "--out {tmp}/one.avi", 2),
]


def test_the_sweep_covers_every_command():
    missing = _commands() - {c for c, _, _ in CASES}
    assert not missing, f"add a failure case for: {sorted(missing)}"


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    notes = tmp / "notes.txt"
    notes.write_text("hello\n" * 50)
    db = tmp / "site.sqlite"
    assert cli.main(["db", "init", "--db", str(db)]) == 0
    with socket.socket() as busy:  # the last port taken, and no port after it: --port 65535 cannot be had
        try:
            busy.bind(("127.0.0.1", 65535))
            busy.listen()
        except OSError:  # another program has it: taken all the same
            pass
        yield {"tmp": str(tmp), "notes": str(notes), "db": str(db), "busy": "65535"}


@pytest.mark.parametrize(
    "command, arguments, status", CASES, ids=[f"{c} {a.split(' ')[0]} {s}".strip() for c, a, s in CASES]
)
def test_a_failure_is_one_line(files, forked, command, arguments, status):
    argv = command.split() + [a.format(**files) for a in arguments.split()]
    run = forked.run(argv)
    err = run.stderr
    assert run.returncode == status, (argv, run.returncode, run.stdout, err)
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert err.startswith(f"mcit {command}: " if command != "nosuch" else "mcit: error: "), err
    assert "internal error" not in err, err  # each of these is the operator's to fix, not a bug
    assert not (Path(files["tmp"]) / "unwritten.sqlite").exists()  # a refused start writes nothing


def _with_render_raising(monkeypatch, func) -> None:
    """``mcit render`` replaced by ``func`` (the parser is otherwise the real one)."""
    parser = cli.build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    sub.choices["render"].set_defaults(func=func)
    monkeypatch.setattr(cli, "build_parser", lambda: parser)


@pytest.mark.parametrize(
    "exc, status, says",
    [
        (ValueError("the scene has no video\nrender it first"), 1, "the scene has no video render it first"),
        (
            FileNotFoundError(2, "No such file or directory", "/x/y.cao"),
            1,
            "/x/y.cao: No such file or directory; check the path",
        ),
        (PermissionError(13, "Permission denied", "/x"), 1, "check its permissions"),
        (OSError(28, "No space left on device", "/x"), 1, "free some space"),
        (RuntimeError("cursor gone"), 70, "internal error (RuntimeError: cursor gone); this is a bug in mcit"),
        (MemoryError(), 1, "ran out of memory"),
        (KeyboardInterrupt(), 130, "stopped (Ctrl-C)"),
    ],
)
def test_the_top_level_turns_any_error_into_one_line(monkeypatch, capsys, exc, status, says):
    def func(args):
        raise exc

    _with_render_raising(monkeypatch, func)
    monkeypatch.delenv("MCIT_TRACEBACK", raising=False)
    code = cli.main(["render", "--scene", "scenes/workcell"])
    err = capsys.readouterr().err
    assert code == status and err.count("\n") == 1 and says in err and "Traceback" not in err, err
    assert err.startswith("mcit render: ")


def test_a_traceback_on_request(monkeypatch, capsys):
    _with_render_raising(monkeypatch, lambda args: 1 / 0)
    monkeypatch.setenv("MCIT_TRACEBACK", "1")
    assert cli.main(["render"]) == 70
    err = capsys.readouterr().err
    assert (
        "Traceback" in err
        and "ZeroDivisionError" in err
        and err.rstrip().splitlines()[-1].startswith("mcit render: error")
    )


@pytest.mark.parametrize(
    "argv, says",
    [
        (
            "serve --fps nan",
            "argument --fps: expected a frame rate above 0 and at most 240 frames per second, got 'nan'",
        ),
        ("serve --fps inf", "got 'inf'"),
        ("serve --fps=-inf", "got '-inf'"),
        ("serve --fps 0", "got '0'"),
        ("serve --fps -25", "got '-25'"),
        ("serve --fps 240.5", "got '240.5'"),
        ("serve --fps 1e400", "got '1e400'"),
        ("serve --fps fast", "argument --fps: expected frames per second (a number), got 'fast'"),
        ("serve --port 70000", "argument --port: expected a TCP port from 1 to 65535 (0: any free port), got '70000'"),
        ("serve --port 65536", "got '65536'"),
        ("serve --port -1", "got '-1'"),
        ("serve --port 80.5", "argument --port: expected a TCP port number, got '80.5'"),
        ("track video.mp4 --fps nan", "argument --fps: expected a frame rate above 0"),
        ("track video.mp4 --fps 0", "argument --fps: expected a frame rate above 0"),
        ("serve --jpeg-quality 0", "argument --jpeg-quality: expected 1 to 100, got '0'"),
        ("serve --jpeg-quality 101", "got '101'"),
        (
            "db import m.cao --xyz 1e300 0 0",
            "argument --xyz: expected a finite coordinate within ±1e+06 m, got '1e300'",
        ),
        ("db import m.cao --xyz nan 0 0", "got 'nan'"),
        ("db import m.cao --rpy-deg inf 0 0", "argument --rpy-deg: expected a finite angle within ±3600 degrees"),
        ("db history --limit 99999999999999999999999", "argument --limit: expected 1 to 10⁹ changes"),
        ("db history --limit -1", "got '-1'"),
    ],
)
def test_a_rate_or_port_out_of_range_is_refused_by_the_parser(capsys, argv, says):
    with pytest.raises(SystemExit) as exit_:
        cli.build_parser().parse_args(argv.split())
    err = capsys.readouterr().err
    command = " ".join(argv.split()[:2]) if argv.startswith("db ") else argv.split()[0]
    assert exit_.value.code == 2 and err.count("\n") == 1 and err.startswith(f"mcit {command}: error: "), err
    assert says in err, err


@pytest.mark.parametrize(
    "argv, name, value",
    [
        ("serve --fps 240", "fps", 240.0),
        ("serve --fps 0.5", "fps", 0.5),
        ("serve", "fps", None),
        ("serve --port 1", "port", 1),
        ("serve --port 65535", "port", 65535),
        ("serve", "port", None),  # the default port, or the next free one (tests/app/test_cli_conventions.py)
        ("serve --port 0", "port", 0),  # any free port: viser binds port 0 and reports the one the system chose
        ("track video.mp4 --fps 60", "fps", 60.0),
        ("track video.mp4", "fps", None),  # the source video's rate
    ],
)
def test_rates_and_ports_in_range_are_kept(argv, name, value):
    assert getattr(cli.build_parser().parse_args(argv.split()), name) == value


def test_output_cut_short_by_its_reader_ends_quietly(tmp_path):
    """``mcit db history | head -1``: the reader leaves; no error line, no traceback (exit 141, as a shell's)."""
    db = tmp_path / "site.sqlite"
    run = [sys.executable, "-m", "app.cli"]
    subprocess.run([*run, "db", "init", "--db", str(db)], cwd=ROOT, check=True, capture_output=True, timeout=120)
    for _ in range(3):
        subprocess.run([*run, "db", "undo", "1", "--db", str(db)], cwd=ROOT, capture_output=True, timeout=120)
    done = subprocess.run(
        f"{sys.executable} -m app.cli db history --db {db} | head -c 10",
        shell=True,
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
        executable="/bin/bash",
    )
    assert done.stderr == "" and len(done.stdout) == 10, done.stderr


@pytest.mark.parametrize("out, says", [("{tmp}", "is not a file"), ("{tmp}/noext", "unknown model type ''")])
def test_db_export_names_a_bad_output_before_writing(tmp_path, capsys, out, says):
    db = tmp_path / "site.sqlite"
    assert cli.main(["db", "init", "--db", str(db)]) == 0
    capsys.readouterr()
    assert cli.main(["db", "export", "table", out.format(tmp=tmp_path), "--db", str(db)]) == 1
    err = capsys.readouterr().err
    assert says in err and err.count("\n") == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["site.sqlite"]  # nothing written
