"""What the overlay draws: database wireframes coloured by status, and one operator's marks."""

from __future__ import annotations

import numpy as np
import pytest

from app.overlay import COLORS, STATUS_COLORS
from app.ui.controls import report_markdown
from app.ui.drawing import draw_database, draw_marks
from app.workflows import Ghost, Marks


def _colors(batch):
    return {tuple(int(v) for v in c) for c in batch.arrays()[1]}


def test_database_colours_by_status_and_labels_above_the_wireframe(site, db):
    db.set_status("parallelepiped", "stale", method="test")
    site.poll()
    batch, labels = draw_database(site.camera, site.objects(), 512, 256)
    cols = _colors(batch)
    assert STATUS_COLORS["stale"] in cols and STATUS_COLORS["known"] in cols
    by_name = {name: (uv, text) for name, uv, text in labels}
    assert by_name["parallelepiped"][1] == "parallelepiped (stale)"
    obj = site.object("parallelepiped")
    top_v = site.camera.project(obj.vertices_world())[:, 1].min()
    assert by_name["parallelepiped"][0][1] < top_v  # above the drawing


def test_the_table_label_is_not_drawn_on_the_parallelepiped(site):
    """The table's label went above the middle of its far edge, where the parallelepiped stands in the
    bundled scene: a new operator read it as the parallelepiped's name. It now goes near the far edge's
    left end, clear of the parallelepiped's drawing."""
    _, labels = draw_database(site.camera, site.objects(), 512, 256)
    uv = {name: p for name, p, _ in labels}["table"]
    P = site.camera.project(site.object("parallelepiped").vertices_world())
    lo, hi = P.min(axis=0) - 10.0, P.max(axis=0) + 10.0
    assert not (lo[0] <= uv[0] <= hi[0] and lo[1] <= uv[1] <= hi[1] + 12.0), (uv, lo, hi)


def test_marks_draw_selection_ghosts_clicks_targets_beam(site):
    obj = site.object("parallelepiped")
    moved = obj.T_world_obj.copy()
    moved[:3, 3] += [0.05, 0.0, 0.0]
    m = Marks(
        points=np.array([[100.0, 100.0]]),
        pending=np.array([[50.0, 60.0]]),
        segments=np.array([[[10.0, 10.0], [60.0, 20.0]]]),
        targets=np.array([[200.0, 150.0]]),
        ghosts=[Ghost(obj.model, moved, "#1", chosen=True), Ghost(obj.model, obj.T_world_obj, "#2")],
        highlight=[("parallelepiped", 0)],
        beam_uv=np.array([300.0, 120.0]),
        labels=[((5.0, 5.0), "1")],
    )
    objects = {o.name: o for o in site.objects()}
    batch, labels = draw_marks(site.camera, m, objects, 512, 256, selected="parallelepiped")
    cols = _colors(batch)
    for key in ("ghost_chosen", "ghost", "click", "pending", "target", "beam", "assigned"):
        assert COLORS[key] in cols, key
    assert STATUS_COLORS["selected"] in cols
    # the chosen ghost (listed first) is drawn after the other: over it where they overlap
    order = [tuple(int(v) for v in c) for c in batch.arrays()[1]]
    last_ghost = max(i for i, c in enumerate(order) if c == COLORS["ghost"])
    assert min(i for i, c in enumerate(order) if c == COLORS["ghost_chosen"]) > last_ghost
    assert len(labels) == 1 and labels[0][1] == "1" and np.allclose(labels[0][0], [5.0, 5.0])
    empty, _ = draw_marks(site.camera, Marks(), objects, 512, 256)
    assert len(empty) == 0


def test_report_markdown_lists_scalars_and_tables():
    text = report_markdown(
        {
            "rms_px": 0.51234,
            "std_t_mm": [1.0, 2.0, 3.0],
            "clicks": [{"click": "edge 1", "residual_px": 0.2}, {"click": "edge 2", "residual_px": 0.7}],
        }
    )
    assert "**RMS (px)**: 0.51\n" in text and "1.0, 2.0, 3.0" in text  # rounded to what it means: 0.01 px, 0.1 mm
    assert "| Click | Residual (px) |" in text and "| edge 2 | 0.70 |" in text
    assert "**RMS (px)**: 0.03" in report_markdown({"rms_px": 0.031})  # not "0" beside the message's 0.03 px
    assert report_markdown({}) == ""
    # σ stays σ (its capital Σ reads as a sum: the panel showed "Σ t (mm)"); coordinates stay lower case
    heads = report_markdown({"std_t_mm": 1.0, "sd_rot_deg": 0.1, "sigma_cm": 2.0, "x_y_z_m": 1.0, "t_s": 3.0})
    assert "**σ translation (mm)**" in heads and "**σ rotation (°)**" in heads and "**σ (cm)**" in heads
    assert "**Change**: 49.04°, 224.8 mm" in report_markdown(
        {"change": {"deg": 49.04, "cm": 22.48}}
    )  # as the messages say it
    nested = report_markdown(
        {"found": {"candidates": 1, "fit_px": 0.31, "std_t_mm": [0.1, 0.8], "change": {"deg": 53.01, "cm": 21.9}}}
    )
    assert "- **Found**\n  - **Candidates**: 1\n  - **Fit (px)**: 0.31\n  - **σ translation (mm)**: 0.1, 0.8" in nested
    assert "  - **Change**: 53.01°, 219.0 mm" in nested and "{" not in nested and "[" not in nested
    assert "**x y z (mm)**" in heads and "**t (s)**" in heads and "Σ" not in heads and "Sd" not in heads
    tiny = report_markdown({"rms_px": 2.332e-14, "std_r_deg": 0.123456, "x_m": 1.234567891})
    assert "e-14" not in tiny and "**RMS (px)**: 0" in tiny and "0.12" in tiny
    assert "**x (mm)**: 1234.6" in tiny  # metres shown in mm, as every other length in the panel
    table = report_markdown({"points": [{"point": "A", "range_m": 1.86881, "to_surface_mm": 3.21}]})
    assert "| Point | Range (mm) | To surface (mm) |" in table and "| A | 1868.8 | 3.2 |" in table


def test_spread_labels_lifts_a_label_off_the_one_it_would_cover():
    from app.ui.drawing import LABEL_LINE_PX, LABEL_OFFSET_PX, spread_labels

    corner = np.array([200.0, 150.0])
    out = spread_labels(
        [(corner, "3→e2"), (corner + [2.0, 1.0], "snapped 2.6 px"), (np.array([400.0, 150.0]), "R1")], 0.5
    )
    (a, _), (b, text), (c, _) = out
    assert text == "snapped 2.6 px"
    assert np.allclose(a, corner + [LABEL_OFFSET_PX * 0.5, -LABEL_OFFSET_PX * 0.5])  # just right of and above its point
    assert a[1] - b[1] >= LABEL_LINE_PX * 0.5 - 1e-9  # a line up: the boxes do not meet
    assert np.allclose(c, [403.0, 147.0])  # far from the others: not moved
    # zoomed in 10×: the same labels on screen are ten times smaller in video pixels
    near = spread_labels([(corner, "3→e2"), (corner + [0.0, 3.0], "snapped 2.6 px")], 0.1)
    assert np.allclose(near[1][0], corner + [0.6, 2.4])  # 3 px apart is room enough there: not moved
    with pytest.raises(ValueError, match="positive"):
        spread_labels([], 0.0)
    # near the image's top a label is moved down instead, off the image no more
    top = spread_labels([(np.array([100.0, 12.0]), "1→e3"), (np.array([101.0, 12.0]), "snapped 1.4 px")], 1.0)
    assert top[1][0][1] - LABEL_LINE_PX >= 0.0 and top[1][0][1] - top[0][0][1] >= LABEL_LINE_PX - 1e-9


def test_an_object_no_camera_can_project_is_left_out_and_said_once(site, caplog):
    """A row at 1e308 m (an old or hostile database) raised in every redraw, and nothing was drawn."""
    import dataclasses

    objs = site.objects()
    far = objs[1].T_world_obj.copy()
    far[0, 3] = 1e308
    bad = dataclasses.replace(objs[1], T_world_obj=far)
    with caplog.at_level("WARNING", logger="mcit.ui"):
        batch, labels = draw_database(site.camera, [objs[0], bad, *objs[2:]], 512, 256)
        draw_database(site.camera, [bad], 512, 256)
    assert {name for name, *_ in labels} == {o.name for o in objs} - {bad.name}
    said = [r for r in caplog.records if bad.name in r.getMessage()]
    assert len(said) == 1 and "is not drawn" in said[0].getMessage()


def test_the_result_headline_says_sigma_and_residuals_on_one_line():
    """Under the buttons, a result's σ and residuals (the Result section below was under the fold at
    1280×720): its top-level rms/std/sd/sigma numbers and lists, nothing else; none: empty."""
    from app.ui.controls import result_headline

    line = str(
        result_headline(
            {
                "object": "box",
                "rms_px": 0.4123,
                "std_t_mm": [0.51, 0.8, 1.2],
                "std_r_deg": [0.051, 0.02, 0.03],
                "clicks": [{"click": "edge 1", "residual_px": 0.3}],
                "change": {"deg": 1.0, "mm": 20.0},
            }
        )
    )
    assert line.startswith("**Result**: RMS (px): 0.41 · σ translation (mm): 0.5, 0.8, 1.2")
    assert (
        "σ rotation (°): 0.05, 0.02, 0.03" in line and "box" not in line and "edge 1" not in line and "20" not in line
    )
    assert str(result_headline({"object": "box", "edges clicked": 3})) == ""
