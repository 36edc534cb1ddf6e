"""The calibrations' share of a modelled object's uncertainty.

Every modelling method states σ from its measurements (clicks, range noise) for a given camera C
and turret pose ``T_world_turret``. Both are themselves estimates: the camera's DLT and the
turret's calibration have covariances, and their errors move every model built through them in a
correlated way that no amount of clicking averages out. ``with_calibration_uncertainty`` rebuilds
the model with the calibrations moved ±1σ along each principal axis of their covariances (central
differences: 2 × (6 + 11) rebuilds at most; exact to first order, and it sees the methods' own
non-linearities at the scale that matters) and adds each quantity's spread to the measurements'
covariance:

    cov = cov_measurements + Σ_k δ_k δ_kᵀ,   δ_k = (q(+σ_k v_k) − q(−σ_k v_k)) / 2

for the quantities q of the result's ``cov_names``, and the same spread Σ_k ‖δ_k‖² is added to the
variance of each stated σ (every dimension, and the position). The camera and the turret are
calibrated from different data, so their shares add.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from ..calibration import check_covariance, perturbed_camera, perturbed_turret, principal_steps
from ..camera import Camera
from ..transforms import log_so3
from .result import ModelResult

__all__ = ["with_calibration_uncertainty", "result_vector"]


def result_vector(result: ModelResult, reference: ModelResult) -> np.ndarray:
    """The quantities of ``reference.cov_names`` read from ``result`` (which must be the same kind
    of model, built from the same measurements through moved calibrations)."""
    if result.kind != reference.kind or result.cov_names != reference.cov_names:
        raise ValueError(
            f"cannot compare a {result.kind} ({len(result.cov_names)} quantities) with a "
            f"{reference.kind} ({len(reference.cov_names)})"
        )
    names = reference.cov_names
    if result.kind == "box":
        # Sizes along the reference's axes (a moved calibration cannot swap them, but the box frame
        # may be chosen with other signs or order: match each axis to the reference's nearest).
        Rr, R = reference.T_world_obj[:3, :3], result.T_world_obj[:3, :3]
        M = Rr.T @ R
        perm = np.argmax(np.abs(M), axis=1)
        if len(set(perm.tolist())) != 3:
            raise ValueError("the moved box's axes do not match the reference's")
        sizes = np.array([result.dimensions[f"size_{'xyz'[j]}"] for j in perm])
        R_aligned = R[:, perm] * np.sign(M[np.arange(3), perm])  # each axis signed like the reference's: ≈ Rr
        rot = log_so3(Rr.T @ R_aligned)
        # The box frame's origin is the bottom face's centre: the same point whatever the axes' order.
        q = {
            "size_x": sizes[0],
            "size_y": sizes[1],
            "size_z": sizes[2],
            "x": result.T_world_obj[0, 3],
            "y": result.T_world_obj[1, 3],
            "z": result.T_world_obj[2, 3],
            "rot_x": rot[0],
            "rot_y": rot[1],
            "rot_z": rot[2],
        }
        return np.array([q[n] for n in names], dtype=float)
    if result.kind in ("cylinder", "cone"):
        a = result.axis.direction
        mid = result.axis.point + 0.5 * result.dimensions["height"] * a
        q = dict(result.dimensions)
        q.update(mid_x=mid[0], mid_y=mid[1], mid_z=mid[2], axis_x=a[0], axis_y=a[1], axis_z=a[2])
        return np.array([q[n] for n in names], dtype=float)
    if result.kind == "polyhedron":
        return np.asarray(result.vertices_world, dtype=float).reshape(-1)  # v0_x, v0_y, v0_z, v1_x, ...
    raise ValueError(f"no calibration share for a model of kind {result.kind!r}")


def _sigma_quantities(result: ModelResult, reference: ModelResult) -> dict[str, np.ndarray]:
    """The quantities behind each of ``reference.sigmas``: every dimension (a box's sizes along the
    reference's axes) and the position (a vector whose squared norm's mean is the σ²)."""
    if result.kind == "box":
        v = result_vector(result, reference)
        names = list(reference.cov_names)
        q = {k: np.array([v[names.index(k)]]) for k in ("size_x", "size_y", "size_z")}
        q["position"] = result.T_world_obj[:3, 3]
    elif result.kind in ("cylinder", "cone"):
        q = {k: np.array([v]) for k, v in result.dimensions.items()}
        a = reference.axis.direction
        mid = result.axis.point + 0.5 * result.dimensions["height"] * result.axis.direction
        q["axis_position"] = (np.eye(3) - np.outer(a, a)) @ mid
    else:
        q = {k: np.array([v]) for k, v in result.dimensions.items()}
        q["position"] = np.asarray(result.vertices_world, dtype=float).mean(axis=0)
    return {k: q[k] for k in reference.sigmas if k in q}


def with_calibration_uncertainty(
    build: Callable[[Camera, np.ndarray], ModelResult],
    camera: Camera,
    T_world_turret: np.ndarray,
    *,
    camera_cov: np.ndarray | None = None,
    turret_cov: np.ndarray | None = None,
    result: ModelResult | None = None,
) -> ModelResult:
    """A modelled object with the camera's and the turret's calibration uncertainty in its σ.

    Parameters
    ----------
    build : callable (camera, T_world_turret) -> ModelResult
        Builds the model from the *same* measurements (raw pan/tilt/range, not world points)
        through the given calibrations.
    camera, T_world_turret : the calibrations the model is built with.
    camera_cov : array (12, 12), optional
        Covariance of ``camera.C.ravel()`` (``calibrate_dlt(...).cov``).
    turret_cov : array (6, 6), optional
        Covariance of the turret's pose (``calibrate_turret(...).cov``: rotation vector, translation
        in the turret frame).
    result : the model built with the nominal calibrations, if already at hand.

    Returns
    -------
    ModelResult
        ``result`` with ``cov`` and ``sigmas`` including the calibrations' share; its
        ``details["sigma_parts"]`` holds σ of every dimension (and position) split into
        "measurements", "camera calibration", "turret calibration" (metres), and
        ``details["cov_measurements"]`` the measurements' covariance alone.
        Without either covariance the result is returned unchanged.
    """
    base = build(camera, T_world_turret) if result is None else result
    if camera_cov is None and turret_cov is None:
        return base
    shares: dict[str, tuple[np.ndarray, dict[str, float]]] = {}
    if camera_cov is not None:
        steps = principal_steps(check_covariance(camera_cov, 12, "camera_cov (of C's entries)"))
        shares["camera calibration"] = _share(
            lambda d: build(perturbed_camera(camera, d), T_world_turret), steps, base, "the camera"
        )
    if turret_cov is not None:
        steps = principal_steps(check_covariance(turret_cov, 6, "turret_cov (of the turret's pose)"))
        shares["turret calibration"] = _share(
            lambda d: build(camera, perturbed_turret(T_world_turret, d)), steps, base, "the turret"
        )
    cov = base.cov + sum(c for c, _ in shares.values())
    parts = {"measurements": dict(base.sigmas)}
    var = {k: v**2 for k, v in base.sigmas.items()}
    for name, (_, var_k) in shares.items():
        parts[name] = {k: float(np.sqrt(v)) for k, v in var_k.items()}
        for k, v in var_k.items():
            var[k] += v
    details = dict(base.details, sigma_parts=parts, cov_measurements=base.cov)
    notes = base.notes + ("σ include the calibrations' share (" + ", ".join(shares) + ")",)
    sigmas = {k: float(np.sqrt(v)) for k, v in var.items()}
    return replace(base, cov=cov, sigmas=sigmas, details=details, notes=notes)


def _share(build_at: Callable[[np.ndarray], ModelResult], steps: np.ndarray, base: ModelResult, what: str):
    """Σ_k δ_k δ_kᵀ of the ``cov_names`` quantities and Σ_k ‖δ_k‖² of each σ's quantity, over the
    principal ±1σ steps (central differences). A rebuild that fails is a ValueError saying so."""
    n = len(base.cov_names)
    share = np.zeros((n, n))
    var = {k: 0.0 for k in _sigma_quantities(base, base)}
    for d in steps:
        try:
            plus, minus = build_at(d), build_at(-d)
            dq = 0.5 * (result_vector(plus, base) - result_vector(minus, base))
            qp, qm = _sigma_quantities(plus, base), _sigma_quantities(minus, base)
        except ValueError as exc:
            raise ValueError(
                f"the model cannot be rebuilt with {what}'s calibration moved by 1σ ({exc}): that "
                f"calibration is too uncertain for this model; calibrate {what} again"
            ) from exc
        share += np.outer(dq, dq)
        for k in var:
            var[k] += float(np.sum((0.5 * (qp[k] - qm[k])) ** 2))
    return share, var
