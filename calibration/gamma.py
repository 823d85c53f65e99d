"""Projector gamma: measure the response to flat levels, pre-correct patterns, or correct the phase.

A projector's non-linear response (camera intensity ~ a + b level^gamma) adds harmonics to the
sinusoids and leaves a periodic ripple in the wrapped phase, the most reported cause of wavy
scans. Two cures:

* pre-correction (:func:`fit_gamma`, :func:`inverse_lut`): project a ramp of flat levels, fit the
  response and hand the projector driver a LUT desired intensity -> drive level
  (``Projector.set_gamma_lut``), so projected patterns come out sinusoidal;
* compensation in processing, where the projector cannot be pre-corrected (a DLP with 1-bit
  patterns, someone else's capture): more phase steps (an N-step algorithm is blind to harmonics
  below N - 1), or a phase-error lookup (:func:`phase_error_table`, :func:`compensate_phase`)
  learnt from the reference plane against a ripple-free phase.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

from calibration.errors import CalibrationError
from processing._validate import finite_pixels

MIN_LEVELS = 5


def ramp_patterns(count: int = 17) -> list[dict]:
    """Flat patterns at ``count`` levels evenly spaced over [0, 1] (capture-format ``flat``)."""
    if count < MIN_LEVELS:
        raise CalibrationError(f"gamma ramp: need at least {MIN_LEVELS} levels, asked for {count}")
    return [{"kind": "flat", "level": float(level)} for level in np.linspace(0.0, 1.0, count)]


@dataclass(frozen=True)
class GammaFit:
    """Projector response I = offset + gain * level ** gamma, and the measured points."""

    gamma: float
    offset: float
    gain: float
    levels: tuple[float, ...]
    responses: tuple[float, ...]
    residual_rms: float

    def normalized_response(self, level: np.ndarray) -> np.ndarray:
        """Model response scaled to 0 at level 0 and 1 at level 1."""
        return np.clip(np.asarray(level, dtype=np.float64), 0.0, 1.0) ** self.gamma

    def as_fields(self) -> dict:
        """Every field, as calibration.json stores it (tuples as lists)."""
        return {key: list(value) if isinstance(value, tuple) else value for key, value in asdict(self).items()}


def _power(level: np.ndarray, offset: float, gain: float, gamma: float) -> np.ndarray:
    return offset + gain * np.power(np.clip(level, 0.0, 1.0), gamma)


def fit_gamma(
    levels: Sequence[float], responses: Sequence[float] | np.ndarray, saturation: float | None = None
) -> GammaFit:
    """Fit I = offset + gain * level ** gamma to mean camera intensities at flat levels.

    Parameters
    ----------
    levels : sequence of float in [0, 1]
        Projected flat levels (at least :data:`MIN_LEVELS`, including 0 and 1 ideally).
    responses : sequence of float
        Mean camera intensity of a region at each level (e.g. :func:`mean_response` of frames).
    saturation : float, optional
        Camera full scale (255 for 8-bit); a response within 0.5 % of it is refused as clipped.
    """
    x = np.asarray(levels, dtype=np.float64).ravel()
    y = np.asarray(responses, dtype=np.float64).ravel()
    if x.size != y.size:
        raise CalibrationError(f"gamma ramp: {x.size} levels but {y.size} responses")
    if x.size < MIN_LEVELS:
        raise CalibrationError(f"gamma ramp: need at least {MIN_LEVELS} levels, found {x.size}")
    if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
        raise CalibrationError("gamma ramp: levels or responses contain NaN or infinity")
    if x.min() < 0 or x.max() > 1:
        raise CalibrationError(f"gamma ramp: levels must lie in [0, 1], found [{x.min():g}, {x.max():g}]")
    if saturation is not None and np.any(y >= 0.995 * saturation):
        level = x[np.argmax(y >= 0.995 * saturation)]
        raise CalibrationError(
            f"gamma ramp: the camera saturates from level {level:g} on ({saturation:g}); lower the exposure"
        )
    order = np.argsort(x)
    x, y = x[order], y[order]
    span = y[-1] - y[0]
    if span <= 0 or np.ptp(y) < 1e-6 * max(1.0, abs(y).max()):
        raise CalibrationError("gamma ramp: the camera intensity does not rise with the level (is the projector on?)")
    from scipy.optimize import curve_fit  # imported here: scipy.optimize costs ~0.2 s at CLI start-up

    try:
        params, _ = curve_fit(_power, x, y, p0=(y[0], span, 2.2), bounds=([-np.inf, 0.0, 0.1], [np.inf, np.inf, 10.0]))
    except (RuntimeError, ValueError) as exc:
        raise CalibrationError(f"gamma ramp: the response model did not fit ({exc})") from exc
    offset, gain, gamma = (float(p) for p in params)
    residual = y - _power(x, offset, gain, gamma)
    return GammaFit(
        gamma=gamma,
        offset=offset,
        gain=gain,
        levels=tuple(float(v) for v in x),
        responses=tuple(float(v) for v in y),
        residual_rms=float(np.sqrt(np.mean(residual**2))),
    )


def mean_response(frames: np.ndarray, mask: np.ndarray | None = None) -> np.ndarray:
    """Mean intensity of each frame (N, H, W) over ``mask`` (default: the central half of the image)."""
    stack = np.asarray(frames, dtype=np.float64)
    if stack.ndim != 3:
        raise CalibrationError(f"gamma frames: expected (N, H, W), found shape {stack.shape}")
    if mask is None:
        mask = np.zeros(stack.shape[1:], dtype=bool)
        h, w = stack.shape[1:]
        mask[h // 4 : h - h // 4 or h, w // 4 : w - w // 4 or w] = True
    return stack[:, np.asarray(mask, dtype=bool)].mean(axis=1)


def inverse_lut(fit: GammaFit, size: int = 256, method: str = "model") -> np.ndarray:
    """LUT (``size``,) desired intensity i/(size-1) -> drive level in [0, 1] that linearises the projector.

    ``method="model"`` inverts the fitted power law; ``"empirical"`` inverts the measured points
    with a monotone (PCHIP) interpolant, for projectors that do not follow a power law.
    """
    if size < 2:
        raise CalibrationError(f"gamma LUT size: expected >= 2, found {size}")
    desired = np.linspace(0.0, 1.0, size)
    if method == "model":
        return (desired ** (1.0 / fit.gamma)).astype(np.float32)
    if method != "empirical":
        raise CalibrationError(f"gamma LUT method: expected 'model' or 'empirical', found {method!r}")
    levels = np.asarray(fit.levels)
    response = np.asarray(fit.responses)
    normalized = (response - response[0]) / (response[-1] - response[0])
    normalized = np.maximum.accumulate(normalized)
    keep = np.concatenate(([True], np.diff(normalized) > 1e-9))
    if keep.sum() < 2:
        raise CalibrationError("gamma ramp: the measured response is flat, cannot invert it")
    from scipy.interpolate import PchipInterpolator  # imported here, as curve_fit above

    inverse = PchipInterpolator(normalized[keep], levels[keep], extrapolate=True)
    return np.clip(inverse(desired), 0.0, 1.0).astype(np.float32)


@dataclass(frozen=True)
class PhaseErrorTable:
    """Mean wrapped-phase error as a function of the measured wrapped phase."""

    centers: np.ndarray  # (B,) bin centres in [-pi, pi)
    error: np.ndarray  # (B,) mean error in rad

    def as_fields(self) -> dict:
        return {"phase_error_centers": self.centers.tolist(), "phase_error_rad": self.error.tolist()}


def _wrap(phase: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * phase))


def phase_error_table(
    measured: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None, bins: int = 128
) -> PhaseErrorTable:
    """Learn the gamma ripple: mean of wrap(measured - reference) per bin of the measured phase.

    Parameters
    ----------
    measured : (H, W) array
        Wrapped (or absolute) phase of the reference plane from the scan's own pattern set.
    reference : (H, W) array
        The same plane's ripple-free phase (many steps, a fitted plane, or pre-corrected fringes).
    """
    m = np.asarray(measured, dtype=np.float64)
    r = np.asarray(reference, dtype=np.float64)
    if m.shape != r.shape:
        raise CalibrationError(f"phase error table: measured {m.shape} and reference {r.shape} differ in shape")
    keep = finite_pixels(m, r, mask=mask)
    if keep.sum() < 10 * bins:
        raise CalibrationError(f"phase error table: {int(keep.sum())} valid pixels, need at least {10 * bins}")
    wrapped = _wrap(m[keep])
    error = _wrap(m[keep] - r[keep])
    error -= np.angle(np.mean(np.exp(1j * error)))  # a constant offset is not ripple
    index = np.clip(((wrapped + np.pi) / (2 * np.pi) * bins).astype(np.intp), 0, bins - 1)
    counts = np.bincount(index, minlength=bins)
    filled = counts > 0
    if filled.sum() < max(bins // 4, 4):
        raise CalibrationError(
            f"phase error table: only {int(filled.sum())} of {bins} phase bins hold pixels; use a larger plane or fewer bins"
        )
    centers = -np.pi + (np.arange(bins) + 0.5) * 2 * np.pi / bins
    mean = np.bincount(index, weights=error, minlength=bins)[filled] / counts[filled]
    # bins no pixel fell in (a plane sampled at few phases) are interpolated, periodically
    return PhaseErrorTable(centers=centers, error=np.interp(centers, centers[filled], mean, period=2 * np.pi))


def compensate_phase(phase: np.ndarray, table: PhaseErrorTable) -> np.ndarray:
    """Subtract the tabulated ripple from a (wrapped or absolute) phase map, periodic in 2 pi."""
    p = np.asarray(phase, dtype=np.float64)
    correction = np.interp(_wrap(p), table.centers, table.error, period=2 * np.pi)
    return p - correction


def smooth_plane_phase(phase: np.ndarray, mask: np.ndarray | None = None, degree: int = 3) -> np.ndarray:
    """A ripple-free stand-in for a flat plane's absolute phase: a 2-D polynomial of ``degree``
    fitted to it (a plane's phase is smooth, perspective included; the gamma ripple is not)."""
    p = np.asarray(phase, dtype=np.float64)
    if p.ndim != 2:
        raise CalibrationError(f"plane phase: expected a 2-D map, found shape {p.shape}")
    keep = np.isfinite(p)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool)
    terms = [(i, j) for i in range(degree + 1) for j in range(degree + 1 - i)]
    if keep.sum() < 4 * len(terms):
        raise CalibrationError(f"plane phase: {int(keep.sum())} valid pixels, too few for a degree-{degree} surface")
    rows, cols = np.indices(p.shape, dtype=np.float64)
    x = (cols - p.shape[1] / 2.0) / p.shape[1]
    y = (rows - p.shape[0] / 2.0) / p.shape[0]
    design = np.stack([x**i * y**j for i, j in terms], axis=-1)
    coef, *_ = np.linalg.lstsq(design[keep], p[keep], rcond=None)
    return np.where(keep, design @ coef, np.nan)


def ripple_table_from_plane(
    phase: np.ndarray, mask: np.ndarray | None = None, bins: int = 64
) -> tuple[PhaseErrorTable, float]:
    """Phase-error table of a plane's absolute phase against its smooth fit, and the ripple's RMS (rad)."""
    smooth = smooth_plane_phase(phase, mask)
    table = phase_error_table(phase, smooth, mask=mask, bins=bins)
    return table, float(np.sqrt(np.mean(table.error**2)))


def table_from_fields(fields: dict) -> PhaseErrorTable:
    """Inverse of :meth:`PhaseErrorTable.as_fields` (calibration.json ``phase_error``)."""
    try:
        centers = np.asarray(fields["phase_error_centers"], dtype=np.float64)
        error = np.asarray(fields["phase_error_rad"], dtype=np.float64)
    except (KeyError, TypeError, ValueError):
        raise CalibrationError("phase_error: expected phase_error_centers and phase_error_rad lists") from None
    if centers.shape != error.shape or centers.ndim != 1 or centers.size < 4:
        raise CalibrationError(
            f"phase_error: expected two equal lists of >= 4 numbers, found {centers.shape} and {error.shape}"
        )
    return PhaseErrorTable(centers=centers, error=error)
