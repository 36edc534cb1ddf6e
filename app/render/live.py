"""The site rendered live: any list of bodies seen through one of the scene's cameras, fast enough for video.

The ray-cast renderer (``app.render.renderer``) is exact but takes about a second a frame; this one
draws the same picture with OpenGL (moderngl, offscreen through EGL; Mesa's llvmpipe on a machine
with no GPU), chosen by ``bench/live_render.py``, at the scene's frame rate on one core.

* The same look as the ray-cast renderer: Lambert with the scene's light and ambient term, times
  ``(1 + texture · value_noise(X_obj))`` with the ray-cast renderer's own two-octave value noise
  fixed to the body (its integer hash ported to GLSL: ``imulExtended`` keeps the 45 low bits of the
  64-bit products that the hash's low 16 bits depend on, so the texture is the same function);
  ``sky`` where nothing is hit; then the lens, the blur and the sensor noise seeded by
  ``(seed, frame_index)`` (numpy's generator, as the ray-cast renderer draws it).
* Geometry through C exactly: the GL projection is built from C's rows (no K/pose split), with
  DESIGN.md's pixel convention (pixel centres at integers, the top-left pixel covering [−0.5, 0.5]²);
  the image is drawn ``supersample`` times finer in each direction with ``msaa`` coverage samples a
  fine pixel (2 × 2 × 4 = 16 a pixel by default) and box-filtered down, so an edge pixel's grey level
  is its area coverage to a few % of the contrast and edges lie where C projects them.
* Bodies are ``BRep.triangles()``: flat faces flat-shaded, curved primitives (cylinders, cones,
  spheres) with angle-weighted smooth normals and as many segments as keep their silhouettes within
  ``tol_px`` of the true ones at the body's distance (re-tessellated when a body comes closer).
* The lens: the undistorted (ideal) image is drawn over the ideal pixels the lens images anywhere
  in the frame, then resampled by one precomputed ``cv2.remap``.
* Speed: the noise-free image is kept while no body moves (same models, poses and appearances
  as the last frame): such a frame costs the sensor noise alone.

OpenGL runs on one thread of the process (``mcit-gl``) that owns the one context; ``render`` may be
called from any thread, and waits for llvmpipe with Python's lock released (the interface's threads
run meanwhile). ``LiveRenderError`` says why when OpenGL cannot start (no libEGL).

``LiveSource`` is a ``VideoSource`` of those frames: the scene's bodies at scene time ``k / fps``
(``scene_bodies``, looping with the recording's length as the recording does), or whatever
``bodies_at`` gives (the robot's links, carried objects). ``mcit serve`` shows it by default.
"""

from __future__ import annotations

import os
import threading
import time
import zlib
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from app.scene import Appearance, RenderSpec, Scene
from app.video import VideoSource
from core.brep import BRep

__all__ = [
    "shutdown_gl",
    "RenderBody",
    "LiveRenderer",
    "LiveRenderError",
    "LiveSource",
    "scene_bodies",
    "scene_loop_s",
    "projection_matrix",
    "smooth_mesh",
    "SUPERSAMPLE",
    "MSAA",
    "gl_description",
]

SUPERSAMPLE = 2  # the image drawn this many times finer along each axis, then box-filtered (bench/live_render.py)
MSAA = 4  # multisample anti-aliasing: coverage samples a (fine) pixel; 2 × 2 × 4 = 16 a pixel (bench/live_render.py)
SILHOUETTE_TOL_PX = 0.02  # largest gap between a tessellated silhouette and the true one
NEAR_M, FAR_M = 0.01, 200.0  # the depth range drawn
_CREASE_COS = np.cos(np.radians(40.0))  # curved surfaces' facets closer than this share their normals
_SALT_MUL = 2654435761  # the ray-cast hash's salt multiplier (app.render.renderer._hash01)
_OCTAVES = ((1.0, 0.7), (2.7, 0.3))  # value_noise's octaves: (frequency, amplitude)


class LiveRenderError(RuntimeError):
    """The live renderer cannot run here (no OpenGL through EGL); the message says why and what to install."""


@dataclass(frozen=True, eq=False)
class RenderBody:
    """One body to draw: its model, its pose and how it is shaded.

    name : for messages. brep : the model (object frame, metres). T_world : array, shape (4, 4), the
    pose ``T_world_obj``. appearance : albedo and texture. salt : seeds the body's texture (the
    ray-cast renderer uses the body's index in ``scene.bodies``, which ``scene_bodies`` gives); None
    takes one from the name, so a body keeps its texture whatever the list's order.
    """

    name: str
    brep: BRep
    T_world: np.ndarray
    appearance: Appearance = Appearance()
    salt: int | None = None

    @property
    def texture_salt(self) -> int:
        return int(self.salt) if self.salt is not None else 4096 + zlib.crc32(self.name.encode()) % 65536


def scene_loop_s(scene: Scene) -> float | None:
    """Seconds after which the scene's scripted motions start again: the length of its first camera's
    recording as a player loops it (frame_count / fps; ``scene_clock`` reads the same from the file),
    None for a scene with no video block (its motions then play once)."""
    v = scene.video
    return None if v is None else v.frame_count / v.fps


def scene_bodies(scene: Scene, t_s: float) -> list[RenderBody]:
    """The scene's bodies at scene time ``t_s`` seconds, looping with the recording's length as the recording
    does; each body's texture salt is its index, as the ray-cast renderer's."""
    loop = scene_loop_s(scene)
    t = float(t_s) % loop if loop else float(t_s)
    return [RenderBody(b.name, b.model, b.pose_at(t), b.appearance, i) for i, b in enumerate(scene.bodies)]


def projection_matrix(C: np.ndarray, u0: int, v0: int, width: int, height: int) -> np.ndarray:
    """The OpenGL clip matrix (4, 4) of the camera C (3, 4) drawing the pixels u0 … u0 + width − 1,
    v0 … v0 + height − 1 (pixel centres at integers, DESIGN.md), row 0 of the framebuffer being v0.

    Clip x / w = 2 (u − u0 + ½) / width − 1 with u = C₀X / C₂X: window x = 0 is the left edge
    u0 − ½ of the first pixel. Likewise v along the framebuffer's rows (read back, row 0 is the image's
    top). Depth: w = C₂X (metres along the axis for a normalised C), mapped to [−1, 1] over [NEAR_M, FAR_M].
    """
    C = np.asarray(C, dtype=float)
    n, f = NEAR_M, FAR_M
    P = np.empty((4, 4))
    P[0] = 2.0 / width * C[0] + (2.0 * (0.5 - u0) / width - 1.0) * C[2]
    P[1] = 2.0 / height * C[1] + (2.0 * (0.5 - v0) / height - 1.0) * C[2]
    P[2] = (f + n) / (f - n) * C[2] + np.array([0.0, 0.0, 0.0, -2.0 * f * n / (f - n)])
    P[3] = C[2]
    return P


def _corner_angles(P: np.ndarray) -> np.ndarray:
    """Angles (T, 3) at each corner of triangles P (T, 3, 3)."""
    out = np.empty(P.shape[:2])
    for k in range(3):
        a = P[:, (k + 1) % 3] - P[:, k]
        b = P[:, (k + 2) % 3] - P[:, k]
        cos = np.einsum("ij,ij->i", a, b) / np.maximum(np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1), 1e-300)
        out[:, k] = np.arccos(np.clip(cos, -1.0, 1.0))
    return out


def smooth_mesh(V: np.ndarray, T: np.ndarray, smooth: bool) -> np.ndarray:
    """Triangle soup (3 T', 6) float32, position and unit normal per corner, of a mesh V (N, 3), T (T, 3).

    smooth : False gives each triangle its own normal (flat faces); True gives each corner the
    angle-weighted mean of the normals of the triangles around its vertex that are within 40° of
    its own (a tessellated cylinder's side is smooth, its rim stays sharp). Degenerate triangles
    (a cone's apex) are dropped.
    """
    V = np.asarray(V, dtype=float).reshape(-1, 3)
    T = np.asarray(T, dtype=np.int64).reshape(-1, 3)
    P = V[T]
    cross = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    length = np.linalg.norm(cross, axis=1)
    keep = length > 1e-14 * max(1.0, float(np.abs(V).max(initial=0.0))) ** 2
    T, P, unit = T[keep], P[keep], cross[keep] / length[keep, None]
    normals = np.repeat(unit[:, None, :], 3, axis=1)
    if smooth and len(T):
        angle = _corner_angles(P).ravel()
        corner_v = T.ravel()
        corner_t = np.repeat(np.arange(len(T)), 3)
        order = np.argsort(corner_v, kind="stable")
        bounds = np.searchsorted(corner_v[order], np.arange(len(V) + 1))
        flat = normals.reshape(-1, 3)
        for v in np.flatnonzero(np.diff(bounds)):
            idx = order[bounds[v] : bounds[v + 1]]
            U = unit[corner_t[idx]]
            S = ((U @ U.T) > _CREASE_COS).astype(float) @ (U * angle[idx, None])
            flat[idx] = S / np.linalg.norm(S, axis=1, keepdims=True)
    return np.concatenate([P, normals], axis=2).reshape(-1, 6).astype(np.float32)


def _solid_radius(part) -> float:
    """The largest radius of a curved primitive (what its tessellation's sagitta scales with)."""
    if getattr(part, "kind", "") == "revolution":
        return float(max(part.r0, part.r1))
    if getattr(part, "kind", "") == "sphere":
        return float(part.radius)
    b = part.bounds()
    return 0.5 * float(np.linalg.norm(b[1] - b[0]))


def segments_for(radius_px: float, tol_px: float = SILHOUETTE_TOL_PX) -> int:
    """Sides of a polygon inscribed in a circle of ``radius_px`` pixels whose sagitta r(1 − cos(π/n)) is
    within ``tol_px``: a multiple of 8, 24 … 2048."""
    if radius_px <= tol_px:
        return 24
    n = np.pi / np.arccos(1.0 - tol_px / radius_px)
    return int(np.clip(8 * np.ceil(n / 8.0), 24, 2048))


# ---------------------------------------------------------------------- the GL thread
_VERTEX = """
#version 450 core
uniform mat4 mvp;
uniform mat3 rot;
in vec3 in_pos;
in vec3 in_nrm;
out vec3 v_obj;
out vec3 v_nrm;
void main() {
    v_obj = in_pos;
    v_nrm = rot * in_nrm;
    gl_Position = mvp * vec4(in_pos, 1.0);
}
"""

# value_noise and _hash01 of app/render/renderer.py. The hash works on int64 and keeps h & 0xFFFF of
# h1 ^ (h1 >> 16), h1 = (h0 ^ (h0 >> 13)) · K: those 16 bits need h1's low 32 bits, which need the low
# 32 bits of h0 ^ (h0 >> 13), i.e. bits 0 … 44 of h0 = the XOR of the products: imulExtended gives each
# signed 64-bit product as (msb, lsb); the salt's product comes from Python as (lo, hi).
_FRAGMENT = """
#version 450 core
uniform vec3 light;
uniform float ambient;
uniform float albedo;
uniform float gain;
uniform float tex_amp;
uniform vec2 freq;
uniform uvec4 salt;
in vec3 v_obj;
in vec3 v_nrm;
out float radiance;

float hash01(ivec3 i, uvec2 s) {
    int hx, lx, hy, ly, hz, lz;
    imulExtended(i.x, 73856093, hx, lx);
    imulExtended(i.y, 19349663, hy, ly);
    imulExtended(i.z, 83492791, hz, lz);
    uint lo = uint(lx) ^ uint(ly) ^ uint(lz) ^ s.x;
    uint hi = uint(hx) ^ uint(hy) ^ uint(hz) ^ s.y;
    uint h = lo ^ ((lo >> 13) | (hi << 19));
    h *= 1274126177u;
    h ^= h >> 16;
    return float(h & 0xFFFFu) / 32767.5 - 1.0;
}

float octave(vec3 P, uvec2 s) {
    vec3 fl = floor(P);
    ivec3 i0 = ivec3(fl);
    vec3 f = P - fl;
    vec3 w = f * f * (3.0 - 2.0 * f);
    float acc = 0.0;
    for (int dx = 0; dx < 2; dx++) {
        float wx = dx == 1 ? w.x : 1.0 - w.x;
        for (int dy = 0; dy < 2; dy++) {
            float wy = dy == 1 ? w.y : 1.0 - w.y;
            for (int dz = 0; dz < 2; dz++) {
                float wz = dz == 1 ? w.z : 1.0 - w.z;
                acc += hash01(i0 + ivec3(dx, dy, dz), s) * wx * wy * wz;
            }
        }
    }
    return acc;
}

void main() {
    vec3 n = normalize(v_nrm);
    float r = albedo * (ambient + (1.0 - ambient) * max(0.0, dot(n, light)));
    if (tex_amp > 0.0) {
        float noise = 0.7 * octave(v_obj * freq.x, salt.xy) + 0.3 * octave(v_obj * freq.y, salt.zw);
        r *= 1.0 + tex_amp * noise;
    }
    radiance = gain * r;
}
"""


class _GLThread:
    """The process's one OpenGL context, created on first use on its own thread, where every GL call runs."""

    _lock = threading.Lock()
    _instance: _GLThread | None = None

    def __init__(self) -> None:
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="mcit-gl")
        self.ctx = None
        self.program = None
        self.error: str | None = None
        self.closed = False  # shut down: its context, and every GL object made in it, released

    @classmethod
    def get(cls) -> _GLThread:
        with cls._lock:
            if cls._instance is None:
                cls._instance = cls()
            return cls._instance

    @classmethod
    def _forget(cls) -> None:
        """In a child forked after OpenGL started: Mesa's display (its rasteriser threads, the parent's) is unusable
        here — a draw would wait for ever —, so the live renderer refuses to start instead."""
        cls._lock = threading.Lock()
        if cls._instance is not None and cls._instance.ctx is not None:
            cls._instance = cls()
            cls._instance.error = (
                "OpenGL was started before this process was forked and cannot be used in the child; start the "
                "process with multiprocessing's 'spawn' method, or render in the parent"
            )
        else:
            cls._instance = None

    def call(self, fn: Callable, *args):
        """``fn(ctx, *args)`` on the GL thread; its result, or its exception raised here."""
        return self._pool.submit(self._run, fn, args).result()

    def _run(self, fn: Callable, args: tuple):
        if self.ctx is None:
            self._start()
        return fn(self, *args)

    def _start(self) -> None:
        if self.error is not None:
            raise LiveRenderError(self.error)
        try:
            import moderngl
        except ImportError as exc:
            self.error = f"moderngl is not installed ({exc}); pip install moderngl"
            raise LiveRenderError(self.error) from None
        # llvmpipe's rasteriser threads, read when the driver loads: one, unless the user says otherwise
        # (the live video's budget is one core; the other runs the solvers and the interface)
        os.environ.setdefault("LP_NUM_THREADS", "1")
        try:
            ctx = moderngl.create_standalone_context(backend="egl", require=450)
        except Exception as exc:  # noqa: BLE001 - any failure of the driver means no live rendering
            self.error = (
                f"no OpenGL 4.5 through EGL here ({str(exc).strip().splitlines()[0] if str(exc).strip() else exc!r}); "
                "install libegl1 and libgl1-mesa-dri (Mesa's llvmpipe renders without a GPU)"
            )
            raise LiveRenderError(self.error) from None
        self.ctx = ctx
        self.program = ctx.program(vertex_shader=_VERTEX, fragment_shader=_FRAGMENT)
        self._finish = _gil_free_finish(ctx)

    @classmethod
    def shutdown(cls) -> None:
        """Release the process's OpenGL context and stop its thread (before the process exits: Mesa's rasteriser
        threads torn down by the exit itself printed "FATAL: exception not rethrown" after a failed start)."""
        with cls._lock:
            gl, cls._instance = cls._instance, None
        if gl is None:
            return
        gl.closed = True
        if gl.ctx is not None:
            try:
                gl._pool.submit(gl.ctx.release).result(timeout=5.0)
            except Exception:  # noqa: BLE001 - at exit: nothing more to do
                pass
        gl._pool.shutdown(wait=True)

    def wait(self) -> None:
        """Wait until the GL has drawn everything asked of it, letting the process's other threads run meanwhile
        (moderngl's own calls hold Python's lock while llvmpipe draws: the interface would stall ~40 ms a frame)."""
        self._finish()

    def describe(self) -> str:
        """The OpenGL renderer and version (e.g. "llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile) Mesa")."""
        return self.call(lambda gl: f"{gl.ctx.info['GL_RENDERER']}, {gl.ctx.info['GL_VERSION']}")


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_GLThread._forget)


def _gil_free_finish(ctx) -> Callable[[], None]:
    """glFinish called through ctypes, which releases Python's lock during the call (moderngl's ``finish`` when
    the function cannot be found)."""
    import ctypes
    import ctypes.util

    for name in ("libEGL.so.1", ctypes.util.find_library("EGL")):
        try:
            egl = ctypes.CDLL(name) if name else None
        except OSError:
            continue
        if egl is None:
            continue
        egl.eglGetProcAddress.restype = ctypes.c_void_p
        egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
        address = egl.eglGetProcAddress(b"glFinish")
        if address:
            return ctypes.CFUNCTYPE(None)(address)
    return ctx.finish


def gl_description() -> str:
    """The OpenGL renderer the live site draws with (e.g. "llvmpipe (LLVM 15.0.6, 256 bits), 4.5 (Core Profile) Mesa
    22.3.6"); LiveRenderError when OpenGL cannot start."""
    return _GLThread.get().describe()


@dataclass
class _Mesh:
    brep: BRep
    segments: int
    vbo: object
    vao: object
    count: int


class LiveRenderer:
    """Renders lists of ``RenderBody`` through one camera of a scene (see the module docstring).

    Parameters
    ----------
    scene : app.scene.Scene
        The camera (``view_name``'s C, size and lens) and the render settings (``scene.render``).
    view_name : str, optional
        The camera; default the first.
    spec : app.scene.RenderSpec, optional
        Light, noise and blur instead of ``scene.render`` (``aa_samples`` is the ray-cast renderer's).
    lens : app.undistort.LensDistortion or None, optional
        Render through this lens instead of the view's (None: no distortion).
    supersample : int
        The image is drawn this many times finer along each axis, then box-filtered.
    msaa : int
        Multisample anti-aliasing: coverage samples a fine pixel (0: none). The defaults, 2 and 4, give 16
        samples a pixel: each edge pixel's grey level within 9 % of the contrast of its exact area coverage
        (2.8 % on average; bench/live_render.py).
    tol_px : float
        Largest gap between a curved body's tessellated silhouette and the true one, pixels.

    Raises LiveRenderError when OpenGL cannot start here.
    """

    _VIEW_LENS = object()

    def __init__(
        self,
        scene: Scene,
        view_name: str | None = None,
        *,
        spec: RenderSpec | None = None,
        lens=_VIEW_LENS,
        supersample: int = SUPERSAMPLE,
        msaa: int = MSAA,
        tol_px: float = SILHOUETTE_TOL_PX,
    ):
        view = scene.view(view_name)
        self.view_name = view.name
        self.camera = view.camera
        self.spec = spec if spec is not None else scene.render
        self.lens = view.lens if lens is LiveRenderer._VIEW_LENS else lens
        if int(supersample) != supersample or not 1 <= supersample <= 8:
            raise ValueError(f"supersample must be an integer 1 … 8, got {supersample!r}")
        self.supersample = int(supersample)
        if msaa not in (0, 2, 4, 8, 16):
            raise ValueError(f"msaa must be 0 (none) or 2, 4, 8, 16 samples a pixel, got {msaa!r}")
        self.msaa = int(msaa)
        self.tol_px = float(tol_px)
        self.width, self.height = self.camera.width, self.camera.height
        self._maps = None
        u0, v0, u1, v1 = 0, 0, self.width - 1, self.height - 1
        if self.lens is not None:
            if (self.lens.width, self.lens.height) != (self.width, self.height):
                raise ValueError(
                    f"the lens was calibrated on {self.lens.width}×{self.lens.height} images, the camera renders "
                    f"{self.width}×{self.height}"
                )
            u0, v0, u1, v1, self._maps = self._lens_maps()
        self.origin = (u0, v0)  # the ideal pixel drawn at the framebuffer's first column and row
        self.ideal_size = (u1 - u0 + 1, v1 - v0 + 1)
        self._P = projection_matrix(self.camera.C, u0, v0, *self.ideal_size)
        # the focal lengths from C's rows (‖M₂‖ = 1: |fx| = ‖M₀ × M₂‖ without skew), not decompose(): scipy's
        # import would cost the interface's start-up ~0.1 s
        M = self.camera.C[:, :3]
        self._f_px = float(max(np.linalg.norm(np.cross(M[0], M[2])), np.linalg.norm(np.cross(M[1], M[2]))))
        self._meshes: dict[int, _Mesh] = {}
        self._extents: dict[int, tuple] = {}
        self._lock = threading.Lock()
        self._key: tuple | None = None  # the bodies of the cached image (``_key``)
        self._cached: dict[bool, np.ndarray] = {}  # blur → noise-free image of those bodies
        self.renders = 0  # images drawn by OpenGL (frames of unmoved bodies reuse the last)
        self._gl = _GLThread.get()
        self._fbo = self._resolved = None
        self._gl.call(self._create)

    # ------------------------------------------------------------------ set-up
    def _lens_maps(self):
        """The ideal pixels the lens images anywhere in the frame: their bounds (a pixel of margin, at most
        one frame's size beyond each side) and the remap maps (frame pixel → drawn image pixel)."""
        w, h = self.width, self.height
        u, v = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
        ideal = self.lens.undistort(np.column_stack([u.ravel(), v.ravel()]))
        ideal = np.where(np.isfinite(ideal), ideal, -1e6)
        inside = np.all(np.abs(ideal - [w / 2, h / 2]) < [1.5 * w, 1.5 * h], axis=1)
        lo = np.floor(ideal[inside].min(axis=0)).astype(int) - 2 if inside.any() else np.array([0, 0])
        hi = np.ceil(ideal[inside].max(axis=0)).astype(int) + 2 if inside.any() else np.array([w - 1, h - 1])
        lo = np.maximum(lo, [-w, -h])
        hi = np.minimum(hi, [2 * w - 1, 2 * h - 1])
        mx = (ideal[:, 0] - lo[0]).reshape(h, w).astype(np.float32)
        my = (ideal[:, 1] - lo[1]).reshape(h, w).astype(np.float32)
        return int(lo[0]), int(lo[1]), int(hi[0]), int(hi[1]), (mx, my)

    def _create(self, gl: _GLThread) -> None:
        ctx, s = gl.ctx, self.supersample
        size = (self.ideal_size[0] * s, self.ideal_size[1] * s)
        self._fbo = ctx.framebuffer(
            color_attachments=[ctx.renderbuffer(size, components=1, dtype="f4", samples=self.msaa)],
            depth_attachment=ctx.depth_renderbuffer(size, samples=self.msaa),
        )
        if self.msaa:  # the multisampled image is resolved (its samples averaged) into this one, then read
            self._resolved = ctx.framebuffer(color_attachments=[ctx.renderbuffer(size, components=1, dtype="f4")])

    def close(self) -> None:
        """Release the GL objects (the renderer cannot render after)."""
        if self._fbo is None or self._gl.closed:  # after shutdown_gl the context took its objects with it
            self._fbo = None
            return

        def release(gl: _GLThread) -> None:
            for m in self._meshes.values():
                m.vao.release()
                m.vbo.release()
            self._meshes.clear()
            for fbo in (self._fbo, self._resolved):
                if fbo is not None:
                    for att in (*fbo.color_attachments, fbo.depth_attachment):
                        if att is not None:
                            att.release()
                    fbo.release()

        self._gl.call(release)
        self._fbo = None

    def __enter__(self) -> LiveRenderer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # ------------------------------------------------------------------ meshes
    def _extent(self, brep: BRep) -> tuple[np.ndarray, float, float]:
        """The centre (3,) of a model's bounds (object frame), their half diagonal and its curved parts'
        largest radius (0 for none), metres; kept per model."""
        got = self._extents.get(id(brep))
        if got is None or got[0] is not brep:
            b = brep.bounds()
            radius = max((_solid_radius(p) for p in brep.solids), default=0.0)
            got = (brep, 0.5 * (b[0] + b[1]), 0.5 * float(np.linalg.norm(b[1] - b[0])), radius)
            if len(self._extents) > 256:
                self._extents.clear()
            self._extents[id(brep)] = got
        return got[1:]

    def _placed(self, body: RenderBody) -> tuple[int, float]:
        """(segments, distance): sides of a circle of this body so that its silhouettes stay within tol_px (0:
        no curved part), and the distance (m) from the optical centre to the centre of its bounds."""
        centre_obj, reach, radius = self._extent(body.brep)
        centre = body.T_world[:3, :3] @ centre_obj + body.T_world[:3, 3]
        distance = float(np.linalg.norm(centre - self.camera.center))
        if radius <= 0:
            return 0, distance
        return segments_for(self._f_px * radius / max(distance - reach, 0.05), self.tol_px), distance

    def _mesh(self, gl: _GLThread, body: RenderBody, segments: int) -> _Mesh:
        key = id(body.brep)
        m = self._meshes.get(key)
        if m is not None and m.brep is body.brep and m.segments >= segments:
            return m
        if m is not None:
            m.vao.release()
            m.vbo.release()
        soup = []
        for part in body.brep.parts:
            V, T = part.triangles(max(segments, 3))
            if len(T):
                soup.append(smooth_mesh(V, T, smooth=part is not body.brep.polyhedron))
        data = np.vstack(soup) if soup else np.zeros((0, 6), np.float32)
        vbo = gl.ctx.buffer(data.tobytes() if len(data) else np.zeros(6, np.float32).tobytes())
        vao = gl.ctx.vertex_array(gl.program, [(vbo, "3f 3f", "in_pos", "in_nrm")])
        m = _Mesh(body.brep, segments, vbo, vao, len(data))
        self._meshes[key] = m
        return m

    # ------------------------------------------------------------------ drawing
    def _draw(self, gl: _GLThread, bodies: Sequence[RenderBody], segments: list[int]) -> np.ndarray:
        prog, spec = gl.program, self.spec
        fbo = self._fbo
        fbo.use()
        fbo.clear(red=spec.gain * spec.sky, depth=1.0)
        gl.ctx.enable(gl.ctx.DEPTH_TEST)
        gl.ctx.disable(gl.ctx.CULL_FACE)
        light = np.asarray(spec.light, dtype=np.float32)
        _set(prog, "light", tuple(float(x) for x in light))
        _set(prog, "ambient", float(spec.ambient))
        _set(prog, "gain", float(spec.gain))
        used = set()
        for body, n in zip(bodies, segments):
            m = self._mesh(gl, body, n)
            used.add(id(body.brep))
            if m.count == 0:
                continue
            T = np.asarray(body.T_world, dtype=float)
            _set_matrix(prog, "mvp", self._P @ T)
            _set_matrix(prog, "rot", T[:3, :3])
            a = body.appearance
            _set(prog, "albedo", float(a.albedo))
            _set(prog, "tex_amp", float(a.texture))
            _set(prog, "freq", (_OCTAVES[0][0] / a.texture_scale_m, _OCTAVES[1][0] / a.texture_scale_m))
            _set(prog, "salt", _salt_words(body.texture_salt))
            m.vao.render(vertices=m.count)
        if len(self._meshes) > 2 * len(used) + 32:  # models no longer drawn: let them go
            for key in [k for k in self._meshes if k not in used]:
                old = self._meshes.pop(key)
                old.vao.release()
                old.vbo.release()
        gl.wait()  # the drawing, with the lock released: then the resolve and the read take little of it
        if self.msaa:
            gl.ctx.copy_framebuffer(self._resolved, fbo)
            gl.wait()
            fbo = self._resolved
        raw = np.frombuffer(fbo.read(components=1, dtype="f4"), dtype=np.float32)
        return raw.reshape(self.ideal_size[1] * self.supersample, self.ideal_size[0] * self.supersample)

    def render_float(self, bodies: Sequence[RenderBody]) -> np.ndarray:
        """The noise-free, unblurred image (H, W) float32 grey levels of ``bodies`` (through the lens, if any)."""
        bodies = _checked(bodies)
        if self._fbo is None:
            raise LiveRenderError("this live renderer was closed")
        import cv2

        placed = [self._placed(b) for b in bodies]
        # nearest first: the depth test then spares the shading of what lies behind (the floor behind the table)
        order = sorted(range(len(bodies)), key=lambda i: placed[i][1])
        img = self._gl.call(self._draw, [bodies[i] for i in order], [placed[i][0] for i in order])
        if self.supersample > 1:  # the box filter: each pixel the mean of its supersample² samples
            img = cv2.resize(img, self.ideal_size, interpolation=cv2.INTER_AREA)
        self.renders += 1
        if self._maps is not None:
            img = cv2.remap(img, self._maps[0], self._maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return img

    def _clean(self, bodies: Sequence[RenderBody], blur: bool) -> np.ndarray:
        """The noise-free image, blurred or not, kept while the bodies stay as they are."""
        key = _key(bodies)
        if not _same(self._key, key):
            self._cached = {False: self.render_float(bodies)}
            self._key = key
        if blur not in self._cached:
            import cv2

            img = self._cached[False]
            if self.spec.blur_sigma_px > 0:
                img = cv2.GaussianBlur(img, (0, 0), self.spec.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
            self._cached[blur] = img
        return self._cached[blur]

    def render(
        self, bodies: Sequence[RenderBody], frame_index: int = 0, *, noise: bool = True, blur: bool = True
    ) -> np.ndarray:
        """The frame (H, W) uint8 grey of ``bodies``: blur, then sensor noise seeded by (spec.seed, frame_index)."""
        if int(frame_index) != frame_index or frame_index < 0:
            raise ValueError(f"frame_index must be a non-negative integer (it seeds the noise), got {frame_index!r}")
        with self._lock:
            img = self._clean(bodies, blur)
        if noise and self.spec.noise_sigma > 0:
            rng = np.random.default_rng([int(self.spec.seed), int(frame_index)])
            img = img + rng.normal(0.0, self.spec.noise_sigma, img.shape)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _set(prog, name: str, value) -> None:
    if name in prog:  # the compiler drops uniforms a shader does not use
        prog[name].value = value


def _set_matrix(prog, name: str, M: np.ndarray) -> None:
    if name in prog:
        prog[name].write(np.ascontiguousarray(M.T, dtype=np.float32).tobytes())  # GL reads columns


def _salt_words(salt: int) -> tuple[int, int, int, int]:
    """(lo, hi) 32-bit words of each octave's salt product (salt + 10 and salt + 27, times the hash's
    multiplier, as value_noise salts them), modulo 2⁶⁴."""
    out = []
    for freq, _ in _OCTAVES:
        p = ((int(salt) + int(freq * 10)) * _SALT_MUL) % (1 << 64)
        out += [p & 0xFFFFFFFF, p >> 32 & 0xFFFFFFFF]
    return tuple(out)


def _checked(bodies: Sequence[RenderBody]) -> list[RenderBody]:
    out = list(bodies)
    for b in out:
        if not isinstance(b, RenderBody):
            raise ValueError(f"render a list of RenderBody, got a {type(b).__name__}")
        T = np.asarray(b.T_world)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ValueError(f"body {b.name!r}: T_world must be a finite 4×4 pose, got shape {T.shape}")
    return out


POSE_TOL = 1e-9  # poses closer than this (m, and rotation entries) draw the same picture


def _key(bodies: Sequence[RenderBody]) -> tuple[tuple, np.ndarray]:
    """What the picture of ``bodies`` depends on: models (by identity), appearances, texture salts, and the
    poses (N, 4, 4), compared within POSE_TOL (a still body's interpolated pose can differ in its last bit)."""
    same = tuple((id(b.brep), b.appearance, b.texture_salt) for b in bodies)
    poses = np.array([np.asarray(b.T_world, dtype=float) for b in bodies]).reshape(-1, 4, 4)
    return same, poses


def _same(a: tuple[tuple, np.ndarray] | None, b: tuple[tuple, np.ndarray]) -> bool:
    return a is not None and a[0] == b[0] and bool(np.all(np.abs(a[1] - b[1]) <= POSE_TOL))


class LiveSource(VideoSource):
    """Frames of a site rendered live through one of the scene's cameras, played like its recording.

    Frame k shows ``bodies_at(k / fps)`` (scene time) with frame k's sensor noise; the position loops with
    the view's recording (its frame count, as a file source loops), so scripted motions replay with the
    recording's period and the emulated devices' scene clock (serve's: the first camera's frame time)
    agrees. Paced by ``FrameGrabber`` on the shared clock as a recording is (``live`` is False); frames
    the grabber skips are not rendered.

    scene : the scene. view_name : the camera (default the first). bodies_at : scene time (s) → list of
    RenderBody (default ``scene_bodies(scene, t)``); an attribute, replaceable while the source runs (the
    robot's links and the objects it carries are added that way). fps : default the view's video's
    (12 without one). renderer : a LiveRenderer to use (default one for the view).
    """

    rendered_live = True  # the frames are drawn from the site's state, not read from a file

    def __init__(
        self,
        scene: Scene,
        view_name: str | None = None,
        bodies_at: Callable[[float], Sequence[RenderBody]] | None = None,
        fps: float | None = None,
        renderer: LiveRenderer | None = None,
    ):
        super().__init__()
        view = scene.view(view_name)
        video = view.video if view.video is not None else scene.video
        self.scene = scene
        self.view_name = view.name
        self.renderer = renderer if renderer is not None else LiveRenderer(scene, view.name)
        self.bodies_at = bodies_at if bodies_at is not None else (lambda t: scene_bodies(scene, t))
        self.fps = float(fps) if fps else (video.fps if video is not None else 12.0)
        if self.fps <= 0:
            raise ValueError(f"fps must be positive, got {fps}")
        self.frame_count = int(np.floor(video.duration_s * self.fps + 1e-9)) + 1 if video is not None else None
        self.width, self.height = view.camera.width, view.camera.height
        self.description = f"live render of {scene.name} ({view.name})"
        self._sampled_at: float | None = None  # when the last frame's site state was read (its stamp)

    def _advance(self) -> int:
        p = self._position + 1
        if self.frame_count and p >= self.frame_count:
            self._position = -1
            p = 0
        return p

    def _read(self) -> np.ndarray | None:
        p = self._advance()
        self._sampled_at = time.time()  # the site's state is read now: the frame's capture time (its stamp)
        grey = self.renderer.render(list(self.bodies_at(p / self.fps)), p)
        return np.repeat(grey[:, :, None], 3, axis=2)

    def _stamp(self) -> float | None:
        return self._sampled_at if self._sampled_at is not None else time.time()

    def skip(self, n: int) -> None:
        """Pass over ``n`` frames without rendering them (the grabber fell behind its clock)."""
        for _ in range(max(0, int(n))):
            self._advance()
            self._index += 1
            self._position += 1

    def close(self) -> None:
        self.renderer.close()


def shutdown_gl() -> None:
    """Release OpenGL before the process exits (``_GLThread.shutdown``); rendering starts it again if asked."""
    _GLThread.shutdown()
