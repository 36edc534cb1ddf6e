"""The overlay's content for one view, as pixel line batches and labels (no viser here).

``draw_database`` draws every database object through C, coloured by status, hidden edges
dashed; ``draw_marks`` draws one operator's workflow marks (selection, clicks, assigned edges,
candidate ghosts, residuals, targets, the beam spot). The interface sends the batches to viser;
the benchmark times them.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

import numpy as np

from app.overlay import (
    COLORS,
    STATUS_COLORS,
    LineBatch,
    ProjectedWireframe,
    circle_marker,
    cross_markers,
    dash_segments,
    project_wireframe,
    project_wireframes,
    wireframe_lines,
)
from app.workflows.base import Marks
from app.workflows.site import SiteObject
from core.camera import Camera

log = logging.getLogger("mcit.ui")

__all__ = [
    "label_anchor",
    "label_anchors",
    "draw_database",
    "draw_object",
    "draw_objects",
    "draw_marks",
    "spread_labels",
]

WIDE_TOP_PX = 160.0  # label_anchor: an outline wider than this (a table) gets its label under its front edge


def label_anchor(pw: ProjectedWireframe, height: int | None = None) -> np.ndarray | None:
    """Pixel (2,) where an object's label goes: just above the top of its drawn wireframe, or None. A
    wide outline (a table) has it just under the middle of its front (lowest) edge instead, kept inside
    the image of ``height`` rows: above, its far edge is where the objects standing on it are drawn (two
    new operators read "table" as the parallelepiped's label, at its middle and near its left end)."""
    return label_anchors([pw], height)[0]


def label_anchors(pws: list[ProjectedWireframe], height: int | None = None) -> list[np.ndarray | None]:
    """``label_anchor`` of each wireframe, their points' extremes taken all at once."""
    points = [pw.seg_uv[pw.visible].reshape(-1, 2) if pw.visible.any() else pw.seg_uv.reshape(-1, 2) for pw in pws]
    out: list[np.ndarray | None] = [None] * len(pws)
    drawn = [i for i, P in enumerate(points) if len(P)]
    if not drawn:
        return out
    counts = np.array([len(points[i]) for i in drawn])
    starts, owner = np.cumsum(counts) - counts, np.repeat(np.arange(len(drawn)), counts)
    x, y = np.concatenate([points[i] for i in drawn]).T

    def lowest(v, where=None):
        return np.minimum.reduceat(v if where is None else np.where(where, v, np.inf), starts)

    def highest(v, where=None):
        return np.maximum.reduceat(v if where is None else np.where(where, v, -np.inf), starts)

    top, bottom = lowest(y), highest(y)
    at_top, at_front = y <= (top + 3.0)[owner], y >= (bottom - 3.0)[owner]
    wide = highest(x) - lowest(x) > WIDE_TOP_PX
    ends = zip(lowest(x, at_top), highest(x, at_top), lowest(x, at_front), highest(x, at_front))
    for i, w, t, b, (lo, hi, front_lo, front_hi) in zip(drawn, wide, top, bottom, ends):
        if w:
            v = float(b) + 16.0
            if height is not None:
                v = min(v, float(height) - 4.0)
            out[i] = np.array([0.5 * (float(front_lo) + float(front_hi)), v])
        else:
            out[i] = np.array([0.5 * (float(lo) + float(hi)), t - 4.0])
    return out


def draw_database(
    camera: Camera, objects: Iterable[SiteObject], width: int, height: int, hidden: str = "dashed"
) -> tuple[LineBatch, list[tuple[str, np.ndarray, str]]]:
    """Every object's wireframe at its database pose, colour by status.

    Returns the batch and labels (name, uv (2,), text).
    """
    batch = LineBatch()
    labels = []
    for obj in objects:
        try:
            one, label, _ = draw_object(camera, obj, width, height, hidden)
        except ValueError as exc:  # a pose no camera can project (an old or hostile row): the others still draw
            _say_undrawable(obj, exc)
            continue
        batch.segments += one.segments
        batch.colors += one.colors
        if label is not None:
            labels.append((obj.name, *label))
    return batch, labels


_SAID: set[tuple[str, int | None]] = set()


def _say_undrawable(obj: SiteObject, exc: Exception) -> None:
    """One log line per object version that cannot be drawn (the overlay is redrawn many times a second)."""
    key = (obj.name, getattr(obj, "version", None))
    if key not in _SAID:
        _SAID.add(key)
        log.warning("%s is not drawn: %s; update its pose, or undo the change that put it there", obj.name, exc)


def draw_object(
    camera: Camera, obj: SiteObject, width: int, height: int, hidden: str = "dashed"
) -> tuple[LineBatch, tuple[np.ndarray, str] | None, ProjectedWireframe]:
    """One object's wireframe at its database pose, colour by status: (batch, label (uv (2,), text)
    or None, its projection)."""
    seg, colors, _, labels, pws = draw_objects(camera, [obj], width, height, hidden)
    batch = LineBatch()
    batch.add(seg, colors)
    return batch, labels[0], pws[0]


def draw_objects(
    camera: Camera, objects: list[SiteObject], width: int, height: int, hidden: str = "dashed"
) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[tuple[np.ndarray, str] | None], list[ProjectedWireframe]]:
    """Objects' wireframes at their database poses, colour by status, projected and dashed all at once:
    (segments (K, 2, 2) pixels, colours (K, 3) uint8, bounds (n + 1,) — object i's lines are
    ``bounds[i]:bounds[i + 1]`` —, each one's label (uv (2,), text) or None, each one's projection)."""
    pws = project_wireframes(camera, [(o.model, o.T_world_obj) for o in objects], width=width, height=height)
    colors = [STATUS_COLORS.get(o.status, STATUS_COLORS["known"]) for o in objects]
    seg, line_colors, bounds = wireframe_lines(pws, colors, hidden)
    labels = []
    for obj, anchor in zip(objects, label_anchors(pws, height)):
        text = obj.name if obj.status == "known" else f"{obj.name} ({obj.status})"
        labels.append(None if anchor is None else (anchor, text))
    return seg, line_colors, bounds, labels, pws


def draw_marks(
    camera: Camera,
    marks: Marks,
    objects: dict[str, SiteObject],
    width: int,
    height: int,
    selected: str | None = None,
    scale: float = 1.0,
) -> tuple[LineBatch, list[tuple[np.ndarray, str]]]:
    """One operator's marks: the selected object, assigned edges, ghosts, tracked poses and their
    edge points, clicks (raw clicks dashed beside the snapped ones in use), residuals, targets and
    the beam spot. Returns the batch and labels (uv (2,), text).

    scale : image pixels per screen pixel relative to the fitted view (0.1 when zoomed in 10×): the
    markers' sizes are multiplied by it, so that they keep their size on screen and do not hide
    what they mark."""
    s = float(scale)
    if not (np.isfinite(s) and s > 0):
        raise ValueError(f"scale must be a positive number, got {scale!r}")
    batch = LineBatch()
    name = marks.selected or selected
    if name in objects:
        obj = objects[name]
        batch.add_wireframe(
            project_wireframe(camera, obj.model, obj.T_world_obj, width=width, height=height), STATUS_COLORS["selected"]
        )
    # the chosen ghost last, drawn over the others (a near-identical candidate hid it: a new operator's run)
    for ghost in sorted(marks.ghosts, key=lambda g: bool(g.chosen)):
        pw = project_wireframe(camera, ghost.model, ghost.T_world_obj, width=width, height=height)
        batch.add_wireframe(
            pw,
            COLORS["ghost_chosen"] if ghost.chosen else COLORS["ghost"],
            hidden="dashed" if ghost.chosen else "removed",
        )
    inside = np.all((marks.robot_path >= 0) & (marks.robot_path <= [width - 1, height - 1]), axis=(1, 2))
    batch.add(marks.robot_path[inside], COLORS["robot_ghost"])  # the tool's way, on the image only
    for links, color in ((marks.robot_ghost, COLORS["robot_ghost"]), (marks.robot_contact, COLORS["click"])):
        for _link, brep, T in links:
            batch.add_wireframe(project_wireframe(camera, brep, T, width=width, height=height), color, hidden="removed")
    for ghost in marks.tracked:
        pw = project_wireframe(camera, ghost.model, ghost.T_world_obj, width=width, height=height)
        color = COLORS["tracked"] if ghost.chosen else tuple(int(c * 0.55) for c in COLORS["tracked"])
        batch.add_wireframe(pw, color, hidden="removed")
    batch.add(cross_markers(marks.found_points, 1.5 * s), COLORS["edge_found"])
    batch.add(cross_markers(marks.rejected_points, 1.5 * s), COLORS["edge_rejected"])
    for item in marks.highlight:  # (object, edge) at its database pose, or (object, edge, T_world_obj)
        obj_name, k = item[0], item[1]
        obj = objects.get(obj_name)
        if obj is None or not 0 <= k < len(obj.model.edges):
            continue
        T = obj.T_world_obj if len(item) < 3 else np.asarray(item[2], float)
        E = obj.model.edge_segments(T)[k]
        if np.all(camera.depth(E) > 0):
            batch.add(camera.project(E).reshape(1, 2, 2), COLORS["assigned"])
    batch.add(marks.assigned_lines, COLORS["assigned"])
    batch.add(dash_segments(marks.raw_segments, 3.0 * s, 3.0 * s)[0], COLORS["raw"])
    batch.add(cross_markers(marks.raw_points, 4.0 * s), COLORS["raw"])
    batch.add(marks.snap_lines, COLORS["raw"])
    batch.add(marks.segments, COLORS["click"])
    batch.add(cross_markers(marks.points, 5.0 * s), COLORS["click"])
    batch.add(cross_markers(marks.pending, 7.0 * s), COLORS["pending"])
    for uv in np.asarray(marks.circles).reshape(-1, 2):
        batch.add(circle_marker(uv, 9.0 * s), COLORS["pending"])
    batch.add(marks.residuals, COLORS["assigned"])
    batch.add(cross_markers(marks.live_points, 2.5 * s), COLORS["beam"])
    for uv in np.asarray(marks.targets).reshape(-1, 2):
        batch.add(circle_marker(uv, 7.0 * s), COLORS["target"])
        batch.add(cross_markers(uv.reshape(1, 2), 10.0 * s), COLORS["target"])
    if marks.beam_uv is not None and np.all(np.isfinite(marks.beam_uv)):
        batch.add(circle_marker(marks.beam_uv, 5.0 * s), COLORS["beam"])
        batch.add(circle_marker(marks.beam_uv, 2.0 * s, n=8), COLORS["beam"])
    labels = [(np.asarray(uv, float), str(text)) for uv, text in marks.labels]
    return batch, labels


LABEL_CHAR_PX = 7.0  # spread_labels: a label's character width and line height on screen (font_screen_scale 0.8)
LABEL_LINE_PX = 15.0
LABEL_OFFSET_PX = 6.0  # ... its corner this far right of and above the point it names


def spread_labels(labels: list[tuple[np.ndarray, str]], image_px_per_screen_px: float) -> list[tuple[np.ndarray, str]]:
    """Labels moved apart so that none covers another: each label's bottom-left corner (image pixels),
    placed just above and right of its point, then lifted a line at a time while its box meets a label
    placed before it (a new operator met "3→e2" written over "snapped 2.6 px" at one corner); moved down
    instead when lifting would take it off the image's top.

    image_px_per_screen_px : the view's scale (the label's size on screen is fixed)."""
    k = float(image_px_per_screen_px)
    if not (np.isfinite(k) and k > 0):
        raise ValueError(f"image_px_per_screen_px must be a positive number, got {image_px_per_screen_px!r}")
    h = LABEL_LINE_PX * k
    placed: list[tuple[float, float, float, float]] = []  # x0, y0 (top), x1, y1 (bottom)
    out = []
    for uv, text in labels:
        x = float(uv[0]) + LABEL_OFFSET_PX * k
        y = float(uv[1]) - LABEL_OFFSET_PX * k
        w = (len(text) * LABEL_CHAR_PX + 4.0) * k

        def met(y_: float) -> list:  # the boxes placed that the label's box with its bottom at y_ meets
            return [b for b in placed if x < b[2] and b[0] < x + w and y_ - h < b[3] and b[1] < y_]

        y0 = y
        for _ in range(len(placed) + 1):  # lifted just above what it meets
            if not met(y):
                break
            y = min(b[1] for b in met(y))
        if y - h < 0.0:  # lifted off the image's top: moved down below the labels instead
            y = y0
            for _ in range(len(placed) + 1):
                if not met(y):
                    break
                y = max(b[3] for b in met(y)) + h
        placed.append((x, y - h, x + w, y))
        out.append((np.array([x, y]), text))
    return out
