"""Where Calibrate turret suggests aiming next: points on the known faces, and how far from where it is
aimed a beam may land.

``face_candidates``: a grid over each planar face of a known object that both the camera and the
turret face, inside the image and seen by both (the first database surface on the camera's ray and on
the turret's beam, and the site's robot, where it stands, not in the way), each with its room to the
face's edges along the face's two axes.

``landing_sd``: the σ, along those axes, of where a beam aimed at a candidate lands when the turret
pose it is aimed with is off by δ ~ N(0, C) (δ in the turret frame, ``T · exp(δ)``): to first order the
beam's point moves by ΔX = R(ω × X_t + v) and slides along the beam back onto the face's plane,
s = (I − d nᵀ / n·d) ΔX. A candidate is offered only where its room is ``ROOM_SIGMAS`` σ or more: the
beam lands on the face aimed at, so the solve associates it with the right plane (a beam that grazes an
edge is associated with the neighbouring face, and a pose centimetres off settles on the wrong side).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from core.transforms import skew

__all__ = [
    "Candidates",
    "face_candidates",
    "landing_rows",
    "landing_sd",
    "room_ratio",
    "unlocking",
    "ROOM_SIGMAS",
]

GRID = 9  # points along each axis of a face
MAX_FACES = 40  # the largest faces that get a grid (a site of thousands of objects: the start stays quick)
EDGE_M = 0.01  # the grid keeps this far inside a face's edges (a thinner face: its middle line)
ROOM_SIGMAS = 2.5  # a candidate's room to its face's edges, in σ of where its beam lands
ROOM_SPARE_M = 0.005  # ... plus this


@dataclass(frozen=True)
class Candidates:
    """X (M, 3) world points, normals (M, 3), names ("table face 1"), e1 / e2 (M, 3) the face's in-plane
    axes, room (M, 4): the distances to the face's extent along −e1, +e1, −e2, +e2 (metres), objects (M,) the
    object each lies on ("table")."""

    X: np.ndarray
    normals: np.ndarray
    names: list
    e1: np.ndarray
    e2: np.ndarray
    room: np.ndarray
    objects: list

    def take(self, keep: np.ndarray) -> Candidates:
        keep = np.asarray(keep, bool)
        return Candidates(
            self.X[keep],
            self.normals[keep],
            [n for n, k in zip(self.names, keep) if k],
            self.e1[keep],
            self.e2[keep],
            self.room[keep],
            [o for o, k in zip(self.objects, keep) if k],
        )


def face_candidates(site, camera, T_world_turret: np.ndarray) -> Candidates:
    """The candidate points of ``site``'s known objects for ``camera`` and the turret at ``T_world_turret``."""
    rows = []
    origin = np.asarray(T_world_turret, float)[:3, 3]
    faces = [f for obj in site.objects() for f in _faces(obj, camera.center, origin)]
    faces.sort(key=lambda f: -f[-1])  # the largest first: a site of thousands of objects keeps MAX_FACES of them
    for name, k, V, n, _ in faces[:MAX_FACES]:
        for x, e1, e2, room in _grid(V, n):
            rows.append((x, n, f"{name} face {k}", e1, e2, room, name))
    if rows:
        X = np.array([r[0] for r in rows])
        uv = camera.project(X)
        inside = (uv[:, 0] >= 4) & (uv[:, 0] <= camera.width - 5) & (uv[:, 1] >= 4) & (uv[:, 1] <= camera.height - 5)
        inside &= camera.depth(X) > 0
        owners = np.array([r[6] for r in rows], dtype=object)
        mesh, owner = site.surfaces()
        robot = _robot_mesh(site)
        for o in (camera.center, origin):
            inside &= _first_is(mesh, owner, o, X, owners)
            if robot is not None:  # a beam at the table behind the arm lands on the arm
                d = X - o
                dist = np.linalg.norm(d, axis=1)
                _, t = _first_hits(robot, o, d / dist[:, None])
                inside &= ~(t < dist - 0.005)
        rows = [r for r, keep in zip(rows, inside) if keep]
    if not rows:
        z = np.zeros((0, 3))
        return Candidates(z, z, [], z, z, np.zeros((0, 4)), [])
    X, N, names, E1, E2, room, objects = zip(*rows)
    return Candidates(np.array(X), np.array(N), list(names), np.array(E1), np.array(E2), np.array(room), list(objects))


def landing_rows(T_world_turret: np.ndarray, c: Candidates) -> np.ndarray:
    """G (M, 2, 6): where a beam aimed at each candidate through ``T_world_turret`` lands, along e1 and
    e2, moves by G δ when that pose is off by δ (first order)."""
    if not len(c.X):
        return np.zeros((0, 2, 6))
    T = np.asarray(T_world_turret, float)
    R, t = T[:3, :3], T[:3, 3]
    Xt = (c.X - t) @ R
    eye = np.broadcast_to(np.eye(3), (len(Xt), 3, 3))
    A = np.einsum("ij,mjk->mik", R, np.concatenate([-np.stack([skew(x) for x in Xt]), eye], axis=2))
    d = c.X - t
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nd = np.einsum("mi,mi->m", c.normals, d)
    P = eye - d[:, :, None] * c.normals[:, None, :] / nd[:, None, None]  # slide along the beam onto the plane
    return np.stack([np.einsum("mi,mij,mjk->mk", e, P, A) for e in (c.e1, c.e2)], axis=1)


def landing_sd(T_world_turret: np.ndarray, cov: np.ndarray, c: Candidates) -> np.ndarray:
    """σ (M, 2), metres, along e1 and e2 of where beams aimed at the candidates through ``T_world_turret``
    land when that pose is off by δ of covariance ``cov`` (6, 6)."""
    G = landing_rows(T_world_turret, c)
    return np.sqrt(np.maximum(np.einsum("mak,kl,mal->ma", G, cov, G), 0.0))


def room_ratio(c: Candidates, sd: np.ndarray) -> np.ndarray:
    """(M,): the room a beam landing with σ ``sd`` (M, 2) needs over the room each candidate has (≤ 1:
    it lands on the face aimed at)."""
    need = ROOM_SIGMAS * sd + ROOM_SPARE_M
    return np.maximum(need[:, 0] / c.room[:, :2].min(axis=1), need[:, 1] / c.room[:, 2:].min(axis=1))


def unlocking(G_target: np.ndarray, cov: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(J,): the landing σ, worst of e1 and e2 (metres), of one target (G_target (2, 6), ``landing_rows``)
    after each candidate beam (rows (J, 6), ``core.calibration.turret_plane_rows``) is added to the
    aiming pose's information (``cov`` (6, 6) its inverse): which beam makes a face that cannot be hit yet
    reachable soonest."""
    U = rows @ cov  # (J, 6)
    denom = 1.0 + np.einsum("ji,ji->j", U, rows)
    base = np.einsum("ak,kl,al->a", G_target, cov, G_target)  # (2,)
    gu = U @ G_target.T  # (J, 2): gᵀ C j
    var = base[None, :] - gu**2 / denom[:, None]
    return np.sqrt(np.maximum(var, 0.0))


def _faces(obj, camera_center: np.ndarray, turret_origin: np.ndarray):
    """(object name, face index, vertices (K, 3), unit normal, area) of each planar face of ``obj``, in the
    world, that faces both the camera and the turret."""
    T = obj.T_world_obj
    model = obj.model
    if not model.faces:
        return
    normals = model.face_normals() @ T[:3, :3].T
    for k, face in enumerate(model.faces):
        V = model.vertices[list(face)] @ T[:3, :3].T + T[:3, 3]
        n, c = normals[k], V.mean(axis=0)
        if n @ (camera_center - c) > 0 and n @ (turret_origin - c) > 0:
            area = 0.5 * float(np.linalg.norm(np.cross(V - c, np.roll(V, -1, axis=0) - c).sum(axis=0)))
            yield obj.name, k, V, n, area


def _grid(V: np.ndarray, n: np.ndarray):
    """(X, e1, e2, room (4,)) on a GRID × GRID grid over the planar polygon V (K, 3) of normal n, EDGE_M
    inside its extent (a thinner extent: its middle), inside the polygon; e1 along its longest edge."""
    c = V.mean(axis=0)
    edges = np.roll(V, -1, axis=0) - V
    e1 = edges[int(np.argmax(np.linalg.norm(edges, axis=1)))]
    e1 = e1 / np.linalg.norm(e1)
    e2 = np.cross(n, e1)
    uv = (V - c) @ np.stack([e1, e2], axis=1)  # the polygon in the face's plane
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    axes = [
        np.linspace(a + EDGE_M, b - EDGE_M, GRID) if b - a > 4 * EDGE_M else np.array([0.5 * (a + b)])
        for a, b in zip(lo, hi)
    ]
    for a in axes[0]:
        for b in axes[1]:
            if _inside(uv, np.array([a, b])):
                yield c + a * e1 + b * e2, e1, e2, np.array([a - lo[0], hi[0] - a, b - lo[1], hi[1] - b])


def _inside(poly: np.ndarray, p: np.ndarray) -> bool:
    """Whether the 2D point p lies inside the polygon poly (K, 2) (even–odd rule)."""
    x, y = p
    inside = False
    for (x1, y1), (x2, y2) in zip(poly, np.roll(poly, -1, axis=0)):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


def _first_is(mesh, owner, origin: np.ndarray, X: np.ndarray, names: np.ndarray) -> np.ndarray:
    """(M,) bool: whether the first database triangle on the ray from ``origin`` towards each X (M, 3)
    belongs to its object ``names`` (M,) and lies at X (within 5 mm), by the surfaces' ray index at once."""
    if mesh is None:
        return np.zeros(len(X), bool)
    d = X - origin
    dist = np.linalg.norm(d, axis=1)
    tri, t = _first_hits(mesh, origin, d / dist[:, None])
    ok = tri >= 0
    out = np.zeros(len(X), bool)
    out[ok] = (np.asarray(owner)[tri[ok]] == names[ok]) & (np.abs(t[ok] - dist[ok]) < 0.005)
    return out


def _first_hits(mesh, origin: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The first triangle of ``mesh`` on each ray from ``origin`` along the unit directions d (M, 3) (−1: none)
    and how far along it lies (inf: none)."""
    tri = mesh.ray.intersects_first(np.broadcast_to(origin, d.shape), d)
    ok = tri >= 0
    t = np.full(len(d), np.inf)
    n = mesh.face_normals[tri[ok]]
    t[ok] = np.einsum("ij,ij->i", n, mesh.triangles[tri[ok], 0] - origin) / np.einsum("ij,ij->i", n, d[ok])
    return tri, t


def _robot_mesh(site):
    """The site's robot where it stands, as one triangle mesh (None: no robot)."""
    cell = getattr(site, "robot", None)
    if cell is None:
        return None
    import trimesh

    Vs, Fs, offset = [], [], 0
    for _, brep, T in cell.link_breps():
        V, F = brep.triangles()
        Vs.append(V @ T[:3, :3].T + T[:3, 3])
        Fs.append(F + offset)
        offset += len(V)
    return trimesh.Trimesh(np.vstack(Vs), np.vstack(Fs), process=False) if Vs else None
