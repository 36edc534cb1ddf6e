"""Read camera intrinsics from the files other tools write: ViSP ``.xml``, OpenCV and ROS ``.yml``/``.yaml``.

mcit works with the global model C (DESIGN.md); a camera given as intrinsics K plus a pose becomes
``C = K [R_cam_world | t_cam_world]`` (``core.camera.Camera.from_intrinsics``). This module only
turns files into K (3, 3) (pixels; fx, skew, u0 / 0, fy, v0 / 0, 0, 1), with the image size and
distortion the file states.

* ViSP writes two XML layouts, both read here: ``vpXmlParserCamera``
  (``<root><camera><name/><image_width/><image_height/><model><type>perspectiveProjWithoutDistortion
  </type><px/><py/><u0/><v0/></model></camera></root>``) and the model-based tracker's settings
  (``<conf><camera><u0/><v0/><px/><py/></camera>…</conf>``, e.g. ``visp-cube/cube.xml``).
  ViSP's pixel origin is the centre of the top-left pixel, like mcit's, so u0, v0 carry over as they are.
  A file may hold several cameras (several names, or one name at several image sizes, as ViSP's
  own files do): ``camera_name`` and ``image_size`` choose one, as ``vpXmlParserCamera::parse`` does.
* OpenCV ``FileStorage`` files (``.yml``/``.yaml``/``.json``/``.xml``) from ``calibrateCamera`` tools,
  keys matched without regard to case (the calibration tutorial writes ``Camera_Matrix``,
  ``Distortion_Coefficients``, ``image_Width``, ``image_Height``): the matrix under
  ``camera_matrix`` (or ``cameraMatrix``, ``K``, ``intrinsics``, ``M``), the size under
  ``image_width``/``image_height`` (or ``width``/``height``, ``image_size``), the distortion under
  ``distortion_coefficients`` (or ``dist_coeffs``, ``D``; the tutorial's ``fisheye_model: 1`` makes it
  the equidistant model).
* ROS ``camera_info`` YAML: the calibrator's ``ost.yaml`` (``camera_name``, ``camera_matrix`` and
  ``distortion_coefficients`` as ``rows``/``cols``/``data`` maps, ``distortion_model``) and a
  ``CameraInfo`` message as ``ros2 topic echo`` / ``rostopic echo`` print it (``header``, ``width``,
  ``height``, ``distortion_model``, ``K``/``k`` and ``D``/``d`` as flat or block lists, the message
  closed by ``---``; of several messages, the first). ``R``/``r`` and ``P``/``p`` (rectification) are
  not used: mcit undistorts with K and the distortion.

YAML is read with PyYAML, except OpenCV's own dialect (a file that opens with ``%YAML:1.0``, as
``cv::FileStorage`` writes it), which OpenCV reads; both give the same tree to one interpretation
(``_intrinsics_from_tree``). ``!!opencv-matrix`` maps read as plain ``rows``/``cols``/``data`` maps.
* A YAML file holding several cameras as top-level maps (``cam0: {…}``, ``left: {…}``): ``camera_name``
  picks the map by its key or its ``camera_name``.

Every failure is one ValueError line naming the file and what was missing or wrong. A K that no lens
has (a focal length beyond 178° to 0.006° of field for the image, a principal point far outside it)
and a distortion that cannot be undone over the image (``_check_lens``) are refused too.
C has no lens distortion: a file whose distortion is not zero (``Intrinsics.has_distortion``)
gives the camera a lens (``app.undistort.lens_of``), and the frames are undistorted on arrival so
that C, with the file's K, holds in the undistorted image.
"""

from __future__ import annotations

import functools
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["Intrinsics", "read_visp_xml", "read_opencv_yml", "read_intrinsics", "read_projection_matrix", "P_SUFFIXES"]

P_SUFFIXES = (".p",)  # a 3×4 projection matrix as text (Oxford VGG's multi-view data, Bundler's and others' exports)

_VISP_NO_DISTORTION = "perspectiveProjWithoutDistortion"
_VISP_DISTORTION = "perspectiveProjWithDistortion"
# Keys are matched without regard to case.
_OPENCV_K_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsics", "M")
_OPENCV_DIST_KEYS = ("distortion_coefficients", "distortion_coefficents", "dist_coeffs", "distCoeffs", "D")
_WIDTH_KEYS = ("image_width", "width")
_HEIGHT_KEYS = ("image_height", "height")
_OPENCV_DIST_COUNTS = (4, 5, 8, 12, 14)  # OpenCV's distortion models (k1 k2 p1 p2 [k3 [k4 k5 k6 [s1..s4 [τx τy]]]])
_DIST_NAMES = {
    "opencv": ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tauX", "tauY"),
    "fisheye": ("k1", "k2", "k3", "k4"),
    "visp": ("kud", "kdu"),
}
# A focal length, in image sides (the larger of width and height): from a 178° field of view to 0.006°.
_MIN_FOCAL_SIDES, _MAX_FOCAL_SIDES = 0.01, 1e4
_MAX_FOCAL_PX = 1e8  # when the file states no image size: 10⁴ sides of a 10⁴-pixel image
_MIN_SHOWN = 0.25  # the least part of the undistorted image that a lens may leave showing the camera's image


@dataclass(frozen=True)
class Intrinsics:
    """What an intrinsics file says.

    K : array, shape (3, 3), pixels. width, height : image size in pixels, or None when the
    file does not state it. distortion : array, shape (k,), the file's distortion coefficients
    (ViSP: (kud, kdu); OpenCV/ROS: (k1, k2, p1, p2[, k3, ...]) or, equidistant, (k1, k2, k3, k4)),
    empty when none. source : the file. distortion_model : "" (none stated), "visp" (kud, kdu),
    "opencv" (OpenCV's 4 to 14 coefficients), or the model the file names ("plumb_bob",
    "rational_polynomial", "equidistant"). name : the camera's name in the file, or None.
    """

    K: np.ndarray
    width: int | None = None
    height: int | None = None
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    source: str = ""
    distortion_model: str = ""
    name: str | None = None

    @property
    def has_distortion(self) -> bool:
        """True when any distortion coefficient is non-zero."""
        return bool(np.any(np.abs(self.distortion) > 0.0))


def _K(px: float, py: float, u0: float, v0: float, skew: float = 0.0) -> np.ndarray:
    return np.array([[px, skew, u0], [0.0, py, v0], [0.0, 0.0, 1.0]])


def _check_K(K: np.ndarray, where: str) -> np.ndarray:
    K = np.asarray(K, dtype=float)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ValueError(f"{where}: the camera matrix must be a finite 3×3 matrix, got shape {K.shape}")
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise ValueError(f"{where}: focal lengths must be positive pixels, got fx={K[0, 0]}, fy={K[1, 1]}")
    if abs(K[2, 2]) <= 0 or abs(K[1, 0]) + abs(K[2, 0]) + abs(K[2, 1]) > 1e-9 * abs(K).max():
        raise ValueError(f"{where}: the camera matrix must be upper triangular with K[2, 2] ≠ 0, got {K.tolist()}")
    return K / K[2, 2]


def _check_size(width: int | None, height: int | None, where: str) -> tuple[int | None, int | None]:
    for what, v in (("width", width), ("height", height)):
        if v is not None and v <= 0:
            raise ValueError(f"{where}: the image {what} must be a positive number of pixels, got {v}")
    return width, height


def _check_plausible_K(K: np.ndarray, width: int | None, height: int | None, where: str) -> None:
    """ValueError when K (finite, fx, fy > 0) is no lens's for the image size (or any size when None):
    a focal length or a principal point absurdly far from the image's scale."""
    fx, fy, skew, u0, v0 = K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]
    if width is not None and height is not None:
        side = max(width, height)
        lo, hi, images = _MIN_FOCAL_SIDES * side, _MAX_FOCAL_SIDES * side, f"{width}×{height} images"
    else:
        lo, hi, images = 1.0, _MAX_FOCAL_PX, "images of any size"
    for what, f in (("fx", fx), ("fy", fy)):
        if not lo <= f <= hi:
            raise ValueError(
                f"{where}: {what}={f:g} px is not a focal length a lens gives for {images} (between "
                f"{lo:g} and {hi:g} px: a field of view from 178° down to 0.006°); check the file's "
                "camera matrix"
            )
    if abs(skew) > max(fx, fy):
        raise ValueError(
            f"{where}: the skew K[0, 1]={skew:g} is larger than the focal lengths (fx={fx:g}, fy={fy:g}): "
            "no camera's pixel axes are that slanted; check the file's camera matrix"
        )
    if width is not None and height is not None:
        far = not (-width <= u0 <= 2 * width and -height <= v0 <= 2 * height)
    else:
        far = max(abs(u0), abs(v0)) > _MAX_FOCAL_PX
    if far:
        raise ValueError(
            f"{where}: the principal point (u0, v0) = ({u0:g}, {v0:g}) px lies far outside "
            f"{images}; check the file's camera matrix"
        )


def _coefficients_text(model: str, d: np.ndarray) -> str:
    names = _DIST_NAMES.get(model, ())
    named = [f"{names[k] if k < len(names) else f'd{k}'}={v:g}" for k, v in enumerate(d) if v != 0.0]
    return ", ".join(named) or "all zero"


def _check_lens(intr: Intrinsics, width: int, height: int) -> None:
    """ValueError when the file's lens distortion cannot be undone over a ``width`` × ``height`` image.

    First, the undistorted image must show the camera's image over at least ``_MIN_SHOWN`` of its
    area (a huge k1 stretches a few central pixels over the whole frame). Then, along rays from the
    principal point (every 5°, and through the four corners), the distance from the principal point
    of the pixel where the lens puts an ideal pixel must grow with the ideal pixel's distance, out
    to the undistorted image's edge and to where the lens's image leaves the frame: a model that
    turns back within the image (a fit's polynomial beyond its data) maps two rays to one pixel,
    leaves the frame's border with no ray, and undistorting the frame mirrors part of it.
    """
    from app.undistort import LensDistortion

    where = intr.source
    try:
        lens = LensDistortion(intr.K, intr.distortion, intr.distortion_model or "opencv", width, height)
    except ValueError as exc:
        raise ValueError(f"{where}: {exc}") from None
    coefficients = _coefficients_text(lens.model, lens.coefficients)
    K, K_inv = lens.K, np.linalg.inv(lens.K)
    pp = K[:2, 2]

    def inside(uv):
        return (uv[..., 0] >= -0.5) & (uv[..., 0] <= width - 0.5) & (uv[..., 1] >= -0.5) & (uv[..., 1] <= height - 0.5)

    with np.errstate(all="ignore"):  # coefficients that overflow far out give inf, judged as such
        u, v = np.meshgrid(np.linspace(0.0, width - 1.0, 65), np.linspace(0.0, height - 1.0, 49))
        shown = float(np.mean(inside(lens.distort(np.column_stack([u.ravel(), v.ravel()])))))
        if shown < _MIN_SHOWN:
            raise ValueError(
                f"the lens distortion in {where} ({coefficients}) stretches the image so far that "
                f"undistorted frames would show it in only {100 * shown:.2g} % of their area: check the "
                "file's distortion coefficients"
            )
        corners = np.array([[0.0, 0.0], [width - 1.0, 0.0], [0.0, height - 1.0], [width - 1.0, height - 1.0]]) - pp
        angles = np.r_[np.radians(np.arange(0.0, 360.0, 5.0)), np.arctan2(corners[:, 1], corners[:, 0])]
        dirs_px = np.column_stack([np.cos(angles), np.sin(angles)])  # image directions from the principal point
        dirs = dirs_px @ K_inv[:2, :2].T
        dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)  # the same directions, normalised coordinates
        radii = np.tan(np.radians(np.linspace(0.0, 89.5, 2000)))  # rays out to 89.5° off the optical axis
        xy = radii[None, :, None] * dirs[:, None, :]  # (directions, radii, 2)
        ideal = xy @ K[:2, :2].T + pp
        seen = lens.distort(ideal.reshape(-1, 2)).reshape(ideal.shape)
        rho = np.linalg.norm((seen - pp) @ K_inv[:2, :2].T, axis=2)
        ideal_in, seen_in = inside(ideal), inside(seen)
        for k in range(len(angles)):
            # out to the undistorted image's edge, and to where the lens's image leaves the frame (its field
            # of view's edge: what the model does with rays beyond it is never seen)
            last = int(np.flatnonzero(ideal_in[k]).max(initial=0))
            entered = np.flatnonzero(seen_in[k])
            if entered.size:
                left = np.flatnonzero(~seen_in[k, entered[0] :])
                last = max(last, (entered[0] + int(left[0])) if left.size else len(radii) - 1)
            if not np.all(np.diff(rho[k, : last + 1]) > 0.0):
                raise ValueError(
                    f"the lens distortion in {where} ({coefficients}) folds the image over itself within "
                    "the image: check the file's distortion coefficients"
                )


def _checked(intr: Intrinsics, image_size: tuple[int, int] | None) -> Intrinsics:
    """``intr`` once its K is a lens's and its distortion can be undone over the image (its size, or ``image_size``)."""
    width, height = (intr.width, intr.height) if intr.width is not None else (image_size or (None, None))
    _check_plausible_K(intr.K, width, height, intr.source)
    if intr.has_distortion and width is not None and height is not None:
        _check_lens(intr, int(width), int(height))
    return intr


def _float(node: ET.Element | None, tag: str, where: str) -> float:
    child = None if node is None else node.find(tag)
    if child is None or child.text is None:
        raise ValueError(f"{where}: missing <{tag}>: give it (ViSP's camera file: <px>, <py>, <u0>, <v0>)")
    try:
        value = float(child.text.strip())
    except ValueError:
        raise ValueError(f"{where}: <{tag}> is not a number: {child.text.strip()!r}") from None
    if not np.isfinite(value):
        raise ValueError(f"{where}: <{tag}> is not finite")
    return value


def _int_or_none(node: ET.Element, tag: str, where: str) -> int | None:
    child = node.find(tag)
    if child is None or child.text is None or not child.text.strip():
        return None
    try:
        return int(child.text.strip())
    except ValueError:
        raise ValueError(f"{where}: <{tag}> is not an integer: {child.text.strip()!r}") from None


def _size_text(w: int | None, h: int | None) -> str:
    return f"{w}×{h}" if w is not None and h is not None else "no size"


def _pick_visp(
    cameras: list[ET.Element], where: str, camera_name: str | None, image_size: tuple[int, int] | None
) -> ET.Element:
    """The one <camera> that ``camera_name`` and ``image_size`` choose (as vpXmlParserCamera::parse)."""

    def name(c):
        return (c.findtext("name") or "").strip()

    def size(c):
        return _int_or_none(c, "image_width", where), _int_or_none(c, "image_height", where)

    listed = "; ".join(f"{name(c) or '(no name)'} {_size_text(*size(c))}" for c in cameras)
    if camera_name is not None:
        named = [c for c in cameras if name(c) == camera_name]
        if not named:
            raise ValueError(f"{where}: no camera named {camera_name!r}; it has: {listed}")
        cameras = named
    among = "in the file"
    if len(cameras) > 1 and image_size is not None:
        sized = [c for c in cameras if size(c) == tuple(image_size)]
        if sized:
            cameras, among = sized, f"for {image_size[0]}×{image_size[1]} images"
        elif all(None not in size(c) for c in cameras):
            raise ValueError(
                f"{where}: no camera{' named ' + repr(camera_name) if camera_name else ''} for "
                f"{image_size[0]}×{image_size[1]} images; it has: {listed}"
            )
    if len(cameras) > 1:
        listed = "; ".join(f"{name(c) or '(no name)'} {_size_text(*size(c))}" for c in cameras)
        raise ValueError(
            f"{where}: {len(cameras)} cameras {among} ({listed}); choose one with --camera-name "
            "(camera_name= in Python)"
        )
    return cameras[0]


# what to do with an .xml camera file that does not parse
_XML_ADVICE = (
    "give the camera file ViSP or OpenCV wrote (vpXmlParserCamera's <root><camera>…, or cv::FileStorage's "
    "<opencv_storage>), or fix the XML at the place named"
)


# what to do with a .yaml/.yml/.json camera file that does not read as one
_YAML_ADVICE = (
    "give the calibration file OpenCV (cv::FileStorage: camera_matrix, image_width, image_height) or ROS "
    "(camera_info: camera_matrix or K, width, height) wrote"
)


def _read_visp(path: Path, camera_name: str | None, image_size: tuple[int, int] | None = None) -> Intrinsics:
    where = str(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{where}: not well-formed XML ({exc}); {_XML_ADVICE}") from None
    cameras = [root] if root.tag == "camera" else root.findall("camera")
    if not cameras:
        raise ValueError(
            f"{where}: no <camera> element; expected a ViSP camera file "
            "(<root><camera>…) or tracker settings (<conf><camera>…)"
        )
    cam = _pick_visp(cameras, where, camera_name, image_size)
    name = (cam.findtext("name") or "").strip() or None
    cw = f"{where}: <camera>" if name is None else f"{where}: <camera> {name!r}"
    width, height = _check_size(_int_or_none(cam, "image_width", cw), _int_or_none(cam, "image_height", cw), cw)
    models = cam.findall("model")
    if not models:  # model-based tracker settings: the parameters sit directly in <camera>
        K = _K(_float(cam, "px", cw), _float(cam, "py", cw), _float(cam, "u0", cw), _float(cam, "v0", cw))
        return Intrinsics(_check_K(K, cw), width, height, np.zeros(0), where, "", name)
    by_type = {(m.findtext("type") or "").strip(): m for m in models}
    if _VISP_NO_DISTORTION in by_type:
        m = by_type[_VISP_NO_DISTORTION]
        mw = f"{cw} <model> {_VISP_NO_DISTORTION}"
        K = _K(_float(m, "px", mw), _float(m, "py", mw), _float(m, "u0", mw), _float(m, "v0", mw))
        return Intrinsics(_check_K(K, mw), width, height, np.zeros(0), where, "", name)
    if _VISP_DISTORTION in by_type:
        m = by_type[_VISP_DISTORTION]
        mw = f"{cw} <model> {_VISP_DISTORTION}"
        K = _K(_float(m, "px", mw), _float(m, "py", mw), _float(m, "u0", mw), _float(m, "v0", mw))
        dist = np.array([_float(m, "kud", mw), _float(m, "kdu", mw)])
        return Intrinsics(_check_K(K, mw), width, height, dist, where, "visp", name)
    raise ValueError(f"{cw}: no <model> of type {_VISP_NO_DISTORTION} or {_VISP_DISTORTION}; found {sorted(by_type)}")


def read_visp_xml(path: str | Path, camera_name: str | None = None) -> np.ndarray:
    """K (3, 3), pixels, from a ViSP camera ``.xml`` (either layout; see the module docstring).

    With several cameras in the file, ``camera_name`` picks one (``<name>``). The model without
    distortion is preferred; a file with only the distortion model gives that model's K
    (``read_intrinsics`` also returns its kud, kdu). ValueError naming the file and element on bad input.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    return _checked(_read_visp(path, camera_name), None).K


# ---------------------------------------------------------------------------- OpenCV / ROS files
def _node_value(node) -> Any:
    """A cv2.FileNode as plain Python: dict, list, float/int, str; an ``!!opencv-matrix`` (or any map
    with rows, cols and data, as ROS writes them untagged) stays a dict for ``_matrix``."""
    if node.isMap():
        return {k: _node_value(node.getNode(k)) for k in node.keys()}
    if node.isSeq():
        return [_node_value(node.at(i)) for i in range(node.size())]
    if node.isInt():
        return int(node.real())
    if node.isReal():
        return float(node.real())
    if node.isString():
        return node.string()
    return None


def _cv_reason(exc: BaseException) -> str:
    """OpenCV's parse error in a few words: "line 2: Incorrect indentation"."""
    import re

    cause = exc.__cause__ if isinstance(exc, SystemError) and exc.__cause__ is not None else exc
    lines = str(cause).strip().splitlines()
    text = lines[-1] if lines else type(cause).__name__
    m = re.search(r"\((\d+)\): (.*?)'?\s*$", text)
    return f"line {m.group(1)}: {m.group(2)}" if m else text.split("error: ", 1)[-1]


def _opencv_tree(path: Path) -> dict:
    """The whole FileStorage file as a dict (OpenCV parses its YAML dialect, XML and JSON)."""
    import cv2

    where = str(path)
    if not path.read_bytes().strip():
        raise ValueError(f"{where}: the file is empty; expected a camera matrix and the image size")
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except (cv2.error, SystemError) as exc:
        raise ValueError(f"{where}: OpenCV cannot parse it ({_cv_reason(exc)})") from None
    if not fs.isOpened():
        raise ValueError(f"{where}: OpenCV cannot open it as a FileStorage (.yml, .yaml, .xml, .json)")
    try:
        root = fs.root()
        tree = _node_value(root) if root.isMap() else None
    except (cv2.error, SystemError) as exc:
        raise ValueError(f"{where}: OpenCV cannot read its contents ({str(exc).strip().splitlines()[-1]})") from None
    finally:
        fs.release()
    if not isinstance(tree, dict) or not tree:
        raise ValueError(f"{where}: holds no named values; expected a camera matrix and the image size")
    return tree


def _is_opencv_yaml(path: Path) -> bool:
    """Whether a YAML file is in OpenCV's dialect: it opens with OpenCV's ``%YAML:1.0`` directive
    (standard YAML writes ``%YAML 1.1``), which PyYAML refuses."""
    head = path.read_bytes()[:64].lstrip(b"\xef\xbb\xbf \t\r\n")
    return head.startswith(b"%YAML:")


@functools.cache
def _yaml_loader():
    import yaml

    class Loader(yaml.SafeLoader):
        """PyYAML's safe loader, with OpenCV's ``!!opencv-matrix`` tag read as the map it tags."""

    Loader.add_constructor(
        "tag:yaml.org,2002:opencv-matrix", lambda loader, node: loader.construct_mapping(node, deep=True)
    )
    return Loader


def _yaml_tree(path: Path) -> dict:
    """A YAML camera file as a dict, read with PyYAML (ROS's ost.yaml, a CameraInfo as ``ros2 topic
    echo`` prints it: the first of its ``---``-separated messages)."""
    import yaml

    where = str(path)
    raw = path.read_bytes()
    if not raw.strip():
        raise ValueError(f"{where}: the file is empty; expected a camera matrix and the image size")
    try:
        text = raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{where}: not a text file (not UTF-8); expected YAML with a camera matrix") from None
    try:
        docs = [d for d in yaml.load_all(text, Loader=_yaml_loader()) if d is not None]
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        at = f"line {mark.line + 1}: " if mark is not None else ""
        what = getattr(exc, "problem", None) or str(exc)
        raise ValueError(
            f"{where}: not valid YAML ({at}{' '.join(str(what).split())}); {_YAML_ADVICE}, or fix the YAML there"
        ) from None
    if not docs or not isinstance(docs[0], dict) or not docs[0]:
        raise ValueError(f"{where}: holds no named values; expected a camera matrix and the image size")
    return docs[0]


def _get(d: dict, keys, want_map: bool = False) -> tuple[str | None, Any]:
    """(key as written, value) of the first of ``keys`` in ``d`` (case-insensitive), or (None, None)."""
    lower = {}
    for k in d:
        lower.setdefault(str(k).lower(), k)
    for k in keys:
        real = lower.get(k.lower())
        if real is not None and d[real] is not None:
            return real, d[real]
    return None, None


def _matrix(value: Any, where: str, shape: tuple[int, ...] | None = None) -> np.ndarray:
    """A matrix from an ``!!opencv-matrix`` / ROS ``{rows, cols, data}`` map, a flat or nested list."""
    if isinstance(value, dict):
        _, rows = _get(value, ("rows",))
        _, cols = _get(value, ("cols",))
        _, data = _get(value, ("data",))
        if data is None:
            raise ValueError(f"{where}: a matrix needs 'data' (with 'rows' and 'cols'); found {sorted(value)}")
        try:
            a = np.asarray(data, dtype=float).ravel()
            if rows is not None and cols is not None:
                a = a.reshape(int(rows), int(cols))
        except (TypeError, ValueError):
            raise ValueError(
                f"{where}: its data is not {rows}×{cols} numbers: give rows × cols numbers in 'data'"
            ) from None
    else:
        if isinstance(value, str) and value.startswith("<array type"):
            raise ValueError(
                f"{where}: the message was echoed without its arrays ({value}); echo it again without --no-arr"
            )
        try:
            a = np.asarray(value, dtype=float)
        except (TypeError, ValueError):
            raise ValueError(f"{where}: not a list of numbers: {value!r}") from None
    if shape is not None and a.shape != shape:
        if a.size != int(np.prod(shape)):
            raise ValueError(
                f"{where}: {int(np.prod(shape))} numbers expected ({'×'.join(map(str, shape))}), got {a.size}"
            )
        a = a.reshape(shape)
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{where}: holds a number that is not finite")
    return a


def _size_value(d: dict, keys, where: str) -> int | None:
    k, v = _get(d, keys)
    if k is None or isinstance(v, (dict, list)):
        return None
    try:
        n = float(v)
    except (TypeError, ValueError):
        raise ValueError(f"{where}: '{k}' is not a number of pixels: {v!r}") from None
    if not n.is_integer():
        raise ValueError(f"{where}: '{k}' is not a whole number of pixels: {v!r}")
    return int(n)


def _has_K(d: Any) -> bool:
    return isinstance(d, dict) and _get(d, _OPENCV_K_KEYS)[0] is not None


def _pick_map(tree: dict, where: str, camera_name: str | None) -> tuple[dict, str | None, str]:
    """(the camera's map, its name, where) in a file of one camera or of several (``cam0: {…}``)."""
    if _has_K(tree):
        _, name = _get(tree, ("camera_name",))
        name = None if name is None else str(name)
        if camera_name is not None and name is not None and name != camera_name:
            raise ValueError(f"{where}: the camera in it is named {name!r}, not {camera_name!r}")
        return tree, name, where
    cams = {str(k): v for k, v in tree.items() if _has_K(v)}
    if not cams:
        keys = ", ".join(_OPENCV_K_KEYS)
        raise ValueError(
            f"{where}: no camera matrix (looked for {keys}, in any case; found {', '.join(map(str, tree))}); "
            f"{_YAML_ADVICE}"
        )

    def name_of(key, m):
        n = _get(m, ("camera_name",))[1]
        return key if n is None else str(n)

    if camera_name is not None:
        hits = [k for k, m in cams.items() if camera_name in (k, name_of(k, m))]
        if not hits:
            raise ValueError(f"{where}: no camera named {camera_name!r}; it has: {', '.join(cams)}")
        key = hits[0]
    elif len(cams) == 1:
        key = next(iter(cams))
    else:
        raise ValueError(
            f"{where}: {len(cams)} cameras in the file ({', '.join(cams)}); choose one with "
            "--camera-name (camera_name= in Python)"
        )
    return cams[key], name_of(key, cams[key]), f"{where}: {key}"


def _intrinsics_from_tree(tree: dict, path: Path, key: str | None, camera_name: str | None) -> Intrinsics:
    where = str(path)
    if key is not None:
        used, value = _get(tree, (key,))
        if used is None:
            raise ValueError(f"{where}: no camera matrix under {key!r}")
        d, name, cw = tree, None, where
    else:
        d, name, cw = _pick_map(tree, where, camera_name)
        used, value = _get(d, _OPENCV_K_KEYS)
    K = _check_K(_matrix(value, f"{cw}: {used}", (3, 3)), f"{cw}: {used}")
    width, height = _size_value(d, _WIDTH_KEYS, cw), _size_value(d, _HEIGHT_KEYS, cw)
    if width is None and height is None:
        k, size = _get(d, ("image_size", "imageSize", "resolution"))
        if k is not None:
            s = _matrix(size, f"{cw}: {k}").ravel()
            if s.size != 2 or not np.all(s == np.round(s)):
                raise ValueError(f"{cw}: '{k}' must be [width, height] in whole pixels, got {s.tolist()}")
            width, height = int(s[0]), int(s[1])
    if (width is None) != (height is None):
        raise ValueError(
            f"{cw}: states the image {'width' if width is not None else 'height'} but not the "
            f"{'height' if width is not None else 'width'}"
        )
    width, height = _check_size(width, height, cw)
    dk, dv = _get(d, _OPENCV_DIST_KEYS)
    dist = np.zeros(0) if dk is None else _matrix(dv, f"{cw}: {dk}").ravel()
    _, model = _get(d, ("distortion_model",))
    model = "" if model is None else str(model).strip()
    _, fisheye = _get(d, ("fisheye_model",))
    if not model and fisheye not in (None, 0, "0", "false"):
        model = "equidistant"
    if dist.size:
        if model == "equidistant" and dist.size != 4:
            raise ValueError(f"{cw}: the equidistant (fisheye) model has 4 distortion coefficients, got {dist.size}")
        if model != "equidistant" and dist.size not in _OPENCV_DIST_COUNTS:
            raise ValueError(
                f"{cw}: '{dk}' holds {dist.size} coefficients; OpenCV's distortion models have "
                f"{', '.join(map(str, _OPENCV_DIST_COUNTS))}"
            )
        model = model or "opencv"
    return Intrinsics(K, width, height, dist, where, model if dist.size else "", name)


def _read_opencv(path: Path, key: str | None, camera_name: str | None = None) -> Intrinsics:
    """A FileStorage file (OpenCV's reader), or a YAML file not in OpenCV's dialect (PyYAML)."""
    yaml_file = path.suffix.lower() in (".yml", ".yaml") and not _is_opencv_yaml(path)
    tree = _yaml_tree(path) if yaml_file else _opencv_tree(path)
    return _intrinsics_from_tree(tree, path, key, camera_name)


def read_opencv_yml(path: str | Path, key: str | None = None) -> np.ndarray:
    """K (3, 3), pixels, from an OpenCV FileStorage file (``.yml``, ``.yaml``, ``.xml``, ``.json``) or a ROS YAML file.

    The matrix is read under ``key`` or the first of camera_matrix, cameraMatrix, K, intrinsics, M
    (any case). ValueError naming the file and key on bad input.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    return _checked(_read_opencv(path, key), None).K


def read_intrinsics(
    path: str | Path, *, camera_name: str | None = None, image_size: tuple[int, int] | None = None
) -> Intrinsics:
    """Intrinsics (K, size, distortion) of a ViSP ``.xml``, an OpenCV or ROS ``.yml``/``.yaml``/``.json``.

    An ``.xml`` is tried as ViSP first, then as an OpenCV FileStorage (``<opencv_storage>``).
    camera_name : the camera to read in a file of several (ViSP ``<name>``, a YAML file's top-level
    key or ``camera_name``); a file of one camera with another name is refused.
    image_size : (width, height) of the images, choosing among ViSP cameras of one name at several
    sizes, and the size K and the distortion are checked against when the file states none.
    ValueError, one line naming the file and what is missing or wrong, on bad input.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such intrinsics file: check the path (a ViSP .xml, an OpenCV or ROS .yaml/.yml)")
    try:
        return _checked(_read_intrinsics(path, camera_name, image_size), image_size)
    except OSError as exc:  # unreadable: permissions, a vanished mount
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc}); check the file's permissions") from None


def read_projection_matrix(path: str | Path) -> np.ndarray:
    """The camera C (3, 4) of a projection-matrix file (``.P``): twelve numbers, three rows of four (``#`` starts a
    comment), mapping world points to pixels (x y, the origin at the top-left pixel's centre) — mcit's global model
    itself, its pose included. ValueError, one line naming the file, otherwise."""
    from core.camera import Camera

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such camera file; check the path")
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc}); check the file's permissions") from None
    words = " ".join(line.split("#", 1)[0] for line in text.splitlines()).split()
    try:
        values = np.array([float(w) for w in words])
    except ValueError:
        raise ValueError(f"{path}: a projection matrix file holds numbers only (3 rows of 4)") from None
    if values.size != 12:
        raise ValueError(f"{path}: a projection matrix file holds 12 numbers (3 rows of 4), got {values.size}")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{path}: the projection matrix holds a number that is not finite")
    C = values.reshape(3, 4)
    try:
        Camera(C, 1, 1)  # of rank 3, a finite optical centre
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    return C


def _read_intrinsics(path: Path, camera_name: str | None, image_size: tuple[int, int] | None) -> Intrinsics:
    suffix = path.suffix.lower()
    if suffix == ".xml":
        try:
            root_tag = ET.parse(path).getroot().tag
        except ET.ParseError as exc:
            raise ValueError(f"{path}: not well-formed XML ({exc}); {_XML_ADVICE}") from None
        if root_tag == "opencv_storage":
            return _read_opencv(path, None, camera_name)
        return _read_visp(path, camera_name, image_size)
    if suffix in (".yml", ".yaml", ".json"):
        return _read_opencv(path, None, camera_name)
    raise ValueError(
        f"{path}: unknown intrinsics format {suffix!r}; use a ViSP .xml, or an OpenCV or ROS .yml/.yaml/.json"
    )
