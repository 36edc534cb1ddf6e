"""Start-up: how long ``mcit serve`` takes to serve its first page, beside a bare viser server.

Run: .venv/bin/python bench/startup.py [--runs 7] [--timeout 60]

Each run starts a process and polls http://127.0.0.1:<port>/ every 5 ms until it answers 200;
the time is from the process's start to that answer (interpreter start, imports, set-up, the
server's first page). The two commands run alternately (bare, mcit, bare, mcit, ...), each on a
free port, so a load change on the machine falls on both; medians over the runs are printed
with the difference (the issue's target: mcit within 0.6 s of the bare server).

* bare: ``python -c "import viser; viser.ViserServer(host=..., port=...)"``, then idle;
* mcit: ``mcit serve`` as an operator starts it (the bundled scene, its video, emulated
  devices), with a database in a temporary folder (seeded from the scene by a first run that
  is not counted, as an operator's database already exists).

With ``--importtime`` the mcit process's ``python -X importtime`` lines for the modules loaded
before the first page are summed per top-level package (self time) and the largest are listed.
"""

from __future__ import annotations

import argparse
import os
import platform
import signal
import socket
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PY = sys.executable


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def bare_cmd(port: int) -> list[str]:
    code = f"import time, viser\nviser.ViserServer(host='127.0.0.1', port={port})\nwhile True: time.sleep(1)\n"
    return [PY, "-c", code]


def mcit_cmd(port: int, db: Path) -> list[str]:
    return [PY, "-m", "app.cli", "serve", "--port", str(port), "--db", str(db)]


def time_to_first_page(cmd: list[str], port: int, timeout_s: float, env=None, stderr=subprocess.DEVNULL) -> float:
    """Seconds from starting cmd to the first HTTP 200 on the port; the process is then stopped."""
    url = f"http://127.0.0.1:{port}/"
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, cwd=ROOT, stdout=subprocess.DEVNULL, stderr=stderr, env=env, start_new_session=True)
    try:
        while True:
            if proc.poll() is not None:
                raise RuntimeError(f"{cmd[:3]} exited with {proc.returncode} before serving a page")
            try:
                with urllib.request.urlopen(url, timeout=1.0) as r:
                    if r.status == 200:
                        return time.perf_counter() - t0
            except (urllib.error.URLError, ConnectionError, OSError):
                pass
            if time.perf_counter() - t0 > timeout_s:
                raise RuntimeError(f"{cmd[:3]} served no page within {timeout_s} s")
            time.sleep(0.005)
    finally:
        os.killpg(proc.pid, signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


def import_table(db: Path, timeout_s: float, top: int = 15) -> None:
    """Self import time per top-level package in mcit serve until its first page."""
    port = free_port()
    with tempfile.TemporaryFile() as err:
        env = dict(os.environ, PYTHONPROFILEIMPORTTIME="1")
        t = time_to_first_page(mcit_cmd(port, db), port, timeout_s, env=env, stderr=err)
        err.seek(0)
        per: dict[str, int] = {}
        for line in err.read().decode(errors="replace").splitlines():
            if not line.startswith("import time:") or "self [us]" in line:
                continue
            fields = line[len("import time:") :].split("|")  # self [us] | cumulative | name
            self_us, pkg = int(fields[0]), fields[2].strip().split(".")[0]
            per[pkg] = per.get(pkg, 0) + self_us
    print(
        f"\nimports of mcit serve before its first page ({t:.2f} s "
        "with -X importtime; self time per top-level package):"
    )
    print("| package | ms |\n|:---|---:|")
    for pkg, us in sorted(per.items(), key=lambda kv: -kv[1])[:top]:
        print(f"| {pkg} | {us / 1000:.0f} |")
    print(f"| all ({len(per)} packages) | {sum(per.values()) / 1000:.0f} |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=7)
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds allowed to each start")
    ap.add_argument("--importtime", action="store_true", help="also list the import time per package")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        db = Path(tmp) / "site.sqlite"
        port = free_port()
        time_to_first_page(mcit_cmd(port, db), port, args.timeout)  # seeds the database; not counted
        port = free_port()
        time_to_first_page(bare_cmd(port), port, args.timeout)  # warms the file cache; not counted
        bare, mcit = [], []
        for _ in range(args.runs):
            port = free_port()
            bare.append(time_to_first_page(bare_cmd(port), port, args.timeout))
            port = free_port()
            mcit.append(time_to_first_page(mcit_cmd(port, db), port, args.timeout))
        med_b, med_m = sorted(bare)[len(bare) // 2], sorted(mcit)[len(mcit) // 2]
        diffs = sorted(m - b for b, m in zip(bare, mcit))
        print(
            f"# mcit serve start-up ({platform.machine()}, Python {platform.python_version()}, {os.cpu_count()} cores, "
            f"load {os.getloadavg()[0]:.1f}); {args.runs} runs each, alternating"
        )
        print("| server | median to first page (s) | min | max |\n|:---|---:|---:|---:|")
        print(f"| bare viser | {med_b:.2f} | {min(bare):.2f} | {max(bare):.2f} |")
        print(f"| mcit serve | {med_m:.2f} | {min(mcit):.2f} | {max(mcit):.2f} |")
        print(f"| difference (pair by pair) | {diffs[len(diffs) // 2]:.2f} | {diffs[0]:.2f} | {diffs[-1]:.2f} |")
        if args.importtime:
            import_table(db, args.timeout)
    return 0


if __name__ == "__main__":
    sys.exit(main())
