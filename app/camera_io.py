"""Read camera intrinsics from the files other tools write: ViSP ``.xml`` and OpenCV ``.yml``.

mcit works with the global model C (DESIGN.md); a camera given as intrinsics K plus a pose becomes
``C = K [R_cam_world | t_cam_world]`` (``core.camera.Camera.from_intrinsics``). This module only
turns files into K (3, 3) (pixels; fx, skew, u0 / 0, fy, v0 / 0, 0, 1), with the image size and
distortion the file states.

* ViSP writes two XML layouts, both read here: ``vpXmlParserCamera``
  (``<root><camera><name/><image_width/><image_height/><model><type>perspectiveProjWithoutDistortion
  </type><px/><py/><u0/><v0/></model></camera></root>``) and the model-based tracker's settings
  (``<conf><camera><u0/><v0/><px/><py/></camera>…</conf>``, e.g. ``visp-cube/cube.xml``).
  ViSP's pixel origin is the centre of the top-left pixel, like mcit's, so u0, v0 carry over as they are.
* OpenCV ``FileStorage`` files (``.yml``/``.yaml``/``.json``/``.xml``) from ``calibrateCamera`` tools:
  the matrix under ``camera_matrix`` (or ``cameraMatrix``, ``K``, ``intrinsics``), the size under
  ``image_width``/``image_height`` (or ``image_size``), the distortion under
  ``distortion_coefficients`` (or ``dist_coeffs``, ``D``).

mcit's camera has no lens distortion: callers that build C from K should refuse a file whose
distortion is not zero (``Intrinsics.has_distortion``) and ask for an undistorted video.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["Intrinsics", "read_visp_xml", "read_opencv_yml", "read_intrinsics"]

_VISP_NO_DISTORTION = "perspectiveProjWithoutDistortion"
_VISP_DISTORTION = "perspectiveProjWithDistortion"
_OPENCV_K_KEYS = ("camera_matrix", "cameraMatrix", "K", "intrinsics", "M")
_OPENCV_DIST_KEYS = ("distortion_coefficients", "dist_coeffs", "distCoeffs", "D")


@dataclass(frozen=True)
class Intrinsics:
    """What an intrinsics file says.

    K : array, shape (3, 3), pixels. width, height : image size in pixels, or None when the
    file does not state it. distortion : array, shape (k,), the file's distortion coefficients
    (ViSP: (kud, kdu); OpenCV: (k1, k2, p1, p2[, k3, ...])), empty when none.
    """

    K: np.ndarray
    width: int | None = None
    height: int | None = None
    distortion: np.ndarray = field(default_factory=lambda: np.zeros(0))
    source: str = ""

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


def _float(node: ET.Element | None, tag: str, where: str) -> float:
    child = None if node is None else node.find(tag)
    if child is None or child.text is None:
        raise ValueError(f"{where}: missing <{tag}>")
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


def _read_visp(path: Path, camera_name: str | None) -> Intrinsics:
    where = str(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ValueError(f"{where}: not well-formed XML ({exc})") from None
    cameras = [root] if root.tag == "camera" else root.findall("camera")
    if not cameras:
        raise ValueError(f"{where}: no <camera> element; expected a ViSP camera file (<root><camera>…) or tracker settings (<conf><camera>…)")
    if camera_name is not None:
        cameras = [c for c in cameras if (c.findtext("name") or "").strip() == camera_name]
        if not cameras:
            raise ValueError(f"{where}: no <camera> named {camera_name!r}")
    if len(cameras) > 1:
        names = [(c.findtext("name") or "").strip() for c in cameras]
        raise ValueError(f"{where}: {len(cameras)} <camera> elements ({names}); pass camera_name= to choose one")
    cam = cameras[0]
    cw = f"{where}: <camera>"
    width = _int_or_none(cam, "image_width", cw)
    height = _int_or_none(cam, "image_height", cw)
    models = cam.findall("model")
    if not models:  # model-based tracker settings: the parameters sit directly in <camera>
        K = _K(_float(cam, "px", cw), _float(cam, "py", cw), _float(cam, "u0", cw), _float(cam, "v0", cw))
        return Intrinsics(_check_K(K, cw), width, height, np.zeros(0), where)
    by_type = {(m.findtext("type") or "").strip(): m for m in models}
    if _VISP_NO_DISTORTION in by_type:
        m = by_type[_VISP_NO_DISTORTION]
        mw = f"{cw} <model> {_VISP_NO_DISTORTION}"
        K = _K(_float(m, "px", mw), _float(m, "py", mw), _float(m, "u0", mw), _float(m, "v0", mw))
        return Intrinsics(_check_K(K, mw), width, height, np.zeros(0), where)
    if _VISP_DISTORTION in by_type:
        m = by_type[_VISP_DISTORTION]
        mw = f"{cw} <model> {_VISP_DISTORTION}"
        K = _K(_float(m, "px", mw), _float(m, "py", mw), _float(m, "u0", mw), _float(m, "v0", mw))
        dist = np.array([_float(m, "kud", mw), _float(m, "kdu", mw)])
        return Intrinsics(_check_K(K, mw), width, height, dist, where)
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
    return _read_visp(path, camera_name).K


def _first_matrix(fs, keys, where: str):
    """(key, matrix) of the first of ``keys`` present in a FileStorage, or (None, None)."""
    for k in keys:
        node = fs.getNode(k)
        if not node.empty():
            M = node.mat()
            if M is None:
                raise ValueError(f"{where}: '{k}' is not a matrix")
            return k, M
    return None, None


def _read_opencv(path: Path, key: str | None) -> Intrinsics:
    import cv2  # OpenCV's own FileStorage reads its YAML dialect (%YAML:1.0, !!opencv-matrix)

    where = str(path)
    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as exc:
        raise ValueError(f"{where}: OpenCV cannot parse it ({str(exc).strip().splitlines()[-1]})") from None
    if not fs.isOpened():
        raise ValueError(f"{where}: OpenCV cannot open it as a FileStorage (.yml, .yaml, .xml, .json)")
    try:
        keys = [key] if key is not None else list(_OPENCV_K_KEYS)
        used, K = _first_matrix(fs, keys, where)
        if K is None:
            raise ValueError(f"{where}: no camera matrix under {keys}; name it 'camera_matrix' or pass key=")
        K = _check_K(K, f"{where}: {used}")
        width = height = None
        w_node, h_node = fs.getNode("image_width"), fs.getNode("image_height")
        if not w_node.empty() and not h_node.empty():
            width, height = int(w_node.real()), int(h_node.real())
        else:
            size = fs.getNode("image_size")  # a sequence [width, height]
            if size.isSeq() and size.size() == 2:
                width, height = int(size.at(0).real()), int(size.at(1).real())
        _, d = _first_matrix(fs, _OPENCV_DIST_KEYS, where)
        dist = np.zeros(0) if d is None else np.asarray(d, dtype=float).ravel()
    finally:
        fs.release()
    return Intrinsics(K, width, height, dist, where)


def read_opencv_yml(path: str | Path, key: str | None = None) -> np.ndarray:
    """K (3, 3), pixels, from an OpenCV FileStorage file (``.yml``, ``.yaml``, ``.xml``, ``.json``).

    The matrix is read under ``key`` or the first of camera_matrix, cameraMatrix, K, intrinsics, M.
    ValueError naming the file and key on bad input.
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such file")
    return _read_opencv(path, key).K


def read_intrinsics(path: str | Path) -> Intrinsics:
    """Intrinsics (K, size, distortion) of a ViSP ``.xml`` or an OpenCV ``.yml``/``.yaml``/``.json``.

    An ``.xml`` is tried as ViSP first, then as an OpenCV FileStorage (``<opencv_storage>``).
    """
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such intrinsics file")
    suffix = path.suffix.lower()
    if suffix == ".xml":
        try:
            root_tag = ET.parse(path).getroot().tag
        except ET.ParseError as exc:
            raise ValueError(f"{path}: not well-formed XML ({exc})") from None
        if root_tag == "opencv_storage":
            return _read_opencv(path, None)
        return _read_visp(path, None)
    if suffix in (".yml", ".yaml", ".json"):
        return _read_opencv(path, None)
    raise ValueError(f"{path}: unknown intrinsics format {suffix!r}; use a ViSP .xml or an OpenCV .yml/.yaml/.json")
