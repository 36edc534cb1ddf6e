"""An object's pose from the files other tools write: the one reader of ``mcit db import --pose`` and
``mcit track --pose``.

The file's suffix says its form; each form gives the pose in the camera frame (``T_cam_obj``, ViSP's
``cMo``) or in the world (``T_world_obj``), and ``PoseFile.in_world(camera)`` brings it to the world
through the camera's pose (``C = K [R_cam_world | t_cam_world]``, ``core.camera.Camera.decompose``):

=========================  ====================================================  =================
suffix                     holds                                                  frame (default)
=========================  ====================================================  =================
``.pos``                   ViSP's ``vpPoseVector``: ``tx ty tz θux θuy θuz``       camera (ViSP's cMo)
                           (metres, then the rotation vector in radians)
``.txt``, ``.dat``         a 4×4 matrix, 16 numbers row by row (ViSP's            camera (ViSP's cMo)
                           ``vpHomogeneousMatrix::save``, ``numpy.savetxt``); the
                           top 3×4 (12 numbers) is enough
``.json``                  a 4×4 (rows) or ``{"xyz": [...], "rpy_deg": [...]}``   world (as the scene
                           (``app.scene.parse_pose``); ``{"T_world_obj": pose}``   files' poses)
                           or ``{"T_cam_obj": pose}`` names its frame
``.init``                  ViSP's model points, and their pixels (below):         camera
                           the pose solved from them (PnP, ``app.vision.pnp``)
=========================  ====================================================  =================

The frame: a matrix file may name it in a comment (``# cMo`` or ``# T_cam_obj``; ``# wMo`` or
``# T_world_obj``), a JSON file by its key; otherwise ``frame=`` (``--pose-frame camera|world``)
chooses, else the default above. A file that names one frame and a ``frame=`` the other is refused.

An ``.init``'s pixels: after its points, as ViSP's ``vpMbTracker::initFromPoints`` reads them (a count,
then ``i j`` — row, column — per point; ``app.models_io.read_init_pixels``), or given apart as
``clicks`` (``--init-clicks U,V ...``, u right, v down), in the order of the file's points, on the
frame the pose is wanted for. They are pixels of the video as recorded: with a lens (``lens``, the
camera file's distortion) they are undistorted first. The camera's K comes from ``camera``.

A rotation must be one to 1e-3 (orthonormal, determinant +1; made exact by ``core.transforms.
orthonormalize``, so that a matrix written with six digits is not refused) and the last row
``0 0 0 1``; every refusal is one ``ValueError`` line naming the file and what to do.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from core.transforms import exp_so3, invert_T, make_T, orthonormalize

__all__ = ["FRAMES", "POSE_SUFFIXES", "PoseFile", "read_pose_file", "read_visp_pos", "read_camera_pose"]

FRAMES = ("camera", "world")
POSE_SUFFIXES = (".pos", ".txt", ".dat", ".json", ".init")
_MATRIX_SUFFIXES = (".txt", ".dat")
_ROTATION_TOL = 1e-3  # largest |RᵀR − I| of a matrix accepted as a rotation (then made exact)
_MAX_BYTES = 1 << 20  # a pose file is a few hundred bytes: a larger one is not one
_MAX_M = 1e6  # |translation|, metres (as model files: app.models_io.cao.MAX_COORD_M)
# A comment naming the matrix's frame: ViSP's names (cMo, wMo) and mcit's (T_cam_obj, T_world_obj).
_NAMES_CAMERA = re.compile(r"\b(cMo|T_cam_obj|T_camera_obj)\b")
_NAMES_WORLD = re.compile(r"\b(wMo|T_world_obj)\b")
_JSON_KEYS = {"T_cam_obj": "camera", "T_world_obj": "world"}


@dataclass(frozen=True)
class PoseFile:
    """A pose read from a file.

    T : array, shape (4, 4), the pose as the file gives it: T_cam_obj (``frame`` "camera") or
    T_world_obj ("world"). frame : "camera" or "world". form : what the file held, in words.
    frame_from : what chose the frame ("the file", "--pose-frame", "the default for <form>").
    cov : (6, 6) covariance of T's (δt, δr) in its frame (``R ← exp([δr]×) R``, ``t ← t + δt``;
    docs/pose.md), or None when the file gives none (only an ``.init``'s PnP gives one).
    details : what the history keeps of it (the .init's points, pixels and RMS).
    """

    T: np.ndarray
    frame: str
    form: str
    path: Path
    frame_from: str
    cov: np.ndarray | None = None
    details: dict[str, Any] = field(default_factory=dict)

    def in_world(self, camera=None) -> tuple[np.ndarray, np.ndarray | None]:
        """(T_world_obj (4, 4), its covariance (6, 6) or None): a camera-frame pose through ``camera``'s
        pose (a ``core.camera.Camera``: T_world_obj = T_world_cam · T_cam_obj); a world pose as it is.
        ValueError when a camera-frame pose has no camera, or a mirrored one (no camera frame)."""
        if self.frame == "world":
            return self.T.copy(), None if self.cov is None else self.cov.copy()
        T_world_cam = invert_T(_camera_pose(camera, self.path, "a pose in the camera frame"))
        B = np.zeros((6, 6))
        B[:3, :3] = B[3:, 3:] = T_world_cam[:3, :3]  # (δt, δr) turned into the world
        cov = None if self.cov is None else B @ self.cov @ B.T
        return T_world_cam @ self.T, cov

    def describe(self) -> str:
        """One phrase for the operator: the form, the frame and what chose it."""
        name = "T_cam_obj, ViSP's cMo" if self.frame == "camera" else "T_world_obj"
        return f"{self.path.name}: {self.form}, {name} ({self.frame_from})"


def _camera_pose(camera, path: Path, what: str) -> np.ndarray:
    """T_cam_world (4, 4) of a Camera; ValueError naming ``path`` when there is none or it is mirrored."""
    if camera is None:
        raise ValueError(
            f"{path}: {what} needs the camera's calibration and there is none; give the site (--site DIR) or a "
            "database whose camera is calibrated, or the pose in the world (--pose-frame world)"
        )
    K, T_cam_world = camera.decompose()
    if K[0, 0] < 0:
        raise ValueError(
            f"{path}: the camera is mirrored (its image is flipped), so it has no camera frame; give the pose in "
            "the world (--pose-frame world, or a JSON pose)"
        )
    return T_cam_world


def _read_text(path: Path) -> str:
    """The file's text; ValueError naming it when it is missing, not a file, too large or not text."""
    if not path.exists():
        raise ValueError(f"{path}: no such pose file; check the path")
    if not path.is_file():
        raise ValueError(f"{path}: not a file; give the pose file")
    try:
        with open(path, "rb") as fh:
            data = fh.read(_MAX_BYTES + 1)
    except OSError as exc:
        raise ValueError(f"{path}: cannot be read ({exc.strerror or exc}); check its permissions") from None
    if len(data) > _MAX_BYTES:
        raise ValueError(f"{path}: more than {_MAX_BYTES >> 20} MB, not a pose file; give the pose file")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a text file, so not a pose file; give the pose file") from None


def _numbers(text: str, path: Path, what: str) -> np.ndarray:
    """Every number of ``text`` (``#`` comments dropped; spaces, commas, semicolons and brackets separate)."""
    body = "\n".join(line.split("#", 1)[0] for line in text.splitlines())
    tokens = [t for t in re.split(r"[\s,;\[\]]+", body) if t]
    try:
        values = np.array([float(t) for t in tokens], dtype=float)
    except ValueError:
        raise ValueError(f"{path}: {what} holds numbers only (and # comments); it holds other text") from None
    if not np.all(np.isfinite(values)):
        raise ValueError(f"{path}: {what} holds a number that is not finite (nan or inf); write the pose again")
    return values


def _rigid(T: np.ndarray, path: Path) -> np.ndarray:
    """``T`` as an exact rigid transform: its rotation made exact when within 1e-3 of one; ValueError
    naming the file for a last row other than 0 0 0 1, a scaled, sheared or mirrored rotation, or a
    translation beyond ±1e6 m."""
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(
            f"{path}: the matrix's last row is {' '.join(f'{v:g}' for v in T[3])}, not 0 0 0 1: not a rigid "
            "transform; give the object's pose (a rotation and a translation)"
        )
    R = T[:3, :3]
    off = float(np.abs(R.T @ R - np.eye(3)).max())
    if off > _ROTATION_TOL or np.linalg.det(R) <= 0:
        why = "mirrored (determinant < 0)" if np.linalg.det(R) <= 0 else f"scaled or sheared (RᵀR − I up to {off:.2g})"
        raise ValueError(
            f"{path}: the matrix's top-left 3×3 is not a rotation but {why}: not a rigid transform; give the "
            "object's pose (a rotation and a translation, in metres)"
        )
    if np.abs(T[:3, 3]).max() > _MAX_M:
        raise ValueError(f"{path}: the translation is beyond ±{_MAX_M:g} m (a pose is in metres); check the file")
    return make_T(orthonormalize(R), T[:3, 3])


def read_visp_pos(path: str | Path) -> np.ndarray:
    """T (4, 4) of a ViSP ``.pos`` file (``vpPoseVector``): six numbers tx ty tz (m) θux θuy θuz (rad).
    ViSP writes an object's pose in the camera (cMo). ValueError naming the file otherwise."""
    path = Path(path)
    values = _numbers(_read_text(path), path, "a ViSP pose file")
    if values.size != 6:
        hint = "; 16 numbers are a 4×4 matrix: name the file .txt" if values.size in (12, 16) else ""
        raise ValueError(
            f"{path}: a ViSP pose file holds six numbers (tx ty tz θux θuy θuz), got {values.size}{hint}; "
            "write the pose again"
        )
    if np.abs(values[:3]).max() > _MAX_M:
        raise ValueError(f"{path}: the translation is beyond ±{_MAX_M:g} m (a pose is in metres); check the file")
    angle = float(np.linalg.norm(values[3:]))
    if angle > np.pi + 1e-6:  # ViSP writes the angle in [0, π]: more is a file in degrees, most likely
        raise ValueError(
            f"{path}: θu's norm is {angle:.4g}, more than π: ViSP writes θu in radians, its norm the angle (at most "
            "π); were these degrees? write the pose again in radians"
        )
    return make_T(exp_so3(values[3:]), values[:3])


def _read_matrix(path: Path) -> tuple[np.ndarray, str | None]:
    """(T (4, 4), the frame a comment names or None) of a matrix text file."""
    text = _read_text(path)
    values = _numbers(text, path, "a 4×4 matrix file")
    if values.size not in (12, 16):
        hint = "; six numbers are a ViSP pose vector: name the file .pos" if values.size == 6 else ""
        raise ValueError(
            f"{path}: a 4×4 matrix file holds 16 numbers (4 rows of 4; or the top 12), got {values.size}{hint}; "
            "write the matrix again"
        )
    T = np.eye(4)
    T[: values.size // 4] = values.reshape(-1, 4)
    comments = " ".join(line.split("#", 1)[1] for line in text.splitlines() if "#" in line)
    said = {f for f, rule in (("camera", _NAMES_CAMERA), ("world", _NAMES_WORLD)) if rule.search(comments)}
    if len(said) > 1:
        raise ValueError(
            f"{path}: its comments name both frames (cMo / T_cam_obj and wMo / T_world_obj); keep the one it is"
        )
    return _rigid(T, path), (said.pop() if said else None)


def _read_json(path: Path) -> tuple[np.ndarray, str | None]:
    """(T (4, 4), the frame its key names or None) of a JSON pose."""
    from app.scene import parse_pose

    try:
        value = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc}); write the pose again") from None
    frame = None
    if isinstance(value, dict) and len(value) == 1 and next(iter(value)) in _JSON_KEYS:
        key, value = next(iter(value.items()))
        frame = _JSON_KEYS[key]
    elif isinstance(value, dict) and set(value) - {"xyz", "rpy_deg"}:
        raise ValueError(
            f'{path}: a JSON pose is a 4×4 matrix (rows), {{"xyz": [...], "rpy_deg": [...]}}, or one of them '
            f'under "T_world_obj" or "T_cam_obj"; got the keys {sorted(value)}'
        )
    try:
        if isinstance(value, list):  # a matrix: rigid to 1e-3 as a text matrix (parse_pose asks for 1e-6)
            M = np.asarray(value, dtype=float)
            if M.shape != (4, 4):
                raise ValueError(f"a pose matrix is 4×4 (4 rows of 4 numbers), got shape {M.shape}")
            if not np.all(np.isfinite(M)):
                raise ValueError("the matrix holds a number that is not finite")
            return _rigid(M, path), frame
        return _rigid(parse_pose(value, str(path)), path), frame
    except (TypeError, ValueError) as exc:
        text = str(exc)
        raise ValueError(text if text.startswith(str(path)) else f"{path}: {text}") from None


MAX_INIT_RMS_PX = 10.0  # clicks by eye put a model's corners 1-3 px RMS from where the pose puts them (the tea box's
# four on frame 0: 2.74 px); beyond this a click is on another corner or out of the file's order (a new user's four
# clicks in reverse order: 30.9 px, on one line: 49.9 px, each stored as a known pose before)
SWAP_CHECK_PX = 0.5  # a PnP this far off (RMS) is tried with each pixel's coordinates swapped …
SWAP_BETTER = 4.0  # … and refused as swapped when that fits this many times better


def _check_pixel_order(path: Path, K, X, uv, lens, camera, rms_px: float, from_file: bool) -> None:
    """ValueError when the pixels fit the model far better with their two coordinates swapped: ViSP's .init gives
    'row column', --init-clicks 'U,V' (column, row), and a swap still gives a pose, a few pixels and centimetres
    off (a helper's cube: RMS 4.5 px and 2.9 cm against 0.16 px)."""
    from app.vision.pnp import solve_pnp

    if rms_px <= SWAP_CHECK_PX:
        return
    swapped = uv[:, ::-1]
    try:
        other = solve_pnp(K, X, swapped if lens is None else lens.undistort(swapped), camera.width, camera.height)
    except ValueError:
        return
    if other.rms_px * SWAP_BETTER < rms_px:
        given = (
            "the file's pixels are read as 'row column' (ViSP's initFromPoints)"
            if from_file
            else ("--init-clicks are U,V (column, then row)")
        )
        raise ValueError(
            f"{path}: the points fit their pixels with RMS {rms_px:.2f} px, and {other.rms_px:.2f} px with each "
            f"pixel's two coordinates swapped: {given}; were they written the other way round? swap them"
        )


def _pose_from_init(path: Path, camera, clicks, lens) -> tuple[np.ndarray, np.ndarray, dict]:
    """(T_cam_obj, its covariance (δt, δr), the details) of an .init's points and their pixels."""
    from app.models_io import read_init_pixels
    from app.vision.pnp import solve_pnp

    X, uv_file = read_init_pixels(path)
    if clicks is not None and uv_file is not None:
        raise ValueError(f"{path}: the file gives its points' pixels and --init-clicks gives them too; give them once")
    uv = uv_file if clicks is None else np.asarray(clicks, dtype=float).reshape(-1, 2)
    if uv is None:
        raise ValueError(
            f"{path}: the file gives the model points but not their pixels; give them in its order with "
            f"--init-clicks U,V ... ({len(X)} pixels), or after its points as ViSP's initFromPoints reads them "
            "(a count, then 'row column' per point)"
        )
    if len(uv) != len(X):
        raise ValueError(
            f"{path}: {len(X)} model points but {len(uv)} pixels; give one pixel per point, in the file's order"
        )
    _camera_pose(camera, path, "solving the pose from clicked points")  # a camera, and not a mirrored one
    K = camera.decompose()[0]
    uv_solved = uv if lens is None else lens.undistort(uv)
    try:
        r = solve_pnp(K, X, uv_solved, camera.width, camera.height)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None
    _check_pixel_order(path, K, X, uv, lens, camera, r.rms_px, clicks is None)
    if r.rms_px > MAX_INIT_RMS_PX:
        worst = int(np.argmax(r.errors_px))
        given = "the file's pixels" if clicks is None else "the --init-clicks"
        raise ValueError(
            f"{path}: the points fit {given} with RMS {r.rms_px:.1f} px (point {worst + 1}: "
            f"{r.errors_px[worst]:.1f} px), more than {MAX_INIT_RMS_PX:.0f} px: a pixel on another corner, or "
            "out of the file's order? give each point's pixel in the order the file lists the points"
        )
    order = [3, 4, 5, 0, 1, 2]  # solve_pnp's (δω, δt) → the database's (δt, δr)
    cov = r.cov_pose[np.ix_(order, order)]
    details = {
        "X_obj": X,
        "uv": uv,
        "pixels_from": "the file" if clicks is None else "--init-clicks",
        "undistorted": lens is not None,
        "rms_px": r.rms_px,
        "residuals_px": r.residuals_px,
    }
    return r.T_cam_world, cov, details


def read_pose_file(path: str | Path, *, frame: str | None = None, camera=None, clicks=None, lens=None) -> PoseFile:
    """Read an object's pose (see the module docstring for the forms and their frames).

    frame : "camera" or "world" for a file that does not say (``--pose-frame``); None: the form's default.
    camera : core.camera.Camera, the camera the pose is seen by: its K solves an ``.init``'s PnP (and
        ``PoseFile.in_world`` uses its pose). clicks : (N, 2) pixels of an ``.init``'s points, when the
        file does not give them. lens : the camera's lens (app.undistort), the pixels being the recorded ones.
    """
    path = Path(path)
    if frame is not None and frame not in FRAMES:
        raise ValueError(f"the pose's frame is 'camera' or 'world', got {frame!r}")
    suffix = path.suffix.lower()
    if suffix not in POSE_SUFFIXES:
        raise ValueError(
            f"{path}: unknown pose file type {suffix or '(no suffix)'!r}; give a ViSP .pos (tx ty tz θux θuy θuz), "
            "a 4×4 matrix in .txt or .dat, a JSON pose (.json) or a ViSP .init with its points' pixels"
        )
    if clicks is not None and suffix != ".init":
        raise ValueError(f"{path}: clicked pixels (--init-clicks) go with an .init file's points, not a {suffix} pose")
    said, cov, details = None, None, {}
    if suffix == ".pos":
        T, form, default = read_visp_pos(path), "ViSP pose vector", "camera"
    elif suffix in _MATRIX_SUFFIXES:
        (T, said), form, default = _read_matrix(path), "4×4 matrix", "camera"
    elif suffix == ".json":
        (T, said), form, default = _read_json(path), "JSON pose", "world"
    else:
        if frame == "world":
            raise ValueError(
                f"{path}: an .init's clicked points give the pose in the camera frame; drop --pose-frame world"
            )
        T, cov, details = _pose_from_init(path, camera, clicks, lens)
        form, said, default = f"ViSP .init points and their pixels (PnP, RMS {details['rms_px']:.2f} px)", "camera", ""
    if said is not None and frame is not None and said != frame:
        raise ValueError(
            f"{path}: the file gives the pose in the {said} frame but --pose-frame says {frame}; drop --pose-frame "
            "or correct the file"
        )
    chosen = said or frame or default
    source = "the file" if said else "--pose-frame" if frame else f"the default for a {form}"
    if suffix == ".init":
        source = "the clicked points' pose in the camera"
    return PoseFile(T, chosen, form, path, source, cov, details)


def read_camera_pose(path: str | Path) -> np.ndarray:
    """A camera's pose in the world, T_world_cam (4, 4), from a 4×4 matrix file (.txt, .dat) or a JSON pose
    (a 4×4 or {"xyz", "rpy_deg"}); ValueError naming the file otherwise (an object's forms, .pos and .init,
    are poses in the camera and have no meaning here)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in _MATRIX_SUFFIXES:
        return _read_matrix(path)[0]
    if suffix == ".json":
        return _read_json(path)[0]
    raise ValueError(
        f"{path}: a camera's pose (T_world_cam) is a 4×4 matrix in .txt or .dat, or a JSON pose (.json); got "
        f"{suffix or '(no suffix)'!r}"
    )
