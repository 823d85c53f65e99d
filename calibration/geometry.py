"""l0, d0 and f0 of the reference-plane model (thesis eq. 1.15) from calibration measurements.

* f0 (cycles/mm on the reference plane) comes from the slope of the reference plane's absolute
  phase and the size of one camera pixel on the plane (:func:`fit_f0`), the pixel size from a
  target of known size (:func:`pixel_mm_from_corners`).
* l0 and d0 come from the plane moved to three or more known heights. Eq. 1.15 inverted,
  dPhi = -2 pi f0 d0 h / (l0 - h), makes 1 / dPhi linear in 1 / h:

      1 / dPhi = a / h + b,   b = 1 / (2 pi f0 d0),   a = -l0 b,

  a straight-line least-squares fit (:func:`fit_l0_d0`) with parameter uncertainties from its
  covariance and residuals in millimetres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from calibration.errors import CalibrationError

#: Fewest plane heights that give l0, d0 and a residual to judge them by.
MIN_HEIGHTS = 3


@dataclass(frozen=True)
class F0Fit:
    """Fringe frequency on the reference plane from its phase slope."""

    f0_per_mm: float
    f0_std_per_mm: float
    slope_rad_per_px: float
    residual_rms_rad: float


@dataclass(frozen=True)
class GeometryFit:
    """Result of :func:`fit_l0_d0`: parameters, 1-sigma uncertainties and per-height residuals."""

    l0_mm: float
    d0_mm: float
    f0_per_mm: float
    l0_std_mm: float
    d0_std_mm: float
    f0_std_per_mm: float
    heights_mm: tuple[float, ...]
    mean_delta_phase: tuple[float, ...]
    residuals_mm: tuple[float, ...]
    flatness_rms_mm: tuple[float, ...] = field(default=())

    @property
    def residual_rms_mm(self) -> float:
        return float(np.sqrt(np.mean(np.square(self.residuals_mm))))

    def as_fields(self) -> dict:
        """The calibration.json keys this fit determines (values plain floats/lists)."""
        return {
            "l0_mm": self.l0_mm,
            "d0_mm": self.d0_mm,
            "f0_per_mm": self.f0_per_mm,
            "heights_mm": list(self.heights_mm),
            "residuals_mm": list(self.residuals_mm),
            "uncertainty": {
                "l0_mm": self.l0_std_mm,
                "d0_mm": self.d0_std_mm,
                "f0_per_mm": self.f0_std_per_mm,
            },
            "plane_flatness_rms_mm": list(self.flatness_rms_mm),
        }


# Pixels this close to an invalid one (the edge of the projector's footprint, a shadow) are left out
# of the fits: partly lit pixels mix lit and unlit surface and their phase (or fringe order) is wrong.
EDGE_PX = 2


def _valid(values: np.ndarray, mask: np.ndarray | None, name: str, edge_px: int = 0) -> np.ndarray:
    keep = np.isfinite(values)
    if mask is not None:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != values.shape:
            raise CalibrationError(f"{name}: mask shape {mask.shape} differs from the phase map {values.shape}")
        keep &= mask
    if edge_px > 0 and not keep.all():
        from scipy import ndimage

        inner = ndimage.binary_erosion(keep, iterations=edge_px, border_value=1)
        if inner.any():
            keep = inner
    return keep


def lit_interior(phase: np.ndarray, edge_px: int = EDGE_PX) -> np.ndarray:
    """``phase`` with NaN within ``edge_px`` of an invalid pixel: the footprint's partly lit edge removed."""
    phase = np.asarray(phase, dtype=np.float64)
    keep = _valid(phase, None, "phase", edge_px)
    return np.where(keep, phase, np.nan)


def _trimmed_mean(values: np.ndarray) -> float:
    """Mean of the values within 5 scaled MADs of the median (medians of quantised phases are biased)."""
    median = np.median(values)
    mad = 1.4826 * np.median(np.abs(values - median))
    inliers = values[np.abs(values - median) <= 5.0 * mad] if mad > 0 else values
    return float(np.mean(inliers))


def _block_medians(values: np.ndarray, blocks: int = 8) -> np.ndarray:
    """Medians of a ``blocks`` x ``blocks`` grid of tiles (NaN ignored): a shape, not pixel noise."""
    values = np.atleast_2d(values)
    rows = max(values.shape[0] // blocks, 1)
    cols = max(values.shape[1] // blocks, 1)
    nr, nc = values.shape[0] // rows, values.shape[1] // cols
    tiles = values[: nr * rows, : nc * cols].reshape(nr, rows, nc, cols).transpose(0, 2, 1, 3).reshape(nr, nc, -1)
    keep = np.isfinite(tiles).sum(axis=2) > 0
    with np.errstate(all="ignore"):
        return np.nanmedian(tiles[keep], axis=1)


def fit_f0(
    reference_phase: np.ndarray,
    pixel_mm: float,
    mask: np.ndarray | None = None,
    min_pixels: int = 16,
) -> F0Fit:
    """Fringe frequency f0 on the reference plane from the slope of its absolute phase.

    A plane Phi = gx x + gy y + c is fitted to the valid pixels; the phase gradient
    |(gx, gy)| in rad/pixel over 2 pi pixel_mm is f0 in cycles/mm (camera looking straight down,
    square pixels of ``pixel_mm`` on the plane).

    Parameters
    ----------
    reference_phase : (H, W) array
        Absolute phase of the reference plane at the frequency f0 refers to.
    pixel_mm : float
        Size of one camera pixel on the plane (see :func:`pixel_mm_from_corners`).
    mask : (H, W) bool array, optional
        Pixels to use (default: every finite one); pixels within :data:`EDGE_PX` of an unusable
        one (a partly lit footprint edge) are left out, and so are outliers of a first fit
        (beyond 5 scaled MADs: wrong fringe orders).
    """
    phase = np.asarray(reference_phase, dtype=np.float64)
    if phase.ndim != 2:
        raise CalibrationError(f"reference phase: expected a 2-D map, found shape {phase.shape}")
    if not (np.isfinite(pixel_mm) and pixel_mm > 0):
        raise CalibrationError(f"pixel_mm: expected > 0, found {pixel_mm}")
    keep = _valid(phase, mask, "reference phase", EDGE_PX)
    count = int(keep.sum())
    if count < min_pixels:
        raise CalibrationError(f"reference phase: {count} valid pixels, need at least {min_pixels} to fit f0")
    rows, cols = np.nonzero(keep)
    design = np.column_stack((cols.astype(np.float64), rows.astype(np.float64), np.ones(count)))
    if np.linalg.matrix_rank(design) < 3:
        raise CalibrationError("reference phase: valid pixels lie on one line, the phase slope is undetermined")
    values = phase[rows, cols]
    coef, *_ = np.linalg.lstsq(design, values, rcond=None)
    residual = values - design @ coef
    # a few pixels with a wrong fringe order (2 pi k off) would tilt the plane: refit without them
    mad = 1.4826 * float(np.median(np.abs(residual - np.median(residual))))
    inliers = np.abs(residual) <= max(5.0 * mad, 1e-9)
    if 16 <= inliers.sum() < count:
        design, values, count = design[inliers], values[inliers], int(inliers.sum())
        coef, *_ = np.linalg.lstsq(design, values, rcond=None)
        residual = values - design @ coef
    dof = max(count - 3, 1)
    sigma2 = float(residual @ residual) / dof
    cov = sigma2 * np.linalg.inv(design.T @ design)
    gx, gy = float(coef[0]), float(coef[1])
    slope = math.hypot(gx, gy)
    if slope * max(phase.shape) < 1e-6:
        raise CalibrationError("reference phase: no phase slope across the view (is the projector on?)")
    slope_std = math.sqrt(max((gx * gx * cov[0, 0] + gy * gy * cov[1, 1] + 2 * gx * gy * cov[0, 1]) / slope**2, 0.0))
    scale = 1.0 / (2.0 * np.pi * pixel_mm)
    return F0Fit(
        f0_per_mm=slope * scale,
        f0_std_per_mm=slope_std * scale,
        slope_rad_per_px=slope,
        residual_rms_rad=float(np.sqrt(np.mean(residual**2))),
    )


def pixel_mm_from_corners(
    corners_px: np.ndarray, pattern_size: tuple[int, int], square_mm: float, keep: np.ndarray | None = None
) -> float:
    """Size of one camera pixel on the plane from the inner corners of a chessboard lying on it.

    Parameters
    ----------
    corners_px : (N, 2) or (N, 1, 2) array
        Inner corners in OpenCV's order (rows of ``pattern_size[0]`` corners).
    pattern_size : (columns, rows)
        Inner corners per row and per column, as given to ``cv2.findChessboardCorners``.
    square_mm : float
        Side of one square.
    keep : (N,) bool array, optional
        Corners to trust (e.g. those the projector lights); steps between two kept neighbours only.
    """
    cols, rows = (int(v) for v in pattern_size)
    corners = np.asarray(corners_px, dtype=np.float64).reshape(-1, 2)
    if corners.shape[0] != cols * rows:
        raise CalibrationError(
            f"chessboard: expected {cols * rows} corners for {cols}x{rows}, found {corners.shape[0]}"
        )
    if not square_mm > 0:
        raise CalibrationError(f"square_mm: expected > 0, found {square_mm}")
    if keep is not None:
        corners = np.where(np.asarray(keep, dtype=bool).reshape(-1, 1), corners, np.nan)
    grid = corners.reshape(rows, cols, 2)
    steps = np.concatenate(
        [np.linalg.norm(np.diff(grid, axis=1), axis=2).ravel(), np.linalg.norm(np.diff(grid, axis=0), axis=2).ravel()]
    )
    steps = steps[np.isfinite(steps)]
    if steps.size == 0 or not np.all(steps > 0):
        raise CalibrationError("chessboard: corners coincide, cannot measure the pixel size")
    return float(square_mm / np.mean(steps))


def fit_l0_d0(
    heights_mm: Sequence[float],
    delta_phases: Sequence[np.ndarray],
    f0_per_mm: float,
    masks: Sequence[np.ndarray | None] | None = None,
    f0_std_per_mm: float = 0.0,
    flatness_tolerance_mm: float | None = 1.0,
) -> GeometryFit:
    """l0 and d0 from the plane at known heights: least squares on 1/dPhi = a/h + b (eq. 1.15).

    Parameters
    ----------
    heights_mm : sequence of float
        Known plane heights above the reference plane (towards the camera positive), at least
        :data:`MIN_HEIGHTS` distinct non-zero values.
    delta_phases : sequence of (H, W) arrays
        Phi_plane - Phi_reference at the frequency f0 refers to, one map per height.
    f0_per_mm : float
        Fringe frequency on the reference plane (:func:`fit_f0`).
    masks : sequence of (H, W) bool arrays, optional
        Valid pixels per height.
    f0_std_per_mm : float
        Uncertainty of f0, propagated into d0's.
    flatness_tolerance_mm : float or None
        Largest RMS spread of a plane's height (with the fitted parameters; medians of an 8 x 8
        grid of tiles, so pixel noise does not count) before the plane is declared not flat or
        not level; None skips the check.

    Returns
    -------
    GeometryFit
    """
    heights = np.asarray(heights_mm, dtype=np.float64).ravel()
    _check_heights(heights, len(delta_phases), f0_per_mm)
    masks = [None] * heights.size if masks is None else list(masks)
    if len(masks) != heights.size:
        raise CalibrationError(f"plane masks: {len(masks)} masks for {heights.size} heights")
    means_arr, maps = _plane_phases(heights, delta_phases, masks)
    x = 1.0 / heights
    y = 1.0 / means_arr
    design = np.column_stack((x, np.ones_like(x)))
    if np.linalg.cond(design) > 1e12:
        raise CalibrationError("plane heights: the least-squares system is singular (heights too close together)")
    (a, b), *_ = np.linalg.lstsq(design, y, rcond=None)
    if not np.isfinite(b) or abs(b) < 1e-15 * max(1.0, abs(a)):
        raise CalibrationError("l0/d0 fit: the phase does not change with 1/h as eq. 1.15 requires (singular fit)")
    l0 = -a / b
    two_pi_f0_d0 = 1.0 / b
    d0 = two_pi_f0_d0 / (2.0 * np.pi * f0_per_mm)
    if not (np.isfinite(l0) and l0 > 0):
        raise CalibrationError(
            f"l0/d0 fit: l0 = {l0:.4g} mm is not a positive distance; check the heights' signs and the plane captures"
        )
    if np.any(heights >= l0):
        raise CalibrationError(f"l0/d0 fit: l0 = {l0:.4g} mm is below the highest plane; the fit is wrong")

    predicted = l0 * means_arr / (means_arr - two_pi_f0_d0)
    residuals = predicted - heights
    l0_std, d0_std = _l0_d0_std(design, y, a, b, d0, f0_per_mm, f0_std_per_mm)
    flatness = _flatness(heights, maps, l0, two_pi_f0_d0, flatness_tolerance_mm)
    return GeometryFit(
        l0_mm=float(l0),
        d0_mm=float(d0),
        f0_per_mm=float(f0_per_mm),
        l0_std_mm=l0_std,
        d0_std_mm=d0_std,
        f0_std_per_mm=float(f0_std_per_mm),
        heights_mm=tuple(float(h) for h in heights),
        mean_delta_phase=tuple(float(m) for m in means_arr),
        residuals_mm=tuple(float(r) for r in residuals),
        flatness_rms_mm=tuple(flatness),
    )


def _check_heights(heights: np.ndarray, maps: int, f0_per_mm: float) -> None:
    """At least MIN_HEIGHTS finite, non-zero, not all equal heights, one phase map each, and a usable f0."""
    if maps != heights.size:
        raise CalibrationError(f"plane heights: {heights.size} heights but {maps} phase maps")
    if heights.size < MIN_HEIGHTS:
        raise CalibrationError(
            f"plane heights: need at least {MIN_HEIGHTS} known heights to fit l0 and d0 with a residual, found {heights.size}"
        )
    if not np.all(np.isfinite(heights)):
        raise CalibrationError("plane heights: contain NaN or infinity")
    if np.any(heights == 0):
        raise CalibrationError("plane heights: 0 mm is the reference plane itself; use heights away from it")
    if np.unique(heights).size < 2:
        raise CalibrationError(f"plane heights: all equal ({heights[0]} mm), the fit is singular")
    if not (np.isfinite(f0_per_mm) and f0_per_mm > 0):
        raise CalibrationError(f"f0_per_mm: expected > 0, found {f0_per_mm}")


def _plane_phases(
    heights: np.ndarray, delta_phases: Sequence[np.ndarray], masks: Sequence[np.ndarray | None]
) -> tuple[np.ndarray, list[np.ndarray]]:
    """Each plane's trimmed mean phase difference, and its map (NaN outside the valid pixels)."""
    means, maps = [], []
    for h, dphi, mask in zip(heights, delta_phases, masks):
        dphi = np.asarray(dphi, dtype=np.float64)
        keep = _valid(dphi, mask, f"plane at {h:g} mm", EDGE_PX)
        if not keep.any():
            raise CalibrationError(f"plane at {h:g} mm: no valid pixel")
        means.append(_trimmed_mean(dphi[keep]))
        maps.append(np.where(keep, dphi, np.nan))
    means_arr = np.asarray(means)
    if np.any(np.abs(means_arr) < 1e-9):
        bad = heights[np.abs(means_arr) < 1e-9][0]
        raise CalibrationError(f"plane at {bad:g} mm: no phase change from the reference plane; was the plane moved?")
    return means_arr, maps


def _l0_d0_std(
    design: np.ndarray, y: np.ndarray, a: float, b: float, d0: float, f0_per_mm: float, f0_std_per_mm: float
) -> tuple[float, float]:
    """Standard deviations of l0 = -a/b and d0 = 1/(2 pi f0 b) from the fit's covariance (and f0's)."""
    dof = y.size - 2
    sigma2 = float(np.sum((y - design @ np.array([a, b])) ** 2)) / dof
    cov = sigma2 * np.linalg.inv(design.T @ design)
    j_l0 = np.array([-1.0 / b, a / b**2])
    j_d0 = np.array([0.0, -1.0 / (2.0 * np.pi * f0_per_mm * b**2)])
    l0_std = math.sqrt(max(float(j_l0 @ cov @ j_l0), 0.0))
    d0_var = float(j_d0 @ cov @ j_d0) + (d0 * f0_std_per_mm / f0_per_mm) ** 2
    return l0_std, math.sqrt(max(d0_var, 0.0))


def _flatness(
    heights: np.ndarray, maps: list[np.ndarray], l0: float, two_pi_f0_d0: float, tolerance_mm: float | None
) -> list[float]:
    """Each plane's height spread (RMS of 8 x 8 tile medians) under the fit; CalibrationError past ``tolerance_mm``."""
    flatness = []
    for h, dphi in zip(heights, maps):
        blocks = _block_medians(l0 * dphi / (dphi - two_pi_f0_d0))
        spread = float(np.sqrt(np.mean((blocks - np.median(blocks)) ** 2)))
        flatness.append(spread)
        if tolerance_mm is not None and spread > tolerance_mm:
            raise CalibrationError(
                f"plane at {h:g} mm: heights spread {spread:.3g} mm RMS across the view (tolerance "
                f"{tolerance_mm:g} mm): the plane is not flat or not level, or the rig does not "
                "follow eq. 1.15 (use the 'polynomial' model)"
            )
    return flatness
