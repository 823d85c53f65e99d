"""Camera intrinsics and lens distortion from views of a chessboard or ChArUco board (OpenCV).

:func:`calibrate_camera` finds the board in every view, runs ``cv2.calibrateCamera`` and reports
the RMS reprojection error overall and per view. :func:`undistort_stack` applies a calibration to
captured frames. Coordinates follow OpenCV: pixel centres at integers, distortion in OpenCV's
order (k1, k2, p1, p2, k3[, ...]).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import cv2
import numpy as np

from calibration.errors import CalibrationError

log = logging.getLogger(__name__)

#: Fewest usable views for a trustworthy camera calibration.
MIN_VIEWS = 3


@dataclass(frozen=True)
class BoardSpec:
    """A calibration target. ``squares`` = (columns, rows) of squares; chessboards have
    (columns - 1) x (rows - 1) inner corners."""

    kind: str = "chessboard"
    squares: tuple[int, int] = (9, 7)
    square_mm: float = 20.0
    marker_mm: float | None = None
    dictionary: str = "DICT_5X5_100"

    def __post_init__(self) -> None:
        if self.kind not in ("chessboard", "charuco"):
            raise CalibrationError(f"board kind: expected 'chessboard' or 'charuco', found {self.kind!r}")
        if min(self.squares) < 3:
            raise CalibrationError(f"board squares: expected at least 3x3, found {self.squares}")
        if not self.square_mm > 0:
            raise CalibrationError(f"board square_mm: expected > 0, found {self.square_mm}")
        if self.kind == "charuco" and not (self.marker_mm or 0) < self.square_mm:
            raise CalibrationError("board marker_mm: a ChArUco marker must be smaller than its square")

    @property
    def inner_corners(self) -> tuple[int, int]:
        """Inner corners (columns, rows): one fewer than squares each way, as OpenCV counts them."""
        return (self.squares[0] - 1, self.squares[1] - 1)

    def object_points(self) -> np.ndarray:
        """Inner corners (N, 3) in mm on the board plane, OpenCV's order (origin at the board's corner)."""
        cols, rows = self.inner_corners
        gx, gy = np.meshgrid(np.arange(1, cols + 1), np.arange(1, rows + 1))
        return np.column_stack((gx.ravel(), gy.ravel(), np.zeros(gx.size))).astype(np.float32) * self.square_mm

    def charuco_board(self) -> "cv2.aruco.CharucoBoard":
        """The OpenCV ChArUco board of this spec (markers 0.7 of a square unless ``marker_mm`` is given)."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(tuple(self.squares), self.square_mm, self.marker_mm or 0.7 * self.square_mm, dictionary)


@dataclass(frozen=True)
class BoardDetection:
    """Board corners found in one view: image points (N, 2) and matching board points (N, 3)."""

    image_points: np.ndarray
    object_points: np.ndarray


@dataclass(frozen=True)
class CameraCalibration:
    """Camera intrinsics and lens distortion fitted to board views, with the fit's quality."""

    camera_matrix: np.ndarray
    distortion: np.ndarray
    image_size: tuple[int, int]       # (width, height)
    rms_px: float                     # RMS reprojection error over every corner
    per_view_rms_px: tuple[float, ...]
    views_used: tuple[int, ...]       # indices of the views in which the board was found
    rvecs: tuple[np.ndarray, ...] = ()
    tvecs: tuple[np.ndarray, ...] = ()
    distortion_std: np.ndarray | None = None  # 1-sigma of the distortion coefficients (first fit)
    distortion_significant: bool = True       # False: no coefficient stood out of its noise, all set to 0

    def as_fields(self) -> dict:
        """calibration.json keys (capture-format.md: ``camera_matrix``, ``distortion``)."""
        return {
            "camera_matrix": self.camera_matrix.tolist(),
            "distortion": self.distortion.ravel().tolist(),
            "camera_image_size": list(self.image_size),
            "reprojection_rms_px": self.rms_px,
            "distortion_significant": self.distortion_significant,
        }


def _gray8(image: np.ndarray, name: str) -> np.ndarray:
    img = np.asarray(image)
    if img.ndim != 2:
        raise CalibrationError(f"{name}: expected a single-channel image, found shape {img.shape}")
    if img.dtype != np.uint8:
        top = float(np.nanmax(img)) if img.size else 0.0
        img = np.clip(img.astype(np.float64) * (255.0 / top if top > 0 else 1.0), 0, 255).astype(np.uint8)
    return img


def detect_board(image: np.ndarray, board: BoardSpec, name: str = "view") -> BoardDetection | None:
    """Corners of ``board`` in one image, refined to sub-pixel; None when the board is not found."""
    gray = _gray8(image, name)
    if board.kind == "chessboard":
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
        found, corners = cv2.findChessboardCorners(gray, board.inner_corners, flags=flags)
        if not found:
            found, corners = cv2.findChessboardCornersSB(gray, board.inner_corners)
            if not found:
                return None
        # refine with a window a quarter of a square wide (the classic detector is unbiased this way)
        points = corners.reshape(-1, 2)
        spacing = float(np.median(np.linalg.norm(np.diff(points, axis=0), axis=1)))
        half = int(np.clip(spacing / 4.0, 2, 11))
        corners = cv2.cornerSubPix(
            gray, corners.astype(np.float32), (half, half), (-1, -1),
            (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6),
        )
        return BoardDetection(corners.reshape(-1, 2).astype(np.float64), board.object_points())
    charuco = board.charuco_board()
    corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco).detectBoard(gray)
    if ids is None or len(ids) < 6:
        return None
    object_points, image_points = charuco.matchImagePoints(corners, ids)
    return BoardDetection(image_points.reshape(-1, 2).astype(np.float64), object_points.reshape(-1, 3).astype(np.float32))


def calibrate_camera(
    views: Sequence[np.ndarray],
    board: BoardSpec,
    flags: int = 0,
    min_views: int = MIN_VIEWS,
    significance: float | None = 2.0,
) -> CameraCalibration:
    """Intrinsics and distortion from views of a board (``cv2.calibrateCamera``).

    Parameters
    ----------
    views : sequence of (H, W) images
        All the same size; views where the board is not found are skipped (and logged).
    board : BoardSpec
    flags : int
        ``cv2.CALIB_*`` flags (e.g. ``cv2.CALIB_FIX_K3`` for few views).
    min_views : int
        Fewest views with a detected board.
    significance : float or None
        When no distortion coefficient differs from 0 by more than ``significance`` standard
        deviations (a narrow lens, few views), the camera is refitted without distortion, so that
        noise is not applied to every capture as a correction. None keeps the first fit.
    """
    if not views:
        raise CalibrationError("camera views: none given")
    shape = np.asarray(views[0]).shape
    detections, used = [], []
    for index, view in enumerate(views):
        if np.asarray(view).shape != shape:
            raise CalibrationError(f"camera view {index}: size {np.asarray(view).shape} differs from view 0 {shape}")
        found = detect_board(view, board, name=f"camera view {index}")
        if found is None:
            log.warning("camera view %d: %s not found, skipped", index, board.kind)
            continue
        detections.append(found)
        used.append(index)
    if len(detections) < min_views:
        raise CalibrationError(
            f"camera views: the {board.kind} was found in {len(detections)} of {len(views)} views, need at least {min_views}"
        )
    size = (int(shape[1]), int(shape[0]))
    object_points = [d.object_points.astype(np.float32).reshape(-1, 1, 3) for d in detections]
    image_points = [d.image_points.astype(np.float32).reshape(-1, 1, 2) for d in detections]
    rms, matrix, distortion, rvecs, tvecs, std_intrinsics, _, _ = cv2.calibrateCameraExtended(
        object_points, image_points, size, None, None, flags=flags
    )
    distortion_std = np.asarray(std_intrinsics, dtype=np.float64).ravel()[4 : 4 + np.asarray(distortion).size]
    coefficients = np.asarray(distortion, dtype=np.float64).ravel()
    significant = True
    if significance is not None:
        free = distortion_std > 0  # fixed coefficients have no deviation
        significant = bool(np.any(np.abs(coefficients[free]) > significance * distortion_std[free]))
        if not significant:
            log.info("camera calibration: no distortion coefficient is significant; refitting without distortion")
            no_distortion = cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
            rms, matrix, distortion, rvecs, tvecs = cv2.calibrateCamera(
                object_points, image_points, size, None, np.zeros(5), flags=flags | no_distortion
            )
    per_view = []
    for obj, img, rvec, tvec in zip(object_points, image_points, rvecs, tvecs):
        projected, _ = cv2.projectPoints(obj, rvec, tvec, matrix, distortion)
        per_view.append(float(np.sqrt(np.mean(np.sum((projected - img) ** 2, axis=2)))))
    log.info("camera calibration: %d views, RMS reprojection error %.3f px", len(detections), rms)
    return CameraCalibration(
        camera_matrix=np.asarray(matrix, dtype=np.float64),
        distortion=np.asarray(distortion, dtype=np.float64).ravel(),
        image_size=size,
        rms_px=float(rms),
        per_view_rms_px=tuple(per_view),
        views_used=tuple(used),
        rvecs=tuple(np.asarray(r).ravel() for r in rvecs),
        tvecs=tuple(np.asarray(t).ravel() for t in tvecs),
        distortion_std=distortion_std,
        distortion_significant=significant,
    )


def undistort_stack(frames: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Frames (N, H, W) or one (H, W) frame with lens distortion removed (same camera matrix).

    One remap table serves the whole stack; pixels whose source lies outside the frame are 0.
    """
    data = np.asarray(frames)
    single = data.ndim == 2
    stack = data[None] if single else data
    if stack.ndim != 3:
        raise CalibrationError(f"frames: expected (N, H, W) or (H, W), found shape {data.shape}")
    matrix = np.asarray(camera_matrix, dtype=np.float64).reshape(3, 3)
    dist = np.asarray(distortion, dtype=np.float64).ravel()
    height, width = stack.shape[1:]
    map_x, map_y = cv2.initUndistortRectifyMap(matrix, dist, None, matrix, (width, height), cv2.CV_32FC1)
    work = stack if stack.dtype in (np.uint8, np.uint16, np.float32) else stack.astype(np.float32)
    out = np.stack([cv2.remap(frame, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT) for frame in work])
    return out[0] if single else out


def undistort_points(pixels: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Normalised, undistorted image coordinates (N, 2) of pixel positions (N, 2) (OpenCV centres)."""
    pts = np.asarray(pixels, dtype=np.float64).reshape(-1, 1, 2)
    return cv2.undistortPoints(
        pts, np.asarray(camera_matrix, np.float64).reshape(3, 3), np.asarray(distortion, np.float64).ravel(),
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-10),
    ).reshape(-1, 2)


def undistort_map(values: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """A smooth per-pixel map (e.g. absolute phase, NaN invalid) resampled as the undistorted frames
    would give it (same remap as :func:`undistort_stack`; NaN spreads to the neighbours it touches)."""
    data = np.asarray(values, dtype=np.float32)
    if data.ndim != 2:
        raise CalibrationError(f"map: expected (H, W), found shape {data.shape}")
    return undistort_stack(data, camera_matrix, distortion).astype(np.float64)


def undistort_pixels(pixels: np.ndarray, camera_matrix: np.ndarray, distortion: np.ndarray) -> np.ndarray:
    """Pixel positions (N, 2) where they land in the undistorted image (same camera matrix)."""
    matrix = np.asarray(camera_matrix, np.float64).reshape(3, 3)
    normalized = undistort_points(pixels, matrix, distortion)
    return normalized @ matrix[:2, :2].T + matrix[:2, 2]
