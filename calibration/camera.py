"""Camera intrinsics and lens distortion from views of a chessboard or ChArUco board (OpenCV).

:func:`calibrate_camera` finds the board in every view, runs ``cv2.calibrateCamera`` and reports
the RMS reprojection error overall and per view. Only corners the projector lights are trusted: a
board view is taken under the projector's white (and its black, the room light alone); where the
projector's footprint ends, the board sits at the ambient level and the corners there are biased
or wrongly matched, so :func:`lit_corners` leaves them out. :func:`undistort_stack` applies a
calibration to captured frames. Coordinates follow OpenCV: pixel centres at integers, distortion in OpenCV's
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
#: Fewest lit corners for a view (or the board on the plane) to be used.
MIN_CORNERS = 8
#: Share of the board's bright level (white minus dark) from which the projector counts as lighting a pixel.
LIT_FRACTION = 0.25
#: A corner is trusted this many squares (its four squares and the refinement window) away from unlit pixels.
LIT_MARGIN_SQUARES = 1.0
#: Corners whose reprojection residual exceeds this many times the median residual (and OUTLIER_FLOOR_PX)
#: are refitted without: a corner snapped to a wrong edge must not bend the lens model.
OUTLIER_FACTOR = 5.0
OUTLIER_FLOOR_PX = 0.25


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

    def charuco_board(self) -> cv2.aruco.CharucoBoard:
        """The OpenCV ChArUco board of this spec (markers 0.7 of a square unless ``marker_mm`` is given)."""
        dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, self.dictionary))
        return cv2.aruco.CharucoBoard(
            tuple(self.squares), self.square_mm, self.marker_mm or 0.7 * self.square_mm, dictionary
        )


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
    image_size: tuple[int, int]  # (width, height)
    rms_px: float  # RMS reprojection error over every corner
    per_view_rms_px: tuple[float, ...]
    views_used: tuple[int, ...]  # indices of the views in which the board was found
    rvecs: tuple[np.ndarray, ...] = ()
    tvecs: tuple[np.ndarray, ...] = ()
    distortion_std: np.ndarray | None = None  # 1-sigma of the distortion coefficients (first fit)
    distortion_significant: bool = True  # False: no coefficient stood out of its noise, all set to 0
    notes: tuple[str, ...] = ()  # views skipped, corners left out (unlit, outliers)

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
            gray,
            corners.astype(np.float32),
            (half, half),
            (-1, -1),
            (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-6),
        )
        return BoardDetection(corners.reshape(-1, 2).astype(np.float64), board.object_points())
    charuco = board.charuco_board()
    corners, ids, _, _ = cv2.aruco.CharucoDetector(charuco).detectBoard(gray)
    if ids is None or len(ids) < 6:
        return None
    object_points, image_points = charuco.matchImagePoints(corners, ids)
    return BoardDetection(
        image_points.reshape(-1, 2).astype(np.float64), object_points.reshape(-1, 3).astype(np.float32)
    )


def projector_lit(white: np.ndarray, dark: np.ndarray | None, square_px: float) -> np.ndarray:
    """Pixels of a board view the projector lights (bool), from the view under its white and its black.

    ``white - dark`` is the projector's share of the light (``dark`` None: the white frame alone,
    room light taken as weak); it is high on the board's white squares and the lit table, near 0
    on unlit pixels and on black squares. Pixels above :data:`LIT_FRACTION` of the bright level
    count as lit, and a closing a little wider than a square's diagonal fills the black squares
    inside the lit area.
    """
    signal = np.asarray(white, dtype=np.float32)
    if dark is not None:
        signal = signal - np.asarray(dark, dtype=np.float32)
    bright = float(np.percentile(signal, 99))
    lit = (signal > LIT_FRACTION * bright).astype(np.uint8) if bright > 0 else np.zeros(signal.shape, np.uint8)
    size = max(3, int(np.ceil(1.6 * square_px)) | 1)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (size, size))
    return cv2.morphologyEx(lit, cv2.MORPH_CLOSE, kernel, borderType=cv2.BORDER_REPLICATE).astype(bool)


def lit_corners(found: BoardDetection, white: np.ndarray, dark: np.ndarray | None = None) -> np.ndarray:
    """Which corners of ``found`` (bool, N) lie at least :data:`LIT_MARGIN_SQUARES` inside the lit area.

    A corner next to the end of the projector's footprint is found on the illumination step or
    matched to the wrong square; one whose squares are all lit is located as well as anywhere.
    """
    points = found.image_points
    spacing = _corner_spacing(points)
    lit = projector_lit(white, dark, spacing)
    distance = cv2.distanceTransform(lit.astype(np.uint8), cv2.DIST_L2, 5)
    cols = np.clip(np.rint(points[:, 0]).astype(int), 0, lit.shape[1] - 1)
    rows = np.clip(np.rint(points[:, 1]).astype(int), 0, lit.shape[0] - 1)
    return distance[rows, cols] >= LIT_MARGIN_SQUARES * spacing


def _corner_spacing(points: np.ndarray) -> float:
    """Typical distance (px) between a corner and its nearest neighbour."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    gaps = np.linalg.norm(pts[:, None, :] - pts[None, :, :], axis=2)
    np.fill_diagonal(gaps, np.inf)
    return float(np.median(gaps.min(axis=1)))


def _reprojection_errors(
    object_points: list[np.ndarray],
    image_points: list[np.ndarray],
    rvecs: Sequence[np.ndarray],
    tvecs: Sequence[np.ndarray],
    matrix: np.ndarray,
    distortion: np.ndarray,
) -> list[np.ndarray]:
    """Per view, every corner's reprojection error (px)."""
    errors = []
    for obj, img, rvec, tvec in zip(object_points, image_points, rvecs, tvecs):
        projected, _ = cv2.projectPoints(obj, rvec, tvec, matrix, distortion)
        errors.append(np.linalg.norm((projected - img).reshape(-1, 2), axis=1))
    return errors


def calibrate_camera(
    views: Sequence[np.ndarray],
    board: BoardSpec,
    flags: int = 0,
    min_views: int = MIN_VIEWS,
    significance: float | None = 2.0,
    darks: Sequence[np.ndarray | None] | None = None,
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
    darks : sequence of (H, W) images or None, optional
        Each view under the projector's black (room light only), or None for a view without one.
        When given, only corners the projector lights are used (:func:`lit_corners`); a view
        with fewer than :data:`MIN_CORNERS` of them is skipped. Either way, corners whose
        reprojection error stands out (:data:`OUTLIER_FACTOR`) are left out and the fit repeated.
    """
    if not views:
        raise CalibrationError("camera views: none given")
    shape = np.asarray(views[0]).shape
    if darks is not None and len(darks) != len(views):
        raise CalibrationError(f"camera views: {len(views)} views but {len(darks)} dark frames")
    detections, used, notes = _detect_views(views, board, darks)
    if len(detections) < min_views:
        raise CalibrationError(
            f"camera views: the {board.kind} was found in {len(detections)} of {len(views)} views, need at least {min_views}"
        )
    size = (int(shape[1]), int(shape[0]))
    fit = _fit_without_outliers(detections, size, flags, min_views, len(views))
    notes.extend(_outlier_notes(fit, used))
    used = [used[i] for i in fit.views_in]
    distortion_std = np.asarray(fit.std_intrinsics, dtype=np.float64).ravel()[4 : 4 + np.asarray(fit.distortion).size]
    significant = True
    if significance is not None:
        free = distortion_std > 0  # fixed coefficients have no deviation
        coefficients = np.asarray(fit.distortion, dtype=np.float64).ravel()
        significant = bool(np.any(np.abs(coefficients[free]) > significance * distortion_std[free]))
        if not significant:
            _refit_without_distortion(fit, size, flags)
    per_view = [
        float(np.sqrt(np.mean(e**2)))
        for e in _reprojection_errors(
            fit.object_points, fit.image_points, fit.rvecs, fit.tvecs, fit.matrix, fit.distortion
        )
    ]
    log.info("camera calibration: %d views, RMS reprojection error %.3f px", len(detections), fit.rms)
    return CameraCalibration(
        camera_matrix=np.asarray(fit.matrix, dtype=np.float64),
        distortion=np.asarray(fit.distortion, dtype=np.float64).ravel(),
        image_size=size,
        rms_px=float(fit.rms),
        per_view_rms_px=tuple(per_view),
        views_used=tuple(used),
        rvecs=tuple(np.asarray(r).ravel() for r in fit.rvecs),
        tvecs=tuple(np.asarray(t).ravel() for t in fit.tvecs),
        distortion_std=distortion_std,
        distortion_significant=significant,
        notes=tuple(notes),
    )


def _detect_views(
    views: Sequence[np.ndarray], board: BoardSpec, darks: Sequence[np.ndarray | None] | None
) -> tuple[list[BoardDetection], list[int], list[str]]:
    """The board found in each view (its lit corners only, when ``darks`` are given): the
    detections, the indices of the views they come from, and notes on the views skipped."""
    shape = np.asarray(views[0]).shape
    detections, used, notes = [], [], []
    for index, view in enumerate(views):
        if np.asarray(view).shape != shape:
            raise CalibrationError(f"camera view {index}: size {np.asarray(view).shape} differs from view 0 {shape}")
        found = detect_board(view, board, name=f"camera view {index}")
        if found is None:
            log.warning("camera view %d: %s not found, skipped", index, board.kind)
            notes.append(f"view {index}: {board.kind} not found, skipped")
            continue
        if darks is not None:
            found = _lit_part(found, view, darks[index], index, notes)
            if found is None:
                continue
        detections.append(found)
        used.append(index)
    return detections, used, notes


def _lit_part(
    found: BoardDetection, view: np.ndarray, dark: np.ndarray | None, index: int, notes: list[str]
) -> BoardDetection | None:
    """The corners of ``found`` the projector lights (None when fewer than MIN_CORNERS), noted."""
    keep = lit_corners(found, view, dark)
    if keep.sum() < MIN_CORNERS:
        notes.append(
            f"view {index}: {int(keep.sum())} of {keep.size} corners lit by the projector (need {MIN_CORNERS}), skipped"
        )
        return None
    if not keep.all():
        notes.append(
            f"view {index}: {int((~keep).sum())} of {keep.size} corners near or beyond the "
            "projector's footprint left out"
        )
        found = BoardDetection(found.image_points[keep], found.object_points[keep])
    return found


@dataclass
class _RobustFit:
    """The last ``cv2.calibrateCameraExtended`` fit of :func:`_fit_without_outliers`, on the corners
    it kept (``inliers`` per detection, ``views_in`` the detections with enough of them)."""

    inliers: list[np.ndarray]
    views_in: list[int]
    limit: float
    object_points: list[np.ndarray]
    image_points: list[np.ndarray]
    rms: float
    matrix: np.ndarray
    distortion: np.ndarray
    rvecs: Sequence[np.ndarray]
    tvecs: Sequence[np.ndarray]
    std_intrinsics: np.ndarray


def _fit_without_outliers(
    detections: list[BoardDetection], size: tuple[int, int], flags: int, min_views: int, total_views: int
) -> _RobustFit:
    """Fit, then keep the corners within OUTLIER_FACTOR of the median residual under that fit, and
    refit until the set settles (at most 4 fits).

    A corner snapped to a wrong edge pulls its neighbours' residuals up under the first fit, so
    corners are judged again (and taken back) under each new one.
    """
    all_objects = [d.object_points.astype(np.float32).reshape(-1, 1, 3) for d in detections]
    all_images = [d.image_points.astype(np.float32).reshape(-1, 1, 2) for d in detections]
    inliers = [np.ones(len(obj), bool) for obj in all_objects]
    for _ in range(4):
        enough = [int(keep.sum()) >= MIN_CORNERS for keep in inliers]
        views_in = [i for i, ok in enumerate(enough) if ok]
        if len(views_in) < min_views:
            raise CalibrationError(
                f"camera views: {len(views_in)} of {total_views} views fit one lens model, need at least {min_views}"
            )
        object_points = [all_objects[i][inliers[i]] for i in views_in]
        image_points = [all_images[i][inliers[i]] for i in views_in]
        rms, matrix, distortion, rvecs, tvecs, std_intrinsics, _, _ = cv2.calibrateCameraExtended(
            object_points, image_points, size, None, None, flags=flags
        )
        errors = _reprojection_errors(
            [all_objects[i] for i in views_in], [all_images[i] for i in views_in], rvecs, tvecs, matrix, distortion
        )
        limit = max(
            OUTLIER_FACTOR * float(np.median(np.concatenate([e[inliers[i]] for i, e in zip(views_in, errors)]))),
            OUTLIER_FLOOR_PX,
        )
        settled = [e <= limit for e in errors]
        if all(np.array_equal(new, inliers[i]) for i, new in zip(views_in, settled)):
            break
        inliers = [np.zeros(len(obj), bool) for obj in all_objects]
        for i, new in zip(views_in, settled):
            inliers[i] = new
    return _RobustFit(
        inliers, views_in, limit, object_points, image_points, rms, matrix, distortion, rvecs, tvecs, std_intrinsics
    )


def _outlier_notes(fit: _RobustFit, used: list[int]) -> list[str]:
    """Notes on the views and corners :func:`_fit_without_outliers` left out (``used``: view index per detection)."""
    notes = []
    for i, keep in enumerate(fit.inliers):
        if i not in fit.views_in:
            notes.append(f"view {used[i]}: fewer than {MIN_CORNERS} corners fit the lens model, skipped")
        elif not keep.all():
            off = int((~keep).sum())
            notes.append(
                f"view {used[i]}: {off} corner{'s' * (off != 1)} off the lens model by more than {fit.limit:.2f} px left out"
            )
    return notes


def _refit_without_distortion(fit: _RobustFit, size: tuple[int, int], flags: int) -> None:
    """Refit ``fit``'s corners with every distortion coefficient held at 0 (updates ``fit``)."""
    log.info("camera calibration: no distortion coefficient is significant; refitting without distortion")
    no_distortion = cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    fit.rms, fit.matrix, fit.distortion, fit.rvecs, fit.tvecs = cv2.calibrateCamera(
        fit.object_points, fit.image_points, size, None, np.zeros(5), flags=flags | no_distortion
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
        pts,
        np.asarray(camera_matrix, np.float64).reshape(3, 3),
        np.asarray(distortion, np.float64).ravel(),
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
