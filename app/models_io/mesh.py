"""Meshes (OBJ, STL, PLY, glTF/GLB) through trimesh: read as feature-edge B-Reps, write surfaces.

Reading merges duplicate vertices (an STL is a triangle soup) and reduces the triangles to their
feature edges with ``core.mesh_features.brep_from_mesh``: a triangulated planar face adds no
false edge. A curved region keeps its triangles as faces whose sides are not edges; the overlay
draws its silhouette at each pose (``core.silhouette``, ``app.overlay.model_wireframe``): a
cylinder's two side lines, a sphere's outline. A glTF scene's meshes are placed by their node
transforms and merged into one model. Bad input raises ``MeshError`` naming the file (and, for
OBJ, the line) and the problem; a mesh that gives nothing to draw (no sharp edge and no curved
region with an outline, e.g. each triangle given twice) loads with a ``MeshWarning`` naming the file.

Writing tessellates the model (``BRep.triangles``: faces fan-triangulated, cylinders and cones
with ``n_circle`` sides) and exports the surface; ``.gltf`` embeds its buffer so the file stands
alone. The edges are not written (these formats carry surfaces): reading the file back recovers
the polyhedral edges through the dihedral-angle threshold, and a cylinder comes back as two rim
polylines and a smooth side drawn by its silhouettes.
"""

from __future__ import annotations

from pathlib import Path

import warnings

import numpy as np

from core.brep import BRep
from core.mesh_features import brep_from_mesh
from core.silhouette import SmoothSides

__all__ = ["MeshError", "MeshWarning", "MESH_SUFFIXES", "read_mesh", "write_mesh"]

MESH_SUFFIXES = (".obj", ".stl", ".ply", ".gltf", ".glb")


class MeshError(ValueError):
    """A mesh file that cannot be read; the message names the file and the problem."""


class MeshWarning(UserWarning):
    """A mesh that loads but that the overlay cannot show; the message names the file."""


def _check_obj(path: Path) -> None:
    """Line-level check of an OBJ's vertices and faces, so an error names its line."""
    n_vertices = 0
    with open(path, "r", errors="replace") as fh:
        for number, raw in enumerate(fh, start=1):
            tokens = raw.split("#", 1)[0].split()
            if not tokens:
                continue
            if tokens[0] == "v":
                try:
                    xyz = [float(t) for t in tokens[1:4]]
                except ValueError:
                    raise MeshError(f"{path}:{number}: vertex coordinates must be numbers, got {raw.strip()!r}") from None
                if len(xyz) < 3 or not np.all(np.isfinite(xyz)):
                    raise MeshError(f"{path}:{number}: a vertex needs 3 finite coordinates, got {raw.strip()!r}")
                n_vertices += 1
            elif tokens[0] == "f":
                if len(tokens) < 4:
                    raise MeshError(f"{path}:{number}: a face needs at least 3 vertices, got {raw.strip()!r}")
                for ref in tokens[1:]:
                    try:
                        i = int(ref.split("/")[0])
                    except ValueError:
                        raise MeshError(f"{path}:{number}: face vertex {ref!r} is not an index") from None
                    if i == 0 or i > n_vertices or -i > n_vertices:
                        raise MeshError(f"{path}:{number}: face vertex index {i} refers to no vertex (1..{n_vertices} defined so far)")


def read_mesh(path: str | Path, angle_deg: float = 30.0) -> BRep:
    """Read a mesh file into a feature-edge ``BRep`` (object frame = the file's frame, metres).

    Parameters
    ----------
    path : an ``.obj``, ``.stl``, ``.ply``, ``.gltf`` or ``.glb`` file.
    angle_deg : dihedral angle from which an edge between two triangles is drawn.
    """
    import trimesh

    path = Path(path).resolve()
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise MeshError(f"{path}: unknown mesh type {suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    if not path.is_file():
        raise MeshError(f"{path}: no such file")
    if suffix == ".obj":
        _check_obj(path)
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for bad files
        raise MeshError(f"{path}: cannot read the mesh: {exc}") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise MeshError(f"{path}: the file holds no triangles")
    V = np.asarray(mesh.vertices, dtype=float)
    if not np.all(np.isfinite(V)):
        raise MeshError(f"{path}: the mesh has non-finite vertex coordinates")
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    try:
        model = brep_from_mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces), angle_deg=angle_deg)
    except ValueError as exc:
        raise MeshError(f"{path}: {exc}") from None
    if not len(model.edges) and not len(SmoothSides.of(model.vertices, model.faces, model.edges)):
        warnings.warn(MeshWarning(
            f"{path}: this mesh gives nothing to draw on the overlay (no sharp edge and no curved surface with an "
            f"outline, e.g. each triangle given twice); export the object again from its CAD program as a closed surface"),
            stacklevel=2)
    return model


def write_mesh(model: BRep, path: str | Path, n_circle: int = 48) -> None:
    """Write a model's surface (triangles, object frame, metres) as OBJ, STL, PLY, glTF or GLB."""
    import trimesh
    from trimesh.exchange.gltf import export_gltf

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"{path}: unknown mesh type {suffix!r}; use one of {', '.join(MESH_SUFFIXES)}")
    V, T = model.triangles(n_circle)
    if len(T) == 0:
        raise ValueError(f"{path}: the model has no surface to export (edges or circles only); export it as .cao")
    mesh = trimesh.Trimesh(V, T, process=False)
    if suffix == ".gltf":
        files = export_gltf(trimesh.Scene(mesh), embed_buffers=True)
        (name, data), = files.items()
        path.write_bytes(data)
    else:
        mesh.export(str(path))
