"""How densely the camera samples the fringes: what spatial corrections may assume.

Spatial methods (voting, fringe-order RPCA, region pooling, ``auto``) read fringe orders from
differences between neighbouring pixels; they need the phase to change by less than pi from one
pixel to the next along the fringe axis (a period above 2 px). Temporal unwrapping has no such
limit, so a capture can be unwrapped right and still be undersampled for them. The absolute phase
from temporal unwrapping gives the true step (the wrapped phase would alias it).
"""

from __future__ import annotations

import numpy as np

from processing._validate import real_array

# Above this phase step per pixel (a period below 2.5 px) neighbouring differences no longer tell
# fringe orders apart reliably once noise is added.
SPATIAL_STEP_LIMIT_RAD = 0.8 * np.pi


def fringe_step_rad(absolute_phase: np.ndarray, valid: np.ndarray, axis: int) -> float:
    """Median absolute phase step between valid neighbours along ``axis`` (radians per pixel).

    Parameters
    ----------
    absolute_phase : (H, W) array
        Absolute (temporally unwrapped) phase; invalid pixels may hold NaN.
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
    head = (slice(None), slice(None, -1)) if axis == 1 else (slice(None, -1), slice(None))
    tail = (slice(None), slice(1, None)) if axis == 1 else (slice(1, None), slice(None))
    both = mask[head] & mask[tail]
    if not both.any():
        return float("nan")
    steps = np.abs(phase[tail][both] - phase[head][both])
    steps = steps[np.isfinite(steps)]
    return float(np.median(steps)) if steps.size else float("nan")


def undersampled_for_spatial_methods(step_rad: float) -> bool:
    """True when fringes are too dense for corrections that compare neighbouring pixels."""
    return bool(np.isfinite(step_rad) and step_rad > SPATIAL_STEP_LIMIT_RAD)
