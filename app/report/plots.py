"""The report's figures (matplotlib, headless): ours drawn over the paper's.

* ``plot_depth_errors`` — Figure III.6: the cylinder's depth error per method against the
  object/sensor distance; the paper's curves (Table III.2 − 5.1 cm) dashed, ours solid.
* ``plot_pose_errors`` — Figures V.1 / V.2: the pose error of each update (translation and
  rotation), one series per method (large / small motion), with the bounds the paper states.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .paper import FIGURE_CLAIMS, TABLE_III_2, depth_errors_cm

__all__ = ["plot_depth_errors", "plot_pose_errors", "METHOD_LABELS"]

METHOD_LABELS = {
    "tangential_vc_rf_cm": "(a) tangential planes, camera + range finder",
    "bisecting_vc_rf_cm": "(b) bisecting planes, camera + range finder",
    "tangential_rf_cm": "(c) tangential planes, range finder alone",
    "fused_cm": "(d) fused maximum likelihood (ours only)",
}
_COLOURS = {"tangential_vc_rf_cm": "C0", "bisecting_vc_rf_cm": "C1", "tangential_rf_cm": "C2", "fused_cm": "C3"}


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def plot_depth_errors(
    ours: Mapping[str, tuple[Sequence[float], Sequence[float]]],
    *,
    title: str = "Figure III.6 — depth error",
    label: str = "ours",
    points: Mapping[str, tuple[Sequence[float], Sequence[float]]] | None = None,
    points_label: str = "this run",
):
    """Figure III.6, ours beside the paper's.

    ours : method → (distances_m (K,), depth errors in cm (K,)); methods named like Table III.2's
    columns (``tangential_vc_rf_cm``, ``bisecting_vc_rf_cm``, ``tangential_rf_cm``) or ``fused_cm``.
    label : the legend's name for these curves (e.g. "simulation"). points : more results, same
    form, drawn as stars without lines and named ``points_label`` (e.g. one measured run).
    Returns the matplotlib Figure.
    """
    unknown = (set(ours) | set(points or {})) - set(METHOD_LABELS)
    if unknown:
        raise ValueError(f"unknown method(s) {sorted(unknown)}; use {list(METHOD_LABELS)}")
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(6.4, 3.8))
    dist = TABLE_III_2.column("distance_m")
    for m in ("tangential_vc_rf_cm", "bisecting_vc_rf_cm", "tangential_rf_cm"):
        ax.plot(
            dist, depth_errors_cm(m), "--o", color=_COLOURS[m], alpha=0.55, ms=4, label=f"paper {METHOD_LABELS[m][:3]}"
        )
    for m, (d, e) in ours.items():
        d, e = np.asarray(d, dtype=float), np.asarray(e, dtype=float)
        if d.shape != e.shape:
            raise ValueError(f"{m}: {d.shape} distances but {e.shape} errors")
        ax.plot(d, e, "-s", color=_COLOURS[m], ms=5, label=f"{label} {METHOD_LABELS[m][:3]}")
    for m, (d, e) in (points or {}).items():
        ax.plot(
            np.asarray(d, dtype=float),
            np.asarray(e, dtype=float),
            "*",
            color=_COLOURS[m],
            ms=12,
            mec="k",
            mew=0.5,
            label=f"{points_label} {METHOD_LABELS[m][:3]}",
        )
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_xlabel("distance object / sensors (m)")
    ax.set_ylabel("depth error (cm)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    return fig


def plot_pose_errors(
    errors: Mapping[str, tuple[Sequence[float], Sequence[float]]],
    *,
    labels: Sequence[str] | None = None,
    title: str = "Figure V.2 — pose error of each update",
    log: bool = False,
    claims: str = "V.2",
):
    """Figures V.1 / V.2: translation (m) and rotation (°) error of each update, per method.

    errors : method ("large", "small", or any name) → (translation errors (K,) m, rotation
    errors (K,) degrees), one value per update. labels : K names of the updates for the x axis.
    log : logarithmic y axes (for the noise-free Figure V.1). claims : which of the paper's
    stated bounds to draw ("V.1", "V.2" or None).
    """
    plt = _pyplot()
    fig, (ax_t, ax_r) = plt.subplots(1, 2, figsize=(8.0, 3.4))
    k_max = 0
    for i, (method, (et, er)) in enumerate(errors.items()):
        et, er = np.asarray(et, dtype=float), np.asarray(er, dtype=float)
        if et.shape != er.shape or et.ndim != 1:
            raise ValueError(
                f"{method}: translation {et.shape} and rotation {er.shape} errors must be two equal 1-D lists"
            )
        x = np.arange(1, len(et) + 1)
        k_max = max(k_max, len(et))
        ax_t.plot(x, et * 100.0, "-o", color=f"C{i}", label=method)
        ax_r.plot(x, er, "-o", color=f"C{i}", label=method)
    bounds = FIGURE_CLAIMS.get(claims or "", {})
    for key, value in bounds.items():
        method = key.split("_")[0]
        if key.endswith("_m"):
            ax_t.axhline(value * 100.0, ls="--", lw=0.8, color="grey")
            ax_t.annotate(
                f"paper {method} ≤ {value * 100:g} cm",
                (0.02, value * 100.0),
                xycoords=("axes fraction", "data"),
                fontsize=7,
            )
        elif key.endswith("_deg"):
            ax_r.axhline(value, ls="--", lw=0.8, color="grey")
            ax_r.annotate(f"paper {method} ≤ {value:g}°", (0.02, value), xycoords=("axes fraction", "data"), fontsize=7)
    for ax, unit in ((ax_t, "translation error (cm)"), (ax_r, "rotation error (°)")):
        ax.set_xlabel("update")
        ax.set_ylabel(unit)
        if log:
            ax.set_yscale("log")
        if labels is not None:
            if len(labels) != k_max:
                raise ValueError(f"{len(labels)} labels for {k_max} updates")
            ax.set_xticks(np.arange(1, k_max + 1), labels, fontsize=7)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    fig.tight_layout()
    return fig
