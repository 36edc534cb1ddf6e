"""Rigid transforms and rotations, in the project's one convention.

``T_a_b`` is a 4×4 homogeneous matrix mapping points in frame b to frame a:
``p_a = T_a_b @ p_b``; inner letters cancel (``T_world_rf = T_world_turret @ T_turret_rf``).
Rotation vectors (axis × angle, radians) are the tangent coordinates used by every solver.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "skew",
    "exp_so3",
    "log_so3",
    "make_T",
    "invert_T",
    "transform_points",
    "rot_x",
    "rot_y",
    "rot_z",
    "rotation_angle",
    "pose_error",
    "random_rotation",
    "orthonormalize",
    "check_T",
]


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix: ``skew(a) @ b == np.cross(a, b)``.

    v : array, shape (3,)  ->  array, shape (3, 3)
    """
    x, y, z = np.asarray(v, dtype=float)
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def exp_so3(r: np.ndarray) -> np.ndarray:
    """Rotation matrix of a rotation vector (Rodrigues).

    r : array, shape (3,), axis × angle in radians  ->  R : array, shape (3, 3)
    """
    r = np.asarray(r, dtype=float)
    theta = float(np.linalg.norm(r))
    K = skew(r)
    if theta < 1e-8:
        # Taylor expansion keeps second order exact near zero.
        return np.eye(3) + K + 0.5 * (K @ K)
    a = np.sin(theta) / theta
    b = (1.0 - np.cos(theta)) / theta**2
    return np.eye(3) + a * K + b * (K @ K)


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation vector (axis × angle, radians, angle in [0, π]) of a rotation matrix.

    R : array, shape (3, 3)  ->  r : array, shape (3,)
    """
    R = np.asarray(R, dtype=float)
    w = np.array([R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]])  # 2 sin θ · axis
    cos_t = np.clip((np.trace(R) - 1.0) / 2.0, -1.0, 1.0)
    theta = float(np.arctan2(0.5 * np.linalg.norm(w), cos_t))  # accurate at every angle
    if theta < 1e-6:
        return 0.5 * w
    if np.pi - theta > 1e-3:
        return theta / (2.0 * np.sin(theta)) * w
    # Near π the antisymmetric part vanishes: read the axis off the symmetric part,
    # S = cos θ I + (1 − cos θ) a aᵀ, which carries no sin θ contamination.
    S = 0.5 * (R + R.T)
    A = (S - cos_t * np.eye(3)) / (1.0 - cos_t)
    k = int(np.argmax(np.diag(A)))
    axis = A[:, k] / np.linalg.norm(A[:, k])
    if w @ axis < 0:
        axis = -axis
    return theta * axis


def make_T(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """4×4 homogeneous transform from R (3, 3) and t (3,)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=float).reshape(3)
    return T


def invert_T(T: np.ndarray) -> np.ndarray:
    """Inverse of a rigid transform: ``invert_T(T_a_b) == T_b_a``."""
    T = np.asarray(T, dtype=float)
    R = T[:3, :3]
    t = T[:3, 3]
    return make_T(R.T, -R.T @ t)


def transform_points(T_a_b: np.ndarray, X_b: np.ndarray) -> np.ndarray:
    """Map points from frame b to frame a.

    T_a_b : array, shape (4, 4); X_b : array, shape (N, 3) or (3,)  ->  X_a, same shape as X_b
    """
    X_b = np.asarray(X_b, dtype=float)
    return X_b @ T_a_b[:3, :3].T + T_a_b[:3, 3]


def rot_x(angle_rad: float) -> np.ndarray:
    """Right-handed rotation about +x by ``angle_rad``: array, shape (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(angle_rad: float) -> np.ndarray:
    """Right-handed rotation about +y by ``angle_rad``: array, shape (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(angle_rad: float) -> np.ndarray:
    """Right-handed rotation about +z by ``angle_rad``: array, shape (3, 3)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rotation_angle(R_a: np.ndarray, R_b: np.ndarray) -> float:
    """Angle in radians of the relative rotation ``R_a.T @ R_b`` (geodesic distance).

    Computed as atan2(sin θ, cos θ) from the relative rotation's antisymmetric part and trace, so
    it stays accurate for tiny angles (arccos of the trace alone cannot resolve below ~1e-8 rad).
    """
    R = np.asarray(R_a).T @ np.asarray(R_b)
    sin_t = 0.5 * np.sqrt((R[2, 1] - R[1, 2]) ** 2 + (R[0, 2] - R[2, 0]) ** 2 + (R[1, 0] - R[0, 1]) ** 2)
    cos_t = (np.trace(R) - 1.0) / 2.0
    return float(np.arctan2(sin_t, cos_t))


def pose_error(T_est: np.ndarray, T_true: np.ndarray) -> tuple[float, float]:
    """(rotation error in degrees, translation error in metres) between two poses ``T_world_obj``."""
    rot_deg = np.degrees(rotation_angle(T_est[:3, :3], T_true[:3, :3]))
    trans_m = float(np.linalg.norm(T_est[:3, 3] - T_true[:3, 3]))
    return float(rot_deg), trans_m


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    """A rotation drawn uniformly on SO(3) (from a uniform unit quaternion)."""
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    w, x, y, z = q
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def orthonormalize(R: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (SVD projection onto SO(3))."""
    U, _, Vt = np.linalg.svd(np.asarray(R, dtype=float))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def check_T(T: np.ndarray, name: str = "T", tol: float = 1e-6) -> np.ndarray:
    """Validate a rigid transform and return it as a float array; ValueError otherwise."""
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4):
        raise ValueError(f"{name} must have shape (4, 4), got {T.shape}")
    if not np.all(np.isfinite(T)):
        raise ValueError(f"{name} contains NaN or inf")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=tol):
        raise ValueError(f"{name} last row must be (0, 0, 0, 1), got {T[3]}")
    R = T[:3, :3]
    if not np.allclose(R.T @ R, np.eye(3), atol=tol) or np.linalg.det(R) < 0:
        raise ValueError(f"{name} rotation part is not a proper rotation (RᵀR ≠ I or det < 0)")
    return T
