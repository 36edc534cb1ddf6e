"""The demo's report: report.md and its PNG figures, the paper's tables beside ours.

Every number of "this run" comes from the replayed session (``DemoResults``) compared with the
scene's truth; every number marked "simulation" from ``app.demo.simulation`` (the same solvers on
simulated measurements, for the distances and the statistics one run cannot give). The paper's
values are ``app.report.paper``'s transcription.
"""

from __future__ import annotations

import platform
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from app.report import TABLE_III_1, TABLE_III_2, TABLE_V_1, ReportWriter, markdown_table
from app.report.plots import METHOD_LABELS, plot_depth_errors, plot_pose_errors
from app.scene import Scene

from .replay import Replay
from .results import DemoResults
from .simulation import BoxSweep, CylinderSweep, PoseSweep, SimSetup

__all__ = ["Simulations", "summary_table", "write_report"]

CM = 100.0
# Our cylinder methods (core.modeling) under Table III.2's column names.
CYLINDER_COLUMNS = {
    "tangential": "tangential_vc_rf_cm",
    "bisecting": "bisecting_vc_rf_cm",
    "rf_tangential": "tangential_rf_cm",
    "fused": "fused_cm",
}


@dataclass(frozen=True)
class Simulations:
    """The simulated sweeps shown beside the run (any may be None when skipped)."""

    setup: SimSetup
    seed: int
    box: BoxSweep | None = None
    cylinder: CylinderSweep | None = None
    pose: PoseSweep | None = None


def _pm(v: float, s: float, digits: int = 2) -> str:
    if not np.isfinite(v):
        return "—"
    return f"{v:.{digits}f} ± {s:.{digits}f}" if np.isfinite(s) else f"{v:.{digits}f}"


def _signed(v: float, digits: int = 2) -> str:
    return "—" if not np.isfinite(v) else f"{v:+.{digits}f}"


def _stats(errors: Sequence[tuple[float, float]]) -> tuple[float, float, float, float]:
    """(mean m, mean °, std m, std °) of (degrees, metres) pairs; NaN when empty."""
    e = np.array([x for x in errors if np.all(np.isfinite(x))], float).reshape(-1, 2)
    if not len(e):
        return (float("nan"),) * 4
    return float(e[:, 1].mean()), float(e[:, 0].mean()), float(e[:, 1].std()), float(e[:, 0].std())


def _nearest_paper_row(table, distance_m: float):
    return min(table.rows, key=lambda r: abs(r[0] - distance_m))


# ---------------------------------------------------------------------- the main table
def summary_table(results: DemoResults) -> str:
    """The report's main table (Markdown): the paper's headline figures beside this run's."""
    rows: list[list[Any]] = []
    for b in results.boxes:
        p = _nearest_paper_row(TABLE_III_1, b.distance_turret_m)
        err = np.abs(b.error) * CM
        rows.append(
            [
                f"Table III.1 box {b.name}: |error| of width / height / length (cm)",
                f"{p[1]:.2f} / {p[2]:.2f} / {p[3]:.2f} at {p[0]:.1f} m",
                f"{err[0]:.2f} / {err[1]:.2f} / {err[2]:.2f} at {b.distance_turret_m:.2f} m "
                f"(σ {b.sigma[0] * CM:.2f} / {b.sigma[1] * CM:.2f} / {b.sigma[2] * CM:.2f})",
            ]
        )
    for c in results.cylinders:
        p = _nearest_paper_row(TABLE_III_2, c.distance_turret_m)
        for k, (m, col) in enumerate(CYLINDER_COLUMNS.items()):
            paper = f"{p[k + 1]:.2f} at {p[0]:.1f} m" if k < 3 else "—"
            ours = c.by_method[m]["depth"] * CM
            rows.append(
                [
                    f"Table III.2 cylinder depth (true {c.depth_true * CM:.1f} cm), {METHOD_LABELS[col]} (cm)",
                    paper,
                    f"{ours:.2f} at {c.distance_turret_m:.2f} m" if np.isfinite(ours) else c.by_method[m]["error"],
                ]
            )
        f = c.by_method["fused"]
        rows.append(
            [
                f"cylinder r / h (true {c.radius_true * CM:.1f} / {c.height_true * CM:.1f} cm), {c.method} (cm)",
                "errors < 0.4 (tangential)",
                f"{_pm(c.by_method[c.method]['radius'] * CM, c.by_method[c.method]['sigma_radius'] * CM)} / "
                f"{_pm(c.by_method[c.method]['height'] * CM, c.by_method[c.method]['sigma_height'] * CM)}"
                + ("" if c.method == "fused" else f"; fused {_pm(f['radius'] * CM, f['sigma_radius'] * CM)}"),
            ]
        )
    if results.poses:
        paper = {r[0]: r[1:] for r in TABLE_V_1.rows}
        large = _stats([p.p3l_error for p in results.poses])
        small = _stats([p.refined_error for p in results.poses])
        n = len(results.poses)
        by_op = sum(p.p3l_source == "workflow" for p in results.poses)
        rows.append(
            [
                "Table V.1 large-motion step (P3L): mean translation / rotation error",
                f"{paper['tz_m'][0] * CM:.2f} cm / {paper['R_deg'][0]:.2f}°",
                f"{large[0] * CM:.2f} cm / {large[1]:.2f}° ({n} updates: {by_op} by the operator's Solve, "
                f"{n - by_op} on the same clicks)",
            ]
        )
        rows.append(
            [
                "Table V.1 small-motion step (refinement): mean translation / rotation error",
                f"{paper['tz_m'][1] * CM:.2f} cm / {paper['R_deg'][1]:.2f}°",
                f"{small[0] * CM:.2f} cm / {small[1]:.2f}° ({n} updates)",
            ]
        )
    cal = results.calibration
    if np.isfinite(cal.camera_rms_px):
        rows.append(
            [
                f"camera calibration (DLT, {cal.camera_points} points): RMS; "
                "calibrated vs true C at the bodies' corners; optical centre",
                "—",
                f"{cal.camera_rms_px:.2f} px; {cal.camera_reprojection_rms_px:.2f} px RMS, "
                f"{cal.camera_reprojection_max_px:.2f} px max; {cal.camera_centre_error_m * CM:.1f} cm off",
            ]
        )
    if np.isfinite(cal.turret_rms_mm):
        rows.append(
            [
                f"turret calibration ({cal.turret_points} points): RMS to the surfaces; pose error",
                "—",
                f"{cal.turret_rms_mm:.1f} mm; {cal.turret_error_deg:.2f}°, {cal.turret_error_m * 1000:.1f} mm",
            ]
        )
    if not rows:
        return "(the script holds no run that the paper's tables measure)\n"
    return markdown_table(["result", "paper", "this run (against the scene's truth)"], rows)


# ---------------------------------------------------------------------- sections
def _setup(
    w: ReportWriter, scene: Scene, replay: Replay, script, sims: Simulations | None, wall_s: dict[str, float]
) -> None:
    g = script.generator
    K = scene.camera.decompose()[0]
    step_deg = np.degrees(scene.turret.step_rad)
    rf = scene.rangefinder
    w.heading("Set-up and noise")
    w.paragraph(
        f"Scene `{scene.name}` ({scene.root}): camera {scene.camera.width} × {scene.camera.height} px, "
        f"f = {abs(K[0, 0]):.0f} px; range finder σ_ρ = {rf.sigma_range_m * 1000:.1f} mm, "
        f"{rf.min_range_m:g}–{rf.max_range_m:g} m, on a turret of {step_deg:.4f}° steps. The video is "
        f"the scene's committed recording (`{scene.video.path.name if scene.video else '—'}`), its "
        "frames drawn over, never re-rendered."
    )
    w.paragraph(
        f"Operator script: {len(script.actions)} recorded actions in {len(script.runs())} workflow runs "
        f"(generator seed {g.get('seed', '—')}, clicks with Gaussian noise σ = {g.get('click_sigma_px', '—')} px"
        f"{', shortened' if g.get('shortened') else ''}), replayed through `app.workflows.Session.run_action` — the "
        "interface's own calls — with the scene clock at each action's video time, the emulated range finder and "
        "turret (in process, speaking the Dimetix DLS and PTU-D46 serial protocols) and a new SQLite database "
        f"seeded from the scene's known objects. Device timing: **{replay.timing}** "
        + (
            "(the emulators' defaults: 19200/9600 baud lines, a measurement 0.1 s + 5 ms/m, the scene's turret speed "
            f"{scene.turret.speed_steps_s:g} steps/s)."
            if replay.timing == "realistic"
            else "(lines without delay, instant measurements, a turret moving 10⁶ steps/s)."
        )
    )
    if sims is not None:
        s = sims.setup
        w.paragraph(
            f"Simulation (labelled so wherever it appears; seed {sims.seed}): the same solvers on "
            "simulated measurements (`core.modeling.simulate`, `core.pose.synthetic`): camera "
            f"{s.width} × {s.height} px, f = {s.f_px:.0f} px, {s.elevation_deg:.1f}° down (the scene's), "
            f"range finder {s.baseline_m * 100:.1f} cm to its right; clicks σ = {s.sigma_px:g} px; range "
            f"σ_ρ = {rf.sigma_range_m * 1000:.0f} mm; whole turret steps of {step_deg:.4f}° with a "
            "uniform ±½-step pointing error. Distances are camera → object centre."
        )
    times = ", ".join(f"{k} {v:.1f} s" for k, v in wall_s.items())
    w.paragraph(f"Wall time on this machine ({platform.machine()}, Python {platform.python_version()}): {times}.")


def _runs(w: ReportWriter, replay: Replay) -> None:
    w.heading("The replayed session")
    rows = []
    for i, r in enumerate(replay.runs, 1):
        rows.append(
            [
                i,
                r.name,
                r.object_name or "",
                f"{r.t_start:.2f}–{r.t_end:.2f}",
                len(r.actions),
                "accepted" if r.accepted else "cancelled",
                r.workflow.message,
                f"{r.wall_s:.2f}",
            ]
        )
    w.markdown(
        markdown_table(
            ["#", "workflow", "object", "video time (s)", "actions", "outcome", "the workflow's message", "wall (s)"],
            rows,
            align="rllrrllr",
        )
    )
    db = replay.site.db
    objs = db.objects()
    rows = []
    for o in objs:
        dims = ", ".join(
            f"{k} {v * CM:.2f}" + (f" ± {o.sigmas[k] * CM:.2f}" if k in o.sigmas else "") for k, v in o.dims.items()
        )
        rows.append([o.name, o.kind, o.status, o.version, dims])
    w.paragraph(
        f"The resulting database (`site.sqlite`): {len(objs)} objects, {len(db.history())} history entries "
        f"(every change with its clicks, measurements and residuals), {len(db.calibrations())} calibrations."
    )
    w.table(["object", "kind", "status", "version", "dimensions (cm)"], rows)


def _box(w: ReportWriter, results: DemoResults, sims: Simulations | None) -> None:
    w.heading("Table III.1 — modelling the box")
    paper = {r[0]: r[1:] for r in TABLE_III_1.rows}
    rows = []
    sweep = sims.box if sims is not None else None
    dists = sorted(set(paper) | set(sweep.distances_m if sweep else ()))
    for d in dists:
        if d in paper:
            rows.append([f"{d:.1f}", "paper (one measurement)", *paper[d]])
        if sweep is not None and d in sweep.distances_m:
            i = sweep.distances_m.index(d)
            for m in ("planes", "fused"):
                r = sweep.rms(m)[i]
                rows.append([f"{d:.1f}", f"simulation, RMS of {sweep.trials} trials ({m})", *(r[:3] * CM), r[3] * 1000])
    for b in results.boxes:
        e = np.abs(b.error) * CM
        ef = np.abs(b.fused[0] - b.truth) * CM
        dv = abs(b.volume_m3 - b.volume_true_m3) * 1000
        dvf = abs(np.prod(b.fused[0]) - b.volume_true_m3) * 1000
        rows.append([f"{b.distance_turret_m:.2f}", f"**this run** ({b.method}, the workflow's), |error|", *e, dv])
        rows.append([f"{b.distance_turret_m:.2f}", "this run, fused fit on the same data, |error|", *ef, dvf])
    w.table(
        ["distance (m)", "source", "width (cm)", "height (cm)", "length (cm)", "volume (dm³)"],
        rows,
        digits=3,
        caption="Errors of the modelled box (w × h × l = 9 × 14 × 9.4 cm); the paper's one measurement per distance, "
        "our simulation's RMS over the trials, and this run's error against the scene's truth.",
    )
    for b in results.boxes:
        rows = []
        for k, name in enumerate(("width", "height", "length")):
            rows.append(
                [
                    name,
                    b.truth[k] * CM,
                    _pm(b.estimate[k] * CM, b.sigma[k] * CM),
                    _signed(b.error[k] * CM),
                    f"{abs(b.error[k]) / b.sigma[k]:.1f}" if b.sigma[k] > 0 else "—",
                    _pm(b.fused[0][k] * CM, b.fused[1][k] * CM),
                    _signed((b.true_camera[0][k] - b.truth[k]) * CM),
                ]
            )
        w.table(
            [
                "dimension",
                "true (cm)",
                f"this run ({b.method}) ± σ",
                "error (cm)",
                "|error| / σ",
                "fused ± σ",
                "error with the true camera (cm)",
            ],
            rows,
            caption=f"{b.name}: {b.distance_turret_m:.2f} m from the range finder, "
            f"{b.distance_camera_m:.2f} m from the camera; range points per face {list(b.points)}.",
        )
        worst = int(np.argmax(np.abs(b.error) / np.maximum(b.sigma, 1e-12)))
        if b.sigma_parts:
            w.table(
                ["σ from", "width (cm)", "height (cm)", "length (cm)"],
                [[src, *(v * CM)] for src, v in b.sigma_parts.items()]
                + [["all (root sum of squares)", *(b.sigma * CM)]],
                digits=3,
                caption=f"{b.name}: what the workflow's σ are made of — the clicks and range noise, and the "
                "camera's and the turret's calibrations, each moved through its covariance "
                "(core.modeling.uncertainty).",
            )
        w.paragraph(
            "The last column of the first table re-runs the same construction on the same clicks and range "
            "points through the scene's *true* camera instead of the calibrated one (a diagnostic only an "
            "emulated site allows): the part of each error that it removes comes from the camera calibration"
            + (
                ", whose share of σ is in the table above"
                if b.sigma_parts
                else ", whose uncertainty these σ do not include"
            )
            + f". Here the largest error relative to σ is the {('width', 'height', 'length')[worst]}: "
            f"{_signed(b.error[worst] * CM)} cm with the calibrated camera, "
            f"{_signed((b.true_camera[0][worst] - b.truth[worst]) * CM)} cm with the true one."
        )


def _cylinder_sigma_note(c) -> str:
    """'; σ include …' naming the calibrations' share of the workflow's axis σ, if any."""
    parts = c.by_method[c.method].get("sigma_parts") or {}
    if len(parts) <= 1:
        return ""
    axis = {k: v.get("axis_position", float("nan")) * 1000 for k, v in parts.items()}
    return "; σ include the calibrations' share — of the workflow's axis position σ: " + ", ".join(
        f"{k} {v:.1f} mm" for k, v in axis.items()
    )


def _cylinder(w: ReportWriter, results: DemoResults, sims: Simulations | None) -> dict:
    w.heading("Table III.2 — modelling the cylinder: depth by method")
    methods = list(CYLINDER_COLUMNS)
    paper = {r[0]: r[1:] for r in TABLE_III_2.rows}
    sweep = sims.cylinder if sims is not None else None
    rows = []
    for d in sorted(set(paper) | set(sweep.distances_m if sweep else ())):
        if d in paper:
            rows.append([f"{d:.1f}", "paper", *paper[d], None])
        if sweep is not None and d in sweep.distances_m:
            i = sweep.distances_m.index(d)
            rows.append(
                [
                    f"{d:.1f}",
                    f"simulation, mean of {sweep.trials} trials",
                    *[sweep.mean_depth(m)[i] * CM for m in methods],
                ]
            )
            rows.append(
                [f"{d:.1f}", "simulation, RMS of (depth − 5.1 cm)", *[sweep.rms(m, 0)[i] * CM for m in methods]]
            )
    for c in results.cylinders:
        rows.append([f"{c.distance_turret_m:.2f}", "**this run**", *[c.by_method[m]["depth"] * CM for m in methods]])
    w.paragraph(
        "*Depth of the cylinder (r = 5.1 cm, h = 16.6 cm: true depth 5.1 cm) — how far behind its front surface "
        "the estimated axis lies along the range finder's horizontal line of sight.*"
    )
    w.markdown(
        markdown_table(
            [
                "distance (m)",
                "source",
                "(a) tangential VC+RF (cm)",
                "(b) bisecting VC+RF (cm)",
                "(c) tangential RF (cm)",
                "(d) fused (cm)",
            ],
            rows,
            digits=4,
            align="llrrrr",
        )
    )
    for c in results.cylinders:
        rows = []
        for m in methods:
            v = c.by_method[m]
            if v["error"]:
                rows.append([m, v["error"], "—", "—", "—", "—"])
                continue
            rows.append(
                [
                    m + (" (the workflow's)" if m == c.method else ""),
                    _pm(v["radius"] * CM, v["sigma_radius"] * CM),
                    _pm(v["height"] * CM, v["sigma_height"] * CM),
                    f"{v['axis_error'] * 1000:.1f} (σ {v['sigma_axis'] * 1000:.1f})",
                    v["depth"] * CM,
                    _signed((v["depth"] - c.depth_true) * CM),
                ]
            )
        w.table(
            [
                "method",
                "radius ± σ (cm)",
                "height ± σ (cm)",
                "axis position error (mm)",
                "depth (cm)",
                "depth error (cm)",
            ],
            rows,
            caption=f"{c.name} (true r = {c.radius_true * CM:.1f} cm, h = {c.height_true * CM:.1f} cm), "
            f"{c.distance_turret_m:.2f} m from the range finder, {c.distance_camera_m:.2f} m from the camera; "
            f"every method on the run's two clicked silhouettes and its two scans ({list(c.beams)} beams, "
            f"{list(c.hits)} returns)" + _cylinder_sigma_note(c) + ".",
        )
    ours = {}
    if sweep is not None:
        ours = {
            CYLINDER_COLUMNS[m]: (list(sweep.distances_m), list((sweep.mean_depth(m) - sweep.radius_m) * CM))
            for m in methods
        }
    points = {}
    for c in results.cylinders:
        for m in methods:
            if np.isfinite(c.by_method[m]["depth"]):
                points[CYLINDER_COLUMNS[m]] = ([c.distance_turret_m], [(c.by_method[m]["depth"] - c.depth_true) * CM])
    return {"ours": ours, "points": points}


def _median(errors: Sequence[tuple[float, float]]) -> tuple[float, float]:
    e = np.array([x for x in errors if np.all(np.isfinite(x))], float).reshape(-1, 2)
    return (float(np.median(e[:, 1])), float(np.median(e[:, 0]))) if len(e) else (float("nan"),) * 2


def _pose(w: ReportWriter, results: DemoResults, sims: Simulations | None) -> None:
    w.heading("Table V.1 — updating the parallelepiped's pose")
    poses = results.poses
    paper = {r[0]: r[1:] for r in TABLE_V_1.rows}
    sources = [(f"this run ({len(poses)} updates)", [p.p3l_error for p in poses], [p.refined_error for p in poses])]
    sim = sims.pose if sims is not None else None
    if sim is not None and len(sim.p3l):
        sources.append(
            (f"simulation ({len(sim.p3l)} problems)", list(map(tuple, sim.p3l)), list(map(tuple, sim.refined)))
        )
    rows = []
    for k, (name, unit) in enumerate((("tz_m", "tz (m)"), ("R_deg", "R (°)"))):
        rows.append([unit, "paper", *paper[name], None, None])
        for label, large, small in sources:
            a, b = _stats(large), _stats(small)
            rows.append([unit, label, a[k], b[k], a[2 + k], b[2 + k], _median(large)[k], _median(small)[k]])
    w.markdown(
        markdown_table(
            [
                "error",
                "source",
                "mean, large-motion step (P3L)",
                "mean, small-motion step (refined)",
                "std, large",
                "std, small",
                "median, large",
                "median, small",
            ],
            rows,
            align="llrrrrrr",
        )
    )
    w.paragraph(
        "*Mean and standard deviation of the pose errors (Table V.1's statistics; the median added): the "
        "paper's (an operator on real images), this run's against the scene's truth, and the simulation's (the "
        "paper's box at ~2 m, 9 edges clicked twice with σ = 1 px). tz: the translation error's norm; R: the "
        "rotation angle of the error. Large-motion step: P3L's first-ranked candidate; small-motion step: the "
        "refinement with every click.*"
    )
    if sim is not None and len(sim.refined):
        gross = int(np.sum(sim.refined[:, 0] > 10.0))
        w.paragraph(
            f"In the simulation the refinement starts from P3L's first candidate and from the next ones while its "
            f"RMS exceeds 3 σ (an operator choosing another ghost); {int(np.sum(sim.candidates_tried > 1))} of "
            f"{len(sim.refined)} problems needed another candidate, {gross} ended "
            f"more than 10° off, and in {sim.refine_failed} no candidate could be "
            f"refined. P3L found no solution in {sim.failed} of {sim.trials}."
        )
    rows = []
    for i, p in enumerate(poses, 1):
        rows.append(
            [
                i,
                f"{p.t_s:.2f}",
                f"{p.motion} ({p.motion_deg:.1f}°, {p.motion_m * CM:.1f} cm)",
                p.edges,
                f"{p.p3l_error[0]:.2f}° / {p.p3l_error[1] * CM:.2f} cm ({p.p3l_source})",
                f"{p.refined_error[0]:.2f}° / {p.refined_error[1] * CM:.2f} cm",
                f"{p.std_deg:.2f}° / {p.std_m * CM:.2f} cm",
                f"{p.rms_px:.2f}",
                f"{p.refined_true_camera[0]:.2f}° / {p.refined_true_camera[1] * CM:.2f} cm",
                f"{p.noise_free_error[0]:.1e}° / {p.noise_free_error[1]:.1e} m",
            ]
        )
    w.table(
        [
            "#",
            "video time (s)",
            "true motion",
            "edges",
            "P3L error",
            "refined error",
            "predicted σ (refined)",
            "RMS (px)",
            "refined, true camera",
            "P3L, noise-free clicks",
        ],
        rows,
        caption="Each update against the true pose at its time. P3L: the candidate the operator's Solve chose "
        '("workflow"), or — for an update refined from the database pose, as the small motions are — P3L on the '
        'same clicks computed for this report ("same clicks"). Predicted σ: the refinement\'s, of the '
        "rotation angle and the position (root sum of squares over the axes), from each click's σ (0.15 px "
        "snapped, the operator's σ raw) and the camera calibration's share (core.pose.uncertainty). "
        '"Refined, true camera": the same refinement through the scene\'s true camera instead of the '
        "calibrated one (a diagnostic: the difference is the camera calibration's share). Last column: "
        "P3L's first candidate on the same edges clicked without noise (each clicked point of the script's "
        "truth, on its model edge at the true pose, through the true camera) — Figure V.1's noise-free test.",
    )
    if sim is not None and len(sim.noise_free):
        nf = sim.noise_free
        w.paragraph(
            f"Noise-free P3L in simulation ({len(nf)} problems, first-ranked candidate): rotation error median "
            f"{np.median(nf[:, 0]):.1e}°, max {nf[:, 0].max():.1e}°; translation median "
            f"{np.median(nf[:, 1]):.1e} m, max {nf[:, 1].max():.1e} m (the paper: 1e-4° and 1e-6 m)."
        )


def write_report(
    out_dir: str | Path,
    scene: Scene,
    script,
    replay: Replay,
    results: DemoResults,
    sims: Simulations | None,
    wall_s: dict[str, float],
    stills: Sequence[tuple[str, str]] = (),
) -> Path:
    """Write ``report.md`` and its figures in ``out_dir``; returns the report's path.

    stills : (file name, caption) of overlay frames already saved in out_dir, shown in the report.
    """
    w = ReportWriter(out_dir, f"mcit demo — scene {scene.name}, the source paper's tables beside ours")
    w.paragraph(
        "Produced by `mcit demo`. *Paper*: the source paper's published values. *This run*: the replayed operator "
        "session, against the scene's ground truth. *Simulation*: the same solvers on simulated measurements, "
        "for the distances and statistics one run cannot give — never presented as measured."
    )
    w.heading("Main results")
    w.markdown(summary_table(results))
    for name, caption in stills:
        w.markdown(f"![{caption}]({name})\n\n*{caption}*\n")
    _setup(w, scene, replay, script, sims, wall_s)
    _runs(w, replay)
    if results.boxes or (sims is not None and sims.box is not None):
        _box(w, results, sims)
    if results.cylinders or (sims is not None and sims.cylinder is not None):
        curves = _cylinder(w, results, sims)
        w.heading("Figure III.6 — depth error against distance", 3)
        w.figure(
            plot_depth_errors(
                curves["ours"],
                label="simulation",
                points=curves["points"],
                points_label="this run",
                title="Figure III.6 — cylinder depth error (paper dashed, simulation solid, this run ★)",
            ),
            "figure_III_6",
            "Depth error (estimated − 5.1 cm) per method and distance.",
        )
    if results.poses:
        _pose(w, results, sims)
        labels = [f"{i}: {p.motion}" for i, p in enumerate(results.poses, 1)]
        key = "P3L, noise-free clicks, true camera"
        nf = {
            key: (
                [max(p.noise_free_error[1], 1e-15) for p in results.poses],
                [max(p.noise_free_error[0], 1e-15) for p in results.poses],
            )
        }
        if all(np.isfinite(nf[key][0])):
            w.heading("Figure V.1 — the large-motion algorithm without click noise", 3)
            w.figure(
                plot_pose_errors(
                    nf,
                    labels=labels,
                    log=True,
                    claims="V.1",
                    title="Figure V.1 — P3L on the run's edges, noise-free clicks",
                ),
                "figure_V_1",
                "P3L's error on each update's edges clicked without noise, with the paper's stated accuracy "
                "(errors below 1e-15 drawn at 1e-15).",
            )
        w.heading("Figure V.2 — both steps on the operator's clicks", 3)
        errs = {
            "P3L (large-motion step)": (
                [p.p3l_error[1] for p in results.poses],
                [p.p3l_error[0] for p in results.poses],
            ),
            "refined (small-motion step)": (
                [p.refined_error[1] for p in results.poses],
                [p.refined_error[0] for p in results.poses],
            ),
        }
        w.figure(
            plot_pose_errors(
                errs, labels=labels, claims="V.2", title="Figure V.2 — pose error of each update (this run)"
            ),
            "figure_V_2",
            "Translation and rotation error of each update against "
            "the scene's truth, with the bounds the paper states.",
        )
    return w.write()
