"""The camera as the paper's global model: one 3×4 matrix C, ``(s·u, s·v, s) = C (X, 1)``.

The paper never splits C into intrinsics and extrinsics (for stability); every solver here takes
a ``Camera`` and works on C. Pixels: u to the right, v down, origin at the centre of the top-left
pixel. World points in metres, in the frame C maps from (``world``).

Normalisation: C is defined up to a non-zero scale of any sign. ``Camera`` scales it so that the
third row's first three entries have unit norm and points in front of the camera have s > 0; s is
then the depth along the optical axis, in metres. The sign is chosen from ``det(C[:, :3])`` (a
right-handed camera with positive focal lengths), or, for a camera whose image is mirrored with
respect to its world frame (a reconstruction in a reflected frame, e.g. the VGG house data), from
world points the caller knows to be in front (``in_front=``).
"""

from __future__ import annotations

import numpy as np

from .checks import MAX_M, MAX_PX, finite_array, image_size
from .geometry import Plane
from .transforms import check_T, make_T

__all__ = ["Camera", "as_uv", "as_segment"]


def as_uv(uv: np.ndarray, name: str = "uv") -> np.ndarray:
    """Validate pixels: array, shape (N, 2), finite, within ±``MAX_PX``; returns float array."""
    return finite_array(uv, (None, 2), name, max_abs=MAX_PX, unit=" px")


def as_segment(seg_uv: np.ndarray, name: str = "seg_uv") -> np.ndarray:
    """Validate an image segment: array, shape (2, 2), two distinct finite pixel endpoints."""
    seg = finite_array(seg_uv, (2, 2), f"{name} (two pixel endpoints)", max_abs=MAX_PX, unit=" px")
    if np.linalg.norm(seg[1] - seg[0]) < 1e-9 * max(1.0, float(np.abs(seg).max())):
        raise ValueError(
            f"{name}: the two pixels {seg[0].tolist()} coincide and do not define a line; "
            "click two distinct points along the edge"
        )
    return seg


def _no_pixel(X: np.ndarray, name: str):
    """ValueError for points whose pixel is not finite: NaN/inf/huge input, or on the principal plane."""
    finite_array(X, X.shape, name)
    raise ValueError(
        f"{name} has a point on the camera's principal plane (depth 0) or too far out "
        f"(max |value| {float(np.abs(X).max()):.3g} m): it has no pixel"
    )


class Camera:
    """A calibrated camera given by its global 3×4 model C.

    Parameters
    ----------
    C : array, shape (3, 4)
        Projection matrix of any scale and sign, mapping world points (metres) to pixels.
    width, height : int
        Image size in pixels.
    in_front : array, shape (N, 3), optional
        World points known to be in front of the camera; fixes the sign of C for mirrored
        cameras. Without it the sign comes from ``det(C[:, :3]) > 0``.
    """

    __slots__ = ("_C", "_M_inv", "_center", "width", "height")

    def __init__(self, C: np.ndarray, width: int, height: int, *, in_front: np.ndarray | None = None):
        C = finite_array(C, (3, 4), "C")
        width, height = image_size(width, height)
        big = float(np.abs(C).max())
        if big > 1e100 or 0.0 < big < 1e-100:
            C = C / big  # C's scale is free: keep its products finite
        M = C[:, :3]
        scale = float(np.linalg.norm(M[2]))
        sv = np.linalg.svd(M, compute_uv=False)
        if scale == 0.0 or sv[-1] <= 1e-12 * sv[0]:
            raise ValueError(
                "C is singular: its left 3×3 block has rank < 3, so it has no finite optical "
                "centre; recalibrate the camera (the calibration points may be coplanar)"
            )
        if in_front is None:
            sign = np.sign(np.linalg.det(M))
        else:
            Xf = np.asarray(in_front, dtype=float)
            Xf = finite_array(
                Xf[None] if Xf.shape == (3,) else Xf, (None, 3), "in_front", max_abs=MAX_M, unit=" m", min_count=1
            )
            s = Xf @ M[2] + C[2, 3]
            sign = np.sign(np.median(s))
            if sign == 0:
                raise ValueError("in_front points lie on the camera's principal plane")
        self._C = C * (sign / scale)
        self._C.setflags(write=False)
        self._M_inv = np.linalg.inv(self._C[:, :3])
        self._center = -self._M_inv @ self._C[:, 3]
        if not np.all(np.abs(self._center) <= MAX_M):
            raise ValueError(
                f"C puts the optical centre at {self._center.tolist()} m, beyond ±{MAX_M:g} m: recalibrate the camera"
            )
        self._center.setflags(write=False)
        self.width = width
        self.height = height

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_intrinsics(cls, K: np.ndarray, T_cam_world: np.ndarray, width: int, height: int) -> Camera:
        """Camera ``C = K [R_cam_world | t_cam_world]`` from intrinsics K (3, 3) and a pose (4, 4)."""
        K = np.asarray(K, dtype=float)
        if K.shape != (3, 3) or not np.all(np.isfinite(K)):
            raise ValueError(f"K must be a finite (3, 3) array, got shape {K.shape}")
        if abs(K[1, 0]) > 1e-9 * abs(K).max() or abs(K[2, 0]) + abs(K[2, 1]) > 1e-9 * abs(K).max():
            raise ValueError("K must be upper triangular (fx, skew, u0; 0, fy, v0; 0, 0, 1)")
        T = check_T(T_cam_world, "T_cam_world")
        return cls(K @ T[:3, :], width, height)

    def decompose(self) -> tuple[np.ndarray, np.ndarray]:
        """Intrinsics and pose, for display: ``C ∝ K [R | t]``.

        Returns K (3, 3) with K[2, 2] = 1, fy > 0, and T_cam_world (4, 4) with a proper rotation.
        fx is negative only for a mirrored camera (see the module's docstring).
        """
        from scipy.linalg import rq  # here, not at the top: scipy costs the interface's start-up ~0.3 s

        M = self._C[:, :3]
        K, R = rq(M)
        D = np.diag(np.sign(np.diag(K)))
        K, R = K @ D, D @ R
        if np.linalg.det(R) < 0:
            F = np.diag([-1.0, 1.0, 1.0])
            K, R = K @ F, F @ R
        t = np.linalg.solve(K, self._C[:, 3])
        return K / K[2, 2], make_T(R, t)

    # ------------------------------------------------------------------ properties
    @property
    def C(self) -> np.ndarray:
        """Normalised projection matrix, shape (3, 4): ‖C[2, :3]‖ = 1, s > 0 in front (read-only)."""
        return self._C

    @property
    def center(self) -> np.ndarray:
        """Optical centre in the world, shape (3,), metres: the null vector of C."""
        return self._center

    @property
    def optical_axis(self) -> np.ndarray:
        """Unit direction of the optical axis in the world, shape (3,), pointing forward."""
        return self._C[2, :3].copy()

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    # ------------------------------------------------------------------ projection
    def project(self, X_world: np.ndarray) -> np.ndarray:
        """Pixels of world points: X_world (N, 3) → uv (N, 2); a single (3,) gives (2,).

        Points behind the camera still get the (mirrored) pixel of their line of sight;
        use ``depth`` to tell them apart.
        """
        X = np.asarray(X_world, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):  # a point too far is said below
            h = X @ self._C[:, :3].T + self._C[:, 3]
            uv = h[..., :2] / h[..., 2:3]
        if not np.isfinite(uv).all():
            _no_pixel(X, "X_world")
        return uv

    def depth(self, X_world: np.ndarray) -> np.ndarray:
        """Depth s (metres along the optical axis, > 0 in front): (N, 3) → (N,), (3,) → float."""
        X = np.asarray(X_world, dtype=float)
        with np.errstate(over="ignore", invalid="ignore"):
            s = X @ self._C[2, :3] + self._C[2, 3]
        if not np.isfinite(s).all():
            finite_array(X, X.shape, "X_world")
            raise ValueError(f"X_world is too large to project (max |value| {float(np.abs(X).max()):.3g} m)")
        return float(s) if X.ndim == 1 else s

    def project_obj(self, T_world_obj: np.ndarray, X_obj: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of object points X_obj (N, 3) when the object is at ``T_world_obj``."""
        T = finite_array(T_world_obj, (4, 4), "T_world_obj")
        return self.project(np.asarray(X_obj, dtype=float) @ T[:3, :3].T + T[:3, 3])

    def rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Back-projected rays of pixels: (origin (3,), unit directions (N, 3)) pointing forward."""
        uv = as_uv(uv)
        h = np.column_stack([uv, np.ones(len(uv))])
        d = h @ self._M_inv.T
        return self._center.copy(), d / np.linalg.norm(d, axis=1, keepdims=True)

    def backproject(self, uv: np.ndarray, depth: np.ndarray) -> np.ndarray:
        """World points (N, 3) at depth s (metres, (N,) or scalar) along the rays of pixels uv (N, 2)."""
        uv = as_uv(uv)
        s = np.broadcast_to(finite_array(depth, np.shape(depth), "depth", max_abs=MAX_M, unit=" m"), (len(uv),))
        h = np.column_stack([uv, np.ones(len(uv))]) * s[:, None]
        return (h - self._C[:, 3]) @ self._M_inv.T

    def pixel_planes(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The paper's eq. (4): the two planes ``m_u·X + a_u = 0``, ``m_v·X + a_v = 0`` of each pixel.

        Returns m_u (N, 3), a_u (N,), m_v (N, 3), a_v (N,), not normalised (as in the paper).
        """
        uv = as_uv(uv)
        C = self._C
        m_u = C[0, :3] - uv[:, :1] * C[2, :3]
        m_v = C[1, :3] - uv[:, 1:2] * C[2, :3]
        a_u = C[0, 3] - uv[:, 0] * C[2, 3]
        a_v = C[1, 3] - uv[:, 1] * C[2, 3]
        return m_u, a_u, m_v, a_v

    @staticmethod
    def image_line(seg_uv: np.ndarray) -> np.ndarray:
        """Homogeneous image line l = p1 × p2 of a segment (2, 2), scaled so that ``l·(u, v, 1)``
        is the signed distance in pixels (positive to the right of p1 → p2 on the screen)."""
        seg = as_segment(seg_uv)
        p1 = np.append(seg[0], 1.0)
        p2 = np.append(seg[1], 1.0)
        l = np.cross(p1, p2)
        return l / np.linalg.norm(l[:2])

    def interpretation_plane(self, seg_uv: np.ndarray) -> Plane:
        """The plane Cᵀl through the optical centre and the image segment (2, 2).

        Every world point whose image lies on the segment's line is on it. Orientation: the
        signed distance is positive for points in front of the camera whose image lies to the
        right of the directed segment p1 → p2 as seen on the screen (u right, v down).
        """
        pi = self._C.T @ self.image_line(seg_uv)
        norm = float(np.linalg.norm(pi[:3]))
        return Plane(pi[:3] / norm, float(pi[3] / norm))

    def in_image(self, uv: np.ndarray, margin_px: float = 0.0) -> np.ndarray:
        """Boolean mask (N,) of pixels inside the image (pixel centres span [0, size − 1])."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        lo = -0.5 + margin_px
        return (
            (uv[:, 0] >= lo)
            & (uv[:, 1] >= lo)
            & (uv[:, 0] <= self.width - 0.5 - margin_px)
            & (uv[:, 1] <= self.height - 0.5 - margin_px)
        )

    def reprojection_errors(self, X_world: np.ndarray, uv: np.ndarray) -> np.ndarray:
        """Per-point reprojection distance in pixels, shape (N,)."""
        return np.linalg.norm(self.project(X_world) - as_uv(uv), axis=1)

    def __repr__(self) -> str:
        K, _ = self.decompose()
        return (
            f"Camera({self.width}×{self.height}, f≈({K[0, 0]:.1f}, {K[1, 1]:.1f}) px, "
            f"centre={np.round(self._center, 4).tolist()} m)"
        )
