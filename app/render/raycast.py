"""Exact ray casting of a scene's bodies, for the renderer and for visibility questions.

Each body's B-Rep is cast analytically, in its own frame, primitive by primitive
(``core.primitives``: each primitive's ``ray_cast``): a convex polyhedron by its face planes, any
other faced model (a mesh) by its triangles, a solid of revolution by the quadric of its lateral
surface and the discs of its caps, a sphere by its quadric — so silhouettes are exact rather than
tessellated. The nearest hit over the primitives wins.

A ray from inside a body meets its surface on the way out (the exit face), as a mesh's would.
This is the one ray caster of mcit: the renderer, the range-finder emulator (``BeamCaster``: one
beam against a scene's true bodies at their poses of a given time) and designation
(``app.workflows.Site.raycast``: a ray against the database's objects) all use it.

Rays are ``X = origin + t · d`` with d of any length; ``t`` is returned in those units. With the
camera's unnormalised ray directions ``d = M⁻¹ (u, v, 1)`` (C = [M | p₄], normalised), t is the
depth s of the hit (metres along the optical axis). Misses have t = +inf, body = −1.

Face labels: the polyhedral part's faces keep their B-Rep face index; the model's other primitives
follow from ``LABEL_SOLID`` on, each taking as many labels as it has (``Primitive.n_labels``): a
model of solids of revolution alone gives solid k the labels ``LABEL_SOLID + 3k`` (lateral),
``+1`` (cap at p0), ``+2`` (cap at p1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.brep import BRep

__all__ = ["Hits", "BodyCaster", "SceneCaster", "BeamCaster", "LABEL_SOLID"]

LABEL_SOLID = 1000


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


class BodyCaster:
    """Ray caster of one B-Rep model in its own frame (see the module docstring)."""

    def __init__(self, model: BRep):
        self.model = model
        # the polyhedral part (parts[0]) labels by its face indices; the others from LABEL_SOLID on
        self._casts = [(model.parts[0], 0)]
        label = LABEL_SOLID
        for p in model.parts[1:]:
            self._casts.append((p, label))
            label += p.n_labels
        self._casts = [(p, first) for p, first in self._casts if p.n_labels]
        lo, hi = model.bounds()
        self.center = 0.5 * (lo + hi)
        P = model.support_points(16)
        # Curves sampled at 16 points lie inside the true curve's bounding radius by < 2 %: pad.
        self.radius = float(np.linalg.norm(P - self.center, axis=1).max()) * 1.03 + 1e-9 if len(P) else 1e-9
        self.has_surface = bool(self._casts)

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
        for part, first in self._casts:
            t, f, nrm = part.ray_cast(o, d)
            closer = t < best
            best = np.where(closer, t, best)
            face = np.where(closer, first + f, face)
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
