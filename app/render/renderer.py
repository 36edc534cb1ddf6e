"""mcit's own deterministic renderer: a scene's bodies seen through its camera C at time t.

Per pixel, a ray ``X = c + s · M⁻¹ (u, v, 1)`` (C = [M | p₄], c the optical centre) is cast
exactly against every body (``raycast``: convex polyhedra by their planes, cylinders and cones as
quadrics), so the nearest hit is a per-pixel z-buffer on the depth s and occlusions are exact.

* Shading: Lambert with one directional light and an ambient term,
  ``albedo · (ambient + (1 − ambient) · max(0, n·L)) · (1 + texture · noise(X_obj))`` times ``gain``
  grey levels; the texture is a smooth value noise fixed to the body (it moves with it). Rays
  that hit nothing see ``sky``.
* Anti-aliasing where it matters: pixels whose centre sample differs in (body, face) from a
  neighbour — every pixel an edge or silhouette crosses — are re-rendered with ``aa_samples``
  samples (a golden-ratio lattice, shifted modulo the pixel by a fixed per-pixel amount so that
  no edge direction is favoured) and box-filtered (the mean over the pixel's square): an edge
  pixel's grey level is its area coverage to about 1 % of the contrast with 89 samples, and the
  image of a true edge lies where C projects it (tests measure both).
* Lens distortion (``lens``, an ``app.undistort.LensDistortion``; by default the scene's): each
  sample of the camera's pixel grid is cast through ``lens.undistort`` (the ideal pixel the lens
  images there), so the frame is what a real lens would give — anti-aliasing included, since the
  sub-pixel samples are mapped too. C then holds in the undistorted image.
* Sensor: optional Gaussian blur (symmetric, so edges do not move), then Gaussian noise seeded
  by ``(seed, frame_index)``, rounded to uint8. Same inputs, same bytes.

Pixel convention (DESIGN.md): u right, v down, origin at the centre of the top-left pixel, which
covers [−0.5, 0.5]².
"""

from __future__ import annotations

import numpy as np

from app.scene import RenderSpec, Scene
from core.camera import Camera

from .raycast import BodyCaster, Hits, SceneCaster

__all__ = ["Renderer", "value_noise", "lattice_offsets", "render_frame"]

_GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


def lattice_offsets(n: int) -> np.ndarray:
    """n sample offsets (n, 2) inside a pixel, in [−0.5, 0.5)²: x stratified (n-rooks), y by the
    golden-ratio lattice, so edges of any direction are resolved to ≈ 1/n of a pixel."""
    if n < 1:
        raise ValueError(f"a pixel needs at least one sample, got {n}")
    i = np.arange(n)
    x = (i + 0.5) / n
    y = np.mod(0.5 + i * _GOLDEN, 1.0)
    return np.column_stack([x, y]) - 0.5


def _hash01(ix: np.ndarray, iy: np.ndarray, iz: np.ndarray, salt: int) -> np.ndarray:
    """Deterministic pseudo-random values in [−1, 1] of integer lattice points."""
    h = (ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791) ^ (salt * 2654435761)
    h = (h ^ (h >> 13)) * 1274126177
    h = h ^ (h >> 16)
    return (h & 0xFFFF).astype(float) / 32767.5 - 1.0


def _hash_unit(ix: np.ndarray, iy: np.ndarray, salt: int) -> np.ndarray:
    """Deterministic pseudo-random values in [0, 1) of pixel indices."""
    return (
        0.5
        * (_hash01(np.asarray(ix, np.int64), np.asarray(iy, np.int64), np.zeros_like(ix, np.int64), salt) + 1.0)
        % 1.0
    )


def value_noise(X: np.ndarray, scale_m: float, salt: int = 0) -> np.ndarray:
    """Smooth noise in [−1, 1] of points X (N, 3), metres, with features of size ``scale_m``
    (trilinear interpolation of lattice values with a smoothstep; two octaves)."""
    out = np.zeros(len(X))
    amp_total = 0.0
    for octave, amp in ((1.0, 0.7), (2.7, 0.3)):
        P = np.asarray(X, dtype=float) * (octave / scale_m)
        i0 = np.floor(P).astype(np.int64)
        f = P - i0
        w = f * f * (3.0 - 2.0 * f)
        acc = np.zeros(len(X))
        for dx in (0, 1):
            for dy in (0, 1):
                for dz in (0, 1):
                    v = _hash01(i0[:, 0] + dx, i0[:, 1] + dy, i0[:, 2] + dz, salt + int(octave * 10))
                    wx = w[:, 0] if dx else 1.0 - w[:, 0]
                    wy = w[:, 1] if dy else 1.0 - w[:, 1]
                    wz = w[:, 2] if dz else 1.0 - w[:, 2]
                    acc += v * wx * wy * wz
        out += amp * acc
        amp_total += amp
    return out / amp_total


class Renderer:
    """Renders a scene's frames (see the module docstring).

    Parameters
    ----------
    scene : app.scene.Scene
        Bodies (models, poses over time, appearance) and the camera.
    camera : core.camera.Camera, optional
        Render through this camera instead of ``scene.camera`` (same C convention).
    spec : app.scene.RenderSpec, optional
        Light, noise, blur and anti-aliasing; default ``scene.render``.
    lens : app.undistort.LensDistortion or None, optional
        Render as seen through this lens; default ``scene.lens`` when ``camera`` is not given, else
        none (pass ``lens=None`` to render the scene's camera without its distortion).
    """

    _SCENE_LENS = object()

    def __init__(self, scene: Scene, camera: Camera | None = None, spec: RenderSpec | None = None, lens=_SCENE_LENS):
        self.scene = scene
        self.camera = camera if camera is not None else scene.camera
        self.spec = spec if spec is not None else scene.render
        if lens is Renderer._SCENE_LENS:
            lens = getattr(scene, "lens", None) if camera is None else None
        if lens is not None and (lens.width, lens.height) != (self.camera.width, self.camera.height):
            raise ValueError(
                f"the lens was calibrated on {lens.width}×{lens.height} images, the camera renders "
                f"{self.camera.width}×{self.camera.height}"
            )
        self.lens = lens
        self._casters = [BodyCaster(b.model) for b in scene.bodies]
        C = self.camera.C
        self._M_inv = np.linalg.inv(C[:, :3])
        w, h = self.camera.width, self.camera.height
        u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
        self._uv = np.column_stack([u.ravel(), v.ravel()])
        self._uv_ideal = self._uv if lens is None else lens.undistort(self._uv)  # the pixel centres' rays, once
        self._albedo = np.array([b.appearance.albedo for b in scene.bodies] + [0.0])
        self._texture = np.array([b.appearance.texture for b in scene.bodies] + [0.0])
        self._tex_scale = np.array([b.appearance.texture_scale_m for b in scene.bodies] + [1.0])
        self._last: tuple[float, np.ndarray, np.ndarray] | None = None  # the last noise-free image

    # ---------------------------------------------------------------- geometry
    def caster(self, t_s: float) -> SceneCaster:
        """The scene's ray caster with every body at its true pose at t_s (seconds)."""
        return SceneCaster.for_scene(self.scene, t_s, self._casters)

    def rays(self, uv: np.ndarray) -> np.ndarray:
        """Directions (N, 3), world frame, of pixels uv (N, 2) of the rendered image (through the lens,
        if any), scaled so that t = depth s."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        if self.lens is not None:
            uv = self.lens.undistort(uv)
        return self._ideal_rays(uv)

    def _ideal_rays(self, uv: np.ndarray) -> np.ndarray:
        return np.column_stack([uv, np.ones(len(uv))]) @ self._M_inv.T

    def cast(self, t_s: float, uv: np.ndarray) -> Hits:
        """Nearest hits of the rays of pixels uv (N, 2) at time t_s; ``Hits.t`` is the depth (m)."""
        return self.caster(t_s).cast(self.camera.center, self.rays(uv))

    # ---------------------------------------------------------------- shading
    def _shade(self, hits: Hits) -> np.ndarray:
        spec = self.spec
        b = hits.body  # −1 (miss) indexes the sentinel at the end of the per-body arrays
        lambert = np.clip(hits.normal @ spec.light, 0.0, None)
        radiance = self._albedo[b] * (spec.ambient + (1.0 - spec.ambient) * lambert)
        tex = self._texture[b]
        textured = np.flatnonzero((tex > 0) & (b >= 0))
        if len(textured):
            for i in np.unique(b[textured]):
                sel = textured[b[textured] == i]
                radiance[sel] *= 1.0 + tex[sel] * value_noise(hits.X_obj[sel], self._tex_scale[i], salt=int(i))
        radiance[b < 0] = spec.sky
        return spec.gain * radiance

    def render_float(self, t_s: float) -> tuple[np.ndarray, np.ndarray]:
        """Noise-free, unblurred image (H, W), float grey levels, and the labels (H, W) int64 of
        the pixel centres (body index × 4096 + face label; −1 where nothing is hit).

        The last time's result is kept, so frames of one time with other noise seeds are cheap.
        """
        if self._last is not None and self._last[0] == t_s:
            return self._last[1].copy(), self._last[2].copy()
        w, h = self.camera.width, self.camera.height
        caster = self.caster(t_s)
        centre = self.camera.center
        hits = caster.cast(centre, self._ideal_rays(self._uv_ideal))
        img = self._shade(hits).reshape(h, w)
        labels = np.where(hits.body >= 0, hits.body * 4096 + hits.face, -1).reshape(h, w)
        mask = _edge_pixels(labels)
        iy, ix = np.nonzero(mask)
        if len(iy) and self.spec.aa_samples > 1:
            off = lattice_offsets(self.spec.aa_samples) + 0.5  # in [0, 1)²
            n = len(off)
            # Each pixel shifts the lattice by its own fixed amount (modulo the pixel): the
            # coverage estimate is then unbiased whatever the edge's direction, even along the
            # lattice's own rows, and stays deterministic.
            shift = np.column_stack([_hash_unit(ix, iy, 1), _hash_unit(ix, iy, 2)])
            sub = np.mod(off[None, :, :] + shift[:, None, :], 1.0) - 0.5
            if self.lens is None:
                uv = (np.column_stack([ix, iy]).astype(float)[:, None, :] + sub).reshape(-1, 2)
            else:  # through the lens: the pixel's ideal centre plus its samples mapped by the local inverse
                # Jacobian (the lens is smooth: second-order error ≈ 1e-4 px at 25 px of distortion)
                c = self._uv_ideal[iy * w + ix]
                J_inv = np.linalg.inv(self.lens.jacobian(c))
                uv = (c[:, None, :] + np.einsum("nij,nsj->nsi", J_inv, sub)).reshape(-1, 2)
            samples = self._shade(caster.cast(centre, self._ideal_rays(uv)))
            img[iy, ix] = samples.reshape(-1, n).mean(axis=1)
        self._last = (t_s, img.copy(), labels.copy())
        return img, labels

    def render(self, t_s: float, frame_index: int = 0, *, noise: bool = True, blur: bool = True) -> np.ndarray:
        """The frame (H, W) uint8 grey at scene time t_s; noise seeded by (spec.seed, frame_index)."""
        import cv2

        if int(frame_index) != frame_index or frame_index < 0:
            raise ValueError(f"frame_index must be a non-negative integer (it seeds the noise), got {frame_index!r}")
        img, _ = self.render_float(t_s)
        if blur and self.spec.blur_sigma_px > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.spec.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        if noise and self.spec.noise_sigma > 0:
            rng = np.random.default_rng([int(self.spec.seed), int(frame_index)])
            img = img + rng.normal(0.0, self.spec.noise_sigma, img.shape)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def render_bgr(self, t_s: float, frame_index: int = 0, **kw) -> np.ndarray:
        """The frame as BGR (H, W, 3) uint8 (grey replicated: the paper's camera is black and white)."""
        g = self.render(t_s, frame_index, **kw)
        return np.repeat(g[:, :, None], 3, axis=2)


def _edge_pixels(labels: np.ndarray) -> np.ndarray:
    """Pixels whose centre label differs from one of their 8 neighbours'.

    Every pixel a straight boundary crosses is among them: if the boundary cuts the pixel's
    square, the neighbour centre opposite the cut-off part (e.g. (1, 1) for a cut corner near
    (0.5, 0.5)) lies beyond the boundary, since an affine function positive at the corner and
    negative at the centre is positive at twice the corner. Only slivers thinner than a pixel
    between two same-label centres can slip through.
    """
    L = np.pad(labels, 1, mode="edge")
    h, w = labels.shape
    diff = np.zeros((h, w), bool)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                diff |= L[1 + dy : 1 + dy + h, 1 + dx : 1 + dx + w] != labels
    return diff


def render_frame(scene: Scene, t_s: float, frame_index: int = 0, **kw) -> np.ndarray:
    """One frame (H, W) uint8 of ``scene`` at t_s; see ``Renderer.render``."""
    return Renderer(scene).render(t_s, frame_index, **kw)
