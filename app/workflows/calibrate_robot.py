"""Calibrate robot: the robot's base pose in the world from edges of its links clicked in the video, at two or
more preset joint configurations (the scene's ``calibration_base_deg``).

**Next pose** (G) sends the robot to the next pose, its motion checked against the database and itself
(``RobotTour``); once it is there the newest frame is frozen. The operator clicks two points along a
straight edge of the robot in the video — a box's edge (the gripper, the fingers) or a link's silhouette
(a cylinder's side) — snapped to the image's edge as Update pose's clicks are. Which feature of the robot's
model it is, is found automatically when only one can be it given how well the estimate is known
(``core.robot.calibration.match_segment``: the features drawn at the current estimate, white, each one's
distance to the clicks against the estimate's covariance); otherwise the operator clicks that edge on the
drawn robot. A base not yet calibrated has no covariance (a drawing's error is unknown), so its first edges
are always assigned by hand; with four edges or more the estimate follows the clicks (the white robot moves
onto the video) with the fit's covariance, and later edges are matched automatically where one alone fits.
**Solve** (R) fits the one base pose that all the clicked edges of every pose share
(``core.robot.calibration.refine_base``: the pose pipeline's refinement, silhouettes recomputed at each estimate),
with σ (clicks, and the camera calibration's share); **Accept** stores it as the database's "robot_base"
calibration (undoable in History like a camera's): the robot is drawn, checked and moved through it from then on.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from core.robot.calibration import BaseClick, RobotFeature, features_at, match_segment, refine_base
from core.transforms import pose_error

from .base import CANCEL, PICK_RADIUS_SCREEN_PX, Control, Marks, Step, WorkflowError, as_pixel, sigma_over
from .robot_tour import TourWorkflow
from .snapping import ClickSnap, Snapper, click_segment, segment_of, snap_marks, weak_snaps

__all__ = ["CalibrateRobot", "MIN_EDGES", "WEAK_SIGMA_MM", "WEAK_SIGMA_DEG", "estimate_from_clicks"]

MIN_EDGES = 6  # Solve needs this many assigned edges (12 residuals for the base's 6 unknowns) …
MIN_POSES = 2  # … clicked at this many poses
ESTIMATE_FROM = 4  # the drawn estimate follows the clicks from this many assigned edges
ESTIMATE_MAX_MM, ESTIMATE_MAX_DEG = 20.0, 2.0  # … when their σ is below these
MIN_SEGMENT_PX = 3.0
MAX_SNAP_USE_PX = 3.0  # a snap that moves an edge farther than this is not used (the click is kept)
# Accept asks once more above these: the target for the base (1°, 3 mm) as one σ.
WEAK_SIGMA_MM, WEAK_SIGMA_DEG = 3.0, 1.0
INSIDE_MM = 2.0  # through the solved base a link this deep in a database object at a pose: a base the video denies


@dataclass
class _Edge:
    """One clicked segment: pixels in use (2, 2), their σ, the snap, the pose it was clicked at, its feature
    (None until assigned) and how it was assigned ("auto", "hand")."""

    seg: np.ndarray
    sigma_px: float
    snap: ClickSnap | None
    pose: int
    feature: RobotFeature | None = None
    how: str = ""


class CalibrateRobot(TourWorkflow):
    name = "calibrate_robot"
    title = "Calibrate robot"
    at_state = "click_edge"  # settled at a pose: its edges are clicked
    snapping = True  # Session.start passes its "Snap clicks" setting as snap=
    actions = (
        "go",
        "skip",
        "stop",
        "click",
        "add_segment",
        "assign_edge",
        "remove_last",
        "edge",
        "remove_edge",
        "solve",
        "accept",
        "cancel",
        "refuse_snap",
        "set_snap",
    )
    controls = (
        TourWorkflow.GO,
        TourWorkflow.SKIP,
        TourWorkflow.STOP,
        Control("solve", "Solve", "R", color="blue", hint="The base's pose from every clicked edge, with σ"),
        Control(
            "accept",
            "Accept",
            "enter",
            color="green",
            hint="Store the base's calibration: the robot is drawn, checked and moved through it",
        ),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last edge as clicked, not moved onto the image's edge"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click"),
        Control("edge", "Edge", kind="choice", hint="A clicked edge: the robot's edge it is, its pose, its residual"),
        Control("remove_edge", "Remove edge", arg="edge", hint="Forget the chosen edge (a wrong one: its residual)"),
        CANCEL,
    )

    which = "base"
    poses_named = "calibration poses for its base"

    def __init__(self, site, client: str = "operator", view: str | None = None, snap: bool = True, sigma_px=1.0):
        super().__init__(site, client, view, snap, sigma_px)
        self.edges: list[_Edge] = []
        self.pending: np.ndarray | None = None
        self.T_start = np.asarray(self.cell.T_world_base, float).copy()  # the database's base
        self.T_est = self.T_start.copy()  # the estimate the white robot is drawn at and edges are matched on
        self.cov_start = None if self.site.robot_base_nominal else self.site.robot_base_cov
        self.cov_est = self.cov_start  # its covariance (None: unknown, every edge is assigned by hand)
        self.fit = None  # core.robot.calibration.BaseFit of the last Solve (None: clicks changed since)
        self.inside: list[str] = []  # what the robot would be inside at the poses through the solved base
        self.edge_chosen: int | None = None  # the edge the operator chose in Edge since the edges last changed

    # ------------------------------------------------------------------ the robot's poses
    def _busy(self) -> str:
        if self.pending is not None or self._unassigned() is not None:
            return "finish the edge under way first (or Remove last)"
        return ""

    # ------------------------------------------------------------------ clicks
    def click(self, uv) -> None:
        """A click on the video: an edge's first or second point, or the drawn edge an edge is."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            k = self.tour.at
            if k is None:
                raise WorkflowError("the robot is not at a calibration pose: Next pose (G) sends it to one")
            waiting = self._unassigned()
            if waiting is not None:
                return self._assign_at(waiting, p)
            if self.pending is None:
                self.pending = p
                self.state = "click_edge_end"
                self.message = ""
                return
            seg = segment_of(self.pending, p, MIN_SEGMENT_PX)
            self.pending = None
            uv_used, sigma, snap = self.snapper.take_segment(seg, self.view, self.sigma_px)
            if snap is not None and snap.applied and snap.moved_px > MAX_SNAP_USE_PX:
                # a robot shows many edges side by side: a snap this far found another one
                why = f"the image's nearest straight edge is {snap.moved_px:.1f} px away: another edge?"
                snap = ClickSnap("segment", seg.copy(), None, snap.moved_px, "edge", reason=why)
                uv_used, sigma = seg, self.sigma_px
            edge = _Edge(np.asarray(uv_used, float), float(sigma), snap, k)
            self.edges.append(edge)
            self._changed()
            said = Snapper.message(f"Edge {len(self.edges)}", snap)
            j, why = None, " (the base is not known well enough yet to match it)"
            if self.cov_est is not None:
                feats, segs = self._candidates(k, world=True)
                j, _ = match_segment(edge.seg, segs, self.camera, self.T_est, self.cov_est, sigma_px=edge.sigma_px)
                why = ""
            if j is None:
                self.state = "assign_edge"
                self.message = (
                    said + " " if said else ""
                ) + f"Which edge of the robot is it{why}? Click it on the white robot."
                return
            self._assign(edge, feats[j], "auto", said)

    def add_segment(self, seg_uv) -> None:
        """Both clicks of a segment (2, 2) at once (scripts), through ``click``."""
        click_segment(self, seg_uv)

    def assign_edge(self, shape: int, kind: str, index: int) -> None:
        """Say which feature of the robot the waiting edge is (scripts; the operator clicks it instead)."""
        with self.lock:
            self._check_open()
            edge = self._unassigned()
            if edge is None:
                raise WorkflowError("no clicked edge waits for its feature")
            try:
                feature = RobotFeature(edge.pose, int(shape), str(kind), int(index))
            except ValueError as exc:
                raise WorkflowError(str(exc)) from None
            if feature not in self._candidates(edge.pose)[0]:
                raise WorkflowError(f"the robot shows no {kind} {index} of shape {shape} at pose {edge.pose + 1}")
            self._assign(edge, feature, "hand", "")

    def _assign_at(self, edge: _Edge, p: np.ndarray) -> None:
        feats, proj = self._candidates(edge.pose)
        if not len(feats):
            raise WorkflowError("no edge of the robot is drawn here: Remove last, and click an edge it shows")
        d = _point_segment_distances(p, proj) / self.click_px_per_screen_px  # screen pixels
        j = int(np.argmin(d))
        if d[j] > PICK_RADIUS_SCREEN_PX:
            raise WorkflowError(
                f"no edge of the white robot within {PICK_RADIUS_SCREEN_PX:.0f} screen px of your click (the nearest "
                f"is {d[j]:.0f} px away): click on the white robot's edge that you clicked in the video"
            )
        self._assign(edge, feats[j], "hand", "")

    def _assign(self, edge: _Edge, feature: RobotFeature, how: str, said: str) -> None:
        edge.feature, edge.how = feature, how
        self.state = "click_edge"
        self._changed()
        name = feature.label(self._links())
        follows = self._follow_estimate()
        self.message = (
            (said + " " if said else "")
            + f"Edge {len(self.edges)} is the {name}"
            + (" (matched automatically: Remove last if it is not)." if how == "auto" else ".")
            + (" The white robot follows your edges." if follows else "")
        )

    def remove_last(self) -> None:
        with self.lock:
            self._check_open()
            if self.pending is not None:
                self.pending = None
                self.message = "The first point is dropped."
            elif self.edges:
                self.edges.pop()
                self.message = f"The last edge is removed: {len(self.edges)} left."
                self._follow_estimate()
            else:
                raise WorkflowError("there is no click to remove")
            self._changed()
            self.state = "click_edge" if self.tour.at is not None else "go"

    def remove_edge(self, i: int) -> None:
        """Forget edge ``i`` (from 0, in the order clicked), wherever it was clicked: one a wrong assignment or a
        wrong click put there, which the Solve's residuals point at."""
        with self.lock:
            self._check_open()
            if self.pending is not None or self._unassigned() is not None:
                raise WorkflowError("finish the edge under way first (or Remove last)")
            if not 0 <= int(i) < len(self.edges):
                raise WorkflowError(f"there is no edge {int(i) + 1}: choose one of the {len(self.edges)} in the list")
            e = self.edges.pop(int(i))
            self.message = (
                f"Edge {int(i) + 1} ({e.feature.label(self._links())}, pose {e.pose + 1}) is removed: "
                f"{len(self.edges)} left."
            )
            self._follow_estimate()
            self._changed()
            self.state = "click_edge" if self.tour.at is not None else "go"

    def edge(self, i: int) -> None:
        """The operator chose edge ``i`` in the Edge chooser (kept until the edges or the Solve change)."""
        with self.lock:
            self.edge_chosen = int(i)

    def choice_value(self, action: str) -> Any:
        """The Edge chooser shows the operator's choice, else the first listed (after a Solve the farthest off: a new
        operator's chooser still showed the first edge clicked, and Remove edge would have taken a good one)."""
        if action != "edge":
            return None
        values = [i for _, i in self.choices("edge")]
        return self.edge_chosen if self.edge_chosen in values else (values[0] if values else None)

    def choices(self, action: str) -> list[tuple[str, Any]]:
        """The Edge chooser: every clicked edge, the farthest off first after a Solve, else the newest first."""
        if action != "edge":
            return []
        with self.lock:
            links = self._links()
            # each assigned edge's residual after a Solve (by the edge: the fit's clicks are the assigned edges)
            res = {} if self.fit is None else dict(zip(map(id, self._assigned()), self.fit.result.click_residuals_px))
            out = []
            for i, e in enumerate(self.edges):
                if e.feature is not None:
                    r = res.get(id(e))
                    off = "" if r is None else f", {r:.1f} px off"
                    rank = i if r is None else r  # (residuals after a Solve, else the order clicked)
                    out.append((rank, f"{i + 1}: {e.feature.label(links)}, pose {e.pose + 1}{off}", i))
            return [(text, i) for _, text, i in sorted(out, key=lambda t: -t[0])]

    def refuse_snap(self) -> None:
        with self.lock:
            self._check_open()
            if not self.edges:
                raise WorkflowError("there is no clicked edge whose snap to refuse")
            edge = self.edges[-1]
            Snapper.refusable(edge.snap).refused = True
            edge.seg, edge.sigma_px = edge.snap.raw.copy(), self.sigma_px
            self._changed()
            self.message = "Snap refused: the last edge is used as you clicked it."

    def set_snap(self, on: bool = True) -> None:
        with self.lock:
            self.message = self.snapper.set(on)

    # ------------------------------------------------------------------ solving
    def _changed(self) -> None:
        self.fit, self.edge_chosen = None, None
        if self.state == "review":
            self.state = "click_edge" if self.tour.at is not None else "go"

    def _unassigned(self) -> _Edge | None:
        return next((e for e in self.edges if e.feature is None), None)

    def _assigned(self) -> list[_Edge]:
        return [e for e in self.edges if e.feature is not None]

    def _links(self) -> list[str]:
        return [link for link, _, _ in self.model.link_breps(self.tour.qs[0])]

    def _candidates(self, k: int, world: bool = False) -> tuple[list[RobotFeature], np.ndarray]:
        """The features of the robot at pose k seen at the estimate, not yet assigned there, and their pixels
        (F, 2, 2) through the camera (``world``: their segments in the world (F, 2, 3))."""
        cam = self.camera
        used = {e.feature for e in self.edges if e.feature is not None}
        feats, segs = [], []
        for f, seg, visible in features_at(self.model, self.tour.arrived[k], self.T_est, cam.center, config=k):
            if visible and f not in used and np.all(cam.depth(seg) > 0):
                feats.append(f)
                segs.append(seg if world else cam.project(seg))
        return feats, np.array(segs).reshape((-1, 2, 3) if world else (-1, 2, 2))

    def _problem(self) -> tuple[np.ndarray, list[BaseClick]]:
        """The poses' joints (K, n) as reported on arrival (poses not reached: their presets) and the clicks."""
        configs = np.array([self.tour.arrived.get(k, q) for k, q in enumerate(self.tour.qs)])
        clicks = [BaseClick(e.seg, e.feature, e.sigma_px, 0) for e in self._assigned()]
        return configs, clicks

    def _follow_estimate(self) -> bool:
        """Move the drawn estimate onto the clicks once they fix it well enough; True when it moved."""
        self.T_est, self.cov_est = self.T_start.copy(), self.cov_start
        configs, clicks = self._problem()
        fit = estimate_from_clicks(self.model, configs, clicks, self.camera, self.T_start)
        if fit is None:
            return False
        self.T_est, self.cov_est = fit.T_world_base, fit.cov
        return True

    def solve(self):
        """The base pose that every assigned edge of every pose fits (``refine_base``), with σ."""
        with self.lock:
            self._check_open()
            edges = self._assigned()
            poses = {e.pose for e in edges}
            if self.pending is not None or self._unassigned() is not None:
                raise WorkflowError("finish the edge under way first (or Remove last)")
            if len(edges) < MIN_EDGES or len(poses) < MIN_POSES:
                raise WorkflowError(
                    f"{len(edges)} edges at {len(poses)} pose(s): Solve needs {MIN_EDGES} edges or more at "
                    f"{MIN_POSES} poses or more (Next pose, G, then click its edges)"
                )
            configs, clicks = self._problem()
            camera, cov, T0 = self.camera, self.site.camera_cov(self.view), self.T_est.copy()
        try:
            fit = refine_base(self.model, configs, clicks, [camera], T0, camera_covs=[cov])
        except ValueError as exc:
            raise WorkflowError(f"Solve: {exc}") from None
        inside = self._inside(fit.T_world_base, dict(self.tour.arrived))
        with self.lock:
            self._check_open()
            if [e.feature for e in self._assigned()] != [c.feature for c in clicks]:
                raise WorkflowError("the clicks changed while solving: Solve again")
            self.inside = inside
            self.fit, self.T_est, self.cov_est, self.state = fit, fit.T_world_base.copy(), fit.cov, "review"
            self.edge_chosen = None  # the chooser shows the farthest off
            self.message = self._solved_text() + "."
            return fit

    def _inside(self, T_world_base: np.ndarray, qs: dict) -> list[str]:
        """What the robot, at the poses it was clicked at (``qs``: pose index → joints), would be inside through
        ``T_world_base``: a link more than INSIDE_MM deep in a database object, which the video showed it was not (a
        wrong edge pulled the base)."""
        from app.robot.collision import CollisionChecker

        checker = CollisionChecker(self.model, T_world_base)
        objects = [o for o in self.site.objects() if o.status != "stale"]
        checker.set_obstacles([(o.name, o.model, o.T_world_obj, 0.0) for o in objects])
        names, out = {o.name for o in objects}, []
        for k, q in sorted(qs.items()):
            for c in checker.check(q):
                if c.other in names and c.distance_m < -INSIDE_MM / 1000:
                    out.append(f"at pose {k + 1} its {c.link} {-1000 * c.distance_m:.0f} mm inside the {c.other}")
                    break
        return out

    def _moved(self) -> tuple[float, float]:
        """(degrees, mm) between the solved base and the database's."""
        deg, m = pose_error(self.fit.T_world_base, self.T_start)
        return deg, 1000 * m

    def _solved_text(self) -> str:
        f = self.fit
        deg, mm = self._moved()
        return (
            f"Solved the base from {len(f.result.kinds)} edges at {len({e.pose for e in self._assigned()})} poses: "
            f"RMS {f.rms_px:.2f} px, σ {1000 * f.std_position_m:.1f} mm and {np.degrees(f.std_angle_rad):.2f}°; "
            f"{mm:.1f} mm and {deg:.2f}° from the database's base"
        )

    def accept(self) -> None:
        """Store the solved base (one transaction): the robot is drawn, checked and moved through it."""
        with self.lock:
            self._check_open()
            if self.fit is None:
                raise WorkflowError("nothing to accept: Solve first")
            f = self.fit
            links = self._links()
            measurements = {
                "camera": self.view,
                "poses_q": [self.tour.arrived[k].tolist() for k in sorted(self.tour.arrived)],
                "edges": [
                    {
                        "pose": e.pose,
                        "feature": e.feature.label(links),
                        "assigned": e.how,
                        "uv": e.seg.tolist(),
                        "sigma_px": e.sigma_px,
                        "snap": None if e.snap is None else e.snap.record(),
                    }
                    for e in self._assigned()
                ],
                "frames": {str(k): fr.record() for k, fr in self.frames.items()},
                "cov_parts": {k: np.asarray(v).tolist() for k, v in f.result.cov_parts.items()},
                "from": np.asarray(self.T_start).tolist(),
            }
            self.site.set_robot_base(
                f.T_world_base,
                cov=f.cov,
                rms_px=f.rms_px,
                residuals_px=f.result.residuals_px,
                measurements=measurements,
                client=self.client,
            )
            deg, mm = self._moved()
            self.accepted, self.state = True, "accepted"
            self.message = (
                f"The robot's base is calibrated ({mm:.1f} mm and {deg:.2f}° from the database's, σ "
                f"{1000 * f.std_position_m:.1f} mm and {np.degrees(f.std_angle_rad):.2f}°): the robot is drawn, "
                "checked and moved through it."
            )

    # ------------------------------------------------------------------ the panel
    def _step(self) -> Step:
        if self.finished:
            return self._finished_step()
        moving = self._tour_step()
        if moving is not None:
            return moving
        t = self.tour
        has = {"cancel"} | ({"remove_last"} if self.edges or self.pending is not None else set())
        if self.edges and self.edges[-1].snap is not None and self.edges[-1].snap.applied:
            has.add("refuse_snap")
        edges, poses = self._assigned(), {e.pose for e in self._assigned()}
        busy = self.pending is not None or self._unassigned() is not None
        has = self._tour_controls(has, not busy)
        if self.edges and not busy:
            has |= {"edge", "remove_edge"}
        if not busy and len(edges) >= MIN_EDGES and len(poses) >= MIN_POSES:
            has.add("solve")
        if t.at is None:
            nxt = "" if t.next_index is None else f"{{go}} sends the robot to pose {t.next_index + 1} of {t.n}. "
            return Step("go", nxt + self._tally(edges, poses), frozenset(has), False)
        if self.pending is not None:
            return Step("click_edge_end", "Click a second point along the same edge of the robot.", frozenset(has))
        if self._unassigned() is not None:
            return Step(
                "assign_edge", "Which edge of the robot is it? Click that edge on the white robot.", frozenset(has)
            )
        if self.fit is not None:
            return Step(
                "review",
                f"{self._solved_text()}. {{accept}} stores it; more edges"
                + (" (or {go})" if "go" in has else "")
                + " and {solve} again improve it.",
                frozenset(has | {"accept", "solve"}),
            )
        return Step(
            "click_edge",
            f"Pose {t.at + 1} of {t.n}: click two points along a straight edge of the robot (a box's edge, a link's "
            "side) in the video. " + self._tally(edges, poses),
            frozenset(has),
        )

    def _tally(self, edges, poses) -> str:
        more = []
        if len(edges) < MIN_EDGES:
            more.append(f"{MIN_EDGES - len(edges)} more edge(s)")
        if len(poses) < MIN_POSES:
            more.append(f"edges at {MIN_POSES - len(poses)} more pose(s)")
        if more:
            return f"{len(edges)} edge(s) at {len(poses)} pose(s) so far; Solve needs {' and '.join(more)}."
        return f"{len(edges)} edges at {len(poses)} poses: {{solve}} fits the base to them."

    def marks(self) -> Marks:
        with self.lock:
            m = Marks()
            k = self.tour.at
            if k is None:
                return m
            cam = self.camera
            m.robot_ghost = self.model.link_breps(self.tour.arrived[k], self.T_est)
            here = [e for e in self.edges if e.pose == k]
            m.segments = np.array([e.seg for e in here]).reshape(-1, 2, 2)
            links = self._links()
            m.labels = [(e.seg.mean(axis=0) + [0.0, -8.0], e.feature.label(links) if e.feature else "?") for e in here]
            m.raw_segments, _, _, snap_labels = snap_marks([e.snap for e in here])
            m.labels += snap_labels
            if self.pending is not None:
                m.pending = self.pending.reshape(1, 2)
            # the white robot's edges the pose's clicked edges are assigned to, highlighted (an operator could not
            # tell which one an assignment took from its label alone)
            assigned = {e.feature for e in here if e.feature is not None}
            if assigned:
                seen = features_at(self.model, self.tour.arrived[k], self.T_est, cam.center, config=k)
                lines = [seg for f, seg, _ in seen if f in assigned and np.all(cam.depth(seg) > 0)]
                m.assigned_lines = cam.project(np.reshape(lines, (-1, 3))).reshape(-1, 2, 2)
            if self.fit is not None:
                m.residuals = self._residual_marks(here, cam)
            return m

    def _residual_marks(self, here: list[_Edge], cam) -> np.ndarray:
        """From each clicked pixel of the pose's edges to its foot on the feature's line at the solution."""
        out = []
        Tb = self.fit.T_world_base
        lines = {c.feature: ln for c, ln in zip(self._problem()[1], self.fit.lines_base)}
        for e in here:
            ln = lines.get(e.feature)
            if ln is None:
                continue
            a, b = cam.project(ln @ Tb[:3, :3].T + Tb[:3, 3])
            d = (b - a) / max(np.linalg.norm(b - a), 1e-9)
            for p in e.seg:
                out.append([p, a + ((p - a) @ d) * d])
        return np.array(out).reshape(-1, 2, 2)

    def summary(self) -> dict[str, Any]:
        with self.lock:
            edges = self._assigned()
            out: dict[str, Any] = {
                "poses": f"{len(self.tour.arrived)} of {self.tour.n} visited",
                "edges": len(edges),
            }
            snaps = [e.snap for e in self.edges if e.snap is not None]
            if snaps:
                out["snapped"] = f"{sum(s.applied for s in snaps)} of {len(snaps)} edges"
            if self.fit is not None:
                f = self.fit
                deg, mm = self._moved()
                out.update(
                    rms_px=f.rms_px,
                    std_position_mm=1000 * f.std_position_m,
                    std_angle_deg=float(np.degrees(f.std_angle_rad)),
                    from_database_mm=mm,
                    from_database_deg=deg,
                )
                res = f.result.click_residuals_px
                links = self._links()
                out["edges_fitted"] = [
                    {"edge": e.feature.label(links), "pose": e.pose + 1, "residual_px": float(r)}
                    for e, r in zip(edges, res)
                ]
            return out

    def weaknesses(self) -> list[str]:
        with self.lock:
            if self.fit is None:
                return []
            f = self.fit
            out = []
            sd_deg, sd_mm = float(np.degrees(f.std_angle_rad)), 1000 * f.std_position_m
            if sd_deg > WEAK_SIGMA_DEG or sd_mm > WEAK_SIGMA_MM:
                out.append(
                    sigma_over(sd_deg, sd_mm, WEAK_SIGMA_DEG, WEAK_SIGMA_MM) + ": click more edges, at more poses"
                )
            if self.inside:
                out.append(
                    "through this base the robot would be " + "; ".join(self.inside) + ", which the video does not "
                    "show: a wrong edge pulled it (the edges' residuals say which: Remove edge forgets one)"
                )
            links = self._links()
            for i, (e, r) in enumerate(zip(self._assigned(), f.result.click_residuals_px)):
                if r > 3 * max(e.sigma_px, 0.5):
                    out.append(
                        f"edge {i + 1} ({e.feature.label(links)}, pose {e.pose + 1}) is {r:.1f} px off (more than 3σ): "
                        "a wrong edge? (Remove edge forgets it)"
                    )
                out += weak_snaps([(f"edge {i + 1}", e.snap)])
            return out


def estimate_from_clicks(model, configs, clicks: list[BaseClick], camera, T_start: np.ndarray):
    """The base the assigned edges fix well enough to draw the robot at and match later edges against
    (``core.robot.calibration.BaseFit``, with its covariance), or None: fewer than ESTIMATE_FROM edges, no unique
    fit, an RMS above 3σ of the clicks, or σ above ESTIMATE_MAX_MM / ESTIMATE_MAX_DEG. Fitted from ``T_start``
    each time: a wrong edge removed leaves no trace."""
    if len(clicks) < ESTIMATE_FROM:
        return None
    try:
        fit = refine_base(model, configs, clicks, [camera], T_start)
    except ValueError:
        return None
    if fit.rms_px > 3 * max(max(c.sigma_px for c in clicks), 0.5):
        return None
    if 1000 * fit.std_position_m > ESTIMATE_MAX_MM or np.degrees(fit.std_angle_rad) > ESTIMATE_MAX_DEG:
        return None
    return fit


def _point_segment_distances(p: np.ndarray, segs: np.ndarray) -> np.ndarray:
    """Distances (F,) of pixel p (2,) to the finite segments (F, 2, 2)."""
    a, b = segs[:, 0], segs[:, 1]
    d = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-12), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - p, axis=1)
