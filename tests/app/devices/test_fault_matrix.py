"""bench/devices.py's fault matrix, one trial per fault and device: every trial has an outcome and
none is a wrong value returned silently (the bench runs more trials and prints the table)."""

import importlib.util
from dataclasses import replace
from pathlib import Path

BENCH = Path(__file__).resolve().parents[3] / "bench" / "devices.py"


def test_one_trial_per_fault_and_device_returns_no_wrong_value(workcell):
    spec = importlib.util.spec_from_file_location("bench_devices", BENCH)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    scene = replace(workcell, turret=replace(workcell.turret, speed_steps_s=4000.0))
    # a loaded machine answers late; the rows side by side (each mostly waits on its serial lines and deadlines)
    results = bench.matrix_trials(scene, 1, seed=3, attempt_timeout_s=0.6, workers=4)
    rows = {d: [name for name, _ in bench.matrix_rows(d)] for d in ("turret", "rangefinder")}
    assert sorted(results) == sorted((d, r) for d in rows for r in rows[d])
    assert all(sum(out.values()) == 1 for out in results.values())
    assert sum(out["WRONG"] for out in results.values()) == 0, {k: v for k, v in results.items() if v["WRONG"]}
    assert all(out["error"] == 1 for (d, r), out in results.items() if r == "device error")
