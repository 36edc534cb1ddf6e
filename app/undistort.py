"""Lens distortion: frames undistorted once, on arrival, so that mcit's distortion-free C holds.

A camera file may give distortion coefficients with K (``app.camera_io.Intrinsics``). mcit keeps
its global model C = K [R | t] (DESIGN.md) and works in the *undistorted* image: every frame is
remapped once when it arrives (``UndistortedSource``, one ``cv2.remap`` with maps computed once),
and display, clicks, snapping, tracking and the overlay then all use that image, where C holds.

Decision: the undistorted image has the same size and the **same K** as the file's (no new camera
matrix). A scene's K and T_world_cam, a C calibrated in mcit and a ViSP pose keep their meaning;
with barrel distortion the undistorted image loses a little of the frame's corners, with
pincushion distortion it shows black borders there.

Models (``LensDistortion.model``), each given as a map from an ideal (undistorted) pixel to the
pixel where the lens puts it (``distort``), inverted exactly by Newton's method (``undistort``):

* ``"opencv"``: OpenCV's k1 k2 p1 p2 [k3 [k4 k5 k6 [s1 s2 s3 s4 [τx τy]]]] (4, 5, 8, 12 or 14
  coefficients; ROS's ``plumb_bob`` and ``rational_polynomial`` are the same model), through
  ``cv2.projectPoints``; maps by ``cv2.initUndistortRectifyMap``.
* ``"fisheye"``: OpenCV's equidistant model k1..k4 (ROS ``equidistant``, the calibration tutorial's
  ``fisheye_model``), through ``cv2.fisheye.distortPoints``; maps by ``cv2.fisheye.initUndistortRectifyMap``.
* ``"visp"``: ViSP's ``perspectiveProjWithDistortion``: u = u0 + px·x·(1 + kud·r²), r² = x² + y²
  (as ``vpMeterPixelConversion`` and ``vpImageTools::undistort`` use it). kdu, ViSP's approximate
  inverse, is not needed: the inverse here is exact.

The renderer (``app.render.Renderer`` with a distortion) casts each pixel's rays through
``undistort``, so a scene's video can be rendered as a real lens would see it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LensDistortion", "UndistortedSource", "lens_of"]

_MODELS = {
    "opencv": "opencv",
    "plumb_bob": "opencv",
    "rational_polynomial": "opencv",
    "radtan": "opencv",
    "equidistant": "fisheye",
    "fisheye": "fisheye",
    "visp": "visp",
}
_COUNTS = {"opencv": (4, 5, 8, 12, 14), "fisheye": (4,), "visp": (2,)}


@dataclass(frozen=True, eq=False)
class LensDistortion:
    """A lens's distortion for images of ``width`` × ``height`` with camera matrix ``K`` (pixels).

    coefficients : the file's numbers (see the module docstring for each model's order);
    model : "opencv", "fisheye" or "visp" (ROS's names are accepted and translated).
    """

    K: np.ndarray
    coefficients: np.ndarray
    model: str
    width: int
    height: int
    _maps: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        model = _MODELS.get(str(self.model).strip().lower())
        if model is None:
            raise ValueError(
                f"unknown lens distortion model {self.model!r}; mcit knows OpenCV's (plumb_bob, "
                "rational_polynomial), the equidistant fisheye model and ViSP's kud"
            )
        d = np.asarray(self.coefficients, dtype=float).ravel()
        if d.size not in _COUNTS[model]:
            raise ValueError(
                f"the {model} distortion model takes {' or '.join(map(str, _COUNTS[model]))} coefficients, got {d.size}"
            )
        if not np.all(np.isfinite(d)):
            raise ValueError("a distortion coefficient is not finite")
        K = np.asarray(self.K, dtype=float)
        if K.shape != (3, 3):
            raise ValueError(f"K must be 3×3, got {K.shape}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ValueError(f"the image size must be positive, got {self.width}×{self.height}")
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "coefficients", d)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))

    # ------------------------------------------------------------------ points
    def distort(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (N, 2) of the undistorted image → where the lens images them (N, 2), pixels."""
        import cv2

        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        if self.model == "visp":
            s = 1.0 + self.coefficients[0] * (x * x + y * y)
            return np.column_stack([K[0, 2] + K[0, 0] * x * s, K[1, 2] + K[1, 1] * y * s])
        if self.model == "fisheye":
            out = cv2.fisheye.distortPoints(
                np.column_stack([x, y])[:, None, :].astype(np.float64), K, self.coefficients
            )
            return out.reshape(-1, 2)
        X = np.column_stack([x, y, np.ones_like(x)])
        out, _ = cv2.projectPoints(X[:, None, :], np.zeros(3), np.zeros(3), K, self.coefficients)
        return out.reshape(-1, 2)

    def jacobian(self, uv: np.ndarray, h: float = 1e-3) -> np.ndarray:
        """d distort / d uv (N, 2, 2) at undistorted pixels uv (N, 2) (central differences)."""
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        n = len(uv)
        d = self.distort(np.concatenate([uv + [h, 0.0], uv - [h, 0.0], uv + [0.0, h], uv - [0.0, h]]))
        du = (d[:n] - d[n : 2 * n]) / (2 * h)
        dv = (d[2 * n : 3 * n] - d[3 * n :]) / (2 * h)
        return np.stack([du, dv], axis=2)

    def undistort(self, uv: np.ndarray, tol_px: float = 1e-7, max_iter: int = 30) -> np.ndarray:
        """Pixels (N, 2) of the camera's (distorted) image → the undistorted image's (N, 2): the exact
        inverse of ``distort`` (Newton's method, to ``tol_px``); NaN where it does not converge
        (beyond the radius where the model folds back)."""
        target = np.asarray(uv, dtype=float).reshape(-1, 2)
        p = target.copy()
        h = 1e-3
        todo = np.arange(len(p))
        for _ in range(max_iter):
            q = p[todo]
            f = self.distort(q) - target[todo]
            err = np.abs(f).max(axis=1)
            done = err < tol_px
            todo, q, f = todo[~done], q[~done], f[~done]
            if not len(todo):
                break
            fu = (self.distort(q + [h, 0.0]) - target[todo] - f) / h
            fv = (self.distort(q + [0.0, h]) - target[todo] - f) / h
            det = fu[:, 0] * fv[:, 1] - fv[:, 0] * fu[:, 1]
            det = np.where(np.abs(det) > 1e-12, det, np.nan)
            du = (fv[:, 1] * f[:, 0] - fv[:, 0] * f[:, 1]) / det
            dv = (-fu[:, 1] * f[:, 0] + fu[:, 0] * f[:, 1]) / det
            p[todo] = q - np.column_stack([du, dv])
        else:
            if len(todo):
                f = self.distort(p[todo]) - target[todo]
                bad = todo[~(np.abs(f).max(axis=1) < tol_px * 100)]
                p[bad] = np.nan
        p[~np.all(np.isfinite(p), axis=1)] = np.nan
        return p

    # ------------------------------------------------------------------ images
    def maps(self) -> tuple[np.ndarray, np.ndarray]:
        """cv2.remap maps (fixed point, ``CV_16SC2``) from the camera's image to the undistorted one,
        computed once: for each undistorted pixel, where the lens put it."""
        if not self._maps:
            import cv2

            size = (self.width, self.height)
            if self.model == "opencv":
                m1, m2 = cv2.initUndistortRectifyMap(self.K, self.coefficients, None, self.K, size, cv2.CV_16SC2)
            elif self.model == "fisheye":
                m1, m2 = cv2.fisheye.initUndistortRectifyMap(
                    self.K, self.coefficients, np.eye(3), self.K, size, cv2.CV_16SC2
                )
            else:
                u, v = np.meshgrid(np.arange(self.width, dtype=float), np.arange(self.height, dtype=float))
                d = self.distort(np.column_stack([u.ravel(), v.ravel()])).astype(np.float32)
                m1, m2 = cv2.convertMaps(d[:, 0].reshape(u.shape), d[:, 1].reshape(u.shape), cv2.CV_16SC2)
            self._maps.extend([m1, m2])
        return self._maps[0], self._maps[1]

    def undistort_image(self, image: np.ndarray) -> np.ndarray:
        """The camera's image (H, W[, 3]) remapped to the undistorted image (bilinear; black outside)."""
        import cv2

        if image.shape[:2] != (self.height, self.width):
            raise ValueError(
                f"the frame is {image.shape[1]}×{image.shape[0]} but the camera was calibrated on "
                f"{self.width}×{self.height} images; give the intrinsics for this size"
            )
        m1, m2 = self.maps()
        return cv2.remap(image, m1, m2, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT)

    def describe(self) -> str:
        """One line for the operator: which model, how strong at the image corner."""
        corner = np.array([[0.0, 0.0], [self.width - 1.0, self.height - 1.0]])
        shift = float(np.max(np.linalg.norm(self.distort(corner) - corner, axis=1)))
        return f"{self.model} lens distortion ({self.coefficients.size} coefficients, {shift:.1f} px at the corners)"


def lens_of(intrinsics, width: int | None = None, height: int | None = None) -> LensDistortion | None:
    """The LensDistortion of an ``app.camera_io.Intrinsics`` (None when it has no distortion).

    width, height : the images' size when the file does not state it."""
    if not intrinsics.has_distortion:
        return None
    w = intrinsics.width if intrinsics.width is not None else width
    h = intrinsics.height if intrinsics.height is not None else height
    if w is None or h is None:
        raise ValueError(
            f"{intrinsics.source}: states lens distortion but not the image size; add image_width and image_height"
        )
    model = intrinsics.distortion_model or "opencv"
    try:
        return LensDistortion(intrinsics.K, intrinsics.distortion, model, w, h)
    except ValueError as exc:
        raise ValueError(f"{intrinsics.source}: {exc}") from None


class UndistortedSource:
    """A video source whose frames are undistorted as they are read (see the module docstring).

    Wraps an ``app.video.VideoSource``: same size, rate, description and timing; each ``read()``
    remaps the frame once with the precomputed maps. A source whose frame size is not the
    calibration's is refused (``app.video.VideoError``).
    """

    def __init__(self, source, lens: LensDistortion):
        from app.video import VideoError

        if (source.width, source.height) != (lens.width, lens.height):
            source.close()
            raise VideoError(
                f"{source.description} gives {source.width}×{source.height} frames but the camera was "
                f"calibrated on {lens.width}×{lens.height} images; give the intrinsics for this size"
            )
        self.source = source
        self.lens = lens
        self.description = f"{source.description}, undistorted ({lens.model} lens)"
        lens.maps()  # computed once, before the first frame

    def __getattr__(self, name):  # width, height, fps, live, frame_count, duration_s, close
        return getattr(self.source, name)

    def read(self):
        from app.video import Frame

        frame = self.source.read()
        return Frame(self.lens.undistort_image(frame.image), frame.index, frame.t_s, frame.stamp)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.source.close()
