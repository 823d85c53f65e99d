"""Projector-camera ("stereo") model: triangulate camera rays with projector planes from absolute phase.

The projector is an inverse camera. A camera pixel's ray X = t (x, y, 1) (undistorted normalised
coordinates) meets the plane of projector points whose column is the one the absolute phase
names: with X_p = R X + T in the projector's frame (R, T: camera -> projector, mm) and that column's
normalised coordinate x_p, (R_0 - x_p R_2) . X + (T_0 - x_p T_2) = 0 gives t in closed form. For
horizontal fringes (axis "y") rows play the part of columns. The projector's lens distortion
depends on both coordinates, of which a phase gives one: the other is taken from the current
estimate of the point and the plane refined by a few fixed-point passes.

calibration.json keys (``"model": "stereo"``): ``camera_matrix``, ``distortion``,
``projector_matrix``, ``projector_distortion``, ``rotation`` (3x3), ``translation_mm`` (3),
``camera_size`` and ``projector_size`` ([width, height], pixels), optional ``plane`` ([nx, ny, nz,
d] in the camera frame: heights are n . X + d) and ``pixel_centre`` (0.5: projector pixel k spans
k .. k + 1 in the product's phase convention, OpenCV puts its centre at k).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from calibration.camera import detect_board
from calibration.errors import CalibrationError
from processing.phase_shift import phase_shift
from processing.temporal import unwrap_hierarchical

STEREO = "stereo"


def _matrix(data: Mapping[str, Any], key: str, shape: tuple[int, ...], where: str) -> np.ndarray:
    if key not in data:
        raise CalibrationError(f"{where}: {key}: missing (model 'stereo' needs it)")
    try:
        value = np.asarray(data[key], dtype=np.float64)
    except (TypeError, ValueError):
        raise CalibrationError(f"{where}: {key}: expected numbers, found {data[key]!r}") from None
    if value.size != int(np.prod(shape)) or not np.all(np.isfinite(value)):
        raise CalibrationError(
            f"{where}: {key}: expected {'x'.join(map(str, shape))} finite numbers, found {value.size}"
        )
    return value.reshape(shape)


def _distortion(data: Mapping[str, Any], key: str, where: str) -> np.ndarray:
    value = np.asarray(data.get(key, []), dtype=np.float64).ravel()
    if value.size not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(value)):
        raise CalibrationError(f"{where}: {key}: expected 0, 4, 5, 8, 12 or 14 OpenCV coefficients, found {value.size}")
    return value


@dataclass(frozen=True)
class StereoModel:
    """Camera and projector as a calibrated stereo pair: pinhole + distortion each, and the camera -> projector transform."""

    camera_matrix: np.ndarray
    camera_distortion: np.ndarray
    projector_matrix: np.ndarray
    projector_distortion: np.ndarray
    rotation: np.ndarray  # camera -> projector
    translation_mm: np.ndarray  # camera -> projector
    camera_size: tuple[int, int]  # (width, height)
    projector_size: tuple[int, int]
    plane: np.ndarray | None = None
    pixel_centre: float = 0.5

    @classmethod
    def from_fields(cls, data: Mapping[str, Any], where: str = "calibration.json") -> StereoModel:
        """Build and validate from calibration.json keys (see the module docstring)."""
        rotation = _matrix(data, "rotation", (3, 3), where)
        if not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-5) or np.linalg.det(rotation) < 0:
            raise CalibrationError(f"{where}: rotation: not a rotation matrix (R R^T != I or det < 0)")
        camera_matrix = _matrix(data, "camera_matrix", (3, 3), where)
        projector_matrix = _matrix(data, "projector_matrix", (3, 3), where)
        for key, m in (("camera_matrix", camera_matrix), ("projector_matrix", projector_matrix)):
            if not (m[0, 0] > 0 and m[1, 1] > 0 and np.allclose(m[2], [0, 0, 1])):
                raise CalibrationError(
                    f"{where}: {key}: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0"
                )
        camera_size = tuple(int(v) for v in _matrix(data, "camera_size", (2,), where))
        projector_size = tuple(int(v) for v in _matrix(data, "projector_size", (2,), where))
        if min(camera_size) < 1 or min(projector_size) < 1:
            raise CalibrationError(f"{where}: camera_size / projector_size: expected positive [width, height]")
        plane = _matrix(data, "plane", (4,), where) if data.get("plane") is not None else None
        if plane is not None:
            norm = np.linalg.norm(plane[:3])
            if norm == 0:
                raise CalibrationError(f"{where}: plane: the normal is zero")
            plane = plane / norm
        return cls(
            camera_matrix=camera_matrix,
            camera_distortion=_distortion(data, "distortion", where),
            projector_matrix=projector_matrix,
            projector_distortion=_distortion(data, "projector_distortion", where),
            rotation=rotation,
            translation_mm=_matrix(data, "translation_mm", (3,), where),
            camera_size=camera_size,  # type: ignore[arg-type]
            projector_size=projector_size,  # type: ignore[arg-type]
            plane=plane,
            pixel_centre=float(data.get("pixel_centre", 0.5)),
        )

    def as_fields(self) -> dict[str, Any]:
        out = {
            "camera_matrix": self.camera_matrix.tolist(),
            "distortion": self.camera_distortion.tolist(),
            "projector_matrix": self.projector_matrix.tolist(),
            "projector_distortion": self.projector_distortion.tolist(),
            "rotation": self.rotation.tolist(),
            "translation_mm": self.translation_mm.tolist(),
            "camera_size": list(self.camera_size),
            "projector_size": list(self.projector_size),
            "pixel_centre": self.pixel_centre,
        }
        if self.plane is not None:
            out["plane"] = self.plane.tolist()
        return out

    @property
    def baseline_mm(self) -> float:
        return float(np.linalg.norm(self.translation_mm))

    def camera_rays(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Undistorted normalised ray directions (N, 3) with z = 1 of camera pixels (rows, cols)."""
        pts = np.stack([cols.astype(np.float64), rows.astype(np.float64)], axis=1).reshape(-1, 1, 2)
        if pts.shape[0] == 0:
            return np.empty((0, 3))
        normalized = cv2.undistortPoints(
            pts,
            self.camera_matrix,
            self.camera_distortion,
            criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 1e-10),
        ).reshape(-1, 2)
        return np.column_stack([normalized, np.ones(len(normalized))])

    def heights(self, points: np.ndarray) -> np.ndarray:
        """Height map (H, W) of triangulated points: distance above ``plane`` if set, else depth Z."""
        if self.plane is None:
            return points[..., 2].copy()
        return points @ self.plane[:3] + self.plane[3]


def _distort_normalised(x: np.ndarray, y: np.ndarray, distortion: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's lens model applied to normalised coordinates (any distortion length)."""
    if distortion.size == 0 or not np.any(distortion):
        return x, y
    pts = np.stack([x.ravel(), y.ravel(), np.ones(x.size)], axis=1).reshape(-1, 1, 3)
    out, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), np.eye(3), distortion)
    out = out.reshape(-1, 2)
    return out[:, 0].reshape(x.shape), out[:, 1].reshape(x.shape)


def projector_coordinate(
    absolute_phase: np.ndarray, frequency: float, extent: float, pixel_centre: float = 0.5
) -> np.ndarray:
    """Projector pixel coordinate (OpenCV convention) named by the absolute phase 2 pi f u / W."""
    if not frequency > 0:
        raise CalibrationError(f"frequency: expected > 0, found {frequency}")
    return np.asarray(absolute_phase, dtype=np.float64) * extent / (2.0 * np.pi * frequency) - pixel_centre


def triangulate(
    model: StereoModel,
    absolute_phase: np.ndarray,
    frequency: float,
    axis: str = "x",
    mask: np.ndarray | None = None,
    extent: float | None = None,
    iterations: int = 4,
) -> np.ndarray:
    """3-D points (H, W, 3) in the camera frame (mm) of every pixel; NaN where invalid.

    Parameters
    ----------
    model : StereoModel
    absolute_phase : (H, W) array
        2 pi f u / W for vertical fringes (``axis="x"``), the same in rows for ``"y"``.
    frequency : float
        Fringes across the projector of the phase given.
    extent : float, optional
        Pattern extent along the axis in projector pixels (default the projector's width/height).
    iterations : int
        Fixed-point passes for the projector's distortion (0 ignores it).
    """
    phase = np.asarray(absolute_phase, dtype=np.float64)
    if phase.ndim != 2:
        raise CalibrationError(f"absolute phase: expected a 2-D map, found shape {phase.shape}")
    if axis not in ("x", "y"):
        raise CalibrationError(f"axis: expected 'x' or 'y', found {axis!r}")
    expected = (model.camera_size[1], model.camera_size[0])
    if phase.shape != expected:
        raise CalibrationError(
            f"absolute phase: shape {phase.shape} does not match the calibrated camera {expected[1]}x{expected[0]}"
        )
    index = 0 if axis == "x" else 1
    if extent is None:
        extent = float(model.projector_size[index])
    coordinate = projector_coordinate(phase, frequency, extent, model.pixel_centre)
    k = model.projector_matrix
    valid = np.isfinite(phase)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    rows, cols = np.nonzero(valid)
    measured = coordinate[rows, cols]
    rays = model.camera_rays(rows, cols)
    r, t = model.rotation, model.translation_mm

    def intersect(target: np.ndarray) -> np.ndarray:
        normal = r[index][None, :] - target[:, None] * r[2][None, :]
        offset = t[index] - target * t[2]
        denominator = np.einsum("nk,nk->n", normal, rays)
        with np.errstate(divide="ignore", invalid="ignore"):
            scale = -offset / denominator
        return rays * scale[:, None]

    # first guess: no distortion, no skew (the loop below corrects both)
    target = (measured - k[0, 2]) / k[0, 0] if index == 0 else (measured - k[1, 2]) / k[1, 1]
    points = intersect(target)
    skewed = index == 0 and k[0, 1] != 0
    if np.any(model.projector_distortion) or skewed:
        for _ in range(max(iterations, 2 if skewed else 0)):
            projected = points @ r.T + t
            with np.errstate(divide="ignore", invalid="ignore"):
                xn = projected[:, 0] / projected[:, 2]
                yn = projected[:, 1] / projected[:, 2]
            ok = np.isfinite(xn) & np.isfinite(yn)
            xn, yn = np.where(ok, xn, 0.0), np.where(ok, yn, 0.0)
            xd, yd = _distort_normalised(xn, yn, model.projector_distortion)
            if index == 0:
                pixel, scale, current = k[0, 0] * xd + k[0, 1] * yd + k[0, 2], k[0, 0], xn
            else:
                pixel, scale, current = k[1, 1] * yd + k[1, 2], k[1, 1], yn
            # move the undistorted coordinate by the pixel misfit (d pixel / d undistorted ~ focal)
            target = np.where(ok, current + (measured - pixel) / scale, target)
            points = intersect(target)
    good = (points[:, 2] > 0) & np.all(np.isfinite(points), axis=1)
    out = np.full((*phase.shape, 3), np.nan)
    out[rows[good], cols[good]] = points[good]
    return out


def fit_plane(points: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Least-squares plane [nx, ny, nz, d] (unit normal) through points (..., 3), oriented so that
    the camera (the origin) is on its positive side: heights n . X + d are positive towards it."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    keep = np.all(np.isfinite(pts), axis=1)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool).ravel()
    pts = pts[keep]
    if len(pts) < 3:
        raise CalibrationError(f"plane: {len(pts)} valid points, need at least 3")
    centre = pts.mean(axis=0)
    _, singular, vt = np.linalg.svd(pts - centre, full_matrices=False)
    if singular[1] < 1e-9 * max(singular[0], 1e-300):
        raise CalibrationError("plane: the points lie on a line, the plane is undetermined")
    normal = vt[2]
    d = -float(normal @ centre)
    if d < 0:
        normal, d = -normal, -d
    return np.concatenate([normal, [d]])


@dataclass(frozen=True)
class BoardPhaseView:
    """One pose of a calibration board seen by the camera, with the projector's absolute phases.

    ``image_points`` (N, 2) camera pixels of the board corners, ``object_points`` (N, 3) their board
    coordinates (mm), ``phase_x`` / ``phase_y`` (H, W) absolute phase of vertical / horizontal
    fringes (NaN invalid) at ``frequency_x`` / ``frequency_y``.
    """

    image_points: np.ndarray
    object_points: np.ndarray
    phase_x: np.ndarray
    phase_y: np.ndarray
    frequency_x: float
    frequency_y: float


def projector_corners(
    view: BoardPhaseView,
    projector_size: tuple[int, int],
    window_px: int = 7,
    pixel_centre: float = 0.5,
    min_pixels: int = 12,
) -> tuple[np.ndarray, np.ndarray]:
    """Projector pixel coordinates (OpenCV convention) of a view's corners, and which were found.

    The phases of the pixels around each corner (a square of half-width ``window_px``) give a
    local homography camera -> projector (the board is flat), evaluated at the sub-pixel corner:
    less noise than one pixel's phase, no bias from the corner's own dark/bright junction.
    """
    width, height = projector_size
    u = projector_coordinate(view.phase_x, view.frequency_x, width, pixel_centre)
    v = projector_coordinate(view.phase_y, view.frequency_y, height, pixel_centre)
    valid = np.isfinite(u) & np.isfinite(v)
    rows, cols = u.shape
    out = np.full((len(view.image_points), 2), np.nan)
    for index, (x, y) in enumerate(view.image_points):
        x0, x1 = int(max(round(x) - window_px, 0)), int(min(round(x) + window_px + 1, cols))
        y0, y1 = int(max(round(y) - window_px, 0)), int(min(round(y) + window_px + 1, rows))
        keep = valid[y0:y1, x0:x1]
        if keep.sum() < min_pixels:
            continue
        gy, gx = np.nonzero(keep)
        source = np.column_stack([gx + x0, gy + y0]).astype(np.float64)
        target = np.column_stack([u[y0:y1, x0:x1][keep], v[y0:y1, x0:x1][keep]])
        homography, _ = cv2.findHomography(source - (x, y), target, 0)
        if homography is None:
            continue
        out[index] = homography[:2, 2] / homography[2, 2]
    return out, np.all(np.isfinite(out), axis=1)


@dataclass(frozen=True)
class StereoCalibration:
    """Result of :func:`calibrate_stereo`: the model and its reprojection errors."""

    model: StereoModel
    rms_px: float  # stereoCalibrate's RMS reprojection error (camera and projector)
    camera_rms_px: float
    projector_rms_px: float
    views_used: int


def calibrate_stereo(
    views: Sequence[BoardPhaseView],
    camera_size: tuple[int, int],
    projector_size: tuple[int, int],
    pixel_centre: float = 0.5,
    flags: int = 0,
    min_views: int = 3,
) -> StereoCalibration:
    """Camera and projector intrinsics, distortion and pose from board views with phase maps.

    The projector "sees" each corner at the coordinates the phases name (:func:`projector_corners`);
    both devices are calibrated on their own (``cv2.calibrateCamera``), then jointly
    (``cv2.stereoCalibrate`` with those intrinsics as the starting guess).
    """
    if len(views) < min_views:
        raise CalibrationError(f"stereo calibration: {len(views)} board views, need at least {min_views}")
    object_points, camera_points, projector_points = [], [], []
    for index, view in enumerate(views):
        expected = (camera_size[1], camera_size[0])
        if view.phase_x.shape != expected or view.phase_y.shape != expected:
            raise CalibrationError(
                f"stereo view {index}: phase maps {view.phase_x.shape} do not match the camera {expected}"
            )
        corners, found = projector_corners(view, projector_size, pixel_centre=pixel_centre)
        if found.sum() < 6:
            raise CalibrationError(
                f"stereo view {index}: only {int(found.sum())} corners have a projector coordinate (is the board lit by the fringes?)"
            )
        object_points.append(view.object_points[found].astype(np.float32).reshape(-1, 1, 3))
        camera_points.append(view.image_points[found].astype(np.float32).reshape(-1, 1, 2))
        projector_points.append(corners[found].astype(np.float32).reshape(-1, 1, 2))
    cam_rms, cam_matrix, cam_dist, _, _ = cv2.calibrateCamera(
        object_points, camera_points, tuple(camera_size), None, None, flags=flags
    )
    proj_rms, proj_matrix, proj_dist, _, _ = cv2.calibrateCamera(
        object_points, projector_points, tuple(projector_size), None, None, flags=flags
    )
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    rms, cam_matrix, cam_dist, proj_matrix, proj_dist, rotation, translation, _, _ = cv2.stereoCalibrate(
        object_points,
        camera_points,
        projector_points,
        cam_matrix,
        cam_dist,
        proj_matrix,
        proj_dist,
        tuple(camera_size),
        criteria=criteria,
        flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS,
    )
    model = StereoModel(
        camera_matrix=np.asarray(cam_matrix, float),
        camera_distortion=np.asarray(cam_dist, float).ravel(),
        projector_matrix=np.asarray(proj_matrix, float),
        projector_distortion=np.asarray(proj_dist, float).ravel(),
        rotation=np.asarray(rotation, float),
        translation_mm=np.asarray(translation, float).ravel(),
        camera_size=(int(camera_size[0]), int(camera_size[1])),
        projector_size=tuple(int(v) for v in projector_size),  # type: ignore[arg-type]
        pixel_centre=pixel_centre,
    )
    return StereoCalibration(model, float(rms), float(cam_rms), float(proj_rms), len(views))


def hierarchical_phase(
    frames: np.ndarray, frequencies: Sequence[int], steps: int, min_modulation_ratio: float = 0.15
) -> np.ndarray:
    """Absolute phase at the last frequency from ``steps``-step stacks at ``frequencies`` (1 first),
    NaN where the fringe modulation is below ``min_modulation_ratio`` of its 99th percentile."""

    stack = np.asarray(frames)
    if stack.ndim != 3 or stack.shape[0] != steps * len(frequencies):
        raise CalibrationError(f"board fringes: expected {steps * len(frequencies)} frames, found shape {stack.shape}")
    results = [phase_shift(stack[i * steps : (i + 1) * steps]) for i in range(len(frequencies))]
    unwrapped = unwrap_hierarchical([r.phase for r in results], list(frequencies))
    modulation = results[-1].modulation
    lit = modulation > min_modulation_ratio * np.percentile(modulation, 99)
    return np.where(unwrapped.valid & lit, unwrapped.phase, np.nan)


def board_phase_view(
    board_image: np.ndarray,
    board: Any,
    frames_x: np.ndarray,
    frames_y: np.ndarray,
    frequencies: Sequence[int],
    steps: int,
) -> BoardPhaseView | None:
    """A :class:`BoardPhaseView` from a board image and vertical / horizontal fringe stacks on it
    (hierarchical frequencies, 1 first); None when the board is not found in the image."""

    found = detect_board(board_image, board)
    if found is None:
        return None
    frequency = float(frequencies[-1])
    return BoardPhaseView(
        found.image_points,
        found.object_points,
        hierarchical_phase(frames_x, frequencies, steps),
        hierarchical_phase(frames_y, frequencies, steps),
        frequency,
        frequency,
    )
