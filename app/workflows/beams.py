"""The range finder's beams checked against the database: the one check every workflow that uses beams
makes (Calibrate turret, Model object, Model polyhedron; Designate states its own along the camera's ray
with the same limit).

Each beam (pan, tilt, range) is cast from the turret through the database (``Site.raycast``, with the
turret calibration in use); where it meets a known object, its measured range is compared with the
range to that object's surface:

    Δ = ρ_measured − ρ_database

σ_Δ combines the range finder's σ_ρ, its pointing noise (a turret step's quantisation) times the range
and the tangent of the beam's incidence on the surface (a beam off by an angle meets an oblique face
nearer or farther), and the turret calibration's share when it has a covariance: the calibration moved
±1σ along its principal axes (``core.calibration.principal_steps``), each moved beam met with the hit
surface's plane, the range changes added in quadrature. |Δ| > ``LIMIT_SIGMA`` σ_Δ, with the measured
point also that far from every database surface, disagrees (a beam that grazes an edge and lands on the
neighbouring face, where the calibration's error sends it, is on the database's surfaces): farther
than the database, its surface is not there (the object has moved); nearer, the object has moved or
something not in the database stands in front of it. A workflow leaves such beams out and says so
(``disagreement_text``): the database must be brought up to date first.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["LIMIT_SIGMA", "BeamCheck", "check_beams", "disagreement_text"]

LIMIT_SIGMA = 3.0  # a beam's range beyond this many σ from the database's disagrees
MAX_INCIDENCE_TAN = 10.0  # the pointing share is capped at a grazing incidence of ~84°


@dataclass(frozen=True)
class BeamCheck:
    """One beam against the database: ``object`` it meets there ("" for none), its measured and the
    database's range (metres; NaN where the beam meets nothing) and σ of their difference."""

    object: str
    measured_m: float
    expected_m: float
    sigma_m: float
    off_surface_m: float = float("inf")  # the measured point's distance to the nearest database surface

    @property
    def delta_m(self) -> float:
        return self.measured_m - self.expected_m

    @property
    def disagrees(self) -> bool:
        """At a known object, measured farther or nearer than ``LIMIT_SIGMA`` σ from its surface."""
        limit = LIMIT_SIGMA * self.sigma_m
        return (
            bool(self.object) and np.isfinite(self.delta_m) and abs(self.delta_m) > limit and self.off_surface_m > limit
        )

    @property
    def farther(self) -> bool:
        """Disagrees, measured beyond the database's surface (the surface is not there)."""
        return self.disagrees and self.delta_m > 0


def check_beams(site, T_world_turret, pan_rad, tilt_rad, range_m, turret_cov=None) -> list[BeamCheck]:
    """Each beam (arrays (N,): radians, radians, metres) checked against ``site``'s database through the
    turret pose ``T_world_turret`` (4, 4) and its covariance ``turret_cov`` (6, 6, or None: not
    counted). A beam without a return (NaN range) meets nothing measured: its check never disagrees."""
    from core.calibration import perturbed_turret, principal_steps
    from core.rangefinder import beam_ray

    T = np.asarray(T_world_turret, float)
    pan, tilt, rho = (np.atleast_1d(np.asarray(a, float)).reshape(-1) for a in (pan_rad, tilt_rad, range_m))
    spec = site.scene.rangefinder
    steps = principal_steps(turret_cov) if turret_cov is not None else np.zeros((0, 6))
    moved = [perturbed_turret(T, s) for s in steps]
    origin, dirs = beam_ray(T, pan, tilt)
    surfaces = None  # the database as one mesh, fetched only when a beam disagrees (its first build imports trimesh)
    out = []
    for i, d in enumerate(dirs.reshape(-1, 3)):
        hit = site.raycast(origin, d) if np.isfinite(rho[i]) else None
        if hit is None:
            out.append(BeamCheck("", float(rho[i]), float("nan"), float("nan")))
            continue
        n = np.asarray(hit.normal, float)
        cos = abs(float(n @ d))
        tan = min(np.sqrt(max(1.0 - cos**2, 0.0)) / max(cos, 1e-9), MAX_INCIDENCE_TAN)
        var = float(spec.sigma_range_m) ** 2 + (hit.distance_m * spec.sigma_angle * tan) ** 2
        for Tm in moved:  # the calibration's share: the moved beam met with the hit surface's plane
            o_m, d_m = beam_ray(Tm, pan[i], tilt[i])
            along = float(n @ d_m)
            if abs(along) > 1e-6:
                var += (float(n @ (hit.X_world - o_m)) / along - hit.distance_m) ** 2
        sigma = float(np.sqrt(var))
        off = float("inf")
        if abs(rho[i] - hit.distance_m) > LIMIT_SIGMA * sigma:  # (only then does it matter: it costs a search)
            surfaces = surfaces or site.surfaces()
            off = _off_facing_faces(*surfaces, hit.name, origin + rho[i] * d, d)
        out.append(BeamCheck(hit.name, float(rho[i]), float(hit.distance_m), sigma, off))
    return out


def _off_facing_faces(mesh, owner, name: str, X: np.ndarray, d: np.ndarray) -> float:
    """The distance (metres) from the measured point X to the faces of object ``name`` turned towards the
    beam (direction d): a beam that grazed an edge and landed on the next such face is on them."""
    if mesh is None:
        return float("inf")
    idx = np.flatnonzero((np.asarray(owner) == name) & (mesh.face_normals @ d < 0))
    if not len(idx):
        return float("inf")
    sub = mesh.submesh([idx], append=True)
    return float(sub.nearest.on_surface(X.reshape(1, 3))[1][0])


def disagreement_text(checks, labels=None, done: str = "left out", aimed=None) -> str:
    """What the operator is told of the beams that disagree (``checks``, a list of BeamCheck; ``labels``
    their names, default "beam k"), one sentence per object, e.g. "the parallelepiped has moved: update
    its pose first (the range finder disagrees, left out: 3 parallelepiped face 2 centre, 1968 mm measured
    against 1847 mm expected, 3σ = 21 mm)"; "" when none disagrees. ``done``: what became of the beams.
    ``aimed``: the object each beam was aimed at, where known (None, or "" for one): a beam aimed at an
    object that met another one in the database was aimed at an object that is not there any more, so that
    object is named, as moved."""
    labels = list(labels) if labels is not None else [f"beam {i + 1}" for i in range(len(checks))]
    aimed = list(aimed) if aimed is not None else [""] * len(checks)
    by_object: dict[str, list[int]] = {}
    for i, c in enumerate(checks):
        if c.disagrees:
            by_object.setdefault(aimed[i] or c.object, []).append(i)
    out = []
    for name, idx in by_object.items():
        beams = "; ".join(
            f"{labels[i]}, {1000 * checks[i].measured_m:.0f} mm measured against {1000 * checks[i].expected_m:.0f} "
            f"mm expected, {LIMIT_SIGMA:.0f}σ = {1000 * LIMIT_SIGMA * checks[i].sigma_m:.0f} mm"
            for i in idx
        )
        moved = all(checks[i].farther or (aimed[i] and aimed[i] != checks[i].object) for i in idx)
        what = (
            f"the {name} has moved: update its pose first"
            if moved
            else f"the {name} has moved, or something not in the database stands in front of it: update its pose first"
        )
        out.append(f"{what} (the range finder disagrees, {done}: {beams})")
    return ". ".join(out)
