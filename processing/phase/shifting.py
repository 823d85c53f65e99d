"""N-step phase shifting: wrapped phase, background and modulation from a fringe stack.

Frames follow capture-format.md: ``I_k = A + B cos(phi + delta_k)`` with ``phi = 2 pi f u / W``
(plus the pattern's ``phase_rad``, which the caller subtracts). Both the uniform shifts
``delta_k = 2 pi k / N`` and arbitrary known shifts reduce to one linear model per pixel,

    I_k = A + (B cos phi) cos delta_k - (B sin phi) sin delta_k,

so a (3, N) weight matrix, computed once from the shifts, turns the stack into
``(A, B cos phi, B sin phi)`` by matrix products: closed form for uniform shifts
(thesis / DESIGN: ``phi = atan2(-sum I_k sin delta_k, sum I_k cos delta_k)``,
``B = 2/N sqrt(S^2 + C^2)``), least squares (normal equations solved once) otherwise.
The products run over blocks of pixels (:mod:`processing._blockwise`): 8-bit frames cast to
float32 a block at a time stay in the CPU cache, several times faster than one product over
the whole image.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from processing import _validate
from processing._blockwise import blockwise
from processing.quantiles import percentile

TWO_PI = 2.0 * np.pi


@dataclass
class PhaseShiftResult:
    """Output of :func:`phase_shift`, all (H, W) float64.

    Attributes
    ----------
    phase : wrapped phase phi in [-pi, pi)
    background : A, the mean intensity
    modulation : B, the fringe amplitude (>= 0); low in shadows and on dark surfaces
    """

    phase: np.ndarray
    background: np.ndarray
    modulation: np.ndarray


@lru_cache(maxsize=64)
def _uniform_weights(steps: int) -> np.ndarray:
    delta = TWO_PI * np.arange(steps) / steps
    return np.stack([np.full(steps, 1.0 / steps), 2.0 / steps * np.cos(delta), -2.0 / steps * np.sin(delta)])


def shift_weights(steps: int, shifts: np.ndarray | None = None) -> np.ndarray:
    """Weights (3, N) that map a stack of N frames to (A, B cos phi, B sin phi).

    Parameters
    ----------
    steps : int
        Number of frames N >= 3.
    shifts : (N,) array, optional
        Phase shifts delta_k in radians; default 2 pi k / N (closed form). Otherwise the least
        squares solution of the 3-parameter model; the shifts must include three distinct
        values modulo 2 pi.

    Returns
    -------
    weights : (3, N) float64 array (read-only for the default shifts)
    """
    steps = _validate.positive_int(steps, "steps", minimum=3)
    if shifts is None:
        weights = _uniform_weights(steps)
        weights.flags.writeable = False
        return weights
    delta = _validate.finite_array(shifts, "shifts", ndim=1).astype(np.float64)
    if delta.shape[0] != steps:
        raise ValueError(f"shifts: expected {steps} values (one per frame), found {delta.shape[0]}")
    return _least_squares_weights(tuple(delta.tolist())).copy()


@lru_cache(maxsize=256)
def _least_squares_weights(delta: tuple[float, ...]) -> np.ndarray:
    """shift_weights of explicit shifts, cached: every capture of a rig repeats the same few sets."""
    steps = len(delta)
    shifts = np.asarray(delta)
    design = np.column_stack([np.ones(steps), np.cos(shifts), np.sin(shifts)])
    singular = np.linalg.svd(design, compute_uv=False)
    if singular[-1] < 1e-6 * singular[0]:
        raise ValueError("shifts: need at least three distinct shifts modulo 2 pi to separate A, B and phi")
    # Normal equations (M^T M) x = M^T I, solved once for all pixels.
    weights = np.linalg.solve(design.T @ design, design.T)
    weights[2] *= -1.0  # the model's sine coefficient is -B sin phi
    return weights


@dataclass(frozen=True)
class Demodulator:
    """Block-level demodulation of one stack, for kernels that go on from the coefficients.

    ``coefficients(frames)`` maps a block of frames (N, P) to (A, B cos phi, B sin phi)
    (without A when ``full`` is False) in the working dtype: float64 for float64 stacks,
    float32 (exact for 8- and 16-bit images) for everything else.
    """

    weights: np.ndarray
    dtype: type
    full: bool

    def coefficients(self, frames: np.ndarray) -> np.ndarray:
        return self.weights @ frames.astype(self.dtype, copy=False)


def demodulator(stack: np.ndarray, shifts: np.ndarray | None = None, full: bool = True) -> Demodulator:
    """Checked (N, H, W) stack -> the :class:`Demodulator` of its shifts (see :func:`shift_weights`)."""
    weights = shift_weights(stack.shape[0], shifts)
    dtype = np.float64 if stack.dtype == np.float64 else np.float32
    return Demodulator(np.ascontiguousarray(weights if full else weights[1:], dtype=dtype), dtype, full)


def block_angle(coeffs: np.ndarray) -> np.ndarray:
    """atan2(B sin phi, B cos phi) of a coefficient block, working dtype, in [-pi, pi]."""
    return np.arctan2(coeffs[-1], coeffs[-2])


def block_modulation(coeffs: np.ndarray) -> np.ndarray:
    """B = sqrt(c^2 + s^2) of a coefficient block."""
    return root_sum_square(coeffs[-2], coeffs[-1])


def root_sum_square(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """sqrt(first^2 + second^2) element-wise, a new array of the inputs' (promoted) dtype.

    Three passes with one temporary instead of ``np.hypot``, whose float32 loop is not vectorised
    on AVX2 CPUs (6.7 ms against 1.1 ms for 1024 x 768 float32, thread CPU time). In float32 it is
    within 1.5 ulp of the exact value (the squares, their sum and the root each rounded; tested),
    overflows where a square does (|x| > 1.8e19) and gives NaN where either input is NaN.
    """
    squared = np.multiply(first, first)
    squared += np.multiply(second, second)
    return np.sqrt(squared, out=squared)


def _folded(phase: np.ndarray) -> np.ndarray:
    """atan2 output as float64 in [-pi, pi) (float32 atan2 can return just above pi)."""
    phase = phase.astype(np.float64, copy=False)
    top = phase >= np.pi
    if top.any():  # rare: scanning the mask only when needed halves the cost
        phase[top] -= TWO_PI
    return phase


def _demodulate(stack: np.ndarray, shifts: np.ndarray | None, full: bool) -> tuple[np.ndarray, ...]:
    """(phase, background, modulation) or (phase,) as flat float64 arrays, block by block."""
    demod = demodulator(stack, shifts, full)

    def kernel(frames: np.ndarray) -> tuple[np.ndarray, ...]:
        coeffs = demod.coefficients(frames)
        phase = _folded(block_angle(coeffs))
        if not full:
            return (phase,)
        return phase, coeffs[0], block_modulation(coeffs)

    dtypes = (np.float64,) * (3 if full else 1)
    return blockwise(kernel, [stack.reshape(stack.shape[0], -1)], dtypes)


def check_stack(stack: np.ndarray) -> np.ndarray:
    """``stack`` as a real (N, H, W) array with N >= 3, else ValueError naming it."""
    arr = _validate.real_array(stack, "stack", ndim=3)
    if arr.shape[0] < 3:
        raise ValueError(f"stack: expected at least 3 frames (N, H, W), found shape {arr.shape}")
    return arr


def phase_shift(stack: np.ndarray, shifts: np.ndarray | None = None) -> PhaseShiftResult:
    """Wrapped phase, background and modulation of an N-step phase-shifted stack.

    Parameters
    ----------
    stack : (N, H, W) array, any integer or float dtype
        Frames I_k = A + B cos(phi + delta_k); N >= 3. Integer and float32 stacks are
        processed in float32 (exact for 8- and 16-bit images), float64 stacks in float64.
    shifts : (N,) array, optional
        delta_k in radians; default 2 pi k / N.

    Returns
    -------
    PhaseShiftResult
        ``phase`` in [-pi, pi), ``background`` A and ``modulation`` B, each (H, W) float64.

    Examples
    --------
    A 4-step stack of one row, A = 100, B = 50, phases -pi/2, pi/4 and pi/2:

    >>> import numpy as np
    >>> phi = np.array([[-np.pi / 2, np.pi / 4, np.pi / 2]])
    >>> stack = np.stack([100 + 50 * np.cos(phi + np.pi / 2 * k) for k in range(4)])
    >>> result = phase_shift(stack)
    >>> np.round(result.phase, 6)
    array([[-1.570796,  0.785398,  1.570796]])
    >>> np.round(result.background, 6), np.round(result.modulation, 6)
    (array([[100., 100., 100.]]), array([[50., 50., 50.]]))
    """
    arr = check_stack(stack)
    _, height, width = arr.shape
    phase, background, modulation = _demodulate(arr, shifts, full=True)
    return PhaseShiftResult(
        phase=phase.reshape(height, width),
        background=background.reshape(height, width),
        modulation=modulation.reshape(height, width),
    )


def wrapped_phase(stack: np.ndarray, shifts: np.ndarray | None = None) -> np.ndarray:
    """Wrapped phase from an N-step phase-shifted stack.

    Parameters
    ----------
    stack : (N, H, W) array
        Frames I_k = A + B cos(phi + delta_k); N >= 3.
    shifts : (N,) array, optional
        delta_k in radians; default 2 pi k / N.

    Returns
    -------
    phi : (H, W) float64 array in [-pi, pi)
    """
    arr = check_stack(stack)
    _, height, width = arr.shape
    (phase,) = _demodulate(arr, shifts, full=False)
    return phase.reshape(height, width)


def shadow_mask(
    modulation: np.ndarray,
    background: np.ndarray | None = None,
    min_modulation: float | None = None,
    min_ratio: float = 0.2,
) -> np.ndarray:
    """Pixels lit by the fringes with enough modulation to trust their phase.

    Parameters
    ----------
    modulation : (H, W) array
        Fringe amplitude B from :func:`phase_shift`.
    background : (H, W) array, optional
        Mean intensity A. When given, a pixel also needs a data modulation B / A >= ``min_ratio``
        (shadows lit only by ambient light have a background but almost no modulation).
    min_modulation : float, optional
        Absolute threshold on B in intensity units. Default (automatic): ``min_ratio`` times the
        99th percentile of B over the image (estimated on a regular subsample of about 16k
        pixels), a robust estimate of the modulation of a well-lit surface that ignores a few
        saturated or hot pixels.
    min_ratio : float
        Fraction in (0, 1] used by the automatic threshold and the data-modulation test.

    Returns
    -------
    valid : (H, W) bool array, True where the pixel is lit and well modulated; NaN is invalid.
    """
    b = _validate.image(modulation, "modulation").astype(np.float64, copy=False)
    ratio = _validate.finite_float(min_ratio, "min_ratio", minimum=0.0, strict=True)
    if ratio > 1.0:
        raise ValueError(f"min_ratio: expected a fraction in (0, 1], found {min_ratio!r}")
    if min_modulation is None:
        threshold = ratio * _robust_high(b)
    else:
        threshold = _validate.finite_float(min_modulation, "min_modulation", minimum=0.0)
    threshold = max(threshold, np.finfo(np.float64).tiny)  # B = 0 is never valid
    inputs = [b.reshape(-1)]
    if background is not None:
        a = _validate.image(background, "background").astype(np.float64, copy=False)
        _validate.same_shape(a, b.shape, "background")
        inputs.append(a.reshape(-1))

    def kernel(mod: np.ndarray, back: np.ndarray | None = None) -> tuple[np.ndarray]:
        valid = mod >= threshold  # NaN compares False
        if back is not None:
            valid &= back > 0
            valid &= mod >= ratio * back
        return (valid,)

    (valid,) = blockwise(kernel, inputs, (np.bool_,))
    return valid.reshape(b.shape)


MODULATION_SAMPLES = 1 << 14  # pixels of the regular subsample behind the automatic threshold


def sample_stride(shape: tuple[int, ...], samples: int = MODULATION_SAMPLES) -> int:
    """Stride of the regular subsample ``flat[::stride]`` of ~``samples`` pixels of an (H, W) map.

    The stride is coprime with the width, so the subsample visits every column, not a few.
    """
    stride = max(1, math.prod(shape) // samples)
    while math.gcd(stride, shape[-1]) != 1:
        stride += 1
    return stride


def fit_residual_variance(sample: np.ndarray, shifts: np.ndarray) -> np.ndarray:
    """Per-pixel residual variance ``sum r^2 / (J - 3)`` of the least-squares sinusoid fit of a
    (J, P) sample with phase shifts ``shifts`` (J,): the camera noise where the fringes are sinusoidal."""
    steps = sample.shape[0]
    residual = _residual_projector(tuple(np.asarray(shifts, dtype=np.float64).tolist())) @ sample
    return np.einsum("jp,jp->p", residual, residual) / (steps - 3)


@lru_cache(maxsize=32)
def _residual_projector(shifts: tuple[float, ...]) -> np.ndarray:
    """(J, J) matrix I - D D^+ taking a sample to its residual from the least-squares sinusoid fit.

    D = [1, cos delta, sin delta] (either sign convention spans the same fit). One product per
    sample instead of two and a pseudo-inverse: the noise estimate runs on every capture.
    """
    design = np.column_stack([np.ones(len(shifts)), np.cos(shifts), np.sin(shifts)])
    projector = np.eye(len(shifts)) - design @ np.linalg.pinv(design)
    projector.flags.writeable = False  # shared by every caller through the cache
    return projector


def robust_high(sample: np.ndarray, fallback: np.ndarray | None = None) -> float:
    """99th percentile of the finite values of a modulation ``sample`` (else of ``fallback``'s)."""
    sub = sample[np.isfinite(sample)]
    if sub.size == 0 and fallback is not None:
        sub = fallback[np.isfinite(fallback)]
    if sub.size == 0:
        raise ValueError("modulation: no finite value to derive a threshold from")
    return percentile(sub, 99.0)  # sub is a fresh copy: reordered in place


def _robust_high(modulation: np.ndarray) -> float:
    """99th percentile of the finite modulation, from a regular subsample of ~16k pixels."""
    flat = modulation.reshape(-1)
    return robust_high(flat[:: sample_stride(modulation.shape)], flat)


def quality_map(modulation: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Data modulation gamma = B / A, clipped to [0, 1]; 0 where A <= 0 or either is NaN.

    A fringe of full contrast has gamma = 1; shadows, ambient light and defocus lower it. Use it
    as the quality map of :func:`processing.unwrap.spatial.unwrap_quality_guided` or for thresholds that
    do not depend on the surface's reflectivity.

    Parameters
    ----------
    modulation, background : (H, W) arrays
        B and A from :func:`phase_shift`.

    Returns
    -------
    gamma : (H, W) float64 array in [0, 1]
    """
    b = _validate.image(modulation, "modulation").astype(np.float64, copy=False)
    a = _validate.image(background, "background").astype(np.float64, copy=False)
    _validate.same_shape(a, b.shape, "background")
    with np.errstate(divide="ignore", invalid="ignore"):
        gamma = np.where(a > 0, b / a, 0.0)
    return np.clip(np.nan_to_num(gamma, nan=0.0, posinf=0.0, neginf=0.0), 0.0, 1.0)
