"""Phase to height (thesis eq. 1.15) and back, error metrics, and point clouds."""

from __future__ import annotations

import numpy as np

from processing._validate import finite_pixels

_PIECE = 1 << 16  # values per piece of phase_to_height: its temporary stays in the CPU cache


def phase_to_height(
    delta_phase: np.ndarray,
    l0_mm: float,
    d0_mm: float,
    f0_per_mm: float,
    dtype: type = np.float64,
    in_place: bool = False,
) -> np.ndarray:
    """Height from the phase difference object - reference (thesis eq. 1.15).

    h = l0 dPhi / (dPhi - 2 pi f0 d0). ``d0`` is signed so that heights towards the camera are
    positive: with d0 > 0 a raised point has a negative phase difference.

    Parameters
    ----------
    delta_phase : array
        Phi_object - Phi_reference in radians, at the frequency whose plane frequency is f0.
    l0_mm, d0_mm, f0_per_mm : float
        Pupil height above the plane, signed baseline, fringe frequency on the plane.
    dtype : float64 or float32
        Working and result precision; float32 (relative rounding 6e-8, far below any phase
        noise) halves the memory traffic of a full image.
    in_place : bool
        Write the heights into ``delta_phase`` when it is an array of ``dtype`` (no full-size
        temporary: a fresh image costs more to allocate than to compute).

    Examples
    --------
    Points 5 and 10 mm above the plane, with the pupil 500 mm above it, a 200 mm baseline and
    0.1 fringe / mm: their phase differences and back.

    >>> import numpy as np
    >>> delta = height_to_phase(np.array([5.0, 10.0]), 500.0, 200.0, 0.1)
    >>> np.round(delta, 6)
    array([-1.26933 , -2.564565])
    >>> np.round(phase_to_height(delta, 500.0, 200.0, 0.1), 9)
    array([ 5., 10.])
    """
    check_geometry(l0_mm, d0_mm, f0_per_mm)
    if dtype not in (np.float64, np.float32):
        raise ValueError(f"dtype: expected numpy.float64 or numpy.float32, found {dtype!r}")
    reuse = (
        in_place
        and isinstance(delta_phase, np.ndarray)
        and delta_phase.dtype == dtype
        and delta_phase.ndim > 0
        and delta_phase.flags.c_contiguous
        and delta_phase.flags.writeable
    )
    height = delta_phase if reuse else np.array(delta_phase, dtype=dtype, ndmin=1)
    # In place over cache-sized pieces, with one small temporary for dPhi - 2 pi f0 d0.
    offset, scale = dtype(2.0 * np.pi * f0_per_mm * d0_mm), dtype(l0_mm)
    flat = height.reshape(-1)
    scratch = np.empty(min(flat.size, _PIECE), dtype=dtype)
    for start in range(0, flat.size, _PIECE):
        piece = flat[start : start + _PIECE]
        below = scratch[: piece.size]
        np.subtract(piece, offset, out=below)
        np.divide(piece, below, out=piece)
        piece *= scale
    return height if np.ndim(delta_phase) else height[0]


def height_to_phase(height_mm: np.ndarray, l0_mm: float, d0_mm: float, f0_per_mm: float) -> np.ndarray:
    """Inverse of :func:`phase_to_height`: dPhi = -2 pi f0 d0 h / (l0 - h)."""
    check_geometry(l0_mm, d0_mm, f0_per_mm)
    h = np.asarray(height_mm, dtype=np.float64)
    if np.any(h >= l0_mm):
        raise ValueError(f"height_mm: every height must be below l0_mm = {l0_mm}")
    return -2.0 * np.pi * f0_per_mm * d0_mm * h / (l0_mm - h)


def check_geometry(l0_mm: float, d0_mm: float, f0_per_mm: float) -> None:
    """Refuse a reference-plane geometry eq. 1.15 cannot use (ValueError naming the parameter)."""
    if not l0_mm > 0:
        raise ValueError(f"l0_mm: expected > 0, found {l0_mm}")
    if d0_mm == 0 or not np.isfinite(d0_mm):
        raise ValueError(f"d0_mm: expected a finite non-zero baseline, found {d0_mm}")
    if not f0_per_mm > 0:
        raise ValueError(f"f0_per_mm: expected > 0, found {f0_per_mm}")


def _masked_pair(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
    estimate = np.asarray(estimate, dtype=np.float64)
    truth = np.asarray(truth, dtype=np.float64)
    if estimate.shape != truth.shape:
        raise ValueError(f"estimate: shape {estimate.shape} differs from truth {truth.shape}")
    keep = finite_pixels(estimate, truth, mask=mask)
    if not keep.any():
        raise ValueError("mask: no valid pixel to compare")
    return estimate[keep], truth[keep]


def nmse(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Normalised mean squared error (thesis eq. 2.18): sum (x_hat - x)^2 / sum x^2 over valid pixels."""
    est, ref = _masked_pair(estimate, truth, mask)
    denominator = float(np.sum(ref * ref))
    if denominator == 0.0:
        raise ValueError("truth: all zero, NMSE undefined")
    return float(np.sum((est - ref) ** 2) / denominator)


def phase_mse(estimate: np.ndarray, truth: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean squared phase error (thesis eq. 3.5) over valid pixels, in rad^2."""
    est, ref = _masked_pair(estimate, truth, mask)
    return float(np.mean((est - ref) ** 2))


def point_cloud(
    height_mm: np.ndarray,
    pixel_mm: float,
    l0_mm: float,
    mask: np.ndarray | None = None,
    center: tuple[float, float] | None = None,
) -> np.ndarray:
    """Points (N, 3) in mm of the valid pixels: X = (x - cx) pixel_mm (l0 - h) / l0, same for Y, Z = h.

    ``center`` is (cx, cy) in pixels, default the image centre. Rows are in C order of the
    valid pixels, so a point's index maps back to its pixel through ``np.nonzero(mask)``.
    """
    h = np.asarray(height_mm, dtype=np.float64)
    if h.ndim != 2:
        raise ValueError(f"height_mm: expected a 2-D map, found shape {h.shape}")
    valid = np.isfinite(h) if mask is None else (np.asarray(mask, dtype=bool) & np.isfinite(h))
    rows, cols = np.nonzero(valid)
    cx, cy = ((h.shape[1] - 1) / 2.0, (h.shape[0] - 1) / 2.0) if center is None else center
    z = h[rows, cols]
    scale = pixel_mm * (l0_mm - z) / l0_mm
    return np.column_stack(((cols - cx) * scale, (rows - cy) * scale, z))
