"""Geometry of the laser range finder on its pan/tilt turret.

The turret convention, written once (every other module uses these functions):

* ``turret`` frame: origin where the pan and tilt axes cross (the beam leaves from there);
  **x forward** (the beam at pan = tilt = 0), **y to the left**, **z up** (the pan axis).
  Picture the turret on the table looking ahead: x points where it looks, z at the ceiling.
* **pan** θx (radians) turns about +z: positive pans to the left (counter-clockwise seen from
  above). **tilt** θy (radians) is the elevation of the beam above the turret's xy plane:
  positive tilts up. The beam's unit direction in the turret frame is
  ``d = (cos θy cos θx, cos θy sin θx, sin θy)``, and a return at range ρ (metres) is the point
  ``X_turret = ρ d`` — spherical coordinates (azimuth θx, elevation θy, radius ρ).
* ``rf`` frame (the paper's R_r): the beam frame, z along the beam, x to the right of the beam,
  y down (like a camera's optical frame), so ``X_turret = T_turret_rf(θx, θy) @ (0, 0, ρ)``:
  ``T_turret_rf = Rz(θx) · Ry(−θy) · R_home`` where ``R_home`` maps rf axes onto turret axes at
  pan = tilt = 0 (z_rf → x, x_rf → −y, y_rf → −z).
* ``T_world_turret`` (from calibration) places the turret in the world:
  ``X_world = T_world_turret @ T_turret_rf(θx, θy) @ (0, 0, ρ)``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .camera import Camera, as_uv
from .checks import finite_array
from .transforms import check_T, make_T, rot_y, rot_z

__all__ = [
    "RangeFinderSpec",
    "RangeScan",
    "R_TURRET_RF_HOME",
    "beam_direction",
    "T_turret_rf",
    "beam_point",
    "beam_ray",
    "aim",
    "quantize_angle",
    "beam_point_cov",
    "AimResult",
    "aim_at_pixel",
]

# Columns are the rf axes expressed in the turret frame at pan = tilt = 0.
R_TURRET_RF_HOME = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


@dataclass(frozen=True)
class RangeFinderSpec:
    """Sensor parameters (defaults: the paper's time-of-flight PS10 on a PTU-D46 turret).

    sigma_range_m : range noise σ_ρ (time of flight), metres.
    min_range_m, max_range_m : valid measuring range; outside it the device reports error 255.
    step_rad : turret angular resolution (0.0514° a step for the PTU-D46).
    sigma_angle_rad : pointing noise of the beam; by default the quantisation noise of one step
        (step / √12), since the turret lands exactly on a step.
    """

    sigma_range_m: float = 0.005
    min_range_m: float = 0.6
    max_range_m: float = 10.0
    step_rad: float = float(np.radians(0.0514))
    sigma_angle_rad: float | None = None

    @property
    def sigma_angle(self) -> float:
        """Effective pointing noise (radians)."""
        if self.sigma_angle_rad is not None:
            return float(self.sigma_angle_rad)
        return self.step_rad / np.sqrt(12.0)


def _angles(pan_rad, tilt_rad):
    pan = np.asarray(pan_rad, dtype=float)
    tilt = np.asarray(tilt_rad, dtype=float)
    if not (np.all(np.isfinite(pan)) and np.all(np.isfinite(tilt))):
        raise ValueError("pan/tilt angles contain NaN or inf")
    return np.broadcast_arrays(pan, tilt)


def beam_direction(pan_rad, tilt_rad) -> np.ndarray:
    """Unit beam direction in the turret frame: shape (..., 3) for angles of shape (...)."""
    pan, tilt = _angles(pan_rad, tilt_rad)
    ct = np.cos(tilt)
    return np.stack([ct * np.cos(pan), ct * np.sin(pan), np.sin(tilt)], axis=-1)


def T_turret_rf(pan_rad: float, tilt_rad: float) -> np.ndarray:
    """Pose (4, 4) of the beam frame rf in the turret frame at the given pan and tilt (radians)."""
    return make_T(rot_z(float(pan_rad)) @ rot_y(-float(tilt_rad)) @ R_TURRET_RF_HOME, np.zeros(3))


def beam_ray(T_world_turret: np.ndarray, pan_rad, tilt_rad) -> tuple[np.ndarray, np.ndarray]:
    """The beam in the world: origin (3,) and unit directions (..., 3)."""
    T = np.asarray(T_world_turret, dtype=float)
    return T[:3, 3].copy(), beam_direction(pan_rad, tilt_rad) @ T[:3, :3].T


def beam_point(T_world_turret: np.ndarray, pan_rad, tilt_rad, range_m) -> np.ndarray:
    """World points (..., 3) measured at pan, tilt (radians) and range (metres); NaN range → NaN."""
    origin, d = beam_ray(T_world_turret, pan_rad, tilt_rad)
    rho = np.asarray(range_m, dtype=float)
    return origin + rho[..., None] * d


def aim(T_world_turret: np.ndarray, X_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angles that put the beam on world points, and the range there.

    X_world : array, shape (N, 3) or (3,). Returns pan_rad, tilt_rad, range_m, each (N,) or scalar.
    ValueError naming the input for a T_world_turret that is no finite rigid transform, points that
    are not finite (NaN, inf) or not (N, 3) / (3,), and a point at the turret's origin.
    """
    T = check_T(T_world_turret, "T_world_turret")
    X = finite_array(X_world, (3,) if np.ndim(X_world) == 1 else (None, 3), "X_world")
    Xt = (X - T[:3, 3]) @ T[:3, :3]  # R.T @ (X - t), row-wise
    rho = np.linalg.norm(Xt, axis=-1)
    if np.any(rho < 1e-9):
        raise ValueError("cannot aim at the turret's own origin")
    pan = np.arctan2(Xt[..., 1], Xt[..., 0])
    tilt = np.arcsin(np.clip(Xt[..., 2] / rho, -1.0, 1.0))
    return pan, tilt, rho


def quantize_angle(angle_rad, step_rad: float):
    """Nearest turret position: the angle rounded to a whole number of steps."""
    return np.round(np.asarray(angle_rad, dtype=float) / step_rad) * step_rad


def beam_point_cov(
    T_world_turret: np.ndarray, pan_rad, tilt_rad, range_m, spec: RangeFinderSpec = RangeFinderSpec()
) -> np.ndarray:
    """Covariance (N, 3, 3), m², of measured world points: σ_ρ along the beam, ρ·σ_angle across it.

    Pan moves the point along ``ρ cos θy`` (the horizontal circle), tilt along ``ρ``.
    """
    pan, tilt = _angles(pan_rad, tilt_rad)
    pan, tilt = np.atleast_1d(pan), np.atleast_1d(tilt)
    rho = np.atleast_1d(np.asarray(range_m, dtype=float))
    R = np.asarray(T_world_turret, dtype=float)[:3, :3]
    d = beam_direction(pan, tilt)
    e_pan = np.stack([-np.sin(pan), np.cos(pan), np.zeros_like(pan)], axis=-1)
    e_tilt = np.stack([-np.sin(tilt) * np.cos(pan), -np.sin(tilt) * np.sin(pan), np.cos(tilt)], axis=-1)
    sa = spec.sigma_angle
    cov_t = (
        spec.sigma_range_m**2 * d[:, :, None] * d[:, None, :]
        + ((rho * np.cos(tilt) * sa) ** 2)[:, None, None] * e_pan[:, :, None] * e_pan[:, None, :]
        + ((rho * sa) ** 2)[:, None, None] * e_tilt[:, :, None] * e_tilt[:, None, :]
    )
    return R @ cov_t @ R.T


@dataclass(frozen=True)
class RangeScan:
    """A sequence of beams: pan_rad, tilt_rad, range_m, each shape (N,); range NaN = no return.

    Misses are kept: the lateral tangent planes of a scanned object lie between the last beam
    that hits it and the first that misses it.
    """

    pan_rad: np.ndarray
    tilt_rad: np.ndarray
    range_m: np.ndarray
    meta: dict = field(default_factory=dict, compare=False)

    def __post_init__(self):
        pan, tilt, rho = (np.asarray(a, dtype=float).reshape(-1) for a in (self.pan_rad, self.tilt_rad, self.range_m))
        if not (len(pan) == len(tilt) == len(rho)):
            raise ValueError(f"scan arrays differ in length: pan {len(pan)}, tilt {len(tilt)}, range {len(rho)}")
        if not (np.all(np.isfinite(pan)) and np.all(np.isfinite(tilt))):
            raise ValueError("scan angles contain NaN or inf")
        if np.any(rho[np.isfinite(rho)] <= 0):
            raise ValueError("scan ranges must be positive (NaN for no return)")
        object.__setattr__(self, "pan_rad", pan)
        object.__setattr__(self, "tilt_rad", tilt)
        object.__setattr__(self, "range_m", rho)

    def __len__(self) -> int:
        return len(self.pan_rad)

    @property
    def hits(self) -> np.ndarray:
        """Boolean mask (N,) of beams that returned a range."""
        return np.isfinite(self.range_m)

    def points(self, T_world_turret: np.ndarray) -> np.ndarray:
        """World points (N, 3) of every beam, NaN rows for misses."""
        return beam_point(T_world_turret, self.pan_rad, self.tilt_rad, self.range_m)

    def rays(self, T_world_turret: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World beams of every shot, hit or miss: origin (3,), unit directions (N, 3)."""
        return beam_ray(T_world_turret, self.pan_rad, self.tilt_rad)


@dataclass(frozen=True)
class AimResult:
    """Outcome of aiming the beam at a clicked pixel.

    pan_rad, tilt_rad : the last commanded angles. range_m : the last range (NaN if no return).
    X_world : array, shape (3,), the measured point (NaN if no return). error_px : distance
    between its image and the clicked pixel. iterations, converged : as usual.
    """

    pan_rad: float
    tilt_rad: float
    range_m: float
    X_world: np.ndarray
    error_px: float
    iterations: int
    converged: bool


def aim_at_pixel(
    camera: Camera,
    T_world_turret: np.ndarray,
    uv: np.ndarray,
    measure: Callable[[float, float], float | None],
    *,
    depth_guess_m: float = 2.0,
    step_rad: float | None = None,
    tol_px: float = 0.25,
    max_iter: int = 12,
) -> AimResult:
    """Put the beam on the surface point seen at a clicked pixel, despite the camera/turret parallax.

    The depth along the pixel's ray is unknown until measured; iterate: take a depth on the
    ray → aim the turret at that point → measure → the measured point's depth along the ray
    becomes the next guess. On a smooth surface this is a contraction whenever the baseline is
    small against the range. ``measure(pan_rad, tilt_rad)`` returns a range in metres, or None
    for no return (then the guess is pushed 20 % further and retried). With ``step_rad`` the
    angles are rounded to whole turret steps and iteration also stops when they stop changing.
    """
    uv = as_uv(np.asarray(uv, dtype=float).reshape(1, 2))
    c, r = camera.rays(uv)
    r = r[0]
    lam = float(depth_guess_m) / max(float(r @ camera.optical_axis), 1e-6)
    last = None
    pan = tilt = rho = np.nan
    X = np.full(3, np.nan)
    err = np.inf
    for it in range(1, max_iter + 1):
        pan, tilt, _ = aim(T_world_turret, c + lam * r)
        pan, tilt = float(pan), float(tilt)
        if step_rad is not None:
            pan, tilt = float(quantize_angle(pan, step_rad)), float(quantize_angle(tilt, step_rad))
        if last == (pan, tilt):
            converged = bool(np.isfinite(err) and (err <= tol_px or step_rad is not None))
            return AimResult(pan, tilt, rho, X, err, it - 1, converged)
        last = (pan, tilt)
        got = measure(pan, tilt)
        if got is None or not np.isfinite(got):
            rho, X, err = np.nan, np.full(3, np.nan), np.inf
            lam *= 1.2
            continue
        rho = float(got)
        X = beam_point(T_world_turret, pan, tilt, rho)
        err = float(np.linalg.norm(camera.project(X) - uv[0]))
        if err <= tol_px:
            return AimResult(pan, tilt, rho, X, err, it, True)
        lam = max(float((X - c) @ r), 1e-3)
    return AimResult(pan, tilt, rho, X, err, max_iter, False)
