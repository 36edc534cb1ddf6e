"""A robot's kinematic tree (URDF's joints and links) and what follows from its joint positions.

A joint moves its child link relative to its parent link as URDF says:
``T_parent_child(q) = T_parent_joint @ M(q)`` with ``M`` a turn by q about ``axis`` (revolute,
continuous) or a slide by q along it (prismatic), identity for a fixed joint. A mimic joint follows
another: ``q = multiplier · q_other + offset``. The actuated joints (not fixed, not mimic) are the
model's joint vector q, in the order given (``joint_names``); angles in radians, slides in metres.

Frames: ``T_base_link`` is a link's pose in the root link's frame ("base"); the tool (the TCP) is
``T_base_tool = T_base_<tool link> @ T_tool_tcp``. Every link may carry shapes (``LinkShape``): B-Reps
placed in the link's frame, for drawing (``link_shapes``, URDF's visual) and for collision
(``collision_shapes``, URDF's collision).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from ..brep import BRep
from ..transforms import check_T, skew

__all__ = ["Joint", "Mimic", "LinkShape", "RobotModel", "JOINT_KINDS"]

JOINT_KINDS = ("revolute", "continuous", "prismatic", "fixed")


@dataclass(frozen=True)
class Mimic:
    """A joint that follows ``joint``: q = multiplier · q_joint + offset."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


@dataclass(frozen=True)
class Joint:
    """One joint of the tree.

    kind : one of ``JOINT_KINDS``. T_parent_joint : array, shape (4, 4), the joint frame (= the child
    link's frame at q = 0) in the parent link's frame (URDF's origin). axis : array, shape (3,), unit,
    joint frame. lower, upper : limits (rad or m; ±inf for a continuous joint). velocity : rad/s or m/s.
    """

    name: str
    kind: str
    parent: str
    child: str
    T_parent_joint: np.ndarray = field(default_factory=lambda: np.eye(4))
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    lower: float = -np.inf
    upper: float = np.inf
    velocity: float = np.inf
    mimic: Mimic | None = None

    def __post_init__(self):
        if self.kind not in JOINT_KINDS:
            raise ValueError(f"joint {self.name!r}: kind must be one of {JOINT_KINDS}, got {self.kind!r}")
        object.__setattr__(self, "T_parent_joint", check_T(self.T_parent_joint, f"joint {self.name!r} origin"))
        axis = np.asarray(self.axis, dtype=float).reshape(3)
        norm = float(np.linalg.norm(axis))
        if self.kind != "fixed" and not (np.isfinite(norm) and norm > 1e-12):
            raise ValueError(f"joint {self.name!r}: its axis must be a non-zero vector, got {axis}")
        object.__setattr__(self, "axis", axis / norm if norm > 1e-12 else np.array([0.0, 0.0, 1.0]))
        if self.kind == "continuous":
            object.__setattr__(self, "lower", -np.inf)
            object.__setattr__(self, "upper", np.inf)
        if np.isnan(self.lower) or np.isnan(self.upper) or self.lower > self.upper:
            raise ValueError(f"joint {self.name!r}: limits must satisfy lower ≤ upper, got {self.lower}, {self.upper}")
        if not self.velocity > 0:
            raise ValueError(f"joint {self.name!r}: its velocity limit must be positive, got {self.velocity}")

    @property
    def moves(self) -> bool:
        return self.kind != "fixed"

    @property
    def actuated(self) -> bool:
        return self.kind != "fixed" and self.mimic is None


@dataclass(frozen=True)
class LinkShape:
    """A B-Rep placed in a link: ``brep`` in its own frame, ``T_link_shape`` (4, 4) its pose in the link."""

    brep: BRep
    T_link_shape: np.ndarray

    def __post_init__(self):
        object.__setattr__(self, "T_link_shape", check_T(self.T_link_shape, "T_link_shape"))

    @property
    def thickness_m(self) -> float:
        """The smallest side of its bounding box in its own frame (a box's thinnest side, a rod's diameter)."""
        lo, hi = self.brep.bounds()
        return float(np.min(hi - lo))

    def radius_about_link_origin(self) -> float:
        """An upper bound (m) of the distance from the link's origin to any point of the shape."""
        lo, hi = self.brep.bounds()
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        return float(np.linalg.norm(corners @ self.T_link_shape[:3, :3].T + self.T_link_shape[:3, 3], axis=1).max())


def _tree_order(joints: tuple[Joint, ...]) -> tuple[str, list[int]]:
    """(root link, joint indices parents-first); ValueError for a forest, a loop or a link with two parents."""
    children = {}
    for j in joints:
        if j.child in children:
            raise ValueError(f"link {j.child!r} is the child of two joints ({children[j.child]!r}, {j.name!r})")
        children[j.child] = j.name
    links = {j.parent for j in joints} | {j.child for j in joints}
    roots = sorted(links - set(children))
    if len(roots) != 1:
        raise ValueError(f"a robot is one tree with one root link; found roots {roots or 'none (a loop)'}")
    by_parent: dict[str, list[int]] = {}
    for i, j in enumerate(joints):
        by_parent.setdefault(j.parent, []).append(i)
    order, todo = [], deque([roots[0]])
    while todo:
        for i in by_parent.get(todo.popleft(), []):
            order.append(i)
            todo.append(joints[i].child)
    if len(order) != len(joints):
        raise ValueError("the joints make a loop: a robot's links form a tree")
    return roots[0], order


class RobotModel:
    """A robot's kinematic tree with its limits and link shapes (see the module docstring).

    Parameters
    ----------
    name : the robot's name.
    joints : every joint (fixed and mimic ones included), in any order; the actuated ones in the
        order of q.
    link_shapes, collision_shapes : dict link name → tuple of ``LinkShape`` (links without shapes absent).
    tool : the tool link (default: "tool0" when there is one, else the last link of the tree).
    T_tool_tcp : array, shape (4, 4), the TCP in the tool link (default identity).
    """

    def __init__(
        self,
        name: str,
        joints,
        link_shapes: dict | None = None,
        collision_shapes: dict | None = None,
        tool: str | None = None,
        T_tool_tcp: np.ndarray | None = None,
    ):
        self.name = str(name)
        self.joints = tuple(joints)
        if not self.joints:
            raise ValueError(f"robot {self.name!r} has no joints")
        names = [j.name for j in self.joints]
        if len(set(names)) != len(names):
            raise ValueError(f"robot {self.name!r}: two joints share a name")
        self.base_link, order = _tree_order(self.joints)
        self.links = (self.base_link, *(self.joints[i].child for i in order))
        self._order = order
        self.joint_names = tuple(j.name for j in self.joints if j.actuated)
        actuated = {n: k for k, n in enumerate(self.joint_names)}
        self._source = []  # per joint: (index in q, multiplier, offset) or None for a fixed joint
        for j in self.joints:
            if j.mimic is not None and j.mimic.joint not in actuated:
                raise ValueError(f"joint {j.name!r} mimics {j.mimic.joint!r}, which is not an actuated joint")
            m = j.mimic
            if not j.moves:
                self._source.append(None)
            elif m is None:
                self._source.append((actuated[j.name], 1.0, 0.0))
            else:
                self._source.append((actuated[m.joint], float(m.multiplier), float(m.offset)))
        act = [j for j in self.joints if j.actuated]
        self.lower = np.array([j.lower for j in act])
        self.upper = np.array([j.upper for j in act])
        self.velocity = np.array([j.velocity for j in act])
        self.link_shapes = self._shapes(link_shapes)
        self.collision_shapes = self._shapes(collision_shapes)
        self.tool = tool if tool is not None else self._default_tool()
        if self.tool not in self.links:
            raise ValueError(f"robot {self.name!r} has no tool link {self.tool!r}; its links: {list(self.links)}")
        self.T_tool_tcp = np.eye(4) if T_tool_tcp is None else check_T(T_tool_tcp, "T_tool_tcp")
        self._link_index = {n: k for k, n in enumerate(self.links)}
        self._terms = self._local_terms()
        self._tool_chain = self.chain(self.tool)
        moving = [i for i in self._tool_chain if self._source[i] is not None]
        to_q = np.zeros((len(moving), self.n))  # d q_joint / d q: the mimic multipliers
        for c, i in enumerate(moving):
            to_q[c, self._source[i][0]] += self._source[i][1]
        turn = np.array([self.joints[i].kind != "prismatic" for i in moving], dtype=bool)
        self._tool_drives = (moving, to_q, turn)
        self._tool_axes = np.array([self.joints[i].axis for i in moving]).reshape(-1, 3)

    def _default_tool(self) -> str:
        """The link named tool0 when there is one, else the deepest link that no prismatic joint (a finger)
        moves (the deepest of all when prismatic joints move every link: a gantry)."""
        if "tool0" in self.links:
            return "tool0"
        depth = {}
        for k, link in enumerate(self.links):
            chain = self.chain(link)
            fingered = any(self.joints[i].kind == "prismatic" for i in chain)
            depth[link] = (bool(chain) and not fingered, len(chain), k)
        return max(depth, key=depth.get)

    def _shapes(self, shapes: dict | None) -> dict[str, tuple[LinkShape, ...]]:
        out = {}
        for link, items in (shapes or {}).items():
            if link not in self.links:
                raise ValueError(f"robot {self.name!r}: shapes given for an unknown link {link!r}")
            if items:
                out[link] = tuple(items)
        return out

    def with_tool(self, tool: str, T_tool_tcp: np.ndarray | None = None) -> RobotModel:
        """The same robot with another tool link (and TCP offset in it)."""
        return RobotModel(self.name, self.joints, self.link_shapes, self.collision_shapes, tool, T_tool_tcp)

    def with_payload(self, name: str, shape: LinkShape) -> RobotModel:
        """The same robot carrying a body: a link ``payload:<name>`` fixed to the tool link, with ``shape``
        (its ``T_link_shape`` the body's pose in the TCP frame) drawn and checked for collisions."""
        link = f"payload:{name}"
        joint = Joint(f"{link}_joint", "fixed", self.tool, link, self.T_tool_tcp)
        shapes = {**self.link_shapes, link: (shape,)}
        collision = {**(self.collision_shapes or self.link_shapes), link: (shape,)}
        return RobotModel(self.name, (*self.joints, joint), shapes, collision, self.tool, self.T_tool_tcp)

    # ------------------------------------------------------------------ structure
    @property
    def n(self) -> int:
        """Number of actuated joints (the length of q)."""
        return len(self.joint_names)

    def joint(self, name: str) -> Joint:
        for j in self.joints:
            if j.name == name:
                return j
        raise KeyError(f"robot {self.name!r} has no joint {name!r}; its joints: {[j.name for j in self.joints]}")

    def chain(self, link: str) -> list[int]:
        """Indices of the joints from the base to ``link``, base first."""
        parent_joint = {j.child: i for i, j in enumerate(self.joints)}
        out = []
        while link in parent_joint:
            out.append(parent_joint[link])
            link = self.joints[out[-1]].parent
        return out[::-1]

    def drive(self, i: int) -> tuple[int, float, float] | None:
        """What moves joint ``i`` (index in ``joints``): (index in q, multiplier, offset), None when fixed."""
        return self._source[i]

    def moves_tool(self) -> np.ndarray:
        """(n,) bool: the actuated joints that move the tool (the others, e.g. a gripper's fingers, do not)."""
        return np.any(self._tool_drives[1] != 0, axis=0)

    def adjacent_links(self) -> set[frozenset[str]]:
        """Pairs of links joined by one joint (they touch by design)."""
        return {frozenset((j.parent, j.child)) for j in self.joints}

    def static_links(self) -> tuple[str, ...]:
        """Links that no joint moves relative to the base (the base and what is fixed to it)."""
        return tuple(k for k in self.links if not any(self.joints[i].moves for i in self.chain(k)))

    def as_q(self, q, name: str = "q") -> np.ndarray:
        """``q`` as a float array (n,); ValueError for a wrong length or a NaN."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n,):
            raise ValueError(f"{name} must have {self.n} joint values {list(self.joint_names)}, got shape {q.shape}")
        if not np.all(np.isfinite(q)):
            bad = self.joint_names[int(np.flatnonzero(~np.isfinite(q))[0])]
            raise ValueError(f"{name}: joint {bad!r} is {q[self.joint_names.index(bad)]}; give finite values")
        return q

    def within_limits(self, q, tol: float = 1e-9) -> str | None:
        """None when q is within every limit; else the first joint out of its limits and by how much."""
        q = self.as_q(q)
        for k, name in enumerate(self.joint_names):
            lo, hi = self.lower[k], self.upper[k]
            if lo - tol <= q[k] <= hi + tol:
                continue
            side, limit = ("lower", lo) if q[k] < lo else ("upper", hi)
            unit, f = ("mm", 1e3) if self.joint(name).kind == "prismatic" else ("°", 180.0 / np.pi)
            return (
                f"joint {name} at {q[k] * f:.1f} {unit} is {abs(q[k] - limit) * f:.1f} {unit} beyond its "
                f"{side} limit {limit * f:.1f} {unit}"
            )
        return None

    # ------------------------------------------------------------------ kinematics
    def as_qs(self, Q, name: str = "Q") -> np.ndarray:
        """Joint positions for k configurations as a float array (k, n); ValueError for a wrong shape or a NaN."""
        Q = np.asarray(Q, dtype=float)
        if Q.ndim != 2 or Q.shape[1] != self.n:
            raise ValueError(f"{name} must have shape (k, {self.n}), got {Q.shape}")
        if not np.all(np.isfinite(Q)):
            raise ValueError(f"{name} holds NaN or inf; give finite joint values")
        return Q

    def _local_terms(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Per joint, T_parent_child(v) = A + f(v) B + g(v) C with f, g = (sin, 1 − cos) for a turn (Rodrigues:
        A = T_parent_joint, B = A·K, C = A·K², K the axis's cross-product matrix) and (v, 0) for a slide."""
        terms = []
        for j in self.joints:
            A = j.T_parent_joint
            K = np.zeros((4, 4))
            if j.kind == "prismatic":
                K[:3, 3] = j.axis
            else:
                K[:3, :3] = skew(j.axis)
            terms.append((A, A @ K, A @ K @ K))
        return terms

    def _frames(self, Q: np.ndarray, joints: list[int] | None = None) -> tuple[dict, dict]:
        """For k configurations Q (k, n): ({link index: T_base_link (k, 4, 4)}, {joint index: T_base_jointframe
        (k, 4, 4), after its motion}) over ``joints`` (parents first; default the whole tree)."""
        T_links = {0: np.broadcast_to(np.eye(4), (len(Q), 4, 4))}
        frames = {}
        for i in self._order if joints is None else joints:
            j = self.joints[i]
            A, B, C = self._terms[i]
            src = self._source[i]
            if src is None:
                local = A
            else:
                v = (src[1] * Q[:, src[0]] + src[2])[:, None, None]
                local = A + v * B if j.kind == "prismatic" else A + np.sin(v) * B + (1.0 - np.cos(v)) * C
            T = T_links[self._link_index[j.parent]] @ local
            frames[i] = T
            T_links[self._link_index[j.child]] = T
        return T_links, frames

    def forward(self, q) -> dict[str, np.ndarray]:
        """``T_base_link`` (4, 4) of every link at joint positions q (n,)."""
        T_links, _ = self._frames(self.as_q(q)[None])
        return {link: T_links[k][0].copy() for k, link in enumerate(self.links)}

    def forward_many(self, Q) -> np.ndarray:
        """``T_base_link`` of every link (in ``links`` order) at k configurations Q (k, n): (k, L, 4, 4)."""
        Q = self.as_qs(Q)
        T_links, _ = self._frames(Q)
        return np.stack([np.broadcast_to(T_links[k], (len(Q), 4, 4)) for k in range(len(self.links))], axis=1)

    def tool_pose(self, q) -> np.ndarray:
        """``T_base_tool`` (4, 4): the TCP's pose in the base at q (n,)."""
        return self.tool_poses(self.as_q(q)[None])[0]

    def tool_poses(self, Q) -> np.ndarray:
        """``T_base_tool`` at k configurations Q (k, n): (k, 4, 4)."""
        Q = self.as_qs(Q)
        T_links, _ = self._frames(Q, self._tool_chain)
        return np.broadcast_to(T_links[self._link_index[self.tool]] @ self.T_tool_tcp, (len(Q), 4, 4)).copy()

    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian (6, n) of the TCP in the base frame: rows (v, ω), d(p_tool, θ)/dq."""
        return self.poses_and_jacobians(self.as_q(q)[None])[1][0]

    def poses_and_jacobians(self, Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(``T_base_tool`` (k, 4, 4), Jacobians (k, 6, n)) at k configurations Q (k, n), from one pass along
        the tool's chain; Q is not checked (the solvers' inner loop)."""
        k = len(Q)
        T_links, frames = self._frames(Q, self._tool_chain)
        T_tool = np.broadcast_to(T_links[self._link_index[self.tool]] @ self.T_tool_tcp, (k, 4, 4))
        p = T_tool[:, :3, 3]
        moving, to_q, turn = self._tool_drives
        if not moving:
            return T_tool, np.zeros((k, 6, self.n))
        F = np.stack([frames[i] for i in moving], axis=1)  # (k, m, 4, 4) the moving joints' frames
        axes = np.einsum("kmij,mj->kmi", F[:, :, :3, :3], self._tool_axes)
        v = np.where(turn[None, :, None], np.cross(axes, p[:, None, :] - F[:, :, :3, 3]), axes)
        w = np.where(turn[None, :, None], axes, 0.0)
        J = np.concatenate([np.einsum("kmi,mn->kin", v, to_q), np.einsum("kmi,mn->kin", w, to_q)], axis=1)
        return T_tool, J

    def link_breps(self, q, T_world_base: np.ndarray | None = None, collision: bool = False) -> list:
        """Every link shape placed in the world: a list of (link name, BRep, T_world_shape (4, 4)).

        collision : False for the drawn shapes (``link_shapes``), True for ``collision_shapes``.
        """
        T_wb = np.eye(4) if T_world_base is None else check_T(T_world_base, "T_world_base")
        T_links, _ = self._frames(self.as_q(q)[None])
        shapes = self.collision_shapes if collision else self.link_shapes
        return [
            (link, s.brep, T_wb @ T_links[k][0] @ s.T_link_shape)
            for k, link in enumerate(self.links)
            for s in shapes.get(link, ())
        ]

    def __repr__(self) -> str:
        return f"RobotModel({self.name!r}, {self.n} joints {list(self.joint_names)}, tool {self.tool!r})"
