"""What the overlay draws, as pixel geometry: the database's wireframes projected through C,
clicked points and segments, ghosts of candidate poses, the beam spot — and the "pixel world"
the interface shows them in. Pure numpy (no viser), so it is tested alone and reused by the
benchmark.

Projection is done here, in Python, with the camera's 3×4 matrix C (viser's own camera has no
principal point or skew). Segments are first clipped in 3D to the half-space in front of the
camera (depth ≥ ``min_depth_m``), then projected and clipped to the image rectangle. Hidden edges
(``BRep.wireframe``'s visibility: exact for convex objects) are dashed. Curved surfaces — solids
and a mesh's curved regions — are drawn by their silhouettes at the current pose (each primitive's
``outline``).

The pixel world (DESIGN.md §"The operator interface"): pixel (u, v) ↔ world (u·k, v·k, 0) of the
viser scene; the video frame is a textured plane on z = 0 and the viewer's camera looks along +z
with −y up, so the image appears upright. A click's ray meets z = 0 at the exact pixel, whatever
the zoom or pan.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from core.brep import BRep
from core.camera import Camera

__all__ = [
    "PixelWorld",
    "STATUS_COLORS",
    "COLORS",
    "clip_segments_depth",
    "clip_segments_rect",
    "dash_segments",
    "ProjectedWireframe",
    "project_wireframe",
    "project_wireframes",
    "LineBatch",
    "wireframe_lines",
    "cross_markers",
    "circle_marker",
    "nearest_segment",
]

# RGB uint8 colours. Status colours follow the database's statuses; "selected" is per operator.
STATUS_COLORS: dict[str, tuple[int, int, int]] = {
    "known": (40, 220, 60),
    "modelled": (40, 190, 255),
    "stale": (255, 150, 20),
    "selected": (255, 240, 0),
}
COLORS: dict[str, tuple[int, int, int]] = {
    "click": (255, 40, 40),
    "pending": (255, 120, 120),
    "ghost": (230, 60, 230),
    "ghost_chosen": (255, 255, 255),
    "beam": (255, 0, 0),
    "target": (0, 255, 255),
    "assigned": (255, 120, 0),
    "preview": (255, 255, 255),
    "turret": (255, 80, 80),
    "raw": (170, 140, 255),  # a raw click beside the snapped one in use (dashed)
    "tracked": (255, 80, 200),  # a tracked pose
    "edge_found": (0, 255, 255),  # image edge points that support the tracked pose
    "edge_rejected": (255, 140, 0),  # those the tracker's robust fit rejected
    "robot": (225, 170, 90),  # the robot at its joint states (tan: far from every status and mark colour)
    "robot_ghost": (255, 255, 255),  # the robot where a previewed motion ends, and the tool's way there
    "robot_ghost_3d": (40, 160, 90),  # the same in the 3D world (white does not show on its grid)
}


@dataclass(frozen=True)
class PixelWorld:
    """Pixel ↔ viser-world mapping for one image size: (u, v) ↔ (x0 + u·k, v·k, z).

    k : world units per pixel. width, height : image size in pixels. x0 : where the image's left edge
    lies along x (world units): each camera's image has its own place, side by side.
    """

    width: int
    height: int
    k: float = 0.01
    x0: float = 0.0

    def to_world(self, uv: np.ndarray, z: float = 0.0) -> np.ndarray:
        """World points (..., 3) of pixels (..., 2) on the plane z."""
        uv = np.asarray(uv, dtype=float)
        xy = uv * self.k
        if self.x0:
            xy = xy + np.array([self.x0, 0.0])
        return np.concatenate([xy, np.full(uv.shape[:-1] + (1,), float(z))], axis=-1)

    def pixel_from_ray(self, origin: np.ndarray, direction: np.ndarray) -> np.ndarray | None:
        """The pixel (2,) where a viewer ray meets the image plane z = 0, or None if it does not."""
        o = np.asarray(origin, dtype=float).reshape(3)
        d = np.asarray(direction, dtype=float).reshape(3)
        if abs(d[2]) < 1e-12:
            return None
        t = -o[2] / d[2]
        if t <= 0:
            return None
        p = o + t * d
        return np.array([p[0] - self.x0, p[1]]) / self.k

    def holds(self, uv: np.ndarray | None) -> bool:
        """True when pixel uv (2,) lies on this image."""
        return uv is not None and -0.5 <= uv[0] <= self.width - 0.5 and -0.5 <= uv[1] <= self.height - 0.5

    @property
    def image_center(self) -> np.ndarray:
        """World position (3,) of the image plane's centre (pixel centres span 0..size − 1)."""
        return np.array([self.x0 + (self.width - 1) / 2.0 * self.k, (self.height - 1) / 2.0 * self.k, 0.0])

    @property
    def render_size(self) -> tuple[float, float]:
        """The image plane's size in world units (width, height)."""
        return self.width * self.k, self.height * self.k

    def fit_camera(
        self, aspect: float, fov_rad: float, margin: float = 1.02
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Viewer camera (position (3,), look_at (3,), up (3,)) showing the whole image, centred.

        aspect : canvas width / height. fov_rad : the viewer's vertical field of view.
        """
        if not (aspect > 0 and 0 < fov_rad < np.pi):
            raise ValueError(f"aspect must be > 0 and fov in (0, π), got {aspect}, {fov_rad}")
        half_h = max(self.height / 2.0, self.width / 2.0 / aspect) * self.k * margin
        distance = half_h / np.tan(fov_rad / 2.0)
        look_at = self.image_center
        return look_at + np.array([0.0, 0.0, -distance]), look_at, np.array([0.0, -1.0, 0.0])


def clip_segments_depth(
    camera: Camera, S_world: np.ndarray, min_depth_m: float = 1e-3
) -> tuple[np.ndarray, np.ndarray]:
    """Clip world segments (K, 2, 3) to the half-space in front of the camera.

    Returns the clipped segments (M, 2, 3) and the index (M,) of the input segment each came from;
    segments wholly behind are dropped.
    """
    S = np.asarray(S_world, dtype=float).reshape(-1, 2, 3)
    if len(S) == 0:
        return S, np.zeros(0, np.int64)
    s = camera.depth(S.reshape(-1, 3)).reshape(-1, 2) - min_depth_m
    keep = (s[:, 0] >= 0) | (s[:, 1] >= 0)
    S, s, idx = S[keep].copy(), s[keep], np.nonzero(keep)[0]
    cross = (s[:, 0] < 0) | (s[:, 1] < 0)
    if np.any(cross):
        a = s[cross, 0] / (s[cross, 0] - s[cross, 1])  # where depth = min_depth on the segment
        P = S[cross, 0] + a[:, None] * (S[cross, 1] - S[cross, 0])
        behind0 = s[cross, 0] < 0
        Sc = S[cross]
        Sc[behind0, 0] = P[behind0]
        Sc[~behind0, 1] = P[~behind0]
        S[cross] = Sc
    return S, idx


def clip_segments_rect(
    seg_uv: np.ndarray, width: int, height: int, margin_px: float = 0.5
) -> tuple[np.ndarray, np.ndarray]:
    """Clip pixel segments (K, 2, 2) to the image rectangle (Liang–Barsky).

    The rectangle is the image's outer border [−margin, size − 1 + margin]. Returns the clipped
    segments (M, 2, 2) and the index (M,) of each in the input.
    """
    P = np.asarray(seg_uv, dtype=float).reshape(-1, 2, 2)
    if len(P) == 0:
        return P, np.zeros(0, np.int64)
    lo = np.array([-margin_px, -margin_px])
    hi = np.array([width - 1 + margin_px, height - 1 + margin_px])
    if np.all((P >= lo) & (P <= hi)):  # wholly inside (most objects): nothing to clip
        return P, np.arange(len(P))
    p0, d = P[:, 0], P[:, 1] - P[:, 0]
    t0 = np.zeros(len(P))
    t1 = np.ones(len(P))
    ok = np.ones(len(P), bool)
    for axis in (0, 1):
        for q_sign, bound in ((-1.0, lo[axis]), (1.0, hi[axis])):
            p = q_sign * d[:, axis]
            q = q_sign * (bound - p0[:, axis]) if q_sign > 0 else (p0[:, axis] - bound)
            parallel = np.abs(p) < 1e-12
            ok &= ~(parallel & (q < 0))
            with np.errstate(divide="ignore", invalid="ignore"):
                r = np.where(parallel, 0.0, q / np.where(parallel, 1.0, p))
            entering = ~parallel & (p < 0)
            leaving = ~parallel & (p > 0)
            t0 = np.where(entering, np.maximum(t0, r), t0)
            t1 = np.where(leaving, np.minimum(t1, r), t1)
    ok &= t0 <= t1
    idx = np.nonzero(ok)[0]
    out = np.stack([p0[ok] + t0[ok, None] * d[ok], p0[ok] + t1[ok, None] * d[ok]], axis=1)
    return out, idx


def dash_segments(seg_uv: np.ndarray, dash_px: float = 6.0, gap_px: float = 4.0) -> tuple[np.ndarray, np.ndarray]:
    """Cut segments (K, 2, 2) into dashes: returns dashes (M, 2, 2) and the source index (M,)."""
    P = np.asarray(seg_uv, dtype=float).reshape(-1, 2, 2)
    if dash_px <= 0 or gap_px < 0:
        raise ValueError(f"dash_px must be > 0 and gap_px ≥ 0, got {dash_px}, {gap_px}")
    period = dash_px + gap_px
    d = P[:, 1] - P[:, 0]
    length = np.linalg.norm(d, axis=1)
    count = np.zeros(len(P), np.int64)
    long_enough = length >= 1e-9
    count[long_enough] = np.ceil(length[long_enough] / period)  # dashes start at 0, period, … < length
    if count.sum() == 0:
        return np.zeros((0, 2, 2)), np.zeros(0, np.int64)
    idx = np.repeat(np.arange(len(P)), count)
    starts = (np.arange(len(idx)) - np.repeat(np.cumsum(count) - count, count)) * period
    ends = np.minimum(starts + dash_px, length[idx])
    u = d[idx] / length[idx, None]
    a = P[idx, 0]
    return np.stack([a + starts[:, None] * u, a + ends[:, None] * u], axis=1), idx


@dataclass(frozen=True)
class ProjectedWireframe:
    """A model's wireframe in one view, in pixels, clipped to the image.

    seg_uv : (K, 2, 2) pixels. visible : (K,) bool. edge_index : (K,) model edge (−1 for
    silhouettes and rims). kind : (K,) "edge" / "silhouette" / "rim".
    """

    seg_uv: np.ndarray
    visible: np.ndarray
    edge_index: np.ndarray
    kind: np.ndarray


def project_wireframe(
    camera: Camera,
    model: BRep,
    T_world_obj: np.ndarray,
    *,
    n_circle: int = 48,
    width: int | None = None,
    height: int | None = None,
) -> ProjectedWireframe:
    """Project a model at a pose through C: hidden-line flags, cylinder and mesh silhouettes, clipping.

    width, height : the image to clip to (default: the camera's).
    """
    return project_wireframes(camera, [(model, T_world_obj)], n_circle=n_circle, width=width, height=height)[0]


def project_wireframes(
    camera: Camera,
    posed: list[tuple[BRep, np.ndarray]],
    *,
    n_circle: int = 48,
    width: int | None = None,
    height: int | None = None,
) -> list[ProjectedWireframe]:
    """``project_wireframe`` of many (model, T_world_obj) at once, one ProjectedWireframe each: each
    model's outline from the optical centre, then one depth clip, one product through C and one image
    clip over all their segments (per object, the numpy calls' overhead was most of a 2,000-object draw)."""
    wfs = [model.wireframe(camera.center, T, n_circle=n_circle) for model, T in posed]
    if not wfs:
        return []
    counts = np.array([len(wf.segments) for wf in wfs])
    owner = np.repeat(np.arange(len(wfs)), counts)
    S, idx = clip_segments_depth(camera, np.concatenate([wf.segments.reshape(-1, 2, 3) for wf in wfs]))
    uv = camera.project(S.reshape(-1, 3)).reshape(-1, 2, 2) if len(S) else np.zeros((0, 2, 2))
    uv, idx2 = clip_segments_rect(uv, width or camera.width, height or camera.height)
    src = idx[idx2]  # ascending: the clips keep the segments' order
    visible, edge_index, kind = (
        np.concatenate([getattr(wf, a) for wf in wfs]) for a in ("visible", "edge_index", "kind")
    )
    bounds = np.searchsorted(owner[src], np.arange(len(wfs) + 1))
    return [
        ProjectedWireframe(uv[a:b], visible[src[a:b]], edge_index[src[a:b]], kind[src[a:b]])
        for a, b in zip(bounds[:-1], bounds[1:])
    ]


def wireframe_lines(
    pws: list[ProjectedWireframe], colors, hidden: str = "dashed", dim: float = 0.55
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Wireframes as lines, one after the other: each one's visible segments solid in its colour (n, 3),
    then its hidden ones dashed and dimmed ("dashed") or left out ("removed"), all dashed at once.

    Returns segments (K, 2, 2) pixels, colours (K, 3) uint8 and bounds (n + 1,): wireframe i's lines
    are ``bounds[i]:bounds[i + 1]``.
    """
    if hidden not in ("dashed", "removed"):
        raise ValueError(f"hidden must be 'dashed' or 'removed', got {hidden!r}")
    n = len(pws)
    colors = np.asarray(colors, dtype=np.uint8).reshape(n, 3)
    if n == 0:
        return np.zeros((0, 2, 2)), np.zeros((0, 3), np.uint8), np.zeros(1, np.int64)
    seg = np.concatenate([np.asarray(pw.seg_uv, dtype=float).reshape(-1, 2, 2) for pw in pws])
    visible = np.concatenate([np.asarray(pw.visible, dtype=bool).reshape(-1) for pw in pws])
    owner = np.repeat(np.arange(n), [len(pw.seg_uv) for pw in pws])
    segs, owners, cols = [seg[visible]], [owner[visible]], [colors[owner[visible]]]
    if hidden == "dashed":
        dashes, idx = dash_segments(seg[~visible])
        dashed_owner = owner[~visible][idx]
        dimmed = (colors * float(dim)).astype(np.uint8)  # each component truncated, as int(c * dim)
        segs, owners, cols = segs + [dashes], owners + [dashed_owner], cols + [dimmed[dashed_owner]]
    order = np.argsort(np.concatenate([2 * o + k for k, o in enumerate(owners)]), kind="stable")
    owner_out = np.concatenate(owners)[order]
    bounds = np.searchsorted(owner_out, np.arange(n + 1))
    return np.concatenate(segs)[order], np.concatenate(cols)[order], bounds


@dataclass
class LineBatch:
    """Pixel segments with a colour each, collected for one ``add_line_segments`` call."""

    segments: list = field(default_factory=list)
    colors: list = field(default_factory=list)

    def add(self, seg_uv: np.ndarray, color: tuple[int, int, int] | np.ndarray) -> None:
        """Add segments (K, 2, 2) in one colour (3,) or one colour per segment (K, 3)."""
        seg = np.asarray(seg_uv, dtype=float).reshape(-1, 2, 2)
        if len(seg) == 0:
            return
        c = np.asarray(color, dtype=np.uint8)
        self.segments.append(seg)
        self.colors.append(np.broadcast_to(c, (len(seg), 3)) if c.ndim == 1 else c.reshape(len(seg), 3))

    def add_wireframe(
        self, pw: ProjectedWireframe, color: tuple[int, int, int], hidden: str = "dashed", dim: float = 0.55
    ) -> None:
        """Visible segments solid; hidden ones dashed and dimmed ("dashed"), or left out ("removed")."""
        seg, colors, _ = wireframe_lines([pw], [color], hidden, dim)
        self.add(seg, colors)

    def __len__(self) -> int:
        return int(sum(len(s) for s in self.segments))

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(segments (K, 2, 2) pixels, colours (K, 3) uint8)."""
        if not self.segments:
            return np.zeros((0, 2, 2)), np.zeros((0, 3), np.uint8)
        return np.concatenate(self.segments), np.concatenate(self.colors).astype(np.uint8)

    def world(self, pw: PixelWorld, z: float) -> tuple[np.ndarray, np.ndarray]:
        """For viser: points (K, 2, 3) in the pixel world on plane z, colours (K, 2, 3) uint8."""
        seg, col = self.arrays()
        return pw.to_world(seg, z), np.repeat(col[:, None, :], 2, axis=1)


def cross_markers(uv: np.ndarray, size_px: float = 5.0) -> np.ndarray:
    """Segments (2N, 2, 2) drawing a '+' of half-size ``size_px`` at each pixel (N, 2)."""
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    h = np.array([size_px, 0.0])
    v = np.array([0.0, size_px])
    return np.concatenate([np.stack([uv - h, uv + h], axis=1), np.stack([uv - v, uv + v], axis=1)])


def circle_marker(uv: np.ndarray, radius_px: float = 6.0, n: int = 16) -> np.ndarray:
    """Segments (n, 2, 2) of a circle of ``radius_px`` around a pixel (2,)."""
    c = np.asarray(uv, dtype=float).reshape(2)
    th = np.linspace(0, 2 * np.pi, n + 1)
    P = c + radius_px * np.column_stack([np.cos(th), np.sin(th)])
    return np.stack([P[:-1], P[1:]], axis=1)


def nearest_segment(seg_uv: np.ndarray, uv: np.ndarray) -> tuple[int, float]:
    """Index of the segment (K, 2, 2) nearest to a pixel (2,) and its distance in pixels; (−1, inf) if none."""
    P = np.asarray(seg_uv, dtype=float).reshape(-1, 2, 2)
    if len(P) == 0:
        return -1, float("inf")
    p = np.asarray(uv, dtype=float).reshape(2)
    a, d = P[:, 0], P[:, 1] - P[:, 0]
    L2 = np.maximum(np.einsum("ij,ij->i", d, d), 1e-12)
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / L2, 0.0, 1.0)
    dist = np.linalg.norm(a + t[:, None] * d - p, axis=1)
    i = int(np.argmin(dist))
    return i, float(dist[i])
