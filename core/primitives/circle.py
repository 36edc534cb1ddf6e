"""A free circular edge (a ViSP ``.cao`` circle): an edge with no surface, always drawn."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from .base import CaoPart, Outline, SampleGroup, circle_basis, closed_curve_outline, no_hits, same_arrays

__all__ = ["Circle"]


@dataclass(frozen=True, eq=False)
class Circle:
    """A circular edge in the object frame.

    centre : array, shape (3,), metres. normal : array, shape (3,), unit normal of the circle's
    plane (normalised on construction). radius : metres, > 0.
    """

    centre: np.ndarray
    normal: np.ndarray
    radius: float

    kind: ClassVar[str] = "circle"
    surface: ClassVar[bool] = False

    def __post_init__(self):
        c = np.asarray(self.centre, dtype=float).reshape(3)
        n = np.asarray(self.normal, dtype=float).reshape(3)
        norm = float(np.linalg.norm(n))
        if not (np.all(np.isfinite(c)) and np.all(np.isfinite(n))) or norm <= 1e-12:
            raise ValueError(f"a circle needs a finite centre and a non-zero normal, got {c}, {n}")
        if not (np.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"a circle's radius must be positive, got {self.radius}")
        object.__setattr__(self, "centre", c)
        object.__setattr__(self, "normal", n / norm)
        object.__setattr__(self, "radius", float(self.radius))

    def __eq__(self, other: object) -> bool:
        return same_arrays(self, other, ("centre", "normal", "radius"))

    __hash__ = None  # arrays inside: not hashable

    @property
    def n_labels(self) -> int:
        return 0

    def basis(self) -> tuple[np.ndarray, np.ndarray]:
        """Two unit vectors (3,), (3,) spanning the circle's plane (e1 × e2 = normal)."""
        return circle_basis(self.normal)

    def polyline(self, n: int = 48) -> np.ndarray:
        """Closed polyline (n + 1, 3) on the circle, object frame."""
        e1, e2 = self.basis()
        th = np.linspace(0.0, 2.0 * np.pi, n + 1)
        return self.centre + self.radius * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)

    # ------------------------------------------------------------------ the protocol
    def ray_cast(self, o_obj: np.ndarray, d_obj: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """An edge has no surface: every ray misses."""
        return no_hits(len(np.asarray(d_obj).reshape(-1, 3)))

    def outline(self, center_obj: np.ndarray, n_circle: int = 48) -> Outline:
        """Its ``n_circle`` chords, kind "circle", always visible (it bounds no face)."""
        return closed_curve_outline(self.polyline(n_circle), np.ones(n_circle, bool), "circle", 0)

    def edge_samples(self, centers_obj: np.ndarray, per_edge: int, n_rim: int) -> list[SampleGroup]:
        """``n_rim`` points around it, seen from every point."""
        e1, e2 = self.basis()
        th = np.linspace(0.0, 2.0 * np.pi, n_rim, endpoint=False)
        P = self.centre + self.radius * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
        D = -np.sin(th)[:, None] * e1 + np.cos(th)[:, None] * e2
        return [(P, D, np.ones((len(np.asarray(centers_obj).reshape(-1, 3)), n_rim), bool))]

    def triangles(self, n_circle: int = 48) -> tuple[np.ndarray, np.ndarray]:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)

    def cao_part(self) -> CaoPart:
        """A ``.cao`` circle: its centre and two rim points spanning its plane."""
        e1, e2 = self.basis()
        P = np.array([self.centre, self.centre + self.radius * e1, self.centre + self.radius * e2])
        return CaoPart(P, circles=((self.radius, 0, 1, 2),))

    def bounds(self) -> np.ndarray:
        """Exact bounds (2, 3): its extent along axis i is r·√(1 − n_i²)."""
        spread = self.radius * np.sqrt(np.maximum(0.0, 1.0 - self.normal**2))
        return np.array([self.centre - spread, self.centre + spread])

    def support_points(self, n: int = 48, min_radius: float = 0.0) -> np.ndarray:
        return self.polyline(n)[:-1]

    def plane_normals(self) -> np.ndarray:
        return np.zeros((0, 3))

    def turn_invariant(self, axis_obj: np.ndarray) -> bool:
        """Its normal is along the line and its centre on it."""
        u = np.asarray(axis_obj, dtype=float).reshape(3)
        return abs(abs(float(self.normal @ u)) - 1.0) < 1e-6 and float(np.linalg.norm(np.cross(self.centre, u))) < 1e-9

    def transformed(self, T_new_obj: np.ndarray) -> Circle:
        R, t = T_new_obj[:3, :3], T_new_obj[:3, 3]
        return Circle(R @ self.centre + t, R @ self.normal, self.radius)

    def to_dict(self) -> dict[str, Any]:
        """Its stored form, with no kind tag: the form databases hold in a model's "circles"."""
        return {"centre": self.centre.tolist(), "normal": self.normal.tolist(), "radius": self.radius}

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Circle:
        return cls(d["centre"], d["normal"], d["radius"])
