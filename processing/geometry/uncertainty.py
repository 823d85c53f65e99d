"""The capture's noise and each pixel's predicted phase and height standard deviation.

A J-step phase-shifting fit of ``I_j = A + B cos(phi + delta_j)`` with additive camera noise of
standard deviation ``sigma_I`` gives the phase with standard deviation (uniform shifts)::

    sigma_phi = sqrt(2 / J) * sigma_I / B

``sigma_I`` comes from the capture itself (:func:`noise_sigma`): for J >= 4 the residual of the
sinusoid fit, ``sum_j r_j^2 / (J - 3)``, averaged over a regular subsample; for three steps the fit
has no residual, so a robust local estimate (median absolute difference of neighbouring pixels
along the fringes, where the fringe does not change) is used instead. The height's standard
deviation follows from the calibration's geometry, ``sigma_h = |d h / d Phi| sigma_phi``
(:func:`height_sigma`, a central difference of the model's own height function).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from processing._aligned import aligned_empty
from processing.phase.shifting import fit_residual_variance, sample_stride
from processing.quantiles import percentile

MAD_TO_SIGMA = 1.4826  # a normal distribution's sigma per median absolute deviation


def _fit_residual_variance(sample: np.ndarray, shifts: np.ndarray | None) -> float:
    """Mean of :func:`~processing.phase.shifting.fit_residual_variance` over the sample's pixels (J, P)."""
    steps = sample.shape[0]
    delta = np.linspace(0.0, 2.0 * np.pi, steps, endpoint=False) if shifts is None else np.asarray(shifts, float)
    per_pixel = fit_residual_variance(sample, delta)
    return float(np.mean(per_pixel[np.isfinite(per_pixel)]))


def _local_variance(frame: np.ndarray, axis: str) -> float:
    """Robust noise variance of one frame from neighbour differences along the fringes (three steps)."""
    along = 0 if axis == "x" else 1  # x fringes vary along columns: neighbours down a column share the fringe
    diff = np.diff(np.asarray(frame, dtype=np.float32), axis=along).ravel()
    diff = diff[np.isfinite(diff)]
    mad = float(np.median(np.abs(diff - np.median(diff))))
    return (MAD_TO_SIGMA * mad) ** 2 / 2.0  # the difference of two pixels has twice the variance


def noise_sigma(
    frames: np.ndarray,
    groups: Sequence[Sequence[int]],
    shifts: Sequence[np.ndarray | None] | None = None,
    axis: str = "x",
) -> float:
    """Camera noise sigma_I (grey levels) of a phase-shifted capture, from its own frames.

    ``groups``: the frame indices of each phase-shifted frequency; ``shifts`` their phase shifts
    (None: uniform). The fit residual of every group with four steps or more, pooled; when all
    groups have three steps, the local estimate of the first frame of each.
    """
    stack = np.asarray(frames)
    flat = stack.reshape(stack.shape[0], -1)
    stride = sample_stride(stack.shape[1:])
    variances = [
        _fit_residual_variance(
            np.asarray(flat[list(indices), ::stride], dtype=np.float64), None if shifts is None else shifts[k]
        )
        for k, indices in enumerate(groups)
        if len(indices) >= 4
    ]
    if not variances:
        variances = [_local_variance(stack[indices[0]], axis) for indices in groups if len(indices)]
    return float(np.sqrt(np.mean(variances))) if variances else float("nan")


def phase_sigma(modulation: np.ndarray, sigma_i: float, steps: int) -> np.ndarray:
    """Predicted phase standard deviation (rad, float32) of each pixel: sqrt(2 / J) sigma_I / B."""
    scale = np.float32(np.sqrt(2.0 / steps) * sigma_i)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.divide(scale, np.asarray(modulation, dtype=np.float32))


def combined_phase_sigma(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Two independent phase sigmas in quadrature, sqrt(first^2 + second^2): the object's and the
    reference's, whose phases a height subtracts. A new float32 map of their shape.

    Through OpenCV's ``magnitude`` (one vectorised pass without a temporary: 0.37 ms against
    1.24 ms for three numpy passes on 1024 x 768, on the uncertainty map's critical path). Within
    2 ulp of the exact value (1.8 measured, tested; numpy's passes: 1.5); NaN where either is NaN.
    """
    import cv2  # a hard dependency; imported on first use like the pass's kernels

    a = np.ascontiguousarray(first, dtype=np.float32)
    b = np.ascontiguousarray(second, dtype=np.float32)
    if a.shape != b.shape:
        raise ValueError(f"second: expected the shape {a.shape} of first, found {b.shape}")
    out = aligned_empty(a.shape)  # the same values wherever the allocator puts it (processing._aligned)
    if out.size:
        cv2.magnitude(a.reshape(-1), b.reshape(-1), out.reshape(-1))
    return out


DIFFERENCE_STEP = 1e-2  # rad: the models are smooth at this scale, and float32 phases resolve it


def height_ahead(
    height_of: Callable[[np.ndarray], np.ndarray], phase: np.ndarray, step: float = DIFFERENCE_STEP
) -> np.ndarray:
    """``height_of(phase + step)``: the model's side of :func:`height_sigma`'s difference.

    It does not need the heights themselves, so a caller can evaluate it beside them.
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        return np.asarray(height_of(phase + np.float32(step)))


def height_sigma(
    height_of: Callable[[np.ndarray], np.ndarray],
    phase: np.ndarray,
    sigma_phi: np.ndarray,
    step: float = DIFFERENCE_STEP,
    base: np.ndarray | None = None,
    ahead: np.ndarray | None = None,
) -> np.ndarray:
    """Height (or point) standard deviation per pixel: |d h / d Phi| sigma_phi, float32.

    ``height_of(phase)`` returns (H, W) heights or (H, W, 3) points in mm, a new array each call
    (the difference is written into it); its derivative is a difference over ``step`` radians (the
    models are smooth at that scale): forward from ``base`` = ``height_of(phase)`` when the caller
    has it (one model evaluation), else central; the length of the point displacement for points.
    ``ahead``: :func:`height_ahead` of the same arguments when the caller evaluated it already
    (it is then written into).
    """
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        ahead = height_ahead(height_of, phase, step) if ahead is None else ahead
        behind = np.asarray(height_of(phase - np.float32(step))) if base is None else np.asarray(base)
        # into the model's own float32 array when it is one: a fresh full-size map costs more to fault in than to fill
        reuse = ahead.dtype == np.float32 and ahead.flags.writeable and ahead.shape == np.broadcast(ahead, behind).shape
        change = np.subtract(ahead, behind, out=ahead) if reuse else np.subtract(ahead, behind, dtype=np.float32)
        if change.ndim == np.ndim(phase) + 1:
            change = np.sqrt(np.einsum("...k,...k->...", change, change))
        np.abs(change, out=change)
        change *= np.float32(1.0 / (step if base is not None else 2.0 * step))
        change *= sigma_phi
        return change


def summary(uncertainty: np.ndarray, mask: np.ndarray) -> dict[str, float] | None:
    """report.json's figures of the uncertainty map over the valid pixels (None when there are none)."""
    values = uncertainty[mask]
    values = values[np.isfinite(values)]
    if not values.size:
        return None
    median, p95 = np.percentile(values, [50, 95])
    return {"median": float(median), "p95": float(p95)}


MIN_CORRECTION_GAIN = 0.3  # a correction is not trusted to have removed more than 91 % of the noise power
# Pixels of the regular subsample the gain's robust spread is taken over: the spread of a median absolute
# deviation over n normal values is about 1.2 / sqrt(n) of it, so 0.5 % here; the whole 1024 x 768 map
# took 40 ms (two float64 medians of every valid pixel) on the correction stage's critical path.
GAIN_SAMPLES = 1 << 16


def correction_gain(before: np.ndarray, after: np.ndarray, sigma_phi: np.ndarray, mask: np.ndarray) -> float:
    """How much of the predicted phase noise a correction left: sqrt(1 - var((before - after) / sigma_phi))

    (var: robust, from the median absolute deviation over a regular subsample of about
    :data:`GAIN_SAMPLES` pixels that visits every column; every pixel of a smaller map).

    A correction that smooths the phase (a projection on the fringe's low-rank or smooth part)
    removes noise orthogonal to what it keeps, so the removed variance is the noise variance it
    took away. Clipped to [:data:`MIN_CORRECTION_GAIN`, 1]: what it removed beyond noise (a
    systematic ripple) must not make the prediction optimistic without bound.
    """
    shape = np.shape(before)
    for name, values in (("after", after), ("sigma_phi", sigma_phi), ("mask", mask)):
        if np.shape(values) != shape:
            raise ValueError(f"{name}: expected the shape {shape} of before, found {np.shape(values)}")
    stride = sample_stride(shape, GAIN_SAMPLES)
    # contiguous copies: numpy's strided loops cost more than the gather
    before, after, sigma_phi, mask = (
        np.ascontiguousarray(np.asarray(a).reshape(-1)[::stride]) for a in (before, after, sigma_phi, mask)
    )
    keep = mask & np.isfinite(before) & np.isfinite(after) & np.isfinite(sigma_phi)
    if not keep.any():
        return 1.0
    sigma = np.asarray(sigma_phi[keep], dtype=np.float64)
    change = np.asarray(before[keep] - after[keep], dtype=np.float64)
    change -= 2.0 * np.pi * np.rint(change / (2.0 * np.pi))  # fringe orders it changed are not noise it removed
    removed = change / np.where(sigma > 0, sigma, np.inf)
    removed -= percentile(removed, 50.0)  # removed: a fresh array, reordered in place
    spread = MAD_TO_SIGMA * percentile(np.abs(removed, out=removed), 50.0)  # order slips are not noise
    share = spread * spread  # the removed noise power as a share of the predicted one, pixel by pixel
    return float(np.sqrt(np.clip(1.0 - share, MIN_CORRECTION_GAIN**2, 1.0)))
