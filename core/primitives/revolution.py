"""A solid of revolution: a cylinder, or a cone/frustum with two radii (a cylinder is r0 == r1).

Given by its axis endpoints p0, p1 and the radii r0, r1 there. Its lateral surface is the quadric
``|q⊥| = r0 + k·h`` (h the height along the axis from p0, k = (r1 − r0)/H), closed by the discs
of its caps. Its silhouette lines depend on the view: seen from a point they are the two
generators whose tangent plane passes through it (``silhouette``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Any, ClassVar

import numpy as np

from .base import CaoPart, Outline, SampleGroup, circle_basis, same_arrays

__all__ = ["Revolution"]

_EPS = 1e-12


@dataclass(frozen=True, eq=False)
class Revolution:
    """A cylinder or cone (frustum) in the object frame.

    p0, p1 : array, shape (3,), axis endpoints (metres). r0, r1 : radii at p0 and p1 (metres);
    equal for a cylinder, one may be 0 for a full cone.

    Ray-cast labels: 0 the lateral surface, 1 the cap at p0, 2 the cap at p1.
    """

    p0: np.ndarray
    p1: np.ndarray
    r0: float
    r1: float

    kind: ClassVar[str] = "revolution"
    surface: ClassVar[bool] = True

    def __post_init__(self):
        p0 = np.asarray(self.p0, dtype=float).reshape(3)
        p1 = np.asarray(self.p1, dtype=float).reshape(3)
        if not (np.all(np.isfinite(p0)) and np.all(np.isfinite(p1))):
            raise ValueError("a solid of revolution's axis endpoints must be finite")
        if np.linalg.norm(p1 - p0) <= 1e-12:
            raise ValueError("a solid of revolution needs two distinct axis endpoints")
        if not (self.r0 >= 0 and self.r1 >= 0) or self.r0 + self.r1 <= 0:
            raise ValueError(f"radii must be non-negative and not both zero, got {self.r0}, {self.r1}")
        object.__setattr__(self, "p0", p0)
        object.__setattr__(self, "p1", p1)
        object.__setattr__(self, "r0", float(self.r0))
        object.__setattr__(self, "r1", float(self.r1))

    def __eq__(self, other: object) -> bool:
        return same_arrays(self, other, ("p0", "p1", "r0", "r1"))

    __hash__ = None  # arrays inside: not hashable

    @property
    def n_labels(self) -> int:
        return 3

    @cached_property
    def axis(self) -> np.ndarray:
        """Unit axis direction p0 → p1, shape (3,), read-only."""
        a = self.p1 - self.p0
        a = a / np.linalg.norm(a)
        a.setflags(write=False)
        return a

    @cached_property
    def height(self) -> float:
        """Length of the axis, metres."""
        return float(np.linalg.norm(self.p1 - self.p0))

    @property
    def is_cylinder(self) -> bool:
        return abs(self.r0 - self.r1) <= 1e-12

    def _radial_basis(self) -> tuple[np.ndarray, np.ndarray]:
        return self._basis

    @cached_property
    def _axis_cross(self) -> np.ndarray:
        """The matrix (3, 3) of a × ·."""
        a = self.axis
        return np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])

    @cached_property
    def _basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors spanning the plane normal to the axis (computed once: drawn every frame)."""
        return circle_basis(self.axis)

    def _caps(self) -> tuple[tuple[np.ndarray, float, np.ndarray], ...]:
        """(centre, radius, outward normal) of the caps at p0 and p1."""
        a = self.axis
        return (self.p0, self.r0, -a), (self.p1, self.r1, a)

    def rim(self, which: int, n: int = 48) -> np.ndarray:
        """Closed polyline (n + 1, 3) of the rim circle at p0 (which=0) or p1 (which=1), obj frame."""
        e1, e2 = self._radial_basis()
        th = np.linspace(0.0, 2.0 * np.pi, n + 1)
        centre, r = (self.p0, self.r0) if which == 0 else (self.p1, self.r1)
        return centre + r * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)

    def _contour_directions(self, centers_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Radial unit vectors (N, 3) of the two contour generators seen from each of N points (N, 3),
        one per sign, and (N,) bool: the point is outside the surface's extension (a contour exists).

        The lateral surface's outward normal at angle θ is ``h·e(θ) + (r0 − r1)·a``; a generator is
        on the contour when its tangent plane passes through the point: ``e·w = k`` with w the
        point's radial offset and ``k = r0 − (r0 − r1)·q_a / h``.
        """
        a = self.axis
        q = np.asarray(centers_obj, dtype=float).reshape(-1, 3) - self.p0
        q_a = q @ a
        w = q - q_a[:, None] * a
        D = np.linalg.norm(w, axis=1)
        k = self.r0 - (self.r0 - self.r1) * q_a / self.height
        ok = (D > np.abs(k)) & (D >= 1e-12)
        w_hat = w / np.where(ok, D, 1.0)[:, None]
        b_hat = w_hat @ self._axis_cross.T  # a × ŵ
        c = np.where(ok, k / np.where(ok, D, 1.0), 0.0)
        s = np.sqrt(np.maximum(0.0, 1.0 - c * c))
        return c[:, None] * w_hat + s[:, None] * b_hat, c[:, None] * w_hat - s[:, None] * b_hat, ok

    def silhouette(self, center_obj: np.ndarray) -> np.ndarray:
        """The two contour generators seen from an optical centre (3,) in the object frame.

        Returns array, shape (2, 2, 3): two segments (from the p0 rim to the p1 rim), or shape
        (0, 2, 3) when the centre is inside the surface's extension (no silhouette).
        """
        e_plus, e_minus, ok = self._contour_directions(np.asarray(center_obj, dtype=float).reshape(1, 3))
        if not ok[0]:
            return np.zeros((0, 2, 3))
        return np.array([[self.p0 + self.r0 * e[0], self.p1 + self.r1 * e[0]] for e in (e_plus, e_minus)])

    def lateral_normal(self, theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Radial unit vectors e(θ) (N, 3) and outward lateral normals (N, 3) (unnormalised)."""
        e1, e2 = self._radial_basis()
        e = np.cos(theta)[:, None] * e1 + np.sin(theta)[:, None] * e2
        return e, self.height * e + (self.r0 - self.r1) * self.axis

    # ------------------------------------------------------------------ the protocol
    def ray_cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest hits of rays (``Primitive.ray_cast``): the lateral quadric, then the caps' discs."""
        o = np.asarray(o_obj, dtype=float).reshape(3)
        d = np.asarray(d_obj, dtype=float).reshape(-1, 3)
        a, H = self.axis, self.height
        k = (self.r1 - self.r0) / H
        q = o - self.p0
        qa = float(q @ a)
        da = d @ a
        qp = q - qa * a
        dp = d - da[:, None] * a
        # |qp + t dp|² = (r0 + k (qa + t da))²
        rq = self.r0 + k * qa
        A = np.einsum("ij,ij->i", dp, dp) - (k * da) ** 2
        B = 2.0 * (dp @ qp - rq * k * da)
        Cc = float(qp @ qp) - rq**2
        n = len(d)
        best = np.full(n, np.inf)
        label = np.full(n, -1, dtype=np.int64)
        disc = B * B - 4 * A * Cc
        good = (np.abs(A) > _EPS) & (disc >= 0)
        sq = np.sqrt(np.where(good, disc, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            roots = [(-B - sq) / (2 * A), (-B + sq) / (2 * A)]
        for t in roots:
            h = qa + t * da
            hit = good & (t > 0) & (h >= 0) & (h <= H) & (rq + k * t * da >= 0) & (t < best)
            best = np.where(hit, t, best)
            label = np.where(hit, 0, label)
        for cap, (r, hval) in enumerate(((self.r0, 0.0), (self.r1, H))):
            if r <= 0:
                continue
            ok = np.abs(da) > _EPS
            with np.errstate(divide="ignore", invalid="ignore"):  # a ray parallel to the cap: t = ±inf or nan
                t = (hval - qa) / da
                X = (q - hval * a) + t[:, None] * d
                rad2 = np.einsum("ij,ij->i", X, X)
            hit = ok & (t > 0) & (rad2 <= r * r) & (t < best)
            best = np.where(hit, t, best)
            label = np.where(hit, 1 + cap, label)
        # Normals: caps ±a; lateral h·e + (r0 − r1)·a (outward), e the radial unit vector.
        normal = np.zeros((n, 3))
        lat = label == 0
        if np.any(lat):
            X = q + best[lat, None] * d[lat]
            radial = X - (X @ a)[:, None] * a
            e = radial / np.maximum(np.linalg.norm(radial, axis=1, keepdims=True), 1e-300)
            nl = H * e + (self.r0 - self.r1) * a
            normal[lat] = nl / np.linalg.norm(nl, axis=1, keepdims=True)
        normal[label == 1] = -a
        normal[label == 2] = a
        return best, label, normal

    def outline(self, center_obj: np.ndarray, n_circle: int = 48) -> Outline:
        """The two silhouette generators (visible; features 0, 1) and the rims (``n_circle`` chords each,
        features 2 + which·n_circle onwards): a rim chord is visible when its cap or the lateral
        surface next to it faces the point."""
        c = np.asarray(center_obj, dtype=float).reshape(3)
        sil = self.silhouette(c)
        m = len(sil)
        rims, lat_n, fixed = self._rims(n_circle)
        visible = [np.ones(m, bool)]
        for centre, cap_n, P in rims:
            cap_facing = float(cap_n @ (c - centre)) > 0
            lat_facing = np.einsum("ij,ij->i", lat_n, c - P) > 0
            visible.append(cap_facing | (lat_facing[:-1] & lat_facing[1:]))
        chords, *ids = fixed
        segments = np.concatenate([sil, chords]) if m else chords.copy()
        kind, edge, feature, chord = (a[2 - m :] for a in ids)  # the silhouettes' rows (m of 2), then the rims'
        return Outline(segments, np.concatenate(visible), kind, edge, feature, chord, 2 + 2 * n_circle)

    def _rims(self, n_circle: int) -> tuple[list, np.ndarray, tuple[np.ndarray, ...]]:
        """What ``outline`` draws that the view does not change, kept per ``n_circle`` (it was most of
        a cylinder's redraw): each rim's (centre, cap's outward normal, points (n + 1, 3)), the lateral
        normals (n + 1, 3) at those points, the rims' chords (K, 2, 3), and the outline's kind, edge,
        feature and chord arrays (2 + K,) as with two silhouettes (with none, all but their first two
        rows); read-only."""
        kept = self.__dict__.setdefault("_rims_by_n", {})
        if n_circle not in kept:
            th = np.linspace(0.0, 2.0 * np.pi, n_circle + 1)
            e, lat_n = self.lateral_normal(th)
            rims, chords, features = [], [np.zeros((0, 2, 3))], [np.arange(2)]
            for which, (centre, r, cap_n) in enumerate(self._caps()):
                if r > 0:  # a cone's point has no rim (its features are kept all the same)
                    P = centre + r * e
                    rims.append((centre, cap_n, P))
                    chords.append(np.stack([P[:-1], P[1:]], axis=1))
                    features.append(2 + which * n_circle + np.arange(n_circle))
            k = n_circle * len(rims)
            fixed = (
                np.concatenate(chords),
                np.concatenate([np.full(2, "silhouette", dtype="<U10"), np.full(k, "rim", dtype="<U10")]),
                np.full(2 + k, -1, np.int64),
                np.concatenate(features).astype(np.int64),
                np.concatenate([np.full(2, -1, np.int64), np.tile(np.arange(n_circle, dtype=np.int64), len(rims))]),
            )
            for a in fixed:
                a.setflags(write=False)
            kept[n_circle] = (rims, lat_n, fixed)
        return kept[n_circle]

    def edge_samples(self, centers_obj: np.ndarray, per_edge: int, n_rim: int) -> list[SampleGroup]:
        """Each rim's ``n_rim`` points (seen when its cap or the lateral surface there faces the point)
        and ``max(per_edge, 4)`` points along each silhouette generator (seen when it exists)."""
        c = np.asarray(centers_obj, dtype=float).reshape(-1, 3)
        N = len(c)
        th = np.linspace(0.0, 2.0 * np.pi, n_rim, endpoint=False)
        e1, e2 = self._radial_basis()
        dirs = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2  # (K, 3) radial directions
        tang = -np.sin(th)[:, None] * e1 + np.cos(th)[:, None] * e2
        lat_n = self.height * dirs + (self.r0 - self.r1) * self.axis
        out: list[SampleGroup] = []
        for centre, r, cap_n in self._caps():
            if r <= 0:
                continue
            P = centre + r * dirs  # (K, 3)
            cap = (c - centre) @ cap_n > 0  # (N,)
            lat = c @ lat_n.T - np.einsum("kj,kj->k", lat_n, P)[None] > 0
            out.append((P, tang, cap[:, None] | lat))
        m = max(per_edge, 4)
        s = (np.arange(m) + 0.5) / m
        e_plus, e_minus, ok = self._contour_directions(c)
        for e in (e_plus, e_minus):
            P0 = self.p0 + self.r0 * e
            P1 = self.p1 + self.r1 * e
            X = P0[:, None] + s[None, :, None] * (P1 - P0)[:, None]
            out.append((X, np.broadcast_to((P1 - P0)[:, None], X.shape), np.broadcast_to(ok[:, None], (N, m))))
        return out

    def triangles(self, n: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """Closed triangle mesh (vertices (2n + 2, 3), triangles (4n, 3)), outward-facing."""
        e1, e2 = self._radial_basis()
        th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ring = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2
        V = np.vstack([self.p0 + self.r0 * ring, self.p1 + self.r1 * ring, self.p0, self.p1])
        i = np.arange(n)
        j = (i + 1) % n
        c0, c1 = 2 * n, 2 * n + 1
        side = np.vstack([np.column_stack([i, j, n + j]), np.column_stack([i, n + j, n + i])])
        bottom = np.column_stack([np.full(n, c0), j, i])
        top = np.column_stack([np.full(n, c1), n + i, n + j])
        return V, np.vstack([side, bottom, top]).astype(np.int64)

    def cao_part(self) -> CaoPart:
        """A ``.cao`` cylinder (its axis ends and radius); ValueError for a cone (the format has none)."""
        if not self.is_cylinder:
            raise ValueError(
                f"a .cao model has cylinders only; this model has a cone (radii {self.r0}, {self.r1}): "
                "export it as glTF or OBJ"
            )
        return CaoPart(np.array([self.p0, self.p1]), cylinders=((0, 1, self.r0),))

    def bounds(self) -> np.ndarray:
        """Exact bounds (2, 3): each rim's extent along axis i is r·√(1 − a_i²)."""
        spread = np.sqrt(np.maximum(0.0, 1.0 - self.axis**2))
        lo = np.minimum(self.p0 - self.r0 * spread, self.p1 - self.r1 * spread)
        hi = np.maximum(self.p0 + self.r0 * spread, self.p1 + self.r1 * spread)
        return np.array([lo, hi])

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        """``n`` points on each rim (radius at least ``min_radius``), (2n, 3)."""
        e1, e2 = self._radial_basis()
        th = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ring = np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2
        return np.vstack([self.p0 + max(self.r0, min_radius) * ring, self.p1 + max(self.r1, min_radius) * ring])

    def plane_normals(self) -> np.ndarray:
        """The caps' outward normals (a cap of radius 0, a cone's apex, is none)."""
        return np.array([n for _, r, n in self._caps() if r > 0]).reshape(-1, 3)

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """Its axis lies on the line (parallel to it, p0 on it)."""
        u = np.asarray(axis_obj, dtype=float).reshape(3)
        return abs(abs(float(self.axis @ u)) - 1.0) < 1e-6 and float(np.linalg.norm(np.cross(self.p0, u))) < 1e-9

    def transformed(self, T_new_obj: np.ndarray) -> Revolution:
        R, t = T_new_obj[:3, :3], T_new_obj[:3, 3]
        return Revolution(R @ self.p0 + t, R @ self.p1 + t, self.r0, self.r1)

    def to_dict(self) -> dict[str, Any]:
        """Its stored form, with no kind tag: the form databases hold in a model's "solids"."""
        return {"p0": self.p0.tolist(), "p1": self.p1.tolist(), "r0": self.r0, "r1": self.r1}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Revolution:
        return cls(d["p0"], d["p1"], d["r0"], d["r1"])
