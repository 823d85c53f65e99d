"""How densely the camera samples the fringes: what spatial corrections may assume.

Spatial methods (voting, fringe-order RPCA, region pooling, ``auto``) read fringe orders from
differences between neighbouring pixels; they need the phase to change by less than pi from one
pixel to the next along the fringe axis (a period above 2 px). Temporal unwrapping has no such
limit, so a capture can be unwrapped right and still be undersampled for them.

The step is measured so that wrong fringe orders cannot fool it: a neighbour difference of the
absolute phase wrapped into [-pi, pi) is the wrapped phase's own step, which holds no order at
all. The captures that need correction most carry the most wrong orders; the median step of the
unwrapped phase measured those errors instead of the fringes (a quarter of the pixels wrong puts
most neighbour pairs across an error) and switched the correction off. Wrapped steps alias above
pi per pixel (a period below 2 px), so the absolute phase's slope over ``LAG_PX`` pixels, where an
order error adds only 2 pi / ``LAG_PX`` per wrong order, says when the fringes are that dense.
"""

from __future__ import annotations

import numpy as np

from processing._validate import real_array
from processing.angles import wrap_to_pi

# Above this phase step per pixel (a period below 2.5 px) neighbouring differences no longer tell
# fringe orders apart reliably once noise is added.
SPATIAL_STEP_LIMIT_RAD = 0.8 * np.pi
# Lag of the alias check: an order error moves the slope over this span by 2 pi / LAG_PX per order.
LAG_PX = 32
# The steps are taken on evenly spaced lines holding at most this many pixels: a median over 65k steps
# is within a fraction of a percent of the whole map's, far inside the guard's margin (2.5 px per fringe
# against the 2 px where wrapped steps alias), and takes 3 ms instead of 12 on 1024 x 768 (every capture
# that auto corrects pays it).
SAMPLE_PIXELS = 1 << 16


def _pairs(mask: np.ndarray, axis: int, lag: int) -> tuple[tuple[slice, slice], tuple[slice, slice], np.ndarray]:
    """Index of the first and second pixel of every pair ``lag`` apart along ``axis``, and where both are valid."""
    head = (slice(None), slice(None, -lag)) if axis == 1 else (slice(None, -lag), slice(None))
    tail = (slice(None), slice(lag, None)) if axis == 1 else (slice(lag, None), slice(None))
    return head, tail, mask[head] & mask[tail]


def _median_step(phase: np.ndarray, mask: np.ndarray, axis: int, lag: int, wrap: bool) -> float:
    """Median |phase difference| / ``lag`` over valid pairs ``lag`` apart (wrapped into [-pi, pi) if ``wrap``)."""
    if phase.shape[axis] <= lag:
        return float("nan")
    head, tail, both = _pairs(mask, axis, lag)
    if not both.any():
        return float("nan")
    steps = phase[tail][both] - phase[head][both]
    steps = np.abs(wrap_to_pi(steps) if wrap else steps)
    steps = steps[np.isfinite(steps)]
    return float(np.median(steps)) / lag if steps.size else float("nan")


def _sampled_lines(phase: np.ndarray, mask: np.ndarray, axis: int) -> tuple[np.ndarray, np.ndarray]:
    """Every k-th line along ``axis`` (rows for axis 1), k chosen so that at most :data:`SAMPLE_PIXELS`
    pixels remain: a median over tens of thousands of steps is as good as over all of them."""
    lines = phase.shape[1 - axis]
    stride = max(1, -(-phase.size // SAMPLE_PIXELS))
    stride = min(stride, max(lines // 16, 1))  # keep at least 16 lines
    pick = (slice(None, None, stride), slice(None)) if axis == 1 else (slice(None), slice(None, None, stride))
    return phase[pick], mask[pick]


def fringe_step_rad(absolute_phase: np.ndarray, valid: np.ndarray, axis: int) -> float:
    """Phase step between valid neighbours along ``axis`` (radians per pixel), blind to fringe orders.

    The median of the neighbour differences wrapped into [-pi, pi) (the wrapped phase's steps; any
    2 pi representation of the phase gives the same), unless the absolute phase's median slope over
    :data:`LAG_PX` pixels exceeds pi per pixel, where wrapped steps alias: then that slope. Both
    medians are taken on evenly spaced lines across the fringes (:data:`SAMPLE_PIXELS` at most).

    Parameters
    ----------
    absolute_phase : (H, W) array
        Absolute (temporally unwrapped) or wrapped phase; invalid pixels may hold NaN.
    valid : (H, W) bool array
    axis : int
        1 for fringes along x (phase grows along rows), 0 for fringes along y.

    Returns
    -------
    step : float
        NaN when no two valid neighbours exist along ``axis``.
    """
    phase = real_array(absolute_phase, "absolute_phase", ndim=2)
    mask = np.asarray(valid, dtype=bool)
    if mask.shape != phase.shape:
        raise ValueError(f"valid: expected the shape of absolute_phase {phase.shape}, found {mask.shape}")
    if axis not in (0, 1):
        raise ValueError(f"axis: expected 0 or 1, found {axis!r}")
    phase, mask = _sampled_lines(phase, mask, axis)
    wrapped_step = _median_step(phase, mask, axis, 1, wrap=True)
    lag = min(LAG_PX, max(phase.shape[axis] // 4, 1))
    slope = _median_step(phase, mask, axis, lag, wrap=False)
    if np.isfinite(slope) and slope > np.pi:
        return slope
    return wrapped_step


def undersampled_for_spatial_methods(step_rad: float) -> bool:
    """True when fringes are too dense for corrections that compare neighbouring pixels."""
    return bool(np.isfinite(step_rad) and step_rad > SPATIAL_STEP_LIMIT_RAD)
