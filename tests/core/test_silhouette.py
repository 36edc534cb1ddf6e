"""Silhouettes of a mesh's smooth regions (core.silhouette) against the analytic outlines.

Cylinder, cone and sphere meshes (trimesh primitives) at a known pose through a known camera: the
contour generator's projection lies within the tessellation's own tolerance of the analytic
outline, and within 0.5 px at the sizes the issue names (a 2,000-face cylinder, a 5,120-face
sphere). The tessellation's tolerance: the faceted surface lies between the true surface (its
vertices are on it) and the surface shrunk by the faces' sag (a cylinder of radius r cut into n
sides: radius r·cos(π/n); a sphere: the distance of the nearest face plane from the centre), so
its outline lies between the two surfaces' analytic outlines.
"""

import numpy as np
import pytest
import trimesh

from core.brep import BRep, Revolution
from core.camera import Camera
from core.mesh_features import brep_from_mesh
from core.silhouette import SmoothSides, contour_segments
from core.transforms import invert_T, make_T, rot_x, rot_z

K = np.array([[800.0, 0, 319.5], [0, 800.0, 239.5], [0, 0, 1]])


def _look_at(eye, target, up=(0.0, 0.0, 1.0)):
    eye = np.asarray(eye, float)
    z = np.asarray(target, float) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    return invert_T(make_T(np.column_stack([x, np.cross(z, x), z]), eye))


CAM = Camera.from_intrinsics(K, _look_at([0.6, -0.7, 0.45], [0, 0, 0.05]), 640, 480)
T = make_T(rot_z(0.3) @ rot_x(0.2), [0.02, -0.01, 0.08])
C_OBJ = (CAM.center - T[:3, 3]) @ T[:3, :3]


def _project(S_obj):
    W = np.asarray(S_obj, float).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
    return CAM.project(W).reshape(-1, 2, 2)


def _dense(S, n=25):
    t = np.linspace(0.0, 1.0, n)[None, :, None]
    return (S[:, :1] + t * (S[:, 1:] - S[:, :1])).reshape(-1, 2)


def _to_segments(P, S):
    """Distance (N,) from each point P (N, 2) to the nearest of the segments S (M, 2, 2)."""
    a, d, p = S[:, 0][None], (S[:, 1] - S[:, 0])[None], P[:, None]
    t = np.clip(((p - a) * d).sum(-1) / np.maximum((d * d).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(a + t[..., None] * d - p, axis=-1).min(axis=1)


def _to_lines(P, S):
    """Distance (N,) from each point to the nearest of the infinite lines through segments S."""
    a, d = S[:, 0], S[:, 1] - S[:, 0]
    n = np.column_stack([-d[:, 1], d[:, 0]]) / np.linalg.norm(d, axis=1)[:, None]
    return np.abs(np.einsum("mk,nmk->nm", n, P[:, None] - a[None])).min(axis=1)


def _mesh_silhouette(mesh):
    b = brep_from_mesh(mesh.vertices, mesh.faces)
    return b, _project(contour_segments(b.vertices, SmoothSides.of(b.vertices, b.faces, b.edges), C_OBJ))


@pytest.mark.parametrize("sections", [64, 500])
def test_cylinder_mesh_shows_its_two_side_lines_on_the_analytic_tangent_lines(sections):
    r, h = 0.05, 0.2
    b, sil = _mesh_silhouette(trimesh.creation.cylinder(r, h, sections=sections))
    assert len(sil) == 2 and len(b.edges) == 2 * sections  # the two side lines; the rims stay feature edges
    true = _project(Revolution([0, 0, -h / 2], [0, 0, h / 2], r, r).silhouette(C_OBJ))
    inner = _project(
        Revolution(
            [0, 0, -h / 2], [0, 0, h / 2], r * np.cos(np.pi / sections), r * np.cos(np.pi / sections)
        ).silhouette(C_OBJ)
    )
    tol = _to_lines(_dense(inner), true).max()  # the tessellation's own tolerance
    err = _to_lines(_dense(sil), true)
    assert err.max() <= tol + 1e-9, (err.max(), tol)
    # each analytic line is drawn: both mesh side lines, one near each
    assert sorted(np.argmin([[_to_lines(_dense(s[None]), t[None]).max() for t in true] for s in sil], axis=1)) == [0, 1]
    # their ends are on the rims: within one side's length (2πr/n, projected) of the analytic ends
    spacing_px = 800 * 2 * np.pi * r / sections / (np.linalg.norm(C_OBJ) - r)
    assert _to_segments(sil.reshape(-1, 2), true).max() <= spacing_px
    if sections == 500:  # 2,000 faces: the figure
        assert len(trimesh.creation.cylinder(r, h, sections=sections).faces) == 2000
        assert err.max() <= 0.5


def test_cone_mesh_shows_its_two_side_lines():
    r, h, n = 0.05, 0.2, 500
    b, sil = _mesh_silhouette(trimesh.creation.cone(r, h, sections=n))
    assert len(sil) == 2 and len(b.edges) == n  # the base rim
    true = _project(Revolution([0, 0, 0], [0, 0, h], r, 0.0).silhouette(C_OBJ))
    inner = _project(Revolution([0, 0, 0], [0, 0, h], r * np.cos(np.pi / n), 0.0).silhouette(C_OBJ))
    err = _to_lines(_dense(sil), true)
    assert err.max() <= _to_lines(_dense(inner), true).max() + 1e-9 and err.max() <= 0.5
    assert sorted(np.argmin([[_to_lines(_dense(s[None]), t[None]).max() for t in true] for s in sil], axis=1)) == [0, 1]


def _sphere_outline(centre, radius, n=2000):
    """The analytic outline of a sphere (obj frame) seen from C_OBJ, as image segments (n, 2, 2)."""
    q = C_OBJ - centre
    d = np.linalg.norm(q)
    u = q / d
    ctr = centre + radius * radius / d * u
    rad = radius * np.sqrt(1.0 - radius * radius / d / d)
    e1 = np.cross(u, [1.0, 0, 0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    th = np.linspace(0.0, 2.0 * np.pi, n + 1)
    P = ctr + rad * (np.cos(th)[:, None] * e1 + np.sin(th)[:, None] * e2)
    return _project(np.stack([P[:-1], P[1:]], axis=1))


@pytest.mark.parametrize("subdivisions", [3, 4])
def test_sphere_mesh_outline_is_the_analytic_outline(subdivisions):
    r = 0.1
    mesh = trimesh.creation.icosphere(subdivisions, r)
    b, sil = _mesh_silhouette(mesh)
    assert len(b.edges) == 0 and len(sil) > 20  # no sharp edge: the outline is all there is to draw
    true = _sphere_outline(np.zeros(3), r)
    # tessellation: every face plane is at least r_in from the centre, so the outline lies between
    # the outlines of the spheres of radii r_in and r
    n = mesh.face_normals
    r_in = float(np.min(np.einsum("ij,ij->i", n, mesh.vertices[mesh.faces[:, 0]])))
    tol = _to_segments(_sphere_outline(np.zeros(3), r_in)[:, 0], true).max()
    err_out = _to_segments(_dense(sil), true).max()  # drawn → analytic
    err_in = _to_segments(true[:, 0], sil).max()  # analytic → drawn: the whole outline is drawn
    assert max(err_out, err_in) <= tol + 1e-6, (err_out, err_in, tol)
    if subdivisions == 4:  # 5,120 faces
        assert len(mesh.faces) == 5120 and max(err_out, err_in) <= 0.5
    # a closed outline: every vertex of the contour is on two of its sides
    _, counts = np.unique(
        contour_segments(b.vertices, SmoothSides.of(b.vertices, b.faces, b.edges), C_OBJ).reshape(-1, 3),
        axis=0,
        return_counts=True,
    )
    assert np.all(counts == 2)


def test_capsule_mesh_has_an_outline_and_no_sharp_edge():
    mesh = trimesh.creation.capsule(0.2, 0.05, count=[32, 32])
    b, sil = _mesh_silhouette(mesh)
    assert len(b.edges) == 0 and len(sil) > 10
    # the outline lies on the capsule's outline: within the tessellation's sag of the two
    # hemispheres' and the cylinder's analytic outlines
    parts = np.concatenate(
        [_sphere_outline(np.array([0, 0, z]), 0.05) for z in (-0.1, 0.1)]
        + [_project(Revolution([0, 0, -0.1], [0, 0, 0.1], 0.05, 0.05).silhouette(C_OBJ))]
    )
    assert _to_segments(_dense(sil), parts).max() < 1.0


def test_polyhedra_have_no_smooth_sides():
    for model in (BRep.box(0.3, 0.2, 0.1), BRep.prism(np.array([[0, 0], [1, 0], [0.5, 1.0]]), 0.2)):
        assert len(SmoothSides.of(model.vertices, model.faces, model.edges)) == 0
    # a box as triangles without its diagonals as edges: the diagonals are coplanar, never a contour
    m = trimesh.creation.box([0.3, 0.2, 0.1])
    assert len(SmoothSides.of(m.vertices, [tuple(f) for f in m.faces], np.zeros((0, 2), int))) == 12  # the 12 box edges


def test_inconsistent_winding_gives_no_silhouette():
    mesh = trimesh.creation.icosphere(2, 0.1)
    F = mesh.faces.copy()
    F[::2] = F[::2, ::-1]  # every other triangle turned inside out
    s = SmoothSides.of(mesh.vertices, [tuple(f) for f in F], np.zeros((0, 2), int))
    good = SmoothSides.of(mesh.vertices, [tuple(f) for f in mesh.faces], np.zeros((0, 2), int))
    assert len(good) == len(mesh.edges_unique) and len(s) < len(good)
    # the sides kept join two faces both flipped or both not: they still face consistently
    kept = {tuple(x) for x in s.sides}
    assert kept <= {tuple(x) for x in good.sides}
