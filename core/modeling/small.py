"""Small helpers for the solvers' inner loops (numpy's cross and the checked Camera calls cost more than the maths)."""

from __future__ import annotations

import numpy as np

__all__ = ["image_line", "interp_plane", "interp_plane_jacobian"]


def image_line(p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Homogeneous line (3,) through pixels p, q (2,), scaled so l·(u, v, 1) is a distance in pixels."""
    l = np.array([p[1] - q[1], q[0] - p[0], p[0] * q[1] - p[1] * q[0]])
    return l / np.hypot(l[0], l[1])


def interp_plane(C: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """Interpretation plane (n, d) as a 4-vector with unit n of a segment (2, 2) under the 3×4 matrix C.

    Same plane and orientation as ``Camera.interpretation_plane`` (without its input checks).
    """
    pi = C.T @ image_line(seg[0], seg[1])
    return pi / np.linalg.norm(pi[:3])


def interp_plane_jacobian(C: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``interp_plane(C, seg)`` (4,) and its derivative (4, 4) with respect to (p₀, p₁, q₀, q₁), the
    segment's ends: π = Cᵀ l with l = (p₁ − q₁, q₀ − p₀, p₀q₁ − p₁q₀) bilinear in the ends, then
    (n, d) = π / ‖π₁₂₃‖."""
    (p0, p1), (q0, q1) = seg
    l = np.array([p1 - q1, q0 - p0, p0 * q1 - p1 * q0])
    dl = np.array([[0.0, 1.0, 0.0, -1.0], [-1.0, 0.0, 1.0, 0.0], [q1, -q0, -p1, p0]])
    pi, dpi = C.T @ l, C.T @ dl
    nu = np.linalg.norm(pi[:3])
    return pi / nu, dpi / nu - np.outer(pi, pi[:3] @ dpi[:3]) / nu**3
