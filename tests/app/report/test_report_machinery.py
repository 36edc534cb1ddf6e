"""The report's machinery: the paper's tables as data, Markdown tables, the figures."""

import numpy as np
import pytest

from app.report import (
    FIGURE_CLAIMS,
    TABLE_III_1,
    TABLE_III_2,
    TABLE_V_1,
    ReportWriter,
    depth_errors_cm,
    format_value,
    markdown_table,
    side_by_side,
)
from app.report.plots import plot_depth_errors, plot_pose_errors


def test_paper_tables_are_transcribed():
    assert TABLE_III_1.column("distance_m") == [1.3, 1.4, 1.5, 1.6]
    assert TABLE_III_1.rows[0] == (1.3, 0.67, 0.73, 0.52, 0.20)
    assert TABLE_III_2.column("bisecting_vc_rf_cm")[-1] == 4.3974
    q = {r[0]: r[1:] for r in TABLE_V_1.rows}
    assert q["tz_m"] == (0.01378, 0.00563, 0.01268, 0.00233)
    assert q["R_deg"] == (0.23342, 0.09810, 0.19033, 0.11136)
    # Figure III.6 as the paper's text reads it: method (a) within 5 mm, (b) improving with
    # distance, (c) worsening with distance.
    a, b, c = (depth_errors_cm(m) for m in ("tangential_vc_rf_cm", "bisecting_vc_rf_cm", "tangential_rf_cm"))
    assert max(abs(v) for v in a) < FIGURE_CLAIMS["III.6"]["tangential_vc_rf_max_cm"]
    assert abs(b[0]) > abs(b[-1]) and abs(c[0]) < abs(c[-1])
    assert depth_errors_cm("tangential_vc_rf_cm")[0] == pytest.approx(4.8314 - 5.1)
    with pytest.raises(KeyError, match="no column 'depth'"):
        TABLE_III_2.column("depth")


def test_format_value():
    assert format_value(0.012345) == "0.0123"
    assert format_value(1234.5) == "1234"  # 3 significant digits, no exponent below 1e5
    assert format_value(2.5e-7) == "2.50e-07"
    assert format_value(None) == "—" and format_value(float("nan")) == "—"
    assert format_value(7) == "7" and format_value(True) == "yes" and format_value("a|b") == "a\\|b"


def test_markdown_table_and_errors():
    t = markdown_table(["d (m)", "err (cm)", "note"], [[1.3, 0.671, "ok"], [1.4, None, "—"]])
    lines = t.strip().splitlines()
    assert lines[0] == "| d (m) | err (cm) | note |"
    assert lines[1] == "|---:|---:|:---|"
    assert lines[2] == "| 1.30 | 0.671 | ok |"
    assert lines[3] == "| 1.40 | — | — |"
    with pytest.raises(ValueError, match="row 0 has 2 cells but the table has 3 columns"):
        markdown_table(["a", "b", "c"], [[1, 2]])
    with pytest.raises(ValueError, match="align must be 2 letters"):
        markdown_table(["a", "b"], [[1, 2]], align="x")


def test_side_by_side_rows_pair_the_paper_and_ours():
    paper = {r[0]: r[1:4] for r in TABLE_III_1.rows}
    ours = {1.3: [0.21, 0.35, 0.4], 1.45: [0.2, 0.3, 0.25]}
    t = side_by_side("distance (m)", ["width (cm)", "height (cm)", "length (cm)"], paper, ours)
    lines = t.strip().splitlines()
    assert lines[0].startswith("| distance (m) | width (cm) (paper) | width (cm) (ours) | height (cm) (paper)")
    assert lines[2] == "| 1.30 | 0.670 | 0.210 | 0.730 | 0.350 | 0.520 | 0.400 |"
    assert "| 1.45 | — | 0.200 |" in t and len(lines) == 2 + 5
    with pytest.raises(ValueError, match="expected 3 values per side"):
        side_by_side("d", ["a", "b", "c"], {1: [1, 2]}, {})


def test_figures_and_report_writer(tmp_path):
    fig = plot_depth_errors({"tangential_vc_rf_cm": ([1.2, 1.4], [0.1, -0.05]), "fused_cm": ([1.2], [0.02])})
    ax = fig.axes[0]
    assert len(ax.lines) == 3 + 2 + 1  # the paper's three curves, ours, the zero line
    np.testing.assert_allclose(ax.lines[0].get_ydata(), depth_errors_cm("tangential_vc_rf_cm"))
    with pytest.raises(ValueError, match="unknown method"):
        plot_depth_errors({"magic_cm": ([1.0], [0.0])})
    fig2 = plot_pose_errors(
        {"large": ([0.012, 0.02], [0.3, 0.2]), "small": ([0.004, 0.005], [0.1, 0.08])}, labels=["1", "2"]
    )
    ax_t, ax_r = fig2.axes
    np.testing.assert_allclose(ax_t.lines[0].get_ydata(), [1.2, 2.0])  # cm
    assert len(ax_r.lines) == 2 + 2  # two methods, two of the paper's bounds in degrees
    with pytest.raises(ValueError, match="two equal 1-D lists"):
        plot_pose_errors({"large": ([0.1, 0.2], [0.3])})
    w = ReportWriter(tmp_path / "out", "Demo report")
    w.heading("Modelling")
    w.table(["d"], [[1.3]], caption="Table III.1")
    w.markdown(side_by_side("d", ["e"], {1.3: [0.67]}, {1.3: [0.2]}))
    png = w.figure(fig, "fig_III_6", "Figure III.6")
    w.figure(fig2, "fig_V_2")
    path = w.write()
    text = path.read_text()
    assert text.startswith("# Demo report") and "## Modelling" in text and "![Figure III.6](fig_III_6.png)" in text
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and (tmp_path / "out" / "fig_V_2.png").is_file()
    with pytest.raises(ValueError, match="heading level"):
        w.heading("x", 7)
