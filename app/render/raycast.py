"""Exact ray casting of a scene's bodies, for the renderer and for visibility questions.

Each body's B-Rep is cast analytically, in its own frame, part by part:

* a convex polyhedron (every vertex on the inner side of every face plane; boxes, prisms,
  pyramids) by clipping the ray against its face planes (Kay–Kajiya slabs generalised);
* a solid of revolution (cylinder, cone, frustum) by the quadric of its lateral surface and the
  discs of its caps, so silhouettes are exact rather than tessellated;
* any other faced model by its triangles (Möller–Trumbore), all triangles at once.

A ray from inside a body meets its surface on the way out (the exit face), as a mesh's would.
This is the one ray caster of mcit: the renderer, the range-finder emulator (``BeamCaster``: one
beam against a scene's true bodies at their poses of a given time) and designation
(``app.workflows.Site.raycast``: a ray against the database's objects) all use it.

Rays are ``X = origin + t · d`` with d of any length; ``t`` is returned in those units. With the
camera's unnormalised ray directions ``d = M⁻¹ (u, v, 1)`` (C = [M | p₄], normalised), t is the
depth s of the hit (metres along the optical axis). Misses have t = +inf, body = −1.

Face labels: polyhedral faces keep their B-Rep face index; a solid of revolution k of the model
takes labels ``LABEL_SOLID + 3k`` (lateral), ``+1`` (cap at p0), ``+2`` (cap at p1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.brep import BRep, Revolution

__all__ = ["Hits", "BodyCaster", "SceneCaster", "BeamCaster", "LABEL_SOLID"]

LABEL_SOLID = 1000
_EPS = 1e-12


@dataclass(frozen=True)
class Hits:
    """Nearest hits of N rays.

    t : array, shape (N,), ray parameter (inf for a miss). body : array, shape (N,), int, index of
    the body hit (−1 for a miss). face : array, shape (N,), int, face label within that body (−1).
    normal : array, shape (N, 3), outward unit normal at the hit, world frame (0 for a miss).
    X_obj : array, shape (N, 3), the hit point in the hit body's frame (metres; 0 for a miss).
    """

    t: np.ndarray
    body: np.ndarray
    face: np.ndarray
    normal: np.ndarray
    X_obj: np.ndarray


def _is_convex(model: BRep, normals: np.ndarray, offsets: np.ndarray) -> bool:
    scale = max(float(np.ptp(model.vertices, axis=0).max()), 1e-9)
    return bool(np.all(model.vertices @ normals.T + offsets <= 1e-9 * scale))


class BodyCaster:
    """Ray caster of one B-Rep model in its own frame (see the module docstring)."""

    def __init__(self, model: BRep):
        self.model = model
        self.solids: tuple[Revolution, ...] = tuple(model.solids)
        self.planes_n = np.zeros((0, 3))
        self.planes_d = np.zeros(0)
        self.triangles = np.zeros((0, 3, 3))
        self.triangle_face = np.zeros(0, dtype=np.int64)
        if model.faces:
            n = model.face_normals()
            d = -np.einsum("ij,ij->i", n, model.face_centroids())
            if _is_convex(model, n, d):
                self.planes_n, self.planes_d = n, d
            else:
                tris, owner = [], []
                for k, f in enumerate(model.faces):
                    for i in range(1, len(f) - 1):
                        tris.append(model.vertices[[f[0], f[i], f[i + 1]]])
                        owner.append(k)
                self.triangles = np.array(tris)
                self.triangle_face = np.array(owner, dtype=np.int64)
        pts = [model.vertices] + [np.vstack([s.rim(0, 16), s.rim(1, 16)]) for s in self.solids]
        P = np.vstack([p for p in pts if len(p)]) if any(len(p) for p in pts) else np.zeros((1, 3))
        self.center = 0.5 * (P.min(axis=0) + P.max(axis=0))
        # Rims sampled at 16 points lie inside the true circle's bounding radius by < 2 %: pad.
        self.radius = float(np.linalg.norm(P - self.center, axis=1).max()) * 1.03 + 1e-9
        self.has_surface = bool(len(self.planes_n) or len(self.triangles) or self.solids)

    # ---------------------------------------------------------------- parts
    def _convex(self, o: np.ndarray, d: np.ndarray):
        num = -(self.planes_n @ o + self.planes_d)  # (F,): n·(o + t d) + c ≤ 0  ⇔  t·den ≤ num
        den = d @ self.planes_n.T  # (N, F)
        with np.errstate(divide="ignore", invalid="ignore"):
            t = num / den
        entering = den < -_EPS
        exiting = den > _EPS
        parallel_out = (~entering & ~exiting) & (num < 0)[None, :]
        t_in_all = np.where(entering, t, -np.inf)
        t_enter = t_in_all.max(axis=1)
        face = t_in_all.argmax(axis=1)
        t_out_all = np.where(exiting, t, np.inf)
        t_exit = t_out_all.min(axis=1)
        ok = (t_enter <= t_exit) & (t_exit > 0) & ~parallel_out.any(axis=1)
        # from outside the first surface met is the entry face; from inside (t_enter <= 0) the exit face
        inside = t_enter <= 0
        face = np.where(inside, t_out_all.argmin(axis=1), face)
        t_hit = np.where(ok, np.where(inside, t_exit, t_enter), np.inf)
        return t_hit, face, self.planes_n[face]

    def _triangles(self, o: np.ndarray, d: np.ndarray):
        """Möller–Trumbore against every triangle at once (rays from one origin o), in blocks of rays.

        With s = o − A, q = s × e1: det = d·(e2 × e1), u = d·(e2 × s)/det, v = d·q/det, t = (q·e2)/det,
        so each is one (rays × triangles) product. Ties go to the lower triangle index.
        """
        n = len(d)
        best = np.full(n, np.inf)
        face = np.full(n, -1, dtype=np.int64)
        normal = np.zeros((n, 3))
        A = self.triangles[:, 0]
        e1 = self.triangles[:, 1] - A
        e2 = self.triangles[:, 2] - A
        s = o - A
        q = np.cross(s, e1)
        w_det = np.cross(e2, e1)
        w_u = np.cross(e2, s)
        t_num = np.einsum("ij,ij->i", q, e2)
        nk = np.cross(e1, e2)
        nk = nk / np.maximum(np.linalg.norm(nk, axis=1, keepdims=True), 1e-300)
        block = max(1, 2_000_000 // max(len(A), 1))
        for lo in range(0, n, block):
            dd = d[lo : lo + block]
            det = dd @ w_det.T  # (m, T)
            ok = np.abs(det) > _EPS
            inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
            u = (dd @ w_u.T) * inv
            v = (dd @ q.T) * inv
            t = t_num * inv
            hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
            t = np.where(hit, t, np.inf)
            k = t.argmin(axis=1)
            tk = t[np.arange(len(dd)), k]
            got = np.isfinite(tk)
            best[lo : lo + block] = tk
            face[lo : lo + block] = np.where(got, self.triangle_face[k], -1)
            normal[lo : lo + block] = np.where(got[:, None], nk[k], 0.0)
        return best, face, normal

    @staticmethod
    def _revolution(s: Revolution, label: int, o: np.ndarray, d: np.ndarray):
        a = s.axis
        H = s.height
        k = (s.r1 - s.r0) / H
        q = o - s.p0
        qa = float(q @ a)
        da = d @ a
        qp = q - qa * a
        dp = d - da[:, None] * a
        # |qp + t dp|² = (r0 + k (qa + t da))²
        rq = s.r0 + k * qa
        A = np.einsum("ij,ij->i", dp, dp) - (k * da) ** 2
        B = 2.0 * (dp @ qp - rq * k * da)
        Cc = float(qp @ qp) - rq**2
        n = len(d)
        best = np.full(n, np.inf)
        face = np.full(n, -1, dtype=np.int64)
        disc = B * B - 4 * A * Cc
        good = (np.abs(A) > _EPS) & (disc >= 0)
        sq = np.sqrt(np.where(good, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            roots = [(-B - sq) / (2 * A), (-B + sq) / (2 * A)]
        for t in roots:
            h = qa + t * da
            hit = good & (t > 0) & (h >= 0) & (h <= H) & (rq + k * t * da >= 0) & (t < best)
            best = np.where(hit, t, best)
            face = np.where(hit, label, face)
        for cap, (_centre, r, hval) in enumerate(((s.p0, s.r0, 0.0), (s.p1, s.r1, H))):
            if r <= 0:
                continue
            ok = np.abs(da) > _EPS
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (hval - qa) / da
            X = (q - hval * a) + t[:, None] * d
            rad2 = np.einsum("ij,ij->i", X, X)
            hit = ok & (t > 0) & (rad2 <= r * r) & (t < best)
            best = np.where(hit, t, best)
            face = np.where(hit, label + 1 + cap, face)
        # Normals: caps ±a; lateral h·e + (r0 − r1)·a (outward), e the radial unit vector.
        normal = np.zeros((n, 3))
        lat = face == label
        if np.any(lat):
            X = q + best[lat, None] * d[lat]
            radial = X - (X @ a)[:, None] * a
            e = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
            nl = H * e + (s.r0 - s.r1) * a
            normal[lat] = nl / np.linalg.norm(nl, axis=1, keepdims=True)
        normal[face == label + 1] = -a
        normal[face == label + 2] = a
        return best, face, normal

    # ---------------------------------------------------------------- public
    def cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hits of rays from one origin, in the object frame.

        o_obj : array, shape (3,), the origin. d_obj : array, shape (N, 3), directions.
        Returns t (N,), face label (N,) int (−1 for a miss), outward normal (N, 3), object frame.
        """
        d = np.asarray(d_obj, dtype=float).reshape(-1, 3)
        o = np.asarray(o_obj, dtype=float).reshape(3)
        n = len(d)
        best = np.full(n, np.inf)
        face = np.full(n, -1, dtype=np.int64)
        normal = np.zeros((n, 3))
        parts = []
        if len(self.planes_n):
            parts.append(self._convex)
        if len(self.triangles):
            parts.append(self._triangles)
        parts += [
            (lambda oo, dd, s=s, k=k: self._revolution(s, LABEL_SOLID + 3 * k, oo, dd))
            for k, s in enumerate(self.solids)
        ]
        for part in parts:
            t, f, nrm = part(o, d)
            closer = t < best
            best = np.where(closer, t, best)
            face = np.where(closer, f, face)
            normal[closer] = nrm[closer]
        return best, face, normal

    def sphere_mask(self, o_obj: np.ndarray, d_obj: np.ndarray) -> np.ndarray:
        """Rays (N,) from the origin o_obj (3,) that meet the model's bounding sphere ahead."""
        d = np.asarray(d_obj, dtype=float).reshape(-1, 3)
        w = self.center - np.asarray(o_obj, dtype=float).reshape(3)
        ww = float(w @ w)
        if ww <= self.radius**2:
            return np.ones(len(d), bool)
        dd = np.einsum("ij,ij->i", d, d)
        wd = d @ w
        return (wd > 0) & (ww - wd * wd / dd <= self.radius**2)


class SceneCaster:
    """Ray caster of a set of bodies at given poses (world frame).

    bodies : sequence of objects with ``.model`` (BRep); poses : matching sequence of T_world_obj (4, 4).
    Build one per scene time (poses change) or reuse ``casters`` across times via ``with_poses``.
    """

    def __init__(self, bodies, poses, casters: list[BodyCaster] | None = None):
        self.bodies = tuple(bodies)
        self.poses = [np.asarray(T, dtype=float) for T in poses]
        if len(self.poses) != len(self.bodies):
            raise ValueError(f"{len(self.bodies)} bodies but {len(self.poses)} poses")
        self.casters = casters if casters is not None else [BodyCaster(b.model) for b in self.bodies]

    @classmethod
    def for_scene(cls, scene, t_s: float = 0.0, casters: list[BodyCaster] | None = None) -> SceneCaster:
        """Every body of ``scene`` (app.scene.Scene) at its true pose at time t_s (seconds)."""
        return cls(scene.bodies, [b.pose_at(t_s) for b in scene.bodies], casters)

    def with_poses(self, poses) -> SceneCaster:
        """The same bodies (and cached casters) at other poses."""
        return SceneCaster(self.bodies, poses, self.casters)

    def cast(self, origin: np.ndarray, dirs: np.ndarray, skip: tuple[int, ...] = ()) -> Hits:
        """Nearest hits of rays ``origin + t · dirs`` (world frame).

        origin : array, shape (3,), one origin (the optical centre, the turret). dirs : array,
        shape (N, 3), any length. skip : indices of bodies to ignore.
        """
        d = np.asarray(dirs, dtype=float).reshape(-1, 3)
        o = np.asarray(origin, dtype=float).reshape(3)
        n = len(d)
        t_best = np.full(n, np.inf)
        body = np.full(n, -1, dtype=np.int64)
        face = np.full(n, -1, dtype=np.int64)
        n_obj = np.zeros((n, 3))
        X_obj = np.zeros((n, 3))
        for i, (caster, T) in enumerate(zip(self.casters, self.poses)):
            if not caster.has_surface or i in skip:
                continue
            R, p = T[:3, :3], T[:3, 3]
            o_obj = (o - p) @ R  # Rᵀ (o − p)
            d_obj = d @ R
            idx = np.flatnonzero(caster.sphere_mask(o_obj, d_obj))
            if not len(idx):
                continue
            if len(idx) < n:
                d_obj = d_obj[idx]
            t, f, nrm = caster.cast(o_obj, d_obj)
            closer = t < t_best[idx]
            sel = idx[closer]
            t_best[sel] = t[closer]
            body[sel] = i
            face[sel] = f[closer]
            n_obj[sel] = nrm[closer]
            X_obj[sel] = o_obj + t[closer, None] * d_obj[closer]
        normal = np.zeros((n, 3))
        for i in np.unique(body[body >= 0]):
            hit = body == i
            normal[hit] = n_obj[hit] @ self.poses[i][:3, :3].T
        return Hits(t_best, body, face, normal, X_obj)

    def occluded(
        self, origin: np.ndarray, X_world: np.ndarray, body: int | None = None, tol_m: float = 1e-6
    ) -> np.ndarray:
        """True (N,) for world points hidden from ``origin`` (3,) by a surface in front of them.

        With ``body`` (the index of the body the points lie on), that body is ignored: a point on
        an edge or a silhouette is then judged only by the other bodies (its own visibility is the
        wireframe's business). ``tol_m``: surfaces closer than this to the point do not count.
        """
        X = np.asarray(X_world, dtype=float).reshape(-1, 3)
        o = np.asarray(origin, dtype=float)
        d = X - o
        h = self.cast(o, d, skip=() if body is None else (body,))
        length = np.linalg.norm(d, axis=1)
        return h.t * length < length - tol_m


class BeamCaster:
    """First surface a single beam meets among a scene's bodies, at their true poses at a given time.

    bodies : a scene (anything with ``.bodies``) or a sequence of bodies with ``.name``, ``.model``
    (BRep), ``.moves`` and ``.pose_at(t_s)`` (app.scene.Body). Each body's caster is built once;
    static bodies' poses are computed once, moving ones at every cast (no rebuild).
    """

    def __init__(self, bodies):
        bodies = tuple(getattr(bodies, "bodies", bodies))
        if not bodies:
            raise ValueError("a scene with no bodies has nothing to measure; add at least a table")
        self.bodies = bodies
        self.casters = [BodyCaster(b.model) for b in bodies]
        self._static = [None if b.moves else np.asarray(b.pose_at(0.0), dtype=float) for b in bodies]

    @property
    def names(self) -> list[str]:
        return [b.name for b in self.bodies]

    def cast(self, origin_world: np.ndarray, direction_world: np.ndarray, t_s: float = 0.0) -> tuple[float, str | None]:
        """Distance (metres) along the beam to the first surface, and the name of the body hit.

        origin_world : array, shape (3,), world frame. direction_world : array, shape (3,), any
        non-zero length (normalised here). t_s : scene time (seconds) for moving bodies.
        Returns (inf, None) when the beam meets nothing.
        """
        o = np.asarray(origin_world, dtype=float).reshape(3)
        d = np.asarray(direction_world, dtype=float).reshape(3)
        norm = float(np.linalg.norm(d))
        if not (np.all(np.isfinite(o)) and np.isfinite(norm) and norm > 0):
            raise ValueError(f"a beam needs a finite origin and a non-zero direction, got {o}, {d}")
        poses = [T if T is not None else b.pose_at(t_s) for T, b in zip(self._static, self.bodies)]
        h = SceneCaster(self.bodies, poses, self.casters).cast(o, (d / norm)[None])
        k = int(h.body[0])
        return (float(h.t[0]), self.bodies[k].name) if k >= 0 else (np.inf, None)
