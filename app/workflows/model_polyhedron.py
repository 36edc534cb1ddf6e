"""Model a polyhedron the operator names — a wedge (a ramp) or a square pyramid — from clicked sides
and range-finder patches (source paper §III: "boxes, polyhedra, cylinders, cones").

The operator names the shape when starting (the panel's Shape: "wedge", "pyramid"), and then, for
each visible face, as for a box (``ModelObject``): clicks its sides in the video (two clicks per
side, snapped to the image's edge), then ``measure()`` — the turret scans a patch of range points
inside the clicked outline; a click after that starts the next face. ``solve()``:

1. which face of the shape each measured face is: the measured face normals seen against the table
   (a wedge's slope is tilted, its back and ends vertical; a pyramid's sides all tilted) and their
   azimuths, which must differ as the shape's do (a turn about the table's normal fits them all),
   with the number of sides clicked (a wedge's end is a triangle);
2. which edge each clicked side is: around the face from the side that lies on the table (a face's
   sides in their order counter-clockwise seen from outside, when all are clicked) for a provisional
   model, then each side to the nearest edge of that face of the provisional model projected in the
   image (best one-to-one match per face); a side clicked on two faces is one edge;
3. the model by ``core.modeling.model_polyhedron``: every vertex the least-squares point of the
   measured face planes, the clicked sides' interpretation planes and the table through it; the
   hidden ones completed from the shape's hints (a wedge's ends are parallel, its back and ends
   vertical). When two readings of the faces fit (a lone face of a symmetric view), the one whose
   model best fits the clicks is kept.

The σ include the camera's and the turret's calibration shares (the model is rebuilt from the raw
beams through calibrations moved by their σ, as for boxes). The preview is a ghost with the shape's
named dimensions ± σ (a wedge: length, depth, height, slope; a pyramid: base sides, height, side
edge) and every edge's length; ``accept()`` adds the object (kind "polyhedron", status "modelled")
with its clicks, range points and the frame the clicks were made on, in one transaction.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from core.brep import BRep
from core.modeling.result import DIMENSION_WORDS
from core.rangefinder import beam_point_cov

from .base import CANCEL, Control, Ghost, Marks, Step, Workflow, WorkflowError, as_pixel
from .model_object import MAX_CLICK_RESIDUAL_PX, MIN_SEGMENT_PX, WEAK_SIGMA_MM, table_support
from .range_modelling import RangeModelling
from .snapping import SnapMixin, snap_marks, weak_snaps

__all__ = ["ModelPolyhedron", "PolyShape", "POLY_SHAPES"]

# A measured face is vertical (a wedge's back or end) when its normal is within this of horizontal.
VERTICAL_DEG = 12.0
# Readings of the faces whose azimuth misfit is within this of the best (rad², summed) are all solved.
FACE_COST_SLACK = 0.12
# A clicked side farther than this from every projected edge of its face (mean of its ends, px) is refused.
MAX_SIDE_DISTANCE_PX = 12.0


@dataclass(frozen=True)
class PolyShape:
    """A standard shape the operator can name.

    template : BRep of nominal proportions in its object frame (the support face on z = 0, z up);
        faces are vertex loops counter-clockwise seen from outside. Only its topology and the
        directions of its face normals (vertical or tilted, azimuth) are used.
    support_face : the face that lies on the table.
    parallel_faces, vertical_faces : ``model_polyhedron``'s completion hints.
    named : dimension name → the edge (i, j) whose length it is (plus "height", always given).
    face_words : what the operator calls each face (prompts).
    """

    name: str
    template: BRep
    support_face: int
    parallel_faces: tuple = ()
    vertical_faces: tuple = ()
    named: dict = field(default_factory=dict)
    face_words: tuple = ()

    @property
    def faces(self) -> list[tuple[int, ...]]:
        return [tuple(int(i) for i in f) for f in self.template.faces]

    def bottom_edge(self, f: int) -> int | None:
        """Index k of the side (loop[k], loop[k+1]) of face f that lies on the support face."""
        base = set(self.faces[self.support_face])
        loop = self.faces[f]
        for k, (a, b) in enumerate(zip(loop, loop[1:] + loop[:1])):
            if a in base and b in base:
                return k
        return None


def _wedge() -> PolyShape:
    # A right triangular prism lying on one rectangular face: the bottom 0-1-2-3, the slope rising
    # from the front edge 0-1 to the top edge 5-4 above the back edge 3-2, the vertical back, two
    # triangular ends (x = 0: 0-5-3; x = L: 1-2-4).
    L, W, H = 0.20, 0.12, 0.08
    V = np.array([[0, 0, 0], [L, 0, 0], [L, W, 0], [0, W, 0], [L, W, H], [0, W, H]], float) - [L / 2, W / 2, 0]
    faces = [(0, 3, 2, 1), (0, 1, 4, 5), (2, 3, 5, 4), (0, 5, 3), (1, 2, 4)]
    return PolyShape(
        "wedge",
        BRep.from_faces(V, faces),
        0,
        parallel_faces=((3, 4),),
        vertical_faces=(2, 3, 4),
        named={"length": (0, 1), "depth": (1, 2), "slope": (1, 4)},
        face_words=("bottom", "slope", "back", "end", "end"),
    )


def _pyramid() -> PolyShape:
    a = 0.08
    B = BRep.pyramid(np.array([[-a, -a], [a, -a], [a, a], [-a, a]]), np.array([0.0, 0.0, 0.07]))
    return PolyShape(
        "pyramid",
        B,
        0,
        named={"side_a": (0, 1), "side_b": (1, 2), "edge": (0, 4)},
        face_words=("base", "side", "side", "side", "side"),
    )


POLY_SHAPES: dict[str, PolyShape] = {s.name: s for s in (_wedge(), _pyramid())}


def _wrap(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _point_segment_px(p: np.ndarray, seg: np.ndarray) -> float:
    """Distance (px) of pixel p (2,) to the image segment seg (2, 2)."""
    d = seg[1] - seg[0]
    t = float(np.clip((p - seg[0]) @ d / max(float(d @ d), 1e-12), 0.0, 1.0))
    return float(np.linalg.norm(p - (seg[0] + t * d)))


def _merge_segments(segs: list[np.ndarray]) -> np.ndarray:
    """One image segment (2, 2) through the ends of several clicks of the same edge: the ends'
    best line, from its extreme projections."""
    if len(segs) == 1:
        return segs[0]
    P = np.concatenate(segs)
    c = P.mean(axis=0)
    u = np.linalg.svd(P - c)[2][0]
    s = (P - c) @ u
    return np.array([c + s.min() * u, c + s.max() * u])


@dataclass
class _FaceData:
    """One measured face, as the solver takes it: range points (N, 3) and covariances (N, 3, 3) in
    the world, the clicked sides (K, 2, 2) in pixels."""

    points: np.ndarray
    covs: np.ndarray
    segs: np.ndarray


class ModelPolyhedron(RangeModelling, SnapMixin, Workflow):
    name = "model_polyhedron"
    form = ("shape", "on_table")
    title = "Model polyhedron"
    actions = (
        "click",
        "add_segment",
        "remove_last",
        "measure",
        "next_face",
        "solve",
        "accept",
        "cancel",
        "refuse_snap",
        "set_snap",
    )
    controls = (
        Control(
            "measure",
            "Measure face",
            "M",
            kind="long",
            color="blue",
            hint="The turret scans range points inside the face's clicked sides",
        ),
        Control("solve", "Solve", "R", color="blue", hint="Build the model from the clicks and ranges"),
        Control("accept", "Accept", "enter", color="green", hint="Add the modelled object to the database"),
        Control(
            "refuse_snap", "Refuse snap", "U", hint="Use the last side as clicked, not moved onto the image's edge"
        ),
        Control("remove_last", "Remove last", "backspace", hint="Undo the last click, measurement or face"),
        CANCEL,
    )

    def __init__(
        self,
        site,
        client: str = "operator",
        view: str | None = None,
        shape: str = "wedge",
        object_name: str | None = None,
        spacing_px: float | None = None,
        snap: bool = True,
        on_table: bool = True,
    ):
        super().__init__(site, client, view)
        self._init_snap(snap)
        if shape not in POLY_SHAPES:
            raise WorkflowError(f"the polyhedron is one of {', '.join(POLY_SHAPES)}, not {shape!r}")
        if not on_table:
            raise WorkflowError(f"a {shape} is modelled lying on the table: tick Lies on the table")
        self.shape = shape
        self.poly = POLY_SHAPES[shape]
        self.spacing_px = spacing_px
        self.support = table_support(site)
        if self.support is None:
            raise WorkflowError(
                f"a {shape} is modelled on the table, and the database has no table: add the table first"
            )
        taken = {o.name for o in site.objects()}
        if object_name is None:
            i = 1
            while f"{shape}_{i}" in taken:
                i += 1
            object_name = f"{shape}_{i}"
        elif object_name in taken:
            raise WorkflowError(f"an object named {object_name!r} already exists; choose another name")
        self.object_name = object_name
        self.max_faces = len(self.poly.faces) - 1
        self.max_sides = max(len(f) for f in self.poly.faces)
        # One entry per face: {"segs", "snaps", "points", "covs", "scan", "good"} (as Model object's box faces).
        self.faces: list[dict[str, Any]] = [self._new_face()]
        self.pending: np.ndarray | None = None
        self.result = None
        self.assignment: list[dict] = []  # per measured face: {"face": topology face, "edges": [(i, j) per side]}
        self._init_acquisition()
        self.state = "click"

    # ------------------------------------------------------------------ clicks
    def _last_snap(self):
        face = self.faces[-1]
        if face["points"] is not None or not face["segs"]:
            return None, None  # a measured face's sides are fixed (Remove last first)
        i = len(face["segs"]) - 1
        return face["snaps"][i], lambda raw: face["segs"].__setitem__(i, raw)

    def _after_refuse(self) -> None:
        self.result = None

    def click(self, uv) -> None:
        """First or second end of a side of the current face; after Measure face, starts the next face."""
        p = as_pixel(uv)
        with self.lock:
            self._check_open()
            if self.pending is None:
                if self.faces[-1]["points"] is not None:
                    if len(self.faces) == self.max_faces:
                        raise WorkflowError(
                            f"a {self.shape} shows at most {self.max_faces} faces and "
                            f"{self.max_faces} are measured: Solve now."
                        )
                    self.faces.append(self._new_face())
                    self.result = None
                    self.message = f"Face {len(self.faces)} started: click two points on each of its sides."
                if len(self.faces[-1]["segs"]) == self.max_sides:
                    raise WorkflowError(
                        f"a face of a {self.shape} has at most {self.max_sides} sides: Measure face "
                        "next, or Remove last."
                    )
                self.pending = p
                return
            seg, snap = self._finish_segment(self.pending, p, MIN_SEGMENT_PX)
            self.pending = None
            self.faces[-1]["segs"].append(seg)
            self.faces[-1]["snaps"].append(snap)
            self.result = None
            self.message = self._snap_message(f"Side {len(self.faces[-1]['segs'])}", snap)

    def add_segment(self, seg_uv) -> None:
        """A clicked side (2, 2) at once (for scripts)."""
        self._click_segment(seg_uv)

    def remove_last(self) -> None:
        """Undo the last click, measurement or face."""
        with self.lock:
            self._check_open()
            if not self._has_something():
                raise WorkflowError("there is no click or measurement to remove")
            self.result = None
            face = self.faces[-1]
            if self.pending is not None:
                self.pending = None
            elif face["points"] is not None:
                face.update(points=None, covs=None, scan=None, good=None)
            elif face["segs"]:
                face["segs"].pop()
                face["snaps"].pop()
            else:
                self.faces.pop()

    def _has_something(self) -> bool:
        f0 = self.faces[0]
        return self.pending is not None or len(self.faces) > 1 or bool(f0["segs"]) or f0["points"] is not None

    def next_face(self) -> None:
        """The current face is done (sides clicked and measured); go on to the next one (a click does it too)."""
        with self.lock:
            self._check_open()
            if self.faces[-1]["points"] is None:
                raise WorkflowError("measure this face first (Measure face)")
            if len(self.faces) == self.max_faces:
                raise WorkflowError(f"a {self.shape} shows at most {self.max_faces} faces: Solve now")
            self.faces.append(self._new_face())

    # ------------------------------------------------------------------ measurement
    def measure(self):
        """Range points on the current face, inside its clicked outline (face patch scan)."""
        return self._measure_face()

    def _face_data(self, faces: list, T_world_turret: np.ndarray) -> list[_FaceData]:
        """The measured faces, their range points through ``T_world_turret`` from the raw beams."""
        out = []
        for f in faces:
            if f["points"] is None:
                continue
            scan, good = f["scan"], f["good"]
            X = scan.points(T_world_turret)[good]
            covs = beam_point_cov(
                T_world_turret, scan.pan_rad[good], scan.tilt_rad[good], scan.range_m[good], self._spec()
            )
            out.append(_FaceData(X, covs, np.array(f["segs"], float).reshape(-1, 2, 2)))
        return out

    # ------------------------------------------------------------------ solve
    def solve(self):
        """Identify the faces, assign the clicked sides to edges, build the model; its preview and
        dimensions ± σ are shown."""
        from core.modeling.uncertainty import with_calibration_uncertainty

        with self.lock:
            self._check_open()
            if self.pending is not None:
                raise WorkflowError("click the other end of the side under way first (or Remove last)")
            faces = [dict(f, segs=list(f["segs"])) for f in self.faces if f["points"] is not None]
            if not faces:
                raise WorkflowError("measure at least one face first (click its sides, then Measure face)")
            unmeasured = [i + 1 for i, f in enumerate(self.faces) if f["points"] is None and f["segs"]]
            if unmeasured:
                raise WorkflowError(
                    f"face {unmeasured[0]} has sides clicked but is not measured: Measure face, "
                    "or Remove last to drop its sides"
                )
            cam, T = self.camera, self.site.T_world_turret
            camera_cov, turret_cov = self.site.camera_cov(self.view), self.site.calibration_covs[1]
        # Outside the lock (the overlay keeps drawing): which face and edge is which is decided once,
        # on the nominal calibrations; the σ shares rebuild with that assignment.
        try:
            assignment, _ = self._assign(cam, self._face_data(faces, T))
            build = lambda c, Tt: self._build(c, self._face_data(faces, Tt), assignment)  # noqa: E731
            result = with_calibration_uncertainty(build, cam, T, camera_cov=camera_cov, turret_cov=turret_cov)
        except ValueError as exc:
            raise WorkflowError(f"cannot build the {self.shape}: {exc}") from None
        with self.lock:
            self._check_open()
            self.result = result
            self.assignment = assignment
            self.state = "review"
            parts = result.details.get("sigma_parts", {})
            self.message = self._dimension_text(result) + (
                f" (σ include the {' and '.join(k for k in parts if k != 'measurements')})" if parts else ""
            )
            return result

    def _face_readings(self, cam, data: list[_FaceData]) -> list[tuple[float, tuple[int, ...]]]:
        """Which topology face each measured face may be: [(misfit, faces)], best first.

        Each measured face's outward normal (towards the camera) against the table: vertical or
        tilted must match the shape's face, and the azimuths must differ as the shape's faces' do
        (one turn ψ about the table's normal fits them all; misfit = Σ (Δazimuth)² in rad²); a face
        with more sides clicked than the shape's face has is excluded, one with fewer costs a little."""
        s = self.support.n
        e1 = np.array([1.0, 0.0, 0.0]) - s[0] * s
        if np.linalg.norm(e1) < 1e-6:
            e1 = np.array([0.0, 1.0, 0.0]) - s[1] * s
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(s, e1)
        meas = []
        for fd in data:
            c = fd.points.mean(axis=0)
            n = np.linalg.svd(fd.points - c)[2][-1]
            if n @ (cam.center - c) < 0:
                n = -n
            meas.append((np.degrees(np.arcsin(np.clip(n @ s, -1, 1))), np.arctan2(n @ e2, n @ e1), len(fd.segs)))
        tn = self.poly.template.face_normals()
        cands = [f for f in range(len(self.poly.faces)) if f != self.poly.support_face]
        out = []
        for perm in itertools.permutations(cands, len(meas)):
            ok, dal, extra = True, [], 0.0
            for (elev, az, nsides), f in zip(meas, perm):
                vertical_t = abs(tn[f][2]) < np.sin(np.radians(VERTICAL_DEG))
                if (abs(elev) < VERTICAL_DEG) != vertical_t or nsides > len(self.poly.faces[f]):
                    ok = False
                    break
                dal.append(az - np.arctan2(tn[f][1], tn[f][0]))
                extra += 0.02 * (len(self.poly.faces[f]) - nsides)
            if not ok:
                continue
            psi = float(np.angle(np.mean(np.exp(1j * np.array(dal)))))
            out.append((float(np.sum(_wrap(np.array(dal) - psi) ** 2)) + extra, perm))
        out.sort(key=lambda x: x[0])
        return out

    def _assign(self, cam, data: list[_FaceData]) -> tuple[list[dict], Any]:
        """The faces' identities and each clicked side's edge: (per measured face {"face", "edges"},
        the model they give). ValueError in the operator's words when no reading works."""
        readings = self._face_readings(cam, data)
        if not readings:
            words = ", ".join(sorted(set(self.poly.face_words[1:])))
            raise ValueError(
                f"the measured faces do not fit a {self.shape} standing on the table (its faces: {words}); "
                "check the shape, or Remove last and measure the faces again"
            )
        best, best_err = None, None
        for cost, perm in readings:
            if cost > readings[0][0] + FACE_COST_SLACK:
                break
            try:
                edges = self._assign_sides(cam, data, perm)
                res = self._build(cam, data, [{"face": f, "edges": e} for f, e in zip(perm, edges)])
            except ValueError as exc:
                best_err = best_err or exc
                continue
            rms = (
                float(np.sqrt(np.mean(np.square(res.residuals["clicks_px"]))))
                if len(res.residuals["clicks_px"])
                else 0.0
            )
            if best is None or rms < best[0]:
                best = (rms, [{"face": f, "edges": e} for f, e in zip(perm, edges)], res)
        if best is None:
            raise best_err
        return best[1], best[2]

    def _assign_sides(self, cam, data: list[_FaceData], perm: tuple[int, ...]) -> list[list[tuple[int, int]]]:
        """Each clicked side's edge (i, j), per measured face of identity ``perm``.

        A provisional model from the faces whose sides are all clicked (in order around the face,
        counter-clockwise seen from outside, from the side on the table) — or, for a face with
        fewer, its side on the table alone — then each side to the nearest projected edge of its
        face (best one-to-one match)."""
        sup = self.support
        provisional: dict[tuple[int, int], list] = {}
        for fd, f in zip(data, perm):
            loop = self.poly.faces[f]
            c = fd.points.mean(axis=0)
            n = np.linalg.svd(fd.points - c)[2][-1]
            if n @ (cam.center - c) < 0:
                n = -n
            o, D = cam.rays(fd.segs.reshape(-1, 2))
            t = (n @ (c - o)) / (D @ n)
            E = (o + t[:, None] * D).reshape(-1, 2, 3)  # the sides' ends on the face's plane
            heights = np.max(E @ sup.n + sup.d, axis=1)
            kb = self.poly.bottom_edge(f)
            ib = int(np.argmin(heights))
            on_table = heights[ib] < 0.25 * max(float(np.ptp(E.reshape(-1, 3) @ sup.n)), 0.02)
            sides = list(zip(loop, loop[1:] + loop[:1]))
            if len(fd.segs) == len(loop) and kb is not None:
                M = E.mean(axis=1)
                u = M[0] - M.mean(axis=0)
                u -= (u @ n) * n
                u /= max(np.linalg.norm(u), 1e-12)
                ang = np.arctan2((M - M.mean(axis=0)) @ np.cross(n, u), (M - M.mean(axis=0)) @ u)
                order = list(np.argsort(ang))
                start = order.index(ib)
                for j in range(len(loop)):
                    a, b = sides[(kb + j) % len(loop)]
                    provisional.setdefault((min(a, b), max(a, b)), []).append(fd.segs[order[(start + j) % len(loop)]])
            elif kb is not None and on_table:
                a, b = sides[kb]
                provisional.setdefault((min(a, b), max(a, b)), []).append(fd.segs[ib])
        res = self._solve_model(cam, data, perm, {e: _merge_segments(s) for e, s in provisional.items()})
        Xw = res.vertices_world
        out = []
        for k, (fd, f) in enumerate(zip(data, perm)):
            loop = self.poly.faces[f]
            sides = [(min(a, b), max(a, b)) for a, b in zip(loop, loop[1:] + loop[:1])]
            proj = [cam.project(Xw[list(e)]) for e in sides]
            dist = np.array(
                [[0.5 * (_point_segment_px(s[0], p) + _point_segment_px(s[1], p)) for p in proj] for s in fd.segs]
            )
            choice = min(
                itertools.permutations(range(len(sides)), len(fd.segs)),
                key=lambda ch: sum(dist[i, j] for i, j in enumerate(ch)),
            )
            for i, j in enumerate(choice):
                if dist[i, j] > MAX_SIDE_DISTANCE_PX:
                    raise ValueError(
                        f"side {i + 1} of face {k + 1} is {dist[i, j]:.1f} px from every side of the "
                        f"{self.shape}'s {self.poly.face_words[f]} it was measured as: click it again "
                        "along the face's edge"
                    )
            out.append([sides[j] for j in choice])
        return out

    def _solve_model(self, cam, data: list[_FaceData], perm, edge_segments: dict):
        from core.modeling import model_polyhedron

        p = self.poly
        try:
            return model_polyhedron(
                cam,
                p.faces,
                face_points={f: fd.points for fd, f in zip(data, perm)},
                face_point_covs={f: fd.covs for fd, f in zip(data, perm)},
                edge_segments=edge_segments,
                support=self.support,
                support_faces=[p.support_face],
                parallel_faces=p.parallel_faces,
                vertical_faces=p.vertical_faces,
            )
        except ValueError as exc:
            if "not fixed" in str(exc) or "no vertex is fixed" in str(exc):
                raise ValueError(
                    f"the measured faces and clicked sides do not fix every corner of the {self.shape}: "
                    "click every side of each face, and measure another face if you see one"
                ) from None
            raise

    def _build(self, cam, data: list[_FaceData], assignment: list[dict]):
        """The model from the measured faces and the assigned sides (a side clicked on two faces is one
        edge); its named dimensions added to ``dimensions`` and ``sigmas``."""
        segs: dict[tuple[int, int], list] = {}
        for fd, a in zip(data, assignment):
            for seg, e in zip(fd.segs, a["edges"]):
                segs.setdefault(tuple(e), []).append(seg)
        res = self._solve_model(
            cam, data, tuple(a["face"] for a in assignment), {e: _merge_segments(s) for e, s in segs.items()}
        )
        dims, sig = {}, {}
        for name, (i, j) in self.poly.named.items():
            key = f"edge_{min(i, j)}_{max(i, j)}"
            dims[name], sig[name] = res.dimensions[key], res.sigmas[key]
        dims["height"], sig["height"] = res.dimensions["height"], res.sigmas["height"]
        dims.update({k: v for k, v in res.dimensions.items() if k not in dims})
        sig.update({k: v for k, v in res.sigmas.items() if k not in sig})
        return replace(res, dimensions=dims, sigmas=sig)

    def _dimension_text(self, r) -> str:
        keys = list(self.poly.named) + ["height"]
        return ", ".join(f"{k} = {100 * r.dimensions[k]:.2f} ± {100 * r.sigmas[k]:.2f} cm" for k in keys)

    # ------------------------------------------------------------------ accept
    def accept(self):
        """Add the modelled object to the database (one transaction, status "modelled")."""
        with self.lock:
            self._check_open()
            if self.result is None:
                raise WorkflowError("nothing to accept: Solve first")
            r = self.result
            measured = [f for f in self.faces if f["points"] is not None]
            clicks = {
                "shape": self.shape,
                "faces": [np.array(f["segs"]).reshape(-1, 2, 2) for f in measured],
                # each measured face's topology face and each clicked side's edge (vertex pair)
                "assignment": [
                    {"face": int(a["face"]), "edges": [list(map(int, e)) for e in a["edges"]]} for a in self.assignment
                ],
                "snaps": [[None if sn is None else sn.record() for sn in f["snaps"]] for f in measured],
                "frame": self.frame_record(),
            }
            measurements = {"faces": [f["points"] for f in measured]}
            return self._write_model(
                r,
                method=f"model {self.shape} ({r.method})",
                clicks=clicks,
                measurements=measurements,
                note=f"shape: {self.shape}, on the table",
                text=self._dimension_text(r),
            )

    # ------------------------------------------------------------------ display
    def _step(self) -> Step:
        done, base = self._common_step()
        if done is not None:
            return done
        if self.result is not None:
            return Step(
                "review",
                f"{self._dimension_text(self.result)}. " + "{accept} to add it, or add faces and {solve} again.",
                frozenset(base | {"solve", "accept"}),
            )
        if self.pending is not None:
            return Step("click_end", "Click the other end of that side.", frozenset(base))
        face = self.faces[-1]
        n = len(self.faces)
        measured = any(f["points"] is not None for f in self.faces)
        if face["points"] is not None:
            nxt = "" if n == self.max_faces else "Click the sides of another face for more accuracy, or "
            return Step(
                "face_measured",
                f"Face {n} of the {self.shape} measured. {nxt}" + "{solve}.",
                frozenset(base | {"solve"}),
            )
        solvable = {"solve"} if measured and not face["segs"] else set()
        tail = " Or {solve} with the faces measured." if solvable else ""
        if len(face["segs"]) < 2:
            return Step(
                "click_sides",
                f"Face {n} of the {self.shape}: click two points on each side of one visible "
                f"face (side {len(face['segs']) + 1}).{tail}",
                frozenset(base | solvable),
            )
        if self.site.devices is None:
            return Step(
                "sides_clicked",
                f"Face {n}: {len(face['segs'])} sides clicked. {self.site.no_devices('measure', sentence=True)}",
                frozenset(base),
            )
        return Step(
            "sides_clicked",
            f"Face {n}: click its other sides, or " + "{measure} (the turret scans inside them).",
            frozenset(base | {"measure"}),
        )

    def weaknesses(self) -> list[str]:
        with self.lock:
            r = self.result
            if r is None:
                return []
            out = [
                f"the {DIMENSION_WORDS.get(k, k.replace('_', ' '))} is uncertain: σ {1000 * v:.1f} mm (more than "
                f"{WEAK_SIGMA_MM:.0f} mm)"
                for k, v in r.sigmas.items()
                if np.isfinite(v) and 1000 * v > WEAK_SIGMA_MM
            ]
            res = np.abs(np.asarray(r.residuals.get("clicks_px", [])))
            if len(res) and res.max() > MAX_CLICK_RESIDUAL_PX:
                out.append(
                    f"a clicked side is {res.max():.1f} px from the model's edge (more than "
                    f"{MAX_CLICK_RESIDUAL_PX:.0f} px)"
                )
            snaps = [sn for f in self.faces for sn in f["snaps"]]
            out += weak_snaps(("a click", sn) for sn in snaps)
            if sum(f["points"] is not None for f in self.faces) == 1:
                out.append(
                    f"one face measured: the hidden corners rest on the clicks and the {self.shape}'s hints "
                    "(measure a second face)"
                )
        return out + self._overlaps(r)

    def marks(self) -> Marks:
        with self.lock:
            m = Marks()
            segs = [s for f in self.faces for s in f["segs"]]
            if segs:
                m.segments = np.array(segs)
            if self.pending is not None:
                m.pending = self.pending.reshape(1, 2)
            m.raw_segments, _, _, m.labels = snap_marks([sn for f in self.faces for sn in f["snaps"]])
            cam = self.camera
            pts = [f["points"] for f in self.faces if f["points"] is not None]
            if pts:
                X = np.concatenate(pts)
                X = X[cam.depth(X) > 0]
                m.points = cam.project(X) if len(X) else np.zeros((0, 2))
            live = self._live_points()
            live = live[cam.depth(live) > 0] if len(live) else live
            m.live_points = cam.project(live) if len(live) else np.zeros((0, 2))
            if self.result is not None:
                r = self.result
                m.ghosts = [Ghost(r.model, r.T_world_obj, self.object_name, chosen=True)]
                top = r.vertices_world[int(np.argmax(r.vertices_world @ self.support.n))]
                if cam.depth(top) > 0:
                    m.labels = [(cam.project(top) - [0, 14], self._dimension_text(r))]
            return m

    def summary(self) -> dict[str, Any]:
        with self.lock:
            out: dict[str, Any] = {"name": self.object_name, "shape": self.shape, "hints": "on the table"}
            out["faces"] = [
                {"face": i + 1, "sides": len(f["segs"]), "points": 0 if f["points"] is None else len(f["points"])}
                for i, f in enumerate(self.faces)
            ]
            if self.result is not None:
                r = self.result
                out["method"] = r.method
                words = self.poly.face_words
                out["faces"] = [
                    dict(row, seen_as=words[a["face"]])
                    for row, a in zip(
                        [row for row, f in zip(out["faces"], self.faces) if f["points"] is not None], self.assignment
                    )
                ]
                parts = r.details.get("sigma_parts", {})
                short = {
                    "measurements": "σ clicks+ranges (cm)",
                    "camera calibration": "σ camera (cm)",
                    "turret calibration": "σ turret (cm)",
                }
                out["dimensions"] = [
                    {
                        "dimension": k,
                        "value_cm": 100 * v,
                        "sigma_cm": 100 * r.sigmas.get(k, float("nan")),
                        **{short.get(src, src): 100 * p.get(k, float("nan")) for src, p in parts.items()},
                    }
                    for k, v in r.dimensions.items()
                ]
            return out
