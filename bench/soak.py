"""Soak of the operator interface: its memory over a long run of database changes with two browsers.

Setup: the bundled scene's database plus extra boxes and cylinders (``--objects``, 50 by default), the
interface on 127.0.0.1 with the ViSP cube sequence at 30 frames/s (else frames of noise), two
browser-like clients (``bench/interface.py``'s websocket readers, each its own process, reading every
message); one object's pose moved 1 cm every ``--every`` seconds (as Accept writes it), by another
process's connection to the database (the site polls it, as when a second program writes) on odd
changes and by the interface's own site on even ones; every 5 minutes one reader leaves and a new one
joins (a browser reloaded).

Measured: the server process's resident memory (RSS, /proc) every 30 s, and Python's own allocations
(``tracemalloc``, one frame a trace) after a warm-up of ``--warmup`` seconds and at the end: the lines
whose allocations grew most are printed, to find what grows. Target (issue 27): RSS flat within 10 %
from the end of the warm-up to the end of a 30-minute run.

Run: ``.venv/bin/python bench/soak.py [--minutes 30] [--every 2] [--objects 50] [--no-trace]``.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from interface import Reader, build  # noqa: E402  (MCIT_BENCH_TREE: another checkout's interface)

from tests.e2e.harness import wait_until  # noqa: E402


def rss_mb() -> float:
    """This process's resident memory, MB (/proc/self/status VmRSS)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def top_growth(before: tracemalloc.Snapshot, after: tracemalloc.Snapshot, n: int = 12) -> list[str]:
    """The ``n`` source lines whose live allocations grew most between two snapshots."""
    filters = [
        tracemalloc.Filter(False, tracemalloc.__file__),
        tracemalloc.Filter(False, "<frozen importlib._bootstrap>"),
    ]
    stats = after.filter_traces(filters).compare_to(before.filter_traces(filters), "lineno")
    rows = []
    for s in sorted(stats, key=lambda s: s.size_diff, reverse=True)[:n]:
        frame = s.traceback[0]
        where = os.path.relpath(frame.filename, ROOT) if frame.filename.startswith(str(ROOT)) else frame.filename
        rows.append(f"| {where}:{frame.lineno} | {s.size_diff / 1024:+.0f} | {s.count_diff:+d} |")
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--minutes", type=float, default=30.0)
    ap.add_argument("--every", type=float, default=2.0, help="seconds between database changes")
    ap.add_argument("--objects", type=int, default=50)
    ap.add_argument("--warmup", type=float, default=120.0, help="seconds before the reference measurement")
    ap.add_argument("--rejoin", type=float, default=300.0, help="seconds between a browser leaving and one joining")
    ap.add_argument("--no-trace", action="store_true", help="no tracemalloc (RSS only)")
    args = ap.parse_args()
    from app.db import Database
    from core.transforms import make_T

    if not args.no_trace:
        tracemalloc.start(1)
    server, site, db, video = build(args.objects, fps=30.0)
    other = Database.open(db.path)  # another program's connection to the same database
    readers = [Reader(server.port), Reader(server.port)]
    samples: list[tuple[float, float, int]] = []  # (seconds, RSS MB, changes)
    t_start = time.monotonic()
    snap0 = None
    rss0 = None
    changes = 0
    last_sample = last_rejoin = -1e9
    try:
        for r in readers:
            r.wait_connected()
        wait_until(lambda: len(server.clients) >= 2 and server.database_drawn, timeout_s=300, what="two panels")
        movable = [o.name for o in site.objects() if o.kind != "table"]
        t_start = time.monotonic()  # from both browsers' panels shown
        end = t_start + args.warmup + 60.0 * args.minutes
        while time.monotonic() < end:
            now = time.monotonic()
            name = movable[changes % len(movable)]
            obj = site.object(name)
            T = obj.T_world_obj @ make_T(np.eye(3), [0.01 if (changes // len(movable)) % 2 == 0 else -0.01, 0, 0])
            if changes % 2:
                rec = other.get(name)
                other.update_pose(rec.id, T, None, expected_version=rec.version, method="bench", client="soak")
            else:
                site.update_pose(obj, T, None, method="bench", client="soak")
            changes += 1
            t = now - t_start
            if snap0 is None and t >= args.warmup:
                snap0 = tracemalloc.take_snapshot() if tracemalloc.is_tracing() else None
                rss0 = rss_mb()  # after the snapshot, which is kept (tens of MB)
                print(f"  warm-up done at {t:.0f} s: RSS {rss0:.1f} MB", file=sys.stderr, flush=True)
            if t - last_sample >= 30.0:
                last_sample = t
                samples.append((t, rss_mb(), changes))
                print(f"  {t:6.0f} s: RSS {samples[-1][1]:.1f} MB, {changes} changes", file=sys.stderr, flush=True)
            if t - last_rejoin >= args.rejoin and t > args.warmup:
                if last_rejoin > 0:  # a browser reloads: one reader leaves, a new one joins
                    readers.pop(0).stop()
                    readers.append(Reader(server.port))
                last_rejoin = t
            time.sleep(max(0.0, t_start + changes * args.every - time.monotonic()))
        rss1 = rss_mb()  # as the process runs
        gc.collect()
        rss1_gc = rss_mb()  # after a full collection (cyclic garbage waits for one), before the second snapshot
        snap1 = tracemalloc.take_snapshot() if tracemalloc.is_tracing() else None
        t_end = time.monotonic() - t_start
        frames = [len(r.frames(time.time() - 60.0, time.time())) / 60.0 for r in readers]
    finally:
        for r in readers:
            r.stop()
        server.stop()
        other.close()
        db.close()
    load = os.getloadavg()[0]
    print(
        f"mcit interface soak — {args.objects} objects, video: {video}; two browser-like clients (one replaced "
        f"every {args.rejoin:.0f} s); a pose written every {args.every:.0f} s (alternately by another program's "
        f"connection and by the interface's site), {changes} changes over {t_end / 60:.1f} min; tracemalloc "
        f"{'on (1 frame)' if snap0 is not None else 'off'}; machine: {os.cpu_count()} cores, load average {load:.1f}"
    )
    print()
    print("| minutes | RSS (MB) | database changes |")
    print("|---|---|---|")
    for t, mb, n in samples[:: max(1, len(samples) // 12)] + [samples[-1]]:
        print(f"| {t / 60:.1f} | {mb:.1f} | {n} |")
    growth = 100.0 * (rss1 - rss0) / rss0
    peak = max(mb for t, mb, _ in samples if t >= args.warmup)
    print()
    print(
        f"RSS after the {args.warmup:.0f} s warm-up {rss0:.1f} MB, at the end {rss1:.1f} MB: {growth:+.1f} % "
        f"(target: within ±10 %); at most {peak:.1f} MB ({100.0 * (peak - rss0) / rss0:+.1f} %) in between; "
        f"{rss1_gc:.1f} MB after a full garbage collection at the end; frames/s received in the last minute: "
        f"{', '.join(f'{f:.1f}' for f in frames)}"
    )
    if snap0 is not None and snap1 is not None:
        traced0 = sum(s.size for s in snap0.statistics("filename")) / 1e6
        traced1 = sum(s.size for s in snap1.statistics("filename")) / 1e6
        print(f"Python allocations (tracemalloc): {traced0:.1f} MB after the warm-up, {traced1:.1f} MB at the end")
        print()
        print("| where (grew most since the warm-up) | KiB | allocations |")
        print("|---|---|---|")
        for row in top_growth(snap0, snap1):
            print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
