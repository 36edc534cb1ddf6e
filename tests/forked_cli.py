"""``mcit`` commands run each in its own process, forked from one that has imported the CLI and what its commands
load (numpy, SciPy, viser, ...; not OpenCV, whose logging ``main`` sets before it is loaded): a sweep of failing
commands otherwise spent most of its CPU starting Python and importing the same modules again for every case (about
0.5 s each).

Each command still runs as ``python -m app.cli`` would: a process of its own, its stdout and stderr its own files
(what native code writes, OpenCV's and FFmpeg's lines, lands there too), its exit status the process's; the forking
process is never touched by a command. What importing wrote on the forking process's stderr (a warning at import,
which a real start would show on every command) fails the run.
"""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# The forking process: imports, says "ready", then forks a child per request line (JSON: argv) and answers a
# line (JSON: status, stdout, stderr) once the child has ended.
_SERVER = r"""
import json, os, sys, tempfile
import app.cli, app.db, app.scene, app.video, app.ui.serve, scipy.optimize, trimesh, viser
assert "cv2" not in sys.modules  # mcit's main() quietens OpenCV's logging before OpenCV loads: each command loads it
reply = os.fdopen(os.dup(1), "w")
sys.stdout.flush()
print("ready", file=reply, flush=True)
for line in sys.stdin:
    request = json.loads(line)
    out, err = tempfile.TemporaryFile(), tempfile.TemporaryFile()
    pid = os.fork()
    if pid == 0:
        try:
            devnull = os.open(os.devnull, os.O_RDONLY)
            os.dup2(devnull, 0)
            os.dup2(out.fileno(), 1)
            os.dup2(err.fileno(), 2)
            try:
                status = app.cli.main(request["argv"])
            except SystemExit as exit_:
                status = exit_.code if isinstance(exit_.code, int) else (0 if exit_.code is None else 1)
            import atexit
            atexit._run_exitfuncs()
            sys.stdout.flush()
            sys.stderr.flush()
        except BaseException:
            import traceback
            traceback.print_exc()
            status = 99
        finally:
            os._exit(status if isinstance(status, int) else 1)
    _, wait_status = os.waitpid(pid, 0)
    texts = []
    for f in (out, err):
        f.seek(0)
        texts.append(f.read().decode("utf-8", "replace"))
        f.close()
    print(json.dumps({"status": os.waitstatus_to_exitcode(wait_status), "stdout": texts[0], "stderr": texts[1]}),
          file=reply, flush=True)
"""


class ForkedCli:
    """Runs ``mcit`` commands (``run``) in processes forked from one prepared process; ``close`` when done."""

    def __init__(self):
        self._err = tempfile.TemporaryFile()
        self._proc = subprocess.Popen(
            [sys.executable, "-c", _SERVER],
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._err,
            text=True,
            start_new_session=True,  # a command that hangs is killed with the forking process (close)
        )
        ready = self._line(120.0)
        assert ready == "ready", f"the forking process did not start: {ready!r} {self.stderr()!r}"
        assert self.stderr() == "", f"importing the CLI wrote on stderr: {self.stderr()!r}"

    def run(self, argv: list[str], timeout_s: float = 300.0) -> subprocess.CompletedProcess:
        """``python -m app.cli *argv`` in a process of its own: its exit status, stdout and stderr."""
        request = {"argv": [str(a) for a in argv]}
        self._proc.stdin.write(json.dumps(request) + "\n")
        self._proc.stdin.flush()
        answer = json.loads(self._line(timeout_s))
        return subprocess.CompletedProcess(argv, answer["status"], answer["stdout"], answer["stderr"])

    def _line(self, timeout_s: float) -> str:
        ready, _, _ = select.select([self._proc.stdout], [], [], timeout_s)
        if not ready:
            os.killpg(self._proc.pid, signal.SIGKILL)  # the forking process and the command it waits for
            self.close()
            raise TimeoutError(f"no answer within {timeout_s:g} s from the forked command")
        return self._proc.stdout.readline().strip()

    def stderr(self) -> str:
        """What the forking process itself wrote on stderr (nothing, unless importing or forking went wrong)."""
        self._err.seek(0)
        return self._err.read().decode("utf-8", "replace")

    def close(self) -> None:
        if self._proc.poll() is None:
            self._proc.stdin.close()
            try:
                self._proc.wait(30)
            except subprocess.TimeoutExpired:
                self._proc.kill()
                self._proc.wait()
        self._err.close()
