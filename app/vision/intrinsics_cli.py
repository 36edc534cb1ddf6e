"""``mcit calibrate-intrinsics FRAMES``: K and the lens distortion from views of a checkerboard or a
ChArUco board (OpenCV), written as an OpenCV camera file that ``app.camera_io.read_intrinsics``
(and every mcit command taking ``--intrinsics`` or a scene's ``intrinsics_file``) reads.

FRAMES is a folder of images or a video file. The board is found in each frame (checkerboard:
``findChessboardCornersSB``; ChArUco: ``aruco.CharucoDetector``), ``cv2.calibrateCamera`` solves K
and OpenCV's 5 coefficients (``--model rational`` for 8), and the file holds ``image_width``,
``image_height``, ``camera_matrix``, ``distortion_model`` (plumb_bob / rational_polynomial),
``distortion_coefficients``, ``rms_px`` (the reprojection error over every corner) and the frames
used. Progress goes to stderr on a terminal (``--quiet``: none). Examples::

    mcit calibrate-intrinsics frames/ --board checkerboard --cols 9 --rows 6 --square-mm 25 --out cam.yml
    mcit calibrate-intrinsics calib.mp4 --every 10 --board charuco --cols 7 --rows 5 --square-mm 30 \
--marker-mm 22 --out cam.yml
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.exit_status import UsageError

__all__ = ["add_calibrate_intrinsics_parser", "Calibration", "calibrate_intrinsics", "write_camera_file"]


@dataclass(frozen=True)
class Calibration:
    """K (3, 3), distortion (k,), the reprojection RMS in pixels, the image size and the frames used."""

    K: np.ndarray
    distortion: np.ndarray
    rms_px: float
    width: int
    height: int
    frames_used: tuple[int, ...]
    frames_seen: int
    model: str


def add_calibrate_intrinsics_parser(sub) -> None:
    p = sub.add_parser(
        "calibrate-intrinsics",
        help="K and the lens distortion from frames of a checkerboard or ChArUco board (writes an OpenCV camera file)",
        description="Calibrate a camera's intrinsics (K and lens distortion) from frames showing a checkerboard or a "
        "ChArUco board, and write them as an OpenCV camera file with the reprojection RMS.",
        epilog="examples:\n" + "\n".join(line for line in __doc__.split("::\n\n")[1].splitlines()),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("frames", help="a folder of images or a video file showing the board in many positions")
    p.add_argument(
        "--board", choices=("checkerboard", "charuco"), default="checkerboard", help="the board (default checkerboard)"
    )
    p.add_argument("--cols", type=int, required=True, help="squares along the board's width")
    p.add_argument("--rows", type=int, required=True, help="squares along the board's height")
    p.add_argument("--square-mm", type=float, required=True, help="side of one square, millimetres")
    p.add_argument("--marker-mm", type=float, help="ChArUco: side of one marker, millimetres")
    p.add_argument("--dictionary", default="DICT_5X5_100", help="ChArUco: the ArUco dictionary (default DICT_5X5_100)")
    p.add_argument(
        "--model",
        choices=("plumb_bob", "rational"),
        default="plumb_bob",
        help="distortion model: plumb_bob (k1 k2 p1 p2 k3, default) or rational (8 coefficients)",
    )
    p.add_argument("--every", type=int, default=1, help="use every N-th frame of a video (default 1)")
    p.add_argument(
        "--out", default="camera.yml", help="camera file to write (.yml, .yaml, .xml or .json; default camera.yml)"
    )
    p.add_argument("--quiet", action="store_true", help="no progress bar (there is none when stderr is not a terminal)")
    p.set_defaults(func=_cmd)


def _frames(source: str, every: int, progress=None):
    """(index, image) of every ``every``-th frame; ``progress(frames read, frames in the source or None)``."""
    from app.vision.sequence import frame_count, iter_frames

    if every < 1:
        raise UsageError(f"--every must be at least 1, got {every}")
    total = frame_count(source) if progress is not None and Path(source).exists() else None
    for i, rgb in iter_frames(source):
        if progress is not None:
            progress(i + 1, total)
        if i % every == 0:
            yield i, rgb


def _grey(rgb: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb


def _checkerboard(cols: int, rows: int, square_m: float):
    import cv2

    inner = (cols - 1, rows - 1)
    obj = np.zeros((inner[0] * inner[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0 : inner[0], 0 : inner[1]].T.reshape(-1, 2) * square_m

    def detect(grey):
        # The classic detector refined by cornerSubPix (on synthetic renders through a known lens its
        # corners gave K within 0.05 %, the sector-based detector's 0.2 %); the latter when it fails.
        ok, corners = cv2.findChessboardCorners(
            grey, inner, flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        )
        if ok:
            c = corners.reshape(inner[1], inner[0], 2)
            spacing = min(
                np.linalg.norm(np.diff(c, axis=0), axis=2).min(), np.linalg.norm(np.diff(c, axis=1), axis=2).min()
            )
            half = int(np.clip(spacing / 3.0, 2, 11))
            corners = cv2.cornerSubPix(
                grey, corners, (half, half), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
            )
        else:
            ok, corners = cv2.findChessboardCornersSB(
                grey, inner, flags=cv2.CALIB_CB_ACCURACY | cv2.CALIB_CB_NORMALIZE_IMAGE
            )
            if not ok:
                return None
        return obj, corners.reshape(-1, 1, 2).astype(np.float32)

    return detect


def charuco_board(cols: int, rows: int, square_m: float, marker_m: float, dictionary: str):
    """The cv2.aruco.CharucoBoard of the command's options; ValueError on a bad dictionary or sizes."""
    import cv2

    if not hasattr(cv2.aruco, dictionary) or not dictionary.startswith("DICT_"):
        raise UsageError(f"--dictionary {dictionary!r} is not an ArUco dictionary (e.g. DICT_5X5_100, DICT_4X4_50)")
    if not 0 < marker_m < square_m:
        raise UsageError(
            f"--marker-mm must be positive and smaller than --square-mm, got {marker_m * 1e3:g} and {square_m * 1e3:g}"
        )
    d = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    return cv2.aruco.CharucoBoard((cols, rows), square_m, marker_m, d)


def _charuco(cols: int, rows: int, square_m: float, marker_m: float, dictionary: str):
    import cv2

    board = charuco_board(cols, rows, square_m, marker_m, dictionary)
    detector = cv2.aruco.CharucoDetector(board)
    all_obj = board.getChessboardCorners()

    def detect(grey):
        corners, ids, _, _ = detector.detectBoard(grey)
        if ids is None or len(ids) < 6:
            return None
        return all_obj[ids.ravel()].astype(np.float32), corners.reshape(-1, 1, 2).astype(np.float32)

    return detect


def calibrate_intrinsics(
    frames,
    *,
    board: str = "checkerboard",
    cols: int,
    rows: int,
    square_mm: float,
    marker_mm: float | None = None,
    dictionary: str = "DICT_5X5_100",
    model: str = "plumb_bob",
) -> Calibration:
    """Calibrate from ``frames``, an iterable of (index, image (H, W[, 3]) uint8); see the module docstring.

    ValueError (one line: what was found, what to do) when the board is seen in fewer than 3 frames,
    the frames change size, or the options are impossible.
    """
    import cv2

    if cols < 3 or rows < 3:
        raise UsageError(f"a board needs at least 3 × 3 squares, got {cols} × {rows}")
    if not square_mm > 0:
        raise UsageError(f"--square-mm must be positive, got {square_mm}")
    if board == "charuco":
        if marker_mm is None:
            raise UsageError("a ChArUco board needs --marker-mm (the side of its markers)")
        detect = _charuco(cols, rows, square_mm / 1e3, marker_mm / 1e3, dictionary)
    elif board == "checkerboard":
        detect = _checkerboard(cols, rows, square_mm / 1e3)
    else:
        raise UsageError(f"unknown board {board!r}: checkerboard or charuco")
    obj_pts, img_pts, used, size, seen = [], [], [], None, 0
    for index, image in frames:
        grey = _grey(image)
        if size is None:
            size = (grey.shape[1], grey.shape[0])
        elif (grey.shape[1], grey.shape[0]) != size:
            raise ValueError(
                f"frame {index} is {grey.shape[1]}×{grey.shape[0]}, the first was {size[0]}×{size[1]}; "
                "calibrate on frames of one size"
            )
        seen += 1
        found = detect(grey)
        if found is not None:
            obj_pts.append(found[0])
            img_pts.append(found[1])
            used.append(int(index))
    if seen == 0:
        raise ValueError("no frame to read; give a folder of images or a video file")
    if len(used) < 3:
        raise ValueError(
            f"the {cols} × {rows} {board} was found in {len(used)} of {seen} frames; at least 3 are needed "
            "(check --cols/--rows: they count squares, not inner corners)"
        )
    flags = cv2.CALIB_RATIONAL_MODEL if model == "rational" else 0
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, _, _ = cv2.calibrateCamera(obj_pts, img_pts, size, None, None, flags=flags, criteria=crit)
    n = 8 if model == "rational" else 5
    return Calibration(
        np.asarray(K, float),
        np.asarray(dist, float).ravel()[:n],
        float(rms),
        size[0],
        size[1],
        tuple(used),
        seen,
        "rational_polynomial" if model == "rational" else "plumb_bob",
    )


def _checked_out(path: str | Path) -> Path:
    path = Path(path)
    if path.suffix.lower() not in (".yml", ".yaml", ".xml", ".json"):
        raise UsageError(f"{path}: write the camera file as .yml, .yaml, .xml or .json")
    return path


def write_camera_file(cal: Calibration, path: str | Path) -> None:
    """Write ``cal`` as an OpenCV FileStorage camera file (written beside, then renamed into place)."""
    import cv2

    path = _checked_out(path)
    tmp = path.with_name(path.stem + ".part" + path.suffix)
    fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
    if not fs.isOpened():
        raise ValueError(f"{path}: cannot be written; check the folder exists and is writable")
    try:
        fs.write("image_width", cal.width)
        fs.write("image_height", cal.height)
        fs.write("camera_matrix", cal.K)
        fs.write("distortion_model", cal.model)
        fs.write("distortion_coefficients", cal.distortion.reshape(1, -1))
        fs.write("rms_px", cal.rms_px)
        fs.write("frames_used", len(cal.frames_used))
        fs.write("frames_seen", cal.frames_seen)
    finally:
        fs.release()
    tmp.replace(path)


def _cmd(args) -> int:
    """Calibrate and write the file; a failure raises (app.cli says it in one line: status 1, 2 for a UsageError)."""
    from app.progress import progress_bar

    _checked_out(args.out)  # before the frames are read
    with progress_bar("frames", quiet=args.quiet) as progress:
        cal = calibrate_intrinsics(
            _frames(args.frames, args.every, progress),
            board=args.board,
            cols=args.cols,
            rows=args.rows,
            square_mm=args.square_mm,
            marker_mm=args.marker_mm,
            dictionary=args.dictionary,
            model=args.model,
        )
    write_camera_file(cal, args.out)
    K = cal.K
    print(
        f"board found in {len(cal.frames_used)} of {cal.frames_seen} frames ({cal.width}×{cal.height}); "
        f"reprojection RMS {cal.rms_px:.2f} px"
    )
    print(
        f"fx {K[0, 0]:.1f} px, fy {K[1, 1]:.1f} px, centre ({K[0, 2]:.1f}, {K[1, 2]:.1f}) px; "
        f"distortion ({cal.model}) {' '.join(f'{d:.4g}' for d in cal.distortion)}"
    )
    print(f"wrote {args.out}")
    return 0
