"""A sphere: a ball's surface, given by its centre and radius.

Seen from a point c outside it, at distance D from the centre C, its outline is the circle where
the tangent cone from c touches it: centred at ``C + (r²/D)·ŵ`` (ŵ the unit vector C → c) in the
plane of normal ŵ, of radius ``r·√(1 − r²/D²)``. A ViSP ``.cao`` file has no sphere.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .base import CaoPart, Outline, SampleGroup, circle_basis, closed_curve_outline, same_arrays

__all__ = ["Sphere"]


@dataclass(frozen=True, eq=False)
class Sphere:
    """A sphere in the object frame. centre : array, shape (3,), metres. radius : metres, > 0.

    Ray-cast label: 0, its surface.
    """

    centre: np.ndarray
    radius: float

    kind: ClassVar[str] = "sphere"
    surface: ClassVar[bool] = True

    def __post_init__(self):
        c = np.asarray(self.centre, dtype=float).reshape(3)
        if not np.all(np.isfinite(c)):
            raise ValueError(f"a sphere's centre must be finite, got {c}")
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"a sphere's radius must be positive, got {self.radius}")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "radius", float(self.radius))

    def __eq__(self, other: object) -> bool:
        return same_arrays(self, other, ("centre", "radius"))

    __hash__ = None  # arrays inside: not hashable

    @property
    def n_labels(self) -> int:
        return 1

    def contour(self, centers_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The outline circle seen from each of N points (N, 3): its centres (N, 3), unit plane normals
        ŵ (N, 3), radii (N,), and (N,) bool: the point is outside the sphere (an outline exists)."""
        w = np.asarray(centers_obj, dtype=float).reshape(-1, 3) - self.centre
        D = np.linalg.norm(w, axis=1)
        ok = D > self.radius
        Ds = np.where(ok, D, 1.0)
        w_hat = np.where(ok[:, None], w / Ds[:, None], [0.0, 0.0, 1.0])
        rho = np.where(ok, self.radius * np.sqrt(np.maximum(0.0, 1.0 - (self.radius / Ds) ** 2)), 0.0)
        return self.centre + (self.radius**2 / Ds)[:, None] * w_hat, w_hat, rho, ok

    # ------------------------------------------------------------------ the protocol
    def ray_cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """|o + t·d − C|² = r²: the smaller positive root (from inside, the larger)."""
        q = np.asarray(o_obj, dtype=float).reshape(3) - self.centre
        d = np.asarray(d_obj, dtype=float).reshape(-1, 3)
        A = np.einsum("ij,ij->i", d, d)
        B = d @ q
        C = float(q @ q) - self.radius**2
        disc = B * B - A * C
        good = (A > 0) & (disc >= 0)
        sq = np.sqrt(np.where(good, disc, 0.0))
        As = np.where(good, A, 1.0)
        near, far = (-B - sq) / As, (-B + sq) / As
        t = np.where(good & (near > 0), near, np.where(good & (far > 0), far, np.inf))
        hit = np.isfinite(t)
        normal = np.where(hit[:, None], q + np.where(hit, t, 0.0)[:, None] * d, 0.0) / self.radius
        return t, np.where(hit, 0, -1).astype(np.int64), normal

    def outline(self, center_obj: np.ndarray, n_circle: int = 48) -> Outline:
        """Its outline circle seen from the point, ``n_circle`` chords of kind "silhouette" (none from inside)."""
        centre, w_hat, rho, ok = self.contour(np.asarray(center_obj, dtype=float).reshape(1, 3))
        if not ok[0]:
            return Outline.empty(n_circle)
        e1, e2 = circle_basis(w_hat[0])
        th = np.linspace(0.0, 2.0 * np.pi, n_circle + 1)
        P = centre[0] + rho[0] * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
        return closed_curve_outline(P, np.ones(n_circle, bool), "silhouette", 0)

    def edge_samples(self, centers_obj: np.ndarray, per_edge: int, n_rim: int) -> list[SampleGroup]:
        """``n_rim`` points around its outline seen from each point (N, n_rim, 3), with their tangents."""
        centre, w_hat, rho, ok = self.contour(centers_obj)
        u = np.cross(w_hat, np.where(np.abs(w_hat[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]]))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        v = np.cross(w_hat, u)
        th = np.linspace(0.0, 2.0 * np.pi, n_rim, endpoint=False)
        cs, sn = np.cos(th)[None, :, None], np.sin(th)[None, :, None]
        X = centre[:, None] + rho[:, None, None] * (cs * u[:, None] + sn * v[:, None])
        D = -sn * u[:, None] + cs * v[:, None]
        return [(X, D, np.broadcast_to(ok[:, None], (len(ok), n_rim)))]

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        """A latitude-longitude mesh: ``n_circle`` meridians, ``n_circle // 2`` bands, outward-facing;
        vertices on the sphere (poles at ±z)."""
        n = max(int(n_circle), 3)
        m = max(n // 2, 2)
        lat = np.linspace(0.0, np.pi, m + 1)[1:-1]
        lon = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
        ring = np.stack(
            [
                np.outer(np.sin(lat), np.cos(lon)),
                np.outer(np.sin(lat), np.sin(lon)),
                np.repeat(np.cos(lat)[:, None], n, 1),
            ],
            axis=-1,
        ).reshape(-1, 3)
        V = self.centre + self.radius * np.vstack([[0.0, 0.0, 1.0], ring, [0.0, 0.0, -1.0]])
        top, bottom = 0, len(V) - 1
        i = np.arange(n)
        j = (i + 1) % n
        tris = [np.column_stack([np.full(n, top), 1 + i, 1 + j])]
        for b in range(m - 2):  # the band between ring b and ring b + 1
            a0, a1 = 1 + b * n, 1 + (b + 1) * n
            tris += [np.column_stack([a0 + i, a1 + i, a1 + j]), np.column_stack([a0 + i, a1 + j, a0 + j])]
        last = 1 + (m - 2) * n
        tris.append(np.column_stack([np.full(n, bottom), last + j, last + i]))
        return V, np.vstack(tris).astype(np.int64)

    def cao_part(self) -> CaoPart:
        """A ``.cao`` file has no sphere: ValueError (a tessellation would read back as a faceted
        mesh, not a sphere)."""
        raise ValueError(
            f"a .cao model has no spheres; this model has one (radius {self.radius}): export it as glTF or OBJ"
        )

    def bounds(self) -> np.ndarray:
        return np.array([self.centre - self.radius, self.centre + self.radius])

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        """The vertices of ``triangles(max(n // 2, 8))`` (on the sphere)."""
        return self.triangles(max(n // 2, 8))[0]

    def plane_normals(self) -> np.ndarray:
        return np.zeros((0, 3))

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """Its centre lies on the line."""
        u = np.asarray(axis_obj, dtype=float).reshape(3)
        return float(np.linalg.norm(np.cross(self.centre, u))) < 1e-9

    def transformed(self, T_new_obj: np.ndarray) -> Sphere:
        return Sphere(T_new_obj[:3, :3] @ self.centre + T_new_obj[:3, 3], self.radius)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": self.kind, "centre": self.centre.tolist(), "radius": self.radius}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Sphere:
        return cls(d["centre"], d["radius"])
