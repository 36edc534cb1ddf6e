"""Synthetic pose problems with known truth: the generator shared by the tests and ``bench/pose.py``.

A problem is a camera (global model C), a true pose ``T_world_obj``, model edges (object frame) and
the operator's clicks on their images: two pixels along each edge (not its endpoints), with
Gaussian noise of ``sigma_px`` on each pixel coordinate.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..brep import BRep
from ..camera import Camera
from ..transforms import invert_T, make_T, random_rotation

__all__ = [
    "LineProblem",
    "PAPER_BOX_M",
    "paper_camera",
    "side_camera",
    "paper_box_pose",
    "random_camera",
    "random_pose_in_view",
    "random_lines_problem",
    "clicks_on_edges",
    "box_problem",
    "paper_problems",
]

#: The paper's test object (§IV.3): a parallelepiped 35 × 23.1 × 13.2 cm (length, width, height).
PAPER_BOX_M = (0.35, 0.231, 0.132)


@dataclass(frozen=True)
class LineProblem:
    """camera; T_world_obj (4, 4) the truth; edges_obj (N, 2, 3) metres; segs_uv (N, 2, 2) the
    noisy clicks; segs_true_uv (N, 2, 2) the same clicks without noise; sigma_px the noise;
    edge_index (N,) which model edge each click is on (−1 for random lines)."""

    camera: Camera
    T_world_obj: np.ndarray
    edges_obj: np.ndarray
    segs_uv: np.ndarray
    segs_true_uv: np.ndarray
    sigma_px: float
    edge_index: np.ndarray


def paper_camera() -> Camera:
    """The paper's camera (§II, §IV.3): 512 × 256 px, f = 500 px, principal point at the centre,
    1.45 m behind and 0.75 m above the table's origin, looking along +y, 25° down (the set-up of
    ``scenes/workcell``): a box on the table near (0.1, 0.45) is ~2 m away."""
    K = np.array([[500.0, 0.0, 255.5], [0.0, 500.0, 127.5], [0.0, 0.0, 1.0]])
    c, s = np.cos(np.radians(25.0)), np.sin(np.radians(25.0))
    R_world_cam = np.array([[1.0, 0.0, 0.0], [0.0, -s, c], [0.0, -c, -s]])  # x right, y down, z forward
    return Camera.from_intrinsics(K, invert_T(make_T(R_world_cam, [0.0, -1.45, 0.75])), 512, 256)


def side_camera() -> Camera:
    """A second view of the paper's table (the camera of ``paper_camera`` turned 90° about the table's
    vertical axis): 2.0 m to the right of the table's origin at the same height, looking along −x, 25°
    down; it sees along ``paper_camera``'s image rows, across its line of sight."""
    K = np.array([[500.0, 0.0, 255.5], [0.0, 500.0, 127.5], [0.0, 0.0, 1.0]])
    c, s = np.cos(np.radians(25.0)), np.sin(np.radians(25.0))
    R_world_cam = np.array([[0.0, s, -c], [1.0, 0.0, 0.0], [0.0, -c, -s]])  # x right, y down, z forward
    return Camera.from_intrinsics(K, invert_T(make_T(R_world_cam, [2.0, 0.45, 0.75])), 512, 256)


def paper_box_pose(rng: np.random.Generator) -> np.ndarray:
    """The box lying on the table (z = 0) with a uniform random yaw, its centre uniform in
    x ∈ [−0.2, 0.4], y ∈ [0.3, 0.6] m: ~1.9–2.2 m from ``paper_camera``."""
    yaw = rng.uniform(0.0, 2.0 * np.pi)
    c, s = np.cos(yaw), np.sin(yaw)
    return make_T(
        np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), [rng.uniform(-0.2, 0.4), rng.uniform(0.3, 0.6), 0.0]
    )


def random_camera(rng: np.random.Generator, width: int = 640, height: int = 480) -> Camera:
    """A camera with random intrinsics (f 400–1200 px, skew ±5 px), a random world frame (pose
    anywhere within ±3 m, any orientation) and C multiplied by a random scale 1e±3 of random sign."""
    K = np.array(
        [
            [rng.uniform(400, 1200), rng.uniform(-5, 5), width / 2 + rng.uniform(-20, 20)],
            [0.0, rng.uniform(400, 1200), height / 2 + rng.uniform(-20, 20)],
            [0.0, 0.0, 1.0],
        ]
    )
    T_cam_world = make_T(random_rotation(rng), rng.uniform(-3, 3, 3))
    C = K @ T_cam_world[:3] * (rng.choice([-1.0, 1.0]) * 10 ** rng.uniform(-3, 3))
    return Camera(C, width, height)


def random_pose_in_view(
    rng: np.random.Generator, camera: Camera, depth_m: tuple[float, float] = (1.5, 4.0), spread: float = 0.1
) -> np.ndarray:
    """A pose ``T_world_obj`` with a uniformly random orientation and its origin at a random depth
    in ``depth_m`` near the optical axis (lateral offset up to ``spread`` × depth)."""
    _, T_cam_world = camera.decompose()
    depth = rng.uniform(*depth_m)
    T_cam_obj = make_T(random_rotation(rng), np.array([*rng.uniform(-spread, spread, 2) * depth, depth]))
    return invert_T(T_cam_world) @ T_cam_obj


def clicks_on_edges(
    rng: np.random.Generator,
    camera: Camera,
    T_world_obj: np.ndarray,
    edges_obj: np.ndarray,
    sigma_px: float = 0.0,
    fractions: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Two clicks along each model edge (N, 2, 3): the images of the points at the given fractions
    of the edge (default: random in [0.1, 0.9], at least 0.3 apart), plus N(0, sigma_px²) noise.

    Returns (segs_uv noisy, segs_true_uv), each (N, 2, 2), pixels.
    """
    edges_obj = np.asarray(edges_obj, dtype=float)
    n = len(edges_obj)
    if fractions is None:
        a = rng.uniform(0.1, 0.6, n)
        s = np.stack([a, a + rng.uniform(0.3, 0.9 - a)], axis=1)
    else:
        s = np.broadcast_to(np.asarray(fractions, dtype=float), (n, 2))
    X = edges_obj[:, :1] + s[..., None] * (edges_obj[:, 1:] - edges_obj[:, :1])
    true = camera.project_obj(T_world_obj, X.reshape(-1, 3)).reshape(n, 2, 2)
    return true + rng.normal(scale=sigma_px, size=true.shape) if sigma_px > 0 else true.copy(), true


def random_lines_problem(
    rng: np.random.Generator,
    n_edges: int,
    sigma_px: float = 0.0,
    camera: Camera | None = None,
    extent_m: float = 0.3,
) -> LineProblem:
    """Random model lines (endpoints uniform in a cube of half-side ``extent_m``) at a random pose
    seen by a random camera (``random_camera``); all endpoints in front of the camera."""
    camera = random_camera(rng) if camera is None else camera
    while True:
        T = random_pose_in_view(rng, camera)
        edges = rng.uniform(-extent_m, extent_m, (n_edges, 2, 3))
        X = edges.reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        if np.all(camera.depth(X) > 0.2):
            break
    segs, true = clicks_on_edges(rng, camera, T, edges, sigma_px)
    return LineProblem(camera, T, edges, segs, true, float(sigma_px), np.full(n_edges, -1))


def box_problem(
    rng: np.random.Generator,
    camera: Camera,
    T_world_obj: np.ndarray,
    size_m: tuple[float, float, float],
    sigma_px: float = 0.0,
    fractions: tuple[float, float] | None = None,
) -> LineProblem:
    """Clicks on every visible edge of a box ``BRep.box(*size_m)`` at ``T_world_obj``, in the
    model's edge order; edges must be whole in the image (ValueError otherwise)."""
    box = BRep.box(*size_m)
    wf = box.wireframe(camera.center, T_world_obj)
    idx = wf.edge_index[wf.visible & (wf.edge_index >= 0)]
    edges = box.edge_segments()[idx]
    uv = camera.project_obj(T_world_obj, edges.reshape(-1, 3))
    if not np.all(camera.in_image(uv)):
        raise ValueError("the box is not whole in the image at this pose")
    segs, true = clicks_on_edges(rng, camera, T_world_obj, edges, sigma_px, fractions)
    return LineProblem(camera, np.asarray(T_world_obj, dtype=float), edges, segs, true, float(sigma_px), idx)


def paper_problems(rng: np.random.Generator, n: int, sigma_px: float = 0.0, n_edges: int = 9) -> list[LineProblem]:
    """``n`` box problems on the paper's set-up (``paper_camera``, the box at ``paper_box_pose``)
    with exactly ``n_edges`` visible edges (9: three faces seen), each clicked twice."""
    camera = paper_camera()
    out: list[LineProblem] = []
    while len(out) < n:
        try:
            pb = box_problem(rng, camera, paper_box_pose(rng), PAPER_BOX_M, sigma_px)
        except ValueError:  # not whole in the image
            continue
        if len(pb.edges_obj) == n_edges:
            out.append(pb)
    return out
