"""Range scans across a solid: which returns are the object, and where its lateral tangents are.

A horizontal scan sweeps the beam across a cylinder or cone: the returns on the object form one
run of smoothly varying ranges; beside it the beam misses or hits the background (a jump in
range). The lateral tangent beam lies between the last beam that hits the object and the first
that does not (DESIGN.md): we take the mid-angle, with the uncertainty of a uniform position
within that step combined with the turret's own pointing noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..rangefinder import RangeFinderSpec, RangeScan, beam_direction, beam_point_cov
from .returns import Returns, make_returns
from .robust import object_runs

__all__ = ["TangentBeam", "ScanSegment", "segment_scan"]


@dataclass(frozen=True)
class TangentBeam:
    """The beam grazing the object at one end of a scan's object run.

    side : -1 at the low-index end of the run, +1 at the high-index end.
    pan_rad, tilt_rad : mid-angles between the last hit and the first beam off the object.
    sigma_pan_rad, sigma_tilt_rad : their standard deviations.
    distance_m : range of the last hit (the distance at which the beam grazes).
    scan_index : which scan it comes from.
    """

    side: int
    pan_rad: float
    tilt_rad: float
    sigma_pan_rad: float
    sigma_tilt_rad: float
    distance_m: float
    scan_index: int

    def direction(
        self, T_world_turret: np.ndarray, pan_rad: float | None = None, tilt_rad: float | None = None
    ) -> np.ndarray:
        """Unit world direction (3,) of the beam (optionally at perturbed angles)."""
        pan = self.pan_rad if pan_rad is None else pan_rad
        tilt = self.tilt_rad if tilt_rad is None else tilt_rad
        return beam_direction(pan, tilt) @ np.asarray(T_world_turret)[:3, :3].T


@dataclass(frozen=True)
class ScanSegment:
    """The object's part of one scan.

    hits_world : array, shape (N, 3), the returns on the object, metres.
    covs : array, shape (N, 3, 3), their covariance (m²).
    dirs_world : array, shape (N, 3), the unit direction of each return's beam (as commanded).
    returns : Returns, the same returns with their beams and noise (for likelihood fits).
    tangents : tuple of TangentBeam (0 to 2: an end of the run at an end of the scan gives none).
    run : (start, stop) indices of the run in the scan.
    """

    hits_world: np.ndarray
    covs: np.ndarray
    dirs_world: np.ndarray
    returns: Returns
    tangents: tuple
    run: tuple


def segment_scan(
    scan: RangeScan,
    T_world_turret: np.ndarray,
    spec: RangeFinderSpec,
    *,
    jump_m: float = 0.05,
    scan_index: int = 0,
    keep=None,
) -> ScanSegment:
    """Find the object in a scan (the run of returns with the most points) and its tangent beams.

    keep : optional function (N, 3) world points → (N,) bool; when given, runs are ranked by how
    many of their points it keeps (e.g. the points inside the camera's silhouette wedge).
    ValueError when the scan has fewer than 3 returns on one object.
    """
    if not isinstance(scan, RangeScan):
        raise ValueError(f"scans must be RangeScan instances, got {type(scan).__name__}")
    runs = object_runs(scan.range_m, jump_m)
    if not runs:
        raise ValueError(f"scan {scan_index} has no return at all: aim it across the object")
    X = scan.points(T_world_turret)
    score = []
    for a, b in runs:
        n = b - a if keep is None else int(np.count_nonzero(keep(X[a:b])))
        score.append((n, -float(np.nanmedian(scan.range_m[a:b]))))
    a, b = runs[max(range(len(runs)), key=lambda i: score[i])]
    if b - a < 3:
        raise ValueError(f"scan {scan_index}: only {b - a} return(s) on the object; scan at the finest step across it")
    covs = beam_point_cov(T_world_turret, scan.pan_rad[a:b], scan.tilt_rad[a:b], scan.range_m[a:b], spec)
    sig_t = float(np.hypot(spec.step_rad / np.sqrt(12.0), spec.sigma_angle))
    tangents = []
    for side, last, nxt in ((-1, a, a - 1), (1, b - 1, b)):
        if nxt < 0 or nxt >= len(scan):
            continue
        dp = abs(scan.pan_rad[nxt] - scan.pan_rad[last])
        dt = abs(scan.tilt_rad[nxt] - scan.tilt_rad[last])
        # The grazing beam is anywhere between the two: uniform over the gap, plus pointing noise.
        tangents.append(
            TangentBeam(
                side,
                0.5 * float(scan.pan_rad[nxt] + scan.pan_rad[last]),
                0.5 * float(scan.tilt_rad[nxt] + scan.tilt_rad[last]),
                float(np.hypot(dp / np.sqrt(12.0), spec.sigma_angle)) if dp > 0 else sig_t,
                float(np.hypot(dt / np.sqrt(12.0), spec.sigma_angle)),
                float(scan.range_m[last]),
                scan_index,
            )
        )
    ret = make_returns(
        T_world_turret, scan.pan_rad[a:b], scan.tilt_rad[a:b], scan.range_m[a:b], spec.sigma_range_m, spec.sigma_angle
    )
    return ScanSegment(X[a:b], covs, ret.dirs, ret, tuple(tangents), (a, b))
