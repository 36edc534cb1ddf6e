"""The robot's collision check (python-fcl): its links against the site's objects and against itself.

Every collision shape of every link (``RobotModel.collision_shapes``; a robot without any is checked
with its drawn shapes) and every obstacle becomes fcl geometries (``app.robot.fcl_shapes``). A
configuration is checked in two phases: a broad phase in numpy (the axis-aligned boxes of every link
part against each obstacle's box grown by its margin, and against the other links' parts, for a
whole batch of configurations at once), then fcl's signed distance for the pairs whose boxes meet.

Rules:
* robot against obstacle: a contact when the distance is within the obstacle's margin (so a
  stale or unknown object can be given a wider one);
* robot against itself: a contact when two links touch or overlap (distance ≤ ``self_margin_m``,
  default 0), links joined by a joint excluded, and the pairs in contact in every one of
  ``n_samples`` random configurations within the limits (parts that overlap by design) excluded too;
* links that no joint moves (the base and what is fixed to it) are not checked against the
  obstacles: no motion changes their contacts (the base stands on the table). ``static_contacts``
  says which of them touch an obstacle.

python-fcl, not coal (hpp-fcl's successor), chosen by ``bench/robot.py``: coal's signed distance with
the objects' placing is faster (4.0 µs against 6.9 µs per call, replayed on the same 1398 calls of 12
previews), but the narrow phase is 4 % of the check's time (9.6 of 233 ms; the rest is the numpy broad
phase and Python), so coal would save about 0.2 ms a preview, for a much larger dependency (a Boost,
assimp and octomap build through cmeel) where python-fcl is one wheel.

``check_path`` runs the samples in order and stops at the first contact: sample them with
``core.robot.joint_path(model, q0, q1, checker.path_step_m)`` so that no point of the robot moves
more than half the thinnest link between samples, and no obstacle or link thinner than that
(with margin 0) is passed over between two samples.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import fcl
import numpy as np

from app.robot.fcl_shapes import fcl_parts
from core.brep import BRep
from core.robot import RobotModel, lever_arms, pair_lever_arms
from core.transforms import check_T, invert_T, transform_points

__all__ = ["Contact", "PathCheck", "CollisionChecker"]

_CHUNK = 32  # configurations per broad-phase batch along a path


@dataclass(frozen=True)
class Contact:
    """A link within its margin of ``other`` (an obstacle's or another link's name); distance_m is the
    signed distance (m, < 0 when they overlap: then a penetration depth as fcl's EPA finds it, which for
    shapes that merely touch face to face was once seen far from the least one; the sign is sure)."""

    link: str
    other: str
    distance_m: float


@dataclass(frozen=True)
class PathCheck:
    """The first contact along sampled configurations: ok, the sample's index (−1 when ok), the link, the
    other body and the signed distance (m, nan when ok); ``samples`` were checked."""

    ok: bool
    index: int = -1
    link: str = ""
    other: str = ""
    distance_m: float = float("nan")
    samples: int = 0


def _corners(bounds: np.ndarray) -> np.ndarray:
    lo, hi = bounds
    return np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])


def _boxes(T: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """World boxes (..., 2, 3) of parts whose local box corners (P, 8, 3) are placed by T (..., P, 4, 4)."""
    X = np.einsum("...pij,pcj->...pci", T[..., :3, :3], corners) + T[..., None, :3, 3]
    return np.stack([X.min(axis=-2), X.max(axis=-2)], axis=-2)


def _meet(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether boxes a (..., 2, 3) and b (..., 2, 3) overlap (broadcast)."""
    return np.all((a[..., 0, :] <= b[..., 1, :]) & (b[..., 0, :] <= a[..., 1, :]), axis=-1)


def _distance(a: fcl.CollisionObject, b: fcl.CollisionObject) -> float:
    return float(fcl.distance(a, b, fcl.DistanceRequest(enable_signed_distance=True), fcl.DistanceResult()))


def _placed(T: np.ndarray) -> fcl.Transform:
    return fcl.Transform(T[:3, :3], T[:3, 3])


class CollisionChecker:
    """The robot ``model`` standing at ``T_world_base`` (4, 4) against obstacles and itself (module docstring).

    self_pairs_ignored : "auto" (links joined by a joint and pairs in contact in every one of ``n_samples``
    random configurations, seeded by ``rng``), or an iterable of (link, link) pairs ignored besides the
    joined ones.
    """

    def __init__(
        self,
        model: RobotModel,
        T_world_base: np.ndarray,
        self_pairs_ignored="auto",
        *,
        self_margin_m: float = 0.0,
        n_samples: int = 200,
        rng: int | np.random.Generator = 0,
    ):
        self.model = model
        self.T_world_base = check_T(T_world_base, "T_world_base")
        self.self_margin_m = float(self_margin_m)
        shapes = model.collision_shapes or model.link_shapes
        self._link_of, self._T_link_geom, corners, self._objects, self.parts = [], [], [], [], []
        for k, link in enumerate(model.links):
            for shape in shapes.get(link, ()):
                for part in fcl_parts(shape.brep):
                    self._link_of.append(k)
                    self._T_link_geom.append(shape.T_link_shape @ part.T_brep_geom)
                    corners.append(transform_points(invert_T(part.T_brep_geom), _corners(part.bounds)))
                    self._objects.append(fcl.CollisionObject(part.geometry, fcl.Transform()))
                    self.parts.append(part)
        if not self._objects:
            raise ValueError(f"robot {model.name!r} has no link shapes to check collisions with")
        self._link_of = np.array(self._link_of)
        self._T_link_geom = np.array(self._T_link_geom)
        self._corners = np.array(corners)  # each part's box corners in its fcl frame
        self.path_step_m = 0.5 * min(s.thickness_m for items in shapes.values() for s in items)
        static = set(model.static_links())
        self._moving = np.array([model.links[k] not in static for k in self._link_of])
        self.ignored_pairs = self._ignored(self_pairs_ignored, n_samples, rng)
        names = model.links
        self._self_pairs = np.array(
            [
                (a, b)
                for a, b in combinations(range(len(self._objects)), 2)
                if self._link_of[a] != self._link_of[b]
                and frozenset((names[self._link_of[a]], names[self._link_of[b]])) not in self.ignored_pairs
            ],
            dtype=np.int64,
        ).reshape(-1, 2)
        levers = {}
        for a, b in self._self_pairs:
            key = (names[self._link_of[a]], names[self._link_of[b]])
            if key not in levers:
                levers[key] = pair_lever_arms(model, *key)
        self._pair_levers = np.array(
            [levers[(names[self._link_of[a]], names[self._link_of[b]])] for a, b in self._self_pairs]
        ).reshape(-1, model.n)
        self.set_obstacles([])

    # ------------------------------------------------------------------ set-up
    def _ignored(self, given, n_samples: int, rng) -> frozenset:
        joined = self.model.adjacent_links()
        self.always_touching = frozenset()
        if not (isinstance(given, str) and given == "auto"):
            return frozenset(joined | {frozenset(p) for p in given})
        rng = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        lo = np.where(np.isfinite(self.model.lower), self.model.lower, -np.pi)
        hi = np.where(np.isfinite(self.model.upper), self.model.upper, np.pi)
        T = self._geom_poses(rng.uniform(lo, hi, size=(max(n_samples, 1), self.model.n)))
        names = self.model.links
        always = set()
        for a, b in combinations(range(len(self._objects)), 2):
            pair = frozenset((names[self._link_of[a]], names[self._link_of[b]]))
            if len(pair) < 2 or pair in joined or pair in always:
                continue
            if all(self._pair_distance(a, T[k, a], b, T[k, b]) <= self.self_margin_m for k in range(len(T))):
                always.add(pair)
        self.always_touching = frozenset(always)
        return frozenset(joined | always)

    def set_obstacles(self, obstacles) -> None:
        """The obstacles: a list of (name, BRep, T_world_obj (4, 4), margin_m ≥ 0)."""
        self._obstacles, boxes, owner, margin, self.obstacle_parts = [], [], [], [], []
        for i, item in enumerate(obstacles):
            try:
                name, brep, T, m = item
            except (TypeError, ValueError):
                raise ValueError(f"obstacle {i}: (name, BRep, T_world_obj, margin_m) expected, got {item!r}") from None
            if not isinstance(brep, BRep):
                raise ValueError(f"obstacle {name!r}: a BRep model expected, got {type(brep).__name__}")
            T = check_T(T, f"obstacle {name!r} T_world_obj")
            if not (np.isfinite(m) and m >= 0):
                raise ValueError(f"obstacle {name!r}: margin_m must be a distance ≥ 0 m, got {m}")
            for part in fcl_parts(brep):
                T_geom = T @ part.T_brep_geom
                self._obstacles.append(fcl.CollisionObject(part.geometry, _placed(T_geom)))
                self.obstacle_parts.append((part, T_geom))
                box = _boxes(T[None], _corners(part.bounds)[None])[0]
                boxes.append(box + np.array([[-m] * 3, [m] * 3]))
                owner.append(str(name))
                margin.append(float(m))
        self._obstacle_boxes = np.array(boxes).reshape(-1, 2, 3)
        self._obstacle_name, self._obstacle_margin = owner, np.array(margin)
        q0 = np.clip(np.zeros(self.model.n), self.model.lower, self.model.upper)
        self.static_contacts = self._obstacle_contacts(q0, ~self._moving, first=False)

    # ------------------------------------------------------------------ checks
    def _geom_poses(self, Q: np.ndarray) -> np.ndarray:
        """World poses (k, P, 4, 4) of every robot part at configurations Q (k, n)."""
        F = self.model.forward_many(Q)[:, self._link_of]
        return self.T_world_base @ F @ self._T_link_geom

    def _pair_distance(self, a: int, T_a: np.ndarray, b: int, T_b: np.ndarray) -> float:
        self._objects[a].setTransform(_placed(T_a))
        self._objects[b].setTransform(_placed(T_b))
        return _distance(self._objects[a], self._objects[b])

    def _sample_contacts(self, T: np.ndarray, boxes: np.ndarray, parts: np.ndarray, first: bool) -> list[Contact]:
        """Contacts at one configuration: parts' poses T (P, 4, 4) and boxes (P, 2, 3); ``parts`` (P,) bool
        checked against the obstacles; ``first``: stop at the first contact."""
        out = []
        names = self.model.links
        hits = _meet(boxes[:, None], self._obstacle_boxes[None]) & parts[:, None]
        for p, o in zip(*np.nonzero(hits)):
            self._objects[p].setTransform(_placed(T[p]))
            d = _distance(self._objects[p], self._obstacles[o])
            if d <= self._obstacle_margin[o]:
                out.append(Contact(names[self._link_of[p]], self._obstacle_name[o], d))
                if first:
                    return out
        pairs = self._self_pairs
        near = pairs[_meet(boxes[pairs[:, 0]], boxes[pairs[:, 1]])] if len(pairs) else pairs
        for a, b in near:
            d = self._pair_distance(a, T[a], b, T[b])
            if d <= self.self_margin_m:
                out.append(Contact(names[self._link_of[a]], names[self._link_of[b]], d))
                if first:
                    return out
        return out

    def _obstacle_contacts(self, q: np.ndarray, parts: np.ndarray, first: bool) -> list[Contact]:
        T = self._geom_poses(q[None])[0]
        saved, self._self_pairs = self._self_pairs, np.zeros((0, 2), dtype=np.int64)
        try:
            return self._sample_contacts(T, _boxes(T, self._corners), parts, first)
        finally:
            self._self_pairs = saved

    def check(self, q) -> list[Contact]:
        """Every contact at joint positions q (n,): one per (link, other) pair, the nearest, closest first."""
        q = self.model.as_q(q)
        T = self._geom_poses(q[None])[0]
        best: dict[tuple[str, str], Contact] = {}
        for c in self._sample_contacts(T, _boxes(T, self._corners), self._moving, first=False):
            key = (c.link, c.other)
            if key not in best or c.distance_m < best[key].distance_m:
                best[key] = c
        return sorted(best.values(), key=lambda c: c.distance_m)

    def check_path(self, qs) -> PathCheck:
        """The first contact along the samples qs (k, n), in order; ``PathCheck(ok=True)`` when none.

        Conservative advancement spares most of fcl's calls: a pair found at distance d, with margin m, is
        not measured again until the bound on the link's travel since (``core.robot.lever_arms``; for two
        links, on the change of their distance: ``pair_lever_arms``) reaches d − m; nothing is skipped that
        could touch.
        """
        Q = self.model.as_qs(qs, "qs")
        dq = np.abs(np.diff(Q, axis=0))
        cum = np.vstack([np.zeros((1, self.model.n)), np.cumsum(dq, axis=0)])  # (k, n) each joint's travel so far
        cum_link = (cum @ lever_arms(self.model).T)[:, self._link_of]  # (k, P) a part's travel bound so far
        cum_pair = cum @ self._pair_levers.T  # (k, pairs) bound on the change of each pair's distance so far
        due_obstacle = np.zeros((len(self._objects), len(self._obstacles)), dtype=np.int64)
        due_self = np.zeros(len(self._self_pairs), dtype=np.int64)
        pairs = self._self_pairs
        for start in range(0, len(Q), _CHUNK):
            T = self._geom_poses(Q[start : start + _CHUNK])
            boxes = _boxes(T, self._corners)
            near_obstacle = _meet(boxes[:, :, None], self._obstacle_boxes[None, None]) & self._moving[None, :, None]
            near_self = _meet(boxes[:, pairs[:, 0]], boxes[:, pairs[:, 1]])
            for j in range(len(T)):
                k = start + j
                for p, o in zip(*np.nonzero(near_obstacle[j] & (due_obstacle <= k))):
                    self._objects[p].setTransform(_placed(T[j, p]))
                    slack = _distance(self._objects[p], self._obstacles[o]) - self._obstacle_margin[o]
                    if slack <= 0:
                        return self._stop(k, p, self._obstacle_name[o], slack + self._obstacle_margin[o])
                    due_obstacle[p, o] = np.searchsorted(cum_link[:, p], cum_link[k, p] + slack)
                for i in np.flatnonzero(near_self[j] & (due_self <= k)):
                    a, b = pairs[i]
                    d = self._pair_distance(a, T[j, a], b, T[j, b])
                    if d <= self.self_margin_m:
                        return self._stop(k, a, self.model.links[self._link_of[b]], d)
                    due_self[i] = np.searchsorted(cum_pair[:, i], cum_pair[k, i] + d - self.self_margin_m)
        return PathCheck(True, samples=len(Q))

    def _stop(self, k: int, part: int, other: str, distance_m: float) -> PathCheck:
        return PathCheck(False, k, self.model.links[self._link_of[part]], other, float(distance_m), k + 1)
