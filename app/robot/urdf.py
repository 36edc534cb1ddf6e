"""A robot from its URDF file: yourdfpy parses the XML, this module checks it and builds a ``RobotModel``.

URDF's boxes, cylinders and spheres become ``BRep.box`` / ``BRep.cylinder`` / a sphere placed as URDF
centres them (``core.robot.shapes``); meshes are read through trimesh into mesh B-Reps
(``app.models_io.read_mesh`` for OBJ, STL, PLY, glTF; trimesh's COLLADA reader for ``.dae``), scaled as
the URDF says. A mesh's file name is resolved as ROS tools do: ``package://name/path`` and relative
names against the URDF's folder and its parents, ``file://`` as a path.

Refused, as one line naming the file and what is wrong (``UrdfError``, a ``ValueError``): text that
is not XML or not a ``<robot>``, a joint without a parent or child link or naming an unknown link,
a joint type mcit does not move (floating, planar), a revolute or prismatic joint without limits, a
mesh file that is missing or unreadable, a tree that is not one tree.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from core.robot import Joint, LinkShape, Mimic, RobotModel, box_shape, cylinder_shape, mesh_shape, sphere_shape

__all__ = ["UrdfError", "load_robot", "load_scene_robot"]


class UrdfError(ValueError):
    """A URDF that mcit cannot use; the message names the file and what is wrong."""


def _check_xml(path: Path) -> None:
    """Refuse a file that is not well-formed XML with a <robot> root and joints naming their links (yourdfpy
    would read around such faults, or fail without saying where)."""
    from xml.etree import ElementTree

    try:
        root = ElementTree.parse(path).getroot()
    except ElementTree.ParseError as exc:
        raise UrdfError(f"{path}: not XML ({exc}); a URDF is an XML file with a <robot> element") from None
    if root.tag != "robot":
        raise UrdfError(f"{path}: the root element is <{root.tag}>; a URDF's is <robot name=...>")
    for k, joint in enumerate(root.findall("joint")):
        name = joint.get("name")
        what = f"joint {name!r}" if name else f"joint #{k + 1}"
        if not name or not joint.get("type"):
            raise UrdfError(f"{path}: {what} needs a name and a type attribute")
        for role in ("parent", "child"):
            element = joint.find(role)
            if element is None or not element.get("link"):
                raise UrdfError(f"{path}: {what} has no <{role} link=...>; a joint names its parent and child links")


def _mesh_file(filename: str, urdf_dir: Path) -> Path | None:
    """The file a URDF mesh name refers to, or None."""
    name = str(filename)
    if name.startswith("file://"):
        p = Path(name[len("file://") :])
        return p if p.is_file() else None
    rest = name[len("package://") :] if name.startswith("package://") else name
    p = Path(rest)
    if p.is_absolute():
        return p if p.is_file() else None
    parts = p.parts
    for base in (urdf_dir, *urdf_dir.parents):
        for skip in range(min(len(parts), 2)):  # package://<package>/path: with and without the package's name
            candidate = base.joinpath(*parts[skip:])
            if candidate.is_file():
                return candidate
    return None


def _read_mesh_file(path: Path):
    from app.models_io import MESH_SUFFIXES, read_mesh

    if path.suffix.lower() in MESH_SUFFIXES:
        return read_mesh(path)
    import trimesh

    from core.mesh_features import brep_from_mesh

    mesh = trimesh.load(str(path), force="mesh", process=False)
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{path}: the file holds no triangles")
    mesh.merge_vertices()
    return brep_from_mesh(np.asarray(mesh.vertices, dtype=float), np.asarray(mesh.faces))


def _shape(geometry, origin, urdf_dir: Path, meshes: dict, where: str) -> LinkShape:
    T = np.eye(4) if origin is None else np.asarray(origin, dtype=float)
    if geometry is None:
        raise UrdfError(f"{where}: has no <geometry>")
    if geometry.box is not None:
        return box_shape(geometry.box.size, T)
    if geometry.cylinder is not None:
        return cylinder_shape(float(geometry.cylinder.radius), float(geometry.cylinder.length), T)
    if geometry.sphere is not None:
        return sphere_shape(float(geometry.sphere.radius), T)
    if geometry.mesh is not None:
        file = _mesh_file(geometry.mesh.filename, urdf_dir)
        if file is None:
            raise UrdfError(f"{where}: mesh file {geometry.mesh.filename!r} not found (looked beside the URDF)")
        if file not in meshes:
            try:
                meshes[file] = _read_mesh_file(file)
            except ValueError as exc:
                raise UrdfError(f"{where}: {exc}") from None
        scale = geometry.mesh.scale
        scale = np.ones(3) if scale is None else np.broadcast_to(np.asarray(scale, dtype=float), (3,))
        return mesh_shape(meshes[file], T, scale)
    raise UrdfError(f"{where}: <geometry> holds no box, cylinder, sphere or mesh")


def _joint(j, links: set, where: str) -> Joint:
    w = f"{where}: joint {j.name!r}"
    for role in ("parent", "child"):
        link = getattr(j, role)
        if link is None:
            raise UrdfError(f"{w} has no <{role} link=...>")
        if link not in links:
            raise UrdfError(f"{w}: its {role} link {link!r} is not defined (add a <link name={link!r}/>)")
    if j.type not in ("revolute", "continuous", "prismatic", "fixed"):
        raise UrdfError(f"{w}: type {j.type!r} is not supported (revolute, continuous, prismatic, fixed)")
    lower, upper, velocity = -np.inf, np.inf, np.inf
    if j.type in ("revolute", "prismatic"):
        if j.limit is None or j.limit.lower is None or j.limit.upper is None:
            raise UrdfError(f"{w}: a {j.type} joint needs <limit lower=... upper=...>")
        lower, upper = float(j.limit.lower), float(j.limit.upper)
    if j.limit is not None and j.limit.velocity:
        velocity = float(j.limit.velocity)
    mimic = None
    if j.mimic is not None:
        m = j.mimic
        mimic = Mimic(m.joint, 1.0 if m.multiplier is None else float(m.multiplier), float(m.offset or 0.0))
    axis = np.array([1.0, 0.0, 0.0]) if j.axis is None else np.asarray(j.axis, dtype=float)  # URDF's default
    origin = np.eye(4) if j.origin is None else np.asarray(j.origin, dtype=float)
    try:
        return Joint(j.name, j.type, j.parent, j.child, origin, axis, lower, upper, velocity, mimic)
    except ValueError as exc:
        raise UrdfError(f"{where}: {exc}") from None


def load_robot(path: str | Path, tool: str | None = None) -> RobotModel:
    """The robot a URDF file describes; ``tool`` its tool link (default: "tool0", else the deepest link
    that no finger moves). ``UrdfError`` for a URDF mcit cannot use."""
    import yourdfpy

    path = Path(path)
    if not path.is_file():
        raise UrdfError(f"{path}: no such URDF file")
    _check_xml(path)
    try:
        urdf = yourdfpy.URDF.load(str(path), build_scene_graph=False, load_meshes=False)
    except Exception as exc:  # noqa: BLE001 - lxml and yourdfpy raise many types for a bad file
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise UrdfError(f"{path}: not a readable URDF ({why}); check that it is a <robot> XML file") from None
    robot = urdf.robot
    names = [link.name for link in robot.links]
    if not robot.joints:
        raise UrdfError(f"{path}: the robot {robot.name!r} has no joints")
    joints = [_joint(j, set(names), str(path)) for j in robot.joints]
    loose = [n for n in names if all(n not in (j.parent, j.child) for j in joints)]
    if loose:
        raise UrdfError(f"{path}: link {loose[0]!r} is joined to no other link; a robot's links form one tree")
    meshes: dict = {}
    visual, collision = {}, {}
    for link in robot.links:
        w = f"{path}: link {link.name!r}"
        visual[link.name] = tuple(
            _shape(v.geometry, v.origin, path.parent, meshes, f"{w} visual") for v in link.visuals
        )
        collision[link.name] = tuple(
            _shape(c.geometry, c.origin, path.parent, meshes, f"{w} collision") for c in link.collisions
        )
    try:
        return RobotModel(robot.name, joints, visual, collision, tool)
    except ValueError as exc:
        raise UrdfError(f"{path}: {exc}") from None


def load_scene_robot(spec) -> tuple[RobotModel, np.ndarray]:
    """A scene's robot (``app.scene.RobotSpec``): (its model with the scene's tool, its home joints (n,)).

    ``UrdfError`` for the file, ``SceneError`` naming the field for a tool or home joint the URDF does not have.
    """
    from app.scene import SceneError

    model = load_robot(spec.urdf_path)
    if spec.tool is None:
        return model, spec.home_q(model)
    if spec.tool not in model.links:
        raise SceneError(f"robot.tool: {spec.urdf_path.name} has no link {spec.tool!r}; its links: {list(model.links)}")
    model = model.with_tool(spec.tool)
    return model, spec.home_q(model)
