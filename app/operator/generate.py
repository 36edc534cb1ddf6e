"""Generate a scene's operator script from its ground truth, as a careful human would click it.

For each workflow the true features are projected through the scene's true camera at the video
time of the action, and each click gets human-like noise: an isotropic Gaussian of σ
``click_sigma_px`` (1 px by default, seeded). Clicks on a straight edge land anywhere along the
part of the edge that is visible (occlusions by other bodies are ray cast exactly), never at its
vertices: the first click in the 10–40 % stretch of the visible run, the second in 60–90 %.
A cylinder's silhouettes are clicked at their ends (their only cue to the height).

The session it records (docs/operator-script.md), in the actions of the workflow layer
(app/workflows), so that the demo replays it call for call:

1. ``calibrate_camera`` — every visible vertex of the known bodies (the table's and the known
   objects' corners): ``choose_vertex`` then ``click`` on its image; ``solve``; ``accept``.
2. ``calibrate_turret`` — points of the known bodies' faces that the turret sees square enough
   (face centres; on the table also points half-way to its corners), faces of different
   orientations first: ``choose_point``, ``measure`` (the turret aims with its current
   calibration and fires); ``solve``; ``accept``.
3. ``model_object`` — each unknown body: a box face by face (two ``click`` s per visible side,
   ``measure`` — the turret scans a patch inside the clicked outline — and ``next_face``), a
   cylinder or cone by its two silhouettes, each clicked at its ends, bottom first (the height
   comes from them), and ``scan`` (two horizontal profiles); ``solve``; ``accept``.
4. ``update_pose`` — after each motion of a known body, once it is still again: two ``click`` s
   and ``assign_edge`` per edge (the first three form a non-degenerate P3L triple: non-parallel,
   not meeting in one vertex); after a large motion (beyond the small-motion method's validity,
   18° or 5 cm, paper §IV.3) ``solve`` (the three-line solver, best candidate pre-selected) then
   ``refine``; after a small one ``refine`` alone (from the database pose); ``accept``.

Steps 1–3 happen while every known body is still (before the first motion); each update in the
still window after its motion. Actions are ``dt_s`` apart in video time.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from itertools import combinations

import numpy as np

from app.render.raycast import SceneCaster
from app.scene import Body, Scene
from core.rangefinder import aim
from core.transforms import invert_T, pose_error, transform_points

from .script import Action, OperatorScript

__all__ = ["ScriptOptions", "generate_script", "still_windows"]


@dataclass(frozen=True)
class ScriptOptions:
    """Knobs of the generated session (defaults: the workcell's recorded script)."""

    seed: int = 8
    click_sigma_px: float = 1.0
    dt_s: float = 0.06
    lead_s: float = 0.3
    turret_points: int = 8
    pose_edges: int = 9
    min_edge_px: float = 15.0
    max_incidence_deg: float = 75.0
    large_motion_deg: float = 18.0
    large_motion_m: float = 0.05

    def replace(self, **changes) -> ScriptOptions:
        return dataclasses.replace(self, **changes)


def still_windows(body: Body, duration_s: float) -> list[tuple[float, float]]:
    """Intervals [t0, t1] (seconds) during which ``body`` does not move, in time order."""
    keys = [(0.0, body.T_world_obj)] + list(body.motion)
    times = sorted({0.0, duration_s} | {t for t, _ in keys if t < duration_s})
    out: list[tuple[float, float]] = []
    for a, b in zip(times, times[1:]):
        if body.is_static(a, b):
            if out and abs(out[-1][1] - a) < 1e-12:
                out[-1] = (out[-1][0], b)
            else:
                out.append((a, b))
    return out


def _round(x, nd: int) -> list[float]:
    return [round(float(v), nd) for v in np.asarray(x, dtype=float).ravel()]


class _Generator:
    def __init__(self, scene: Scene, options: ScriptOptions):
        self.scene = scene
        self.o = options
        self.cam = scene.camera
        self.rng = np.random.default_rng(options.seed)
        self.actions: list[Action] = []
        self.t = 0.0
        self._casters = None
        self.index = {b.name: i for i, b in enumerate(scene.bodies)}

    # ------------------------------------------------------------------ basics
    def caster(self, t_s: float) -> SceneCaster:
        c = SceneCaster.for_scene(self.scene, t_s, self._casters)
        self._casters = c.casters
        return c

    def emit(self, workflow: str, action: str, truth: dict | None = None, **args) -> None:
        self.actions.append(Action(round(self.t, 3), workflow, action, args, truth))
        self.t += self.o.dt_s

    def noisy(self, uv_true: np.ndarray) -> list[float]:
        return _round(np.asarray(uv_true) + self.rng.normal(0.0, self.o.click_sigma_px, 2), 3)

    def visible_run(self, caster: SceneCaster, body: int, A: np.ndarray, B: np.ndarray, n: int = 80):
        """Longest stretch [a, b] (fractions of A→B) seen by the camera, or None."""
        s = (np.arange(n) + 0.5) / n
        P = A + s[:, None] * (B - A)
        uv = self.cam.project(P)
        ok = self.cam.in_image(uv, margin_px=3.0) & (self.cam.depth(P) > 0)
        ok &= ~caster.occluded(self.cam.center, P, body=body, tol_m=1e-4)
        best, start = None, None
        for i, v in enumerate(np.append(ok, False)):
            if v and start is None:
                start = i
            elif not v and start is not None:
                if best is None or i - start > best[1] - best[0]:
                    best = (start, i)
                start = None
        if best is None:
            return None
        a, b = best[0] / n, best[1] / n
        length_px = float(np.linalg.norm(self.cam.project(A + b * (B - A)) - self.cam.project(A + a * (B - A))))
        return (a, b) if length_px >= self.o.min_edge_px else None

    def click_edge(self, workflow: str, A: np.ndarray, B: np.ndarray, run: tuple[float, float], truth: dict) -> None:
        """Two clicks along the visible run of the 3D segment A→B (world), in either order."""
        a, b = run
        L = b - a
        fr = [a + L * self.rng.uniform(0.1, 0.4), a + L * self.rng.uniform(0.6, 0.9)]
        if self.rng.random() < 0.5:
            fr.reverse()
        for f in fr:
            X = A + f * (B - A)
            uv_true = self.cam.project(X)
            self.emit(
                workflow, "click", dict(truth, X_world=_round(X, 6), uv_true=_round(uv_true, 4)), uv=self.noisy(uv_true)
            )

    def facing(self, n_world: np.ndarray, X: np.ndarray, eye: np.ndarray, max_deg: float = 89.0) -> bool:
        v = eye - X
        return bool(n_world @ v > np.cos(np.radians(max_deg)) * np.linalg.norm(v))

    # ------------------------------------------------------------------ workflows
    def calibrate_camera(self) -> None:
        caster = self.caster(self.t)
        wf = "calibrate_camera"
        self.emit(wf, "start")
        c = self.cam.center
        for body in self.scene.known:
            bi = self.index[body.name]
            T = body.pose_at(self.t)
            V = transform_points(T, body.model.vertices) if len(body.model.vertices) else np.zeros((0, 3))
            normals = body.model.face_normals() @ T[:3, :3].T if body.model.faces else np.zeros((0, 3))
            for k, X in enumerate(V):
                faces = [f for f, loop in enumerate(body.model.faces) if k in loop]
                if faces and not any(self.facing(normals[f], X, c) for f in faces):
                    continue
                uv = self.cam.project(X)
                if (
                    not self.cam.in_image(uv[None], margin_px=5.0)[0]
                    or caster.occluded(c, X[None], body=bi, tol_m=1e-4)[0]
                ):
                    continue
                self.emit(wf, "choose_vertex", {"X_world": _round(X, 6)}, name=body.name, index=int(k))
                self.emit(wf, "click", {"X_world": _round(X, 6), "uv_true": _round(uv, 4)}, uv=self.noisy(uv))
        self.emit(wf, "solve", {"C": np.round(self.cam.C, 9).tolist()})
        self.emit(wf, "accept")

    def _turret_candidates(self, caster: SceneCaster) -> list[tuple[str, np.ndarray, np.ndarray]]:
        """Known surface points the camera and the turret both see, the face square enough to the
        beam, within range and limits: (label, X_world, normal_world). Each face's centre, and on
        large faces (the table's) points half-way from the centre to each corner."""
        T_wt = self.scene.turret.T_world_turret
        eye_t, eye_c = T_wt[:3, 3], self.cam.center
        spec = self.scene.rangefinder
        out = []
        for body in self.scene.known:
            if not body.model.faces:
                continue
            bi = self.index[body.name]
            T = body.pose_at(self.t)
            normals = body.model.face_normals() @ T[:3, :3].T
            for f, loop in enumerate(body.model.faces):
                V = transform_points(T, body.model.vertices[list(loop)])
                ctr = V.mean(axis=0)
                n = normals[f]
                if not (self.facing(n, ctr, eye_t, self.o.max_incidence_deg) and self.facing(n, ctr, eye_c)):
                    continue
                inset = [ctr + 0.5 * (v - ctr) for v in V] if np.linalg.norm(np.ptp(V, axis=0)) > 0.5 else []
                for j, X in enumerate([ctr] + inset):
                    if not self.cam.in_image(self.cam.project(X)[None], margin_px=10.0)[0]:
                        continue
                    if (
                        caster.occluded(eye_t, X[None], body=bi, tol_m=1e-4)[0]
                        or caster.occluded(eye_c, X[None], body=bi, tol_m=1e-4)[0]
                    ):
                        continue
                    pan, tilt, rho = aim(T_wt, X)
                    if not (spec.min_range_m + 0.05 <= rho <= spec.max_range_m - 0.05):
                        continue
                    if not self.scene.turret.within_limits(float(pan), float(tilt)):
                        continue
                    out.append((f"{body.name} face {f} " + ("centre" if j == 0 else f"inset {j}"), X, n))
        return out

    def calibrate_turret(self) -> None:
        caster = self.caster(self.t)
        cands = self._turret_candidates(caster)
        N = np.array([n for _, _, n in cands]).reshape(-1, 3)
        orientations = len({tuple(np.round(n, 3)) for n in N})
        if len(cands) < 3 or orientations < 3:
            raise ValueError(
                f"the turret reaches {len(cands)} known face centres of {orientations} orientations; "
                "its calibration needs faces of 3 orientations"
            )
        # Faces of the most different orientations first (they fix the pose), then spread in space.
        P = np.array([X for _, X, _ in cands])
        chosen = [int(np.argmax(N[:, 2]))]
        while len(chosen) < min(self.o.turret_points, len(cands)):
            angle = np.min(np.arccos(np.clip(N @ N[chosen].T, -1, 1)), axis=1)
            dist = np.min(np.linalg.norm(P[:, None, :] - P[chosen][None, :, :], axis=2), axis=1)
            score = np.where(angle > 0.1, 10.0 + angle, 0.0) + dist
            score[chosen] = -1.0
            chosen.append(int(np.argmax(score)))
        wf = "calibrate_turret"
        step = self.scene.turret.step_rad
        T_wt = self.scene.turret.T_world_turret
        self.emit(wf, "start", shots=3)
        for i in chosen:
            label, X, n = cands[i]
            pan, tilt, rho = aim(T_wt, X)
            truth = {
                "X_world": _round(X, 6),
                "normal_world": _round(n, 9),
                "pan_steps_exact": round(float(pan) / step, 3),
                "tilt_steps_exact": round(float(tilt) / step, 3),
                "range_m_exact": round(float(rho), 6),
            }
            self.emit(wf, "choose_point", truth, X_world=_round(X, 6), label=label)
            self.emit(wf, "measure", truth)
        self.emit(wf, "solve", {"T_world_turret": np.round(T_wt, 9).tolist()})
        self.emit(wf, "accept")

    def _start_model(self, body: Body, shape: str, truth: dict) -> None:
        self.emit("model_object", "start", truth, object_name=body.name, shape=shape, vertical=True, on_table=True)

    def model_box(self, body: Body) -> None:
        caster = self.caster(self.t)
        bi = self.index[body.name]
        T = body.pose_at(self.t)
        c = self.cam.center
        model = body.model
        normals = model.face_normals() @ T[:3, :3].T
        wf = "model_object"
        truth = {"model": model.to_dict(), "T_world_obj": np.round(T, 9).tolist()}
        self._start_model(body, "box", truth)
        faces = []
        for f, loop in enumerate(model.faces):
            V = transform_points(T, model.vertices[list(loop)])
            if normals[f][2] < -0.5 or not self.facing(normals[f], V.mean(axis=0), c, 80.0):
                continue
            faces.append((0 if normals[f][2] > 0.9 else 1, float(self.cam.project(V.mean(axis=0))[0]), f))
        faces.sort()
        if len(faces) > 3:
            raise ValueError(f"{body.name}: {len(faces)} faces face the camera; a box shows at most 3")
        for i, (_, _, f) in enumerate(faces):
            loop = list(model.faces[f])
            V = transform_points(T, model.vertices[loop])
            for a, b in zip(range(len(loop)), list(range(1, len(loop))) + [0]):
                run = self.visible_run(caster, bi, V[a], V[b])
                if run is None:
                    continue
                k = _edge_index(model, loop[a], loop[b])
                self.click_edge(wf, V[a], V[b], run, {"body": body.name, "face": f, "edge": k})
            n = normals[f]
            self.emit(wf, "measure", {"face": f, "plane": _round(np.append(n, -n @ V[0]), 9)})
            if i + 1 < len(faces):
                self.emit(wf, "next_face")
        self.emit(wf, "solve")
        self.emit(wf, "accept", truth)

    def model_revolution(self, body: Body) -> None:
        self.caster(self.t)  # the scene's ray casters at this time, kept for the steps that follow
        bi = self.index[body.name]
        T = body.pose_at(self.t)
        s = body.model.solids[0]
        c_obj = transform_points(invert_T(T), self.cam.center[None])[0]
        sil = s.silhouette(c_obj)
        if len(sil) != 2:
            raise ValueError(f"{body.name}: the camera sees no silhouette of this solid")
        sil_w = transform_points(T, sil.reshape(-1, 3)).reshape(2, 2, 3)
        order = np.argsort([self.cam.project(seg.mean(axis=0))[0] for seg in sil_w])
        wf = "model_object"
        truth = {
            "model": body.model.to_dict(),
            "T_world_obj": np.round(T, 9).tolist(),
            "axis_world": _round(transform_points(T, np.array([s.p0, s.p1])), 6),
            "radius_m": [s.r0, s.r1],
        }
        self._start_model(body, "cylinder" if s.is_cylinder else "cone", truth)
        for i in order:
            # A silhouette is clicked at its two ends, the bottom one first: the workflow takes the
            # solid's height from them (a silhouette has no vertex to click beside).
            ends = sil_w[i]
            if self.cam.project(ends[0])[1] < self.cam.project(ends[1])[1]:
                ends = ends[::-1]
            visible = ~self.caster(self.t).occluded(self.cam.center, ends, body=bi, tol_m=1e-4)
            if not visible.all():
                raise ValueError(f"{body.name}: an end of silhouette {i} is hidden")
            for X in ends:
                uv = self.cam.project(X)
                truth = {"body": body.name, "silhouette": int(i), "X_world": _round(X, 6), "uv_true": _round(uv, 4)}
                self.emit(wf, "click", truth, uv=self.noisy(uv))
        self.emit(wf, "scan")
        self.emit(wf, "solve")
        self.emit(wf, "accept", truth)

    def update_pose(self, body: Body, T_before: np.ndarray) -> None:
        caster = self.caster(self.t)
        bi = self.index[body.name]
        T = body.pose_at(self.t)
        rot_deg, trans_m = pose_error(T, T_before)
        method = "large" if (rot_deg > self.o.large_motion_deg or trans_m > self.o.large_motion_m) else "small"
        wire = body.model.wireframe(self.cam.center, T)
        edges = []
        for k in range(len(body.model.edges)):
            if not wire.visible[k]:
                continue
            A, B = body.model.edge_segments(T)[k]
            run = self.visible_run(caster, bi, A, B)
            if run is None:
                continue
            length = float(
                np.linalg.norm(self.cam.project(A + run[1] * (B - A)) - self.cam.project(A + run[0] * (B - A)))
            )
            edges.append((length, k, A, B, run))
        edges.sort(key=lambda e: -e[0])
        triple = _p3l_triple(body, [e[1] for e in edges])
        if triple is None:
            raise ValueError(
                f"{body.name} at t = {self.t:.2f} s: no three visible edges form a non-degenerate P3L triple"
            )
        rest = [e for e in edges if e[1] not in triple]
        chosen = [e for k in triple for e in edges if e[1] == k] + rest[: max(0, self.o.pose_edges - 3)]
        wf = "update_pose"
        truth = {
            "T_world_obj": np.round(T, 9).tolist(),
            "T_before": np.round(T_before, 9).tolist(),
            "motion_deg": round(rot_deg, 4),
            "motion_m": round(trans_m, 6),
            "motion": method,
        }
        self.emit(wf, "start", truth, object_name=body.name)
        for _, k, A, B, run in chosen:
            self.click_edge(wf, A, B, run, {"body": body.name, "edge": int(k)})
            self.emit(wf, "assign_edge", {"body": body.name, "edge": int(k)}, edge=int(k))
        if method == "large":
            self.emit(wf, "solve", truth)
        self.emit(wf, "refine", truth)
        self.emit(wf, "accept", truth)


def _edge_index(model, a: int, b: int) -> int:
    E = model.edges
    hit = np.flatnonzero(((E[:, 0] == a) & (E[:, 1] == b)) | ((E[:, 0] == b) & (E[:, 1] == a)))
    assert len(hit) == 1, (a, b)
    return int(hit[0])


def _p3l_triple(body: Body, order: list[int]) -> tuple[int, int, int] | None:
    """The first triple (in ``order``, longest first) of pairwise non-parallel edges that do not
    all meet in one vertex."""
    E = body.model.edges
    D = body.model.vertices[E[:, 1]] - body.model.vertices[E[:, 0]]
    D = D / np.linalg.norm(D, axis=1, keepdims=True)
    for tri in combinations(order[:10], 3):
        if any(abs(D[i] @ D[j]) > 0.95 for i, j in combinations(tri, 2)):
            continue
        if set(E[tri[0]]) & set(E[tri[1]]) & set(E[tri[2]]):
            continue
        return tri
    return None


def generate_script(scene: Scene, options: ScriptOptions = ScriptOptions()) -> OperatorScript:
    """The recorded session of ``scene`` (see the module docstring)."""
    if scene.video is None:
        raise ValueError(f"scene {scene.name!r} has no video: the script's times are video times")
    g = _Generator(scene, options)
    duration = scene.video.duration_s
    movers = [b for b in scene.known if b.moves]
    first_move = min((still_windows(b, duration)[0][1] for b in movers), default=duration)
    g.t = options.lead_s
    g.calibrate_camera()
    g.calibrate_turret()
    for body in scene.unknown:
        if body.model.faces and body.kind == "box" and len(body.model.faces) == 6:
            g.model_box(body)
        elif body.model.solids:
            g.model_revolution(body)
        else:
            raise ValueError(
                f"{body.name}: the modelling workflow knows boxes, cylinders and cones, not this {body.kind}"
            )
    if g.t > first_move:
        raise ValueError(
            f"the calibration and modelling clicks need {g.t:.1f} s of still video but the first motion starts at "
            f"{first_move:.1f} s: lengthen the first still window or lower dt_s"
        )
    updates = []
    for body in movers:
        windows = still_windows(body, duration)
        for prev, cur in zip(windows, windows[1:]):
            updates.append((cur[0], body, body.pose_at(prev[0])))
    for start, body, T_before in sorted(updates, key=lambda u: u[0]):
        g.t = max(g.t, start + options.lead_s)
        g.update_pose(body, T_before)
        window_end = next(w[1] for w in still_windows(body, duration) if w[0] <= start < w[1])
        if g.t > window_end:
            raise ValueError(
                f"{body.name}: the update after the motion ending at {start:.1f} s needs until {g.t:.1f} s, "
                f"but the body moves again at {window_end:.1f} s"
            )
    generator = dataclasses.asdict(options)
    generator["tool"] = "mcit script (app/operator/generate.py)"
    description = (
        f"Recorded session on scene {scene.name!r}: calibrate the camera and the turret, model "
        f"{', '.join(b.name for b in scene.unknown) or 'no unknown object'}, update "
        f"{', '.join(b.name for b in movers) or 'no moving object'} after each motion. Clicks carry Gaussian noise of "
        f"σ = {options.click_sigma_px:g} px (seed {options.seed}); 'truth' holds the noise-free values."
    )
    return OperatorScript(scene.name, tuple(g.actions), description, generator)
