"""Synthetic views of calibration targets (chessboard, ChArUco) through a known pinhole camera.

A board is a flat texture in its own plane (z = 0, millimetres, origin at the board's top-left
corner, the same frame as OpenCV's ``CharucoBoard.getChessboardCorners``). Every camera pixel is
undistorted (``cv2.undistortPoints``), its ray intersected with the board plane through the
pose's homography, and the texture sampled there (``cv2.remap``). What the camera sees therefore
carries the camera's true intrinsics and distortion, which calibration must recover.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

ARUCO_DICTIONARY = "DICT_5X5_100"


@dataclass(frozen=True)
class PinholeCamera:
    """Camera intrinsics (OpenCV convention: pixel centres at integers) and distortion."""

    camera_matrix: np.ndarray
    distortion: np.ndarray
    width: int
    height: int

    @classmethod
    def simple(cls, width: int, height: int, focal_px: float, distortion=(0.0, 0.0, 0.0, 0.0, 0.0)) -> PinholeCamera:
        matrix = np.array([[focal_px, 0, (width - 1) / 2.0], [0, focal_px, (height - 1) / 2.0], [0, 0, 1]], float)
        return cls(matrix, np.asarray(distortion, float), width, height)


def chessboard_texture(squares: tuple[int, int], square_mm: float, px_per_mm: float, margin_mm: float) -> np.ndarray:
    """Chessboard of ``squares`` = (columns, rows) squares with a white margin, float image in [0, 1]."""
    cols, rows = squares
    width = int(round((cols * square_mm + 2 * margin_mm) * px_per_mm))
    height = int(round((rows * square_mm + 2 * margin_mm) * px_per_mm))
    x = (np.arange(width) + 0.5) / px_per_mm - margin_mm
    y = (np.arange(height) + 0.5) / px_per_mm - margin_mm
    ix = np.floor(x / square_mm)[None, :]
    iy = np.floor(y / square_mm)[:, None]
    inside = (ix >= 0) & (ix < cols) & (iy >= 0) & (iy < rows)
    black = ((ix + iy) % 2 == 0) & inside
    return np.where(black, 0.0, 1.0)


def charuco_texture(
    squares: tuple[int, int],
    square_mm: float,
    marker_mm: float,
    px_per_mm: float,
    margin_mm: float,
    dictionary: str = ARUCO_DICTIONARY,
) -> np.ndarray:
    """ChArUco board image (OpenCV's own ``generateImage``) with a white margin, float in [0, 1]."""
    board = cv2.aruco.CharucoBoard(
        tuple(squares), square_mm, marker_mm, cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary))
    )
    size = (int(round(squares[0] * square_mm * px_per_mm)), int(round(squares[1] * square_mm * px_per_mm)))
    image = board.generateImage(size, marginSize=0, borderBits=1).astype(np.float64) / 255.0
    pad = int(round(margin_mm * px_per_mm))
    return np.pad(image, pad, constant_values=1.0)


def render_board_view(
    texture: np.ndarray,
    px_per_mm: float,
    margin_mm: float,
    camera: PinholeCamera,
    rvec: np.ndarray,
    tvec: np.ndarray,
    background: float = 0.35,
    gain: float = 200.0,
    offset: float = 20.0,
    blur_px: float = 0.7,
    noise_dn: float = 1.0,
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """8-bit camera image of a board texture at pose (rvec, tvec) (board frame -> camera frame)."""
    rng = np.random.default_rng(0) if rng is None else rng
    xs, ys = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    pixels = np.stack([xs.ravel(), ys.ravel()], axis=1).reshape(-1, 1, 2)
    normalized = cv2.undistortPoints(
        pixels,
        camera.camera_matrix,
        camera.distortion,
        criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 40, 1e-10),
    ).reshape(-1, 2)
    rotation, _ = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64))
    homography = np.column_stack((rotation[:, 0], rotation[:, 1], np.asarray(tvec, dtype=np.float64).ravel()))
    board = np.linalg.solve(homography, np.column_stack((normalized, np.ones(len(normalized)))).T)
    facing = board[2] > 0
    bx = board[0] / board[2]
    by = board[1] / board[2]
    map_x = ((bx + margin_mm) * px_per_mm - 0.5).reshape(camera.height, camera.width).astype(np.float32)
    map_y = ((by + margin_mm) * px_per_mm - 0.5).reshape(camera.height, camera.width).astype(np.float32)
    # prefilter the texture to the footprint of one camera pixel (point sampling would alias the
    # edges onto the pixel grid and bias the corners)
    footprint_mm = float(np.linalg.norm(np.asarray(tvec, dtype=np.float64))) / float(camera.camera_matrix[0, 0])
    sigma = 0.5 * footprint_mm * px_per_mm
    source = texture.astype(np.float32)
    if sigma > 0.3:
        source = cv2.GaussianBlur(source, (0, 0), sigma)
    seen = cv2.remap(source, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    seen = np.where((seen < 0) | ~facing.reshape(seen.shape), background, seen)
    if blur_px > 0:
        seen = cv2.GaussianBlur(seen, (0, 0), blur_px)
    image = offset + gain * seen + rng.normal(0.0, noise_dn, seen.shape)
    return np.clip(np.rint(image), 0, 255).astype(np.uint8)


def board_pose(
    tilt_x_deg: float,
    tilt_y_deg: float,
    spin_deg: float,
    center_mm: tuple[float, float, float],
    board_size_mm: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray]:
    """Pose (rvec, tvec) placing the board's centre at ``center_mm`` in the camera frame, tilted."""
    rx, _ = cv2.Rodrigues(np.array([np.radians(tilt_x_deg), 0.0, 0.0]))
    ry, _ = cv2.Rodrigues(np.array([0.0, np.radians(tilt_y_deg), 0.0]))
    rz, _ = cv2.Rodrigues(np.array([0.0, 0.0, np.radians(spin_deg)]))
    rotation = rx @ ry @ rz
    half = np.array([board_size_mm[0] / 2.0, board_size_mm[1] / 2.0, 0.0])
    tvec = np.asarray(center_mm, dtype=np.float64) - rotation @ half
    rvec, _ = cv2.Rodrigues(rotation)
    return rvec.ravel(), tvec


def calibration_views(
    camera: PinholeCamera,
    kind: str,
    squares: tuple[int, int],
    square_mm: float,
    marker_mm: float | None = None,
    count: int = 8,
    distance_mm: float = 400.0,
    seed: int = 0,
) -> tuple[list[np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    """``count`` views of a board at varied tilts, filling most of the image; returns (images, poses)."""
    rng = np.random.default_rng(seed)
    margin = square_mm
    board_mm = (squares[0] * square_mm, squares[1] * square_mm)
    focal = float(camera.camera_matrix[0, 0])
    view_mm = camera.width * distance_mm / focal
    px_per_mm = max(2.0, 2.0 * camera.width / view_mm)
    if kind == "chessboard":
        texture = chessboard_texture(squares, square_mm, px_per_mm, margin)
    elif kind == "charuco":
        texture = charuco_texture(squares, square_mm, marker_mm if marker_mm else 0.7 * square_mm, px_per_mm, margin)
    else:
        raise ValueError(f"kind: expected 'chessboard' or 'charuco', found {kind!r}")
    images, poses = [], []
    for _ in range(count):
        tilt_x = rng.uniform(-25, 25)
        tilt_y = rng.uniform(-25, 25)
        spin = rng.uniform(-10, 10)
        shift = rng.uniform(-0.12, 0.12, size=2) * view_mm
        rvec, tvec = board_pose(
            tilt_x, tilt_y, spin, (shift[0], shift[1] * 0.75, distance_mm * rng.uniform(0.9, 1.1)), board_mm
        )
        images.append(render_board_view(texture, px_per_mm, margin, camera, rvec, tvec, rng=rng))
        poses.append((rvec, tvec))
    return images, poses
