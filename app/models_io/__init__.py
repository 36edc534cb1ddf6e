"""Model files in and out: ViSP ``.cao`` and meshes (OBJ, STL, PLY, glTF/GLB) ⇄ ``core.brep.BRep``.

``load_model(path)`` and ``save_model(model, path)`` choose the format by the file's suffix.
``MODEL_LOADERS`` names the reader of each kind of model file a scene may reference (``"cao"``,
``"mesh"``).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from core.brep import BRep

from .cao import (
    CaoError,
    CaoOptions,
    CaoWarning,
    cao_text,
    concat_breps,
    read_cao,
    read_cao_options,
    read_init,
    read_init_pixels,
    write_cao,
)
from .mesh import MAX_MESH_BYTES, MAX_MESH_FACES, MESH_SUFFIXES, MeshError, MeshWarning, read_mesh, write_mesh

__all__ = [
    "MODEL_LOADERS",
    "CaoError",
    "CaoWarning",
    "CaoOptions",
    "MeshError",
    "MeshWarning",
    "MODEL_SUFFIXES",
    "MAX_MESH_BYTES",
    "MAX_MESH_FACES",
    "load_model",
    "save_model",
    "read_cao",
    "read_cao_options",
    "read_init",
    "read_init_pixels",
    "write_cao",
    "cao_text",
    "read_mesh",
    "write_mesh",
    "concat_breps",
]

MODEL_SUFFIXES = (".cao",) + MESH_SUFFIXES


def load_model(path: str | Path, angle_deg: float = 30.0, *, max_faces: int = MAX_MESH_FACES) -> BRep:
    """Read a model file (``.cao`` or a mesh; ``angle_deg``: meshes' feature-edge threshold;
    ``max_faces``: the most triangles a mesh may hold, see ``read_mesh``; a ``.cao`` has its own limits)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".cao":
        return read_cao(path)
    if suffix in MESH_SUFFIXES:
        return read_mesh(path, angle_deg=angle_deg, max_faces=max_faces)
    raise ValueError(f"{path}: unknown model type {suffix!r}; use one of {', '.join(MODEL_SUFFIXES)}")


def save_model(model: BRep, path: str | Path, comment: str = "") -> None:
    """Write a model file (``.cao`` keeps edges and cylinders; meshes keep the surface)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".cao":
        write_cao(model, path, comment)
    elif suffix in MESH_SUFFIXES:
        write_mesh(model, path)
    else:
        raise ValueError(f"{path}: unknown model type {suffix!r}; use one of {', '.join(MODEL_SUFFIXES)}")


# The reader of each kind of model file a scene file may name: kind → fn(path) -> BRep.
MODEL_LOADERS: dict[str, Callable[[Path], BRep]] = {"cao": read_cao, "mesh": read_mesh}
