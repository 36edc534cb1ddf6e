"""Model any polyhedron from a face/edge topology: the paper's §III.1 construction.

The operator names the shape (its faces as vertex loops: a prism, a pyramid, ...) and measures:
range points on some faces (each gives a face plane), clicked image edges (each gives an
interpretation plane), and the support the object lies on (a face plane given outright). Every
vertex is the least-squares point of all the measured planes through it, so an edge shared by two
faces is the segment between two such vertices: it comes out once, consistent with both.

Vertices hidden from the sensors are completed from the operator's geometric hints, each face
plane that no sensor measured being inferred from vertices already fixed:

* ``parallel_faces`` (f, g): f's plane has g's normal and passes through f's fixed vertices;
* ``vertical_faces``: the face is perpendicular to the support (a right prism's sides) and
  passes through two fixed vertices;
* otherwise, a face with three fixed vertices is the plane through them.

The covariance of every vertex (measured or completed) is propagated to first order from the
face fits, the clicks and the support.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..brep import BRep
from ..camera import Camera, as_segment
from ..geometry import Plane, angle_between_planes
from ..transforms import make_T
from .lm import numeric_jacobian
from .observations import PlaneObs, fit_face_plane, interpretation_plane_obs, plane_var_at, support_obs
from .result import ModelResult
from .vertices import solve_vertices

__all__ = ["model_polyhedron"]


def _spans(N: np.ndarray) -> bool:
    if len(N) < 3:
        return False
    sv = np.linalg.svd(np.asarray(N), compute_uv=False)
    return bool(sv[-1] >= 0.05 * sv[0])


def _lsq_point(N: np.ndarray, d: np.ndarray, w: np.ndarray) -> np.ndarray:
    sw = np.sqrt(w)
    return np.linalg.lstsq(N * sw[:, None], -d * sw, rcond=None)[0]


def model_polyhedron(
    camera: Camera,
    faces: Sequence[Sequence[int]],
    *,
    face_points: Mapping[int, np.ndarray] | None = None,
    face_point_covs: Mapping[int, np.ndarray] | None = None,
    edge_segments: Mapping[tuple[int, int], np.ndarray] | None = None,
    support: Plane | None = None,
    support_faces: Sequence[int] = (),
    parallel_faces: Sequence[tuple[int, int]] = (),
    vertical_faces: Sequence[int] = (),
    sigma_px: float = 1.0,
    sigma_point_m: float | None = None,
    support_sigma_m: float = 1e-3,
    plane_fit: str = "tls",
    robust: bool = True,
    min_angle_deg: float = 5.0,
) -> ModelResult:
    """Build a polyhedron from its topology and the measurements of its faces and edges.

    Parameters
    ----------
    camera : Camera
    faces : sequence of vertex loops (counter-clockwise seen from outside), indices 0..V−1.
    face_points : {face index: array (N, 3)} range points aimed at that face, metres.
    face_point_covs : {face index: array (N, 3, 3)} their covariances (m²), optional.
    edge_segments : {(i, j): array (2, 2)} the clicked image segment of the edge joining
        vertices i and j (either order).
    support : Plane, optional, with ``support_faces``: the faces lying on it.
    parallel_faces, vertical_faces : completion hints for hidden vertices (module docstring).
    sigma_px, sigma_point_m, support_sigma_m, plane_fit, robust, min_angle_deg : as ``model_box``.

    Returns
    -------
    ModelResult
        kind "polyhedron", method "planes"; ``model`` in a frame at the vertices' centroid (on
        the support, z along its normal, when the object lies on one); dimensions "edge_i_j"
        (every edge's length) and "height" (above the support) with sigmas; ``cov`` is the
        joint covariance (3V, 3V) of the world vertices (``cov_names`` "v{k}_x", ...).
    """
    loops, V, topo = _topology(faces)
    face_points = dict(face_points or {})
    face_point_covs = dict(face_point_covs or {})
    edge_segments = dict(edge_segments or {})
    _check_hints(len(loops), face_points, support, support_faces, parallel_faces, vertical_faces)

    planes, face_refs, fits, sup = _face_observations(
        face_points, face_point_covs, support, support_faces, sigma_point_m, support_sigma_m, plane_fit, robust
    )
    edge_refs, segs = _edge_observations(camera, loops, topo, edge_segments, planes, face_refs, sigma_px, min_angle_deg)
    measured, incidence = _measured_vertices(V, loops, planes, face_refs, edge_refs)
    X1, cov1, vres, J1 = solve_vertices(planes, incidence, [str(v) for v in measured], return_jacobian=True)
    known, completion, pvec0 = _complete_hidden_vertices(
        V, loops, planes, face_refs, edge_refs, measured, X1, cov1, sup, parallel_faces, vertical_faces
    )
    cov = _vertex_covariance(planes, completion, X1, J1, pvec0, V)
    Xw = np.array([known[v] for v in range(V)])

    origin, R, z = _object_frame(camera, Xw, loops, sup, support_faces)
    dims, sig = _dimensions(Xw, cov, topo.edges, sup, z, support_sigma_m)
    residuals = {"clicks_px": _click_residuals(camera, Xw, segs), "vertex_planes_m": np.concatenate(vres)}
    for f, fit in fits.items():
        residuals[f"face_{f}_points_m"] = fit.fits[fit.method].residuals_m
    return ModelResult(
        kind="polyhedron",
        method="planes",
        model=BRep(((Xw - origin) @ R), topo.edges, topo.faces),
        T_world_obj=make_T(R, origin),
        dimensions=dims,
        sigmas=sig,
        cov=cov,
        cov_names=tuple(f"v{v}_{c}" for v in range(V) for c in "xyz"),
        vertices_world=Xw,
        residuals=residuals,
        details={
            "measured_vertices": completion.measured,
            "completed_vertices": completion.derived,
            "completion": [(s[0], s[1]) + ((s[2],) if s[0] == "plane" else ()) for s in completion.recipe],
            "face_fits": {f: fit.fits for f, fit in fits.items()},
            "planes": planes,
        },
    ).check_finite()


# ------------------------------------------------------------------------------ the measurements
def _topology(faces: Sequence[Sequence[int]]) -> tuple[list[tuple[int, ...]], int, BRep]:
    """The faces as tuples of vertex indices, the number of vertices V and the B-Rep of that topology."""
    loops = [tuple(int(i) for i in f) for f in faces]
    if not loops:
        raise ValueError("model_polyhedron needs the faces of the shape (vertex loops)")
    V = max(max(f) for f in loops) + 1
    return loops, V, BRep.from_faces(np.zeros((V, 3)), loops)


def _check_hints(n_faces, face_points, support, support_faces, parallel_faces, vertical_faces) -> None:
    """Every face index named in range; the support given where a hint needs it."""
    for f in list(face_points) + list(support_faces) + [g for pr in parallel_faces for g in pr] + list(vertical_faces):
        if not 0 <= int(f) < n_faces:
            raise ValueError(f"face index {f} is out of range 0..{n_faces - 1}")
    if support_faces and support is None:
        raise ValueError("support_faces given without the support plane")
    if vertical_faces and support is None:
        raise ValueError("vertical_faces are perpendicular to the support: give the support plane")


def _face_observations(
    face_points, face_point_covs, support, support_faces, sigma_point_m, support_sigma_m, plane_fit, robust
) -> tuple[list[PlaneObs], dict[int, list[int]], dict, PlaneObs | None]:
    """The measured face planes: each face's fit to its range points, then the support once per face on it.

    Returns (planes, face_refs {face: indices into planes}, fits {face: FaceFit}, the support's PlaneObs or None).
    """
    planes: list[PlaneObs] = []
    face_refs: dict[int, list[int]] = {}
    fits = {}
    for f, X in face_points.items():
        fit = fit_face_plane(
            X, covs=face_point_covs.get(f), sigma_m=sigma_point_m, method=plane_fit, robust=robust, label=f"face {f}"
        )
        fits[f] = fit
        face_refs.setdefault(int(f), []).append(len(planes))
        planes.append(fit.obs)
    sup = None
    if support is not None:
        sup = support_obs(support, support_sigma_m)
        for f in support_faces:
            face_refs.setdefault(int(f), []).append(len(planes))
            planes.append(PlaneObs(sup.plane, sup.cov, f"support (face {f})"))
    return planes, face_refs, fits, sup


def _edge_observations(
    camera, loops, topo, edge_segments, planes, face_refs, sigma_px, min_angle_deg
) -> tuple[dict[tuple[int, int], list[int]], dict[tuple[int, int], np.ndarray]]:
    """Appends each clicked edge's interpretation plane to ``planes``.

    An interpretation plane too close to a measured plane of a face along that edge (the face seen
    edge-on) raises ValueError. Returns (edge_refs {edge: indices into planes}, segs {edge: (2, 2)}).
    """
    edge_set = {(min(a, b), max(a, b)) for a, b in topo.edges}
    edge_refs: dict[tuple[int, int], list[int]] = {}
    min_angle = np.radians(min_angle_deg)
    segs = {}
    for key, seg in edge_segments.items():
        i, j = int(key[0]), int(key[1])
        e = (min(i, j), max(i, j))
        if e not in edge_set:
            raise ValueError(f"edge_segments has ({i}, {j}), which is not an edge of the given faces")
        seg = as_segment(seg, f"edge_segments[{key}]")
        ip = interpretation_plane_obs(camera, seg, sigma_px, f"edge {e}")
        for f, loop in enumerate(loops):
            if i in loop and j in loop:
                for pi in face_refs.get(f, []):
                    ang = angle_between_planes(ip.plane, planes[pi].plane)
                    if ang < min_angle:
                        raise ValueError(
                            f"the interpretation plane of edge {e} is {np.degrees(ang):.1f}° from the plane of "
                            f"face {f} (< {min_angle_deg}°): the camera sees that face edge-on, so the edge cannot "
                            "be placed on it"
                        )
        edge_refs.setdefault(e, []).append(len(planes))
        planes.append(ip)
        segs[e] = seg
    return edge_refs, segs


def _vertex_refs(v: int, loops, face_refs: Mapping[int, list], edge_refs) -> list:
    """The planes through vertex v: ("m", i) for measured plane i (its faces' and its edges'), ("d", f)
    for face f's inferred plane. ``face_refs`` lists plain indices (measured) or such pairs."""
    refs = []
    for f, loop in enumerate(loops):
        if v in loop:
            refs += [("m", i) if isinstance(i, int) else i for i in face_refs.get(f, [])]
    for e, idx in edge_refs.items():
        if v in e:
            refs += [("m", i) for i in idx]
    return refs


def _measured_vertices(V: int, loops, planes, face_refs, edge_refs) -> tuple[list[int], list[list[int]]]:
    """The vertices fixed by measured planes alone (three crossing there) and each one's planes."""
    measured, incidence = [], []
    for v in range(V):
        refs = [i for _, i in _vertex_refs(v, loops, face_refs, edge_refs)]
        if _spans(np.array([planes[i].plane.n for i in refs]).reshape(-1, 3)):
            measured.append(v)
            incidence.append(refs)
    if not measured:
        raise ValueError("no vertex is fixed by the measurements: each needs 3 measured planes crossing there")
    return measured, incidence


# ------------------------------------------------------------------- completing the hidden vertices
def _plane_vec(ref, pvec: np.ndarray, dplanes: Mapping[int, np.ndarray]) -> np.ndarray:
    """(n, d) of a plane reference: a measured plane's row of pvec, or an inferred face plane."""
    return pvec[ref[1]] if ref[0] == "m" else dplanes[ref[1]]


def _infer_plane(rule: str, args: tuple, Xk, pvec: np.ndarray, dplanes) -> np.ndarray:
    """(n, d) of a face plane no sensor measured, from its fixed vertices args[0] by the hint ``rule``.

    "parallel": the normal of plane args[1] through the vertices' mean offset; "vertical": containing
    the support's normal (pvec[args[1]]) and the vertices' main direction across it; "through": the
    total-least-squares plane of the vertices.
    """
    pts = np.array([Xk[v] for v in args[0]])
    if rule == "parallel":
        n = _plane_vec(args[1], pvec, dplanes)[:3]
        return np.append(n, -float(np.mean(pts @ n)))
    if rule == "vertical":
        s_n = pvec[args[1]][:3]
        P = pts - pts.mean(axis=0)
        P = P - np.outer(P @ s_n, s_n)
        u = np.linalg.svd(P)[2][0]
        n = np.cross(s_n, u)
        n /= np.linalg.norm(n)
        return np.append(n, -float(np.mean(pts @ n)))
    c = pts.mean(axis=0)
    n = np.linalg.svd(pts - c)[2][-1]
    return np.append(n, -float(n @ c))


def _choose_rule(f: int, loop, known, face_refs, parallel, vertical_faces, sup_ref):
    """The hint that infers face f's plane from its fixed vertices, as (rule, args), or (None, None)."""
    D = [v for v in loop if v in known]
    for g in parallel.get(f, []):
        if face_refs.get(g) and len(D) >= 1:
            return "parallel", (D, face_refs[g][0])
    if f in vertical_faces and len(D) >= 2:
        return "vertical", (D, sup_ref)
    if len(D) >= 3:
        P = np.array([known[v] for v in D])
        if np.linalg.svd(P - P.mean(axis=0), compute_uv=False)[1] > 1e-6:
            return "through", (D,)
    return None, None


def _completion_weights(refs, Nd: np.ndarray, planes, derived_src, block) -> np.ndarray:
    """Weights of the planes (rows of Nd) placing a hidden vertex: 1 / a measured plane's variance at the
    vertex; 1 / an inferred plane's variance along its normal of the fixed vertices it was drawn through."""
    x_guess = _lsq_point(Nd[:, :3], Nd[:, 3], np.ones(len(Nd)))
    var = []
    for ref, row in zip(refs, Nd):
        if ref[0] == "m":
            var.append(plane_var_at(planes[ref[1]], x_guess))
        else:
            src = [u for u in derived_src[ref[1]] if u in block]
            var.append(np.mean([row[:3] @ block[u] @ row[:3] for u in src]) if src else 1e-6)
    return 1.0 / np.maximum(np.array(var), 1e-16)


@dataclass(frozen=True)
class _Completion:
    """How the hidden vertices were completed, as steps to replay in order: ("plane", f, rule, args)
    infers face f's plane (``_infer_plane``), ("vertex", v, refs, w) places vertex v at the weighted
    least-squares point of the planes refs."""

    measured: list[int]
    derived: list[int]
    recipe: list[tuple]

    def replay(self, x1: np.ndarray, pvec: np.ndarray) -> np.ndarray:
        """The completed vertices (3 × len(derived),) from the measured ones x1 (flat) and the planes pvec."""
        Xk = {v: x1[3 * k : 3 * k + 3] for k, v in enumerate(self.measured)}
        dpl: dict[int, np.ndarray] = {}
        for step in self.recipe:
            if step[0] == "plane":
                _, f, rule, args = step
                dpl[f] = _infer_plane(rule, args, Xk, pvec, dpl)
            else:
                _, v, refs, w = step
                Nd = np.array([_plane_vec(r, pvec, dpl) for r in refs])
                Xk[v] = _lsq_point(Nd[:, :3], Nd[:, 3], w)
        return np.concatenate([Xk[v] for v in self.derived]) if self.derived else np.zeros(0)

    def planes_read(self) -> set[int]:
        """The measured planes the recipe reads (the only ones that move the completed vertices)."""
        used = set()
        for step in self.recipe:
            refs = step[2] if step[0] == "vertex" else ([step[3][1]] if step[2] == "parallel" else [])
            used |= {r[1] for r in refs if r[0] == "m"}
        return used


def _complete_hidden_vertices(
    V, loops, planes, face_refs, edge_refs, measured, X1, cov1, sup, parallel_faces, vertical_faces
):
    """Fix the vertices the measurements leave hidden from the hints, round after round.

    Returns (known {vertex: (3,)}, the _Completion to replay, pvec0: the measured planes' (n, d)
    rows, and the support's last when given: the plane "vertical" reads).
    """
    block = {v: cov1[3 * k : 3 * k + 3, 3 * k : 3 * k + 3] for k, v in enumerate(measured)}
    pvec0 = np.array([p.plane.as_vector() for p in planes])
    known = {v: X1[k] for k, v in enumerate(measured)}
    frefs: dict[int, list] = {f: [("m", i) for i in idx] for f, idx in face_refs.items()}
    recipe: list[tuple] = []
    derived_planes: dict[int, np.ndarray] = {}
    derived_src: dict[int, list] = {}
    parallel = {}
    for f, g in parallel_faces:
        parallel.setdefault(int(f), []).append(int(g))
        parallel.setdefault(int(g), []).append(int(f))
    sup_ref = None
    if sup is not None:
        sup_ref = len(planes)
        pvec0 = np.vstack([pvec0, sup.plane.as_vector()])
    progress = True
    while progress and len(known) < V:
        progress = False
        for f, loop in enumerate(loops):
            if frefs.get(f):
                continue
            rule, args = _choose_rule(f, loop, known, frefs, parallel, vertical_faces, sup_ref)
            if rule is not None:
                derived_planes[f] = _infer_plane(rule, args, known, pvec0, derived_planes)
                derived_src[f] = list(args[0])
                recipe.append(("plane", f, rule, args))
                frefs[f] = [("d", f)]
                progress = True
        for v in range(V):
            if v in known:
                continue
            refs = _vertex_refs(v, loops, frefs, edge_refs)
            Nd = np.array([_plane_vec(r, pvec0, derived_planes) for r in refs]).reshape(-1, 4)
            if _spans(Nd[:, :3]):
                w = _completion_weights(refs, Nd, planes, derived_src, block)
                known[v] = _lsq_point(Nd[:, :3], Nd[:, 3], w)
                recipe.append(("vertex", v, refs, w))
                progress = True
    missing = [v for v in range(V) if v not in known]
    if missing:
        raise ValueError(
            f"vertices {missing} are not fixed: no 3 measured or inferred planes cross there; measure or "
            "click more of their faces and edges, or give the hints (parallel_faces, vertical_faces, support)"
        )
    derived = [v for v in range(V) if v not in measured]
    return known, _Completion(measured, derived, recipe), pvec0


def _vertex_covariance(planes, completion: _Completion, X1, J1, pvec0, V: int) -> np.ndarray:
    """Joint covariance (3V, 3V) of the world vertices from the measured planes' covariances: the measured
    vertices through the solver's Jacobian J1, the completed ones through the recipe (central differences)."""
    P = len(planes)
    S = np.zeros((4 * P, 4 * P))
    for i, p in enumerate(planes):
        S[4 * i : 4 * i + 4, 4 * i : 4 * i + 4] = p.cov
    J_all = np.zeros((3 * V, 4 * P))
    for k, v in enumerate(completion.measured):
        J_all[3 * v : 3 * v + 3] = J1[3 * k : 3 * k + 3]
    if completion.derived:
        x1 = X1.reshape(-1)
        Jx = numeric_jacobian(lambda x: completion.replay(x, pvec0), x1, 1e-7, central=True)
        h_p = np.zeros(pvec0.size)  # only the planes the recipe reads move the derived vertices
        h_p[[4 * i + c for i in sorted(completion.planes_read()) for c in range(4)]] = 1e-7
        Jp = numeric_jacobian(
            lambda p: completion.replay(x1, p.reshape(pvec0.shape)), pvec0.reshape(-1), h_p, central=True
        )[:, : 4 * P]
        Jd = Jx @ J1 + Jp
        for k, v in enumerate(completion.derived):
            J_all[3 * v : 3 * v + 3] = Jd[3 * k : 3 * k + 3]
    cov = J_all @ S @ J_all.T
    return 0.5 * (cov + cov.T)


# ------------------------------------------------------------------------------------ the result
def _object_frame(camera, Xw: np.ndarray, loops, sup: PlaneObs | None, support_faces):
    """The object frame's origin (3,) and axes R (3, 3), and the support's upward normal z (None without).

    On the support: the origin at the mean of the vertices of the faces on it, z up (towards the
    camera's side), x along the world's x projected on the support. Else the vertices' centroid,
    the world's axes.
    """
    if sup is None:
        return Xw.mean(axis=0), np.eye(3), None
    z = sup.plane.n if sup.plane.n @ camera.center + sup.plane.d > 0 else -sup.plane.n
    base = sorted({v for f in support_faces for v in loops[f]}) or list(range(len(Xw)))
    origin = Xw[base].mean(axis=0)
    x = np.array([1.0, 0.0, 0.0]) - z[0] * z
    if np.linalg.norm(x) < 1e-6:
        x = np.array([0.0, 1.0, 0.0]) - z[1] * z
    x /= np.linalg.norm(x)
    return origin, np.column_stack([x, np.cross(z, x), z]), z


def _dimensions(Xw: np.ndarray, cov: np.ndarray, edges, sup, z, support_sigma_m: float) -> tuple[dict, dict]:
    """Every edge's length, the height above the support (when given) and their sigmas, and the sigma
    of the vertices' centroid ("position")."""
    V = len(Xw)
    dims, sig = {}, {}
    for a, b in edges:
        d = Xw[b] - Xw[a]
        L = float(np.linalg.norm(d))
        g = np.zeros(3 * V)
        g[3 * b : 3 * b + 3] = d / L
        g[3 * a : 3 * a + 3] = -d / L
        name = f"edge_{min(a, b)}_{max(a, b)}"
        dims[name] = L
        sig[name] = float(np.sqrt(max(g @ cov @ g, 0.0)))
    if sup is not None:
        hts = Xw @ z + (sup.plane.d if sup.plane.n @ z > 0 else -sup.plane.d)
        top = int(np.argmax(hts))
        dims["height"] = float(hts[top])
        g = np.zeros(3 * V)
        g[3 * top : 3 * top + 3] = z
        sig["height"] = float(np.sqrt(max(g @ cov @ g + support_sigma_m**2, 0.0)))
    sel = np.zeros((3, 3 * V))
    for v in range(V):
        sel[:, 3 * v : 3 * v + 3] = np.eye(3) / V
    sig["position"] = float(np.sqrt(np.trace(sel @ cov @ sel.T)))
    return dims, sig


def _click_residuals(camera, Xw: np.ndarray, segs) -> np.ndarray:
    """Signed pixel distances of each clicked end to the image line of its model edge."""
    click_res = []
    for (a, b), seg in segs.items():
        uv = camera.project(Xw[[a, b]])
        l = np.cross(np.append(uv[0], 1.0), np.append(uv[1], 1.0))
        l /= np.linalg.norm(l[:2])
        click_res += list(np.column_stack([seg, np.ones(2)]) @ l)
    return np.array(click_res)
