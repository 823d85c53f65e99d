"""Every phase-shifted frequency's evidence in the final absolute phase, weighted by its noise.

Temporal unwrapping gives the absolute phase ``Phi_K`` of the highest frequency ``f_K``; the
lower frequencies only served to find its fringe order. Yet each of them measures the same
projector coordinate: unwrapped with ``Phi_K`` (order ``k = rint((Phi_K f_k / f_K - phi_k) / 2 pi)``)
and scaled to the highest frequency's units, frequency ``k`` gives

    Phi_K^(k) = (f_K / f_k) (phi_k + 2 pi k),    var = (f_K / f_k)^2 2 sigma_I^2 / (J_k B_k^2)

(``J_k`` steps, modulation ``B_k``, camera noise ``sigma_I``: the phase-shifting noise model of
:mod:`processing.geometry.uncertainty`). The frames of different frequencies carry independent
noise, so the minimum-variance combination is the inverse-variance weighted mean,

    w_k = J_k B_k^2 (f_k / f_K)^2,   Phi = Phi_K + sum_k w_k (Phi_K^(k) - Phi_K) / sum_k w_k,
    var(Phi) = 2 sigma_I^2 / sum_k w_k

(``sigma_I`` cancels from the weights). Close frequencies (two-frequency pairs such as 15 and 16,
heterodyne sets such as 64, 58, 53) each carry nearly the highest's weight; a unit frequency under
64 carries 1/4096 of it and changes nothing.

A frequency enters a pixel only where it agrees with the highest: ``|Phi_K^(k) - Phi_K|`` within
:data:`AGREEMENT_SIGMAS` standard deviations of their difference and under pi (a larger offset
would move the highest frequency's fringe order). Where it disagrees (a slip of its own order, a
shadow edge, a specular spot in one set) it is left out of that pixel; a pixel where every lower
frequency disagrees keeps the highest's value. :func:`fuse_frequencies` counts those pixels.

Everything is element-wise: the functions take maps or flat blocks of any shape alike.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

TWO_PI = 2.0 * np.pi
# A lower frequency further than this from the highest (in standard deviations of their difference)
# is left out: 6 rejects by chance ~2e-9 of the pixels (none of a megapixel image), while 4 would
# reject 6e-5, pixels whose large but honest noise then costs the fused phase 0.05 % of RMS error.
AGREEMENT_SIGMAS = 6.0
_INVERSE_TWO_PI = np.array(1.0 / TWO_PI, dtype=np.float32)
_PI_SQUARED = np.array(np.pi**2, dtype=np.float32)
_MIN_SCALED_BOUND = 1e-6  # smallest c^2 2 sigma_I^2 (grey^2) whose weights are scaled by its inverse


@dataclass
class FusedPhase:
    """Output of :func:`fuse_frequencies` (arrays of the input's shape, float32).

    ``phase``: the fused absolute phase at the highest frequency (NaN where the input was).
    ``sigma``: its predicted standard deviation (rad), sqrt(2 sigma_I^2 / sum w). ``disagreeing``:
    pixels (finite phase) where at least one lower frequency was left out for disagreeing.
    """

    phase: np.ndarray
    sigma: np.ndarray
    disagreeing: int


def fuse_frequencies(
    absolute: np.ndarray,
    wrapped: Sequence[np.ndarray],
    frequencies: Sequence[float],
    modulation: Sequence[np.ndarray],
    steps: Sequence[int],
    sigma_i: float,
    out: np.ndarray | None = None,
    sigma_out: np.ndarray | None = None,
) -> FusedPhase:
    """The inverse-variance weighted absolute phase of every frequency, in the highest's units.

    Parameters
    ----------
    absolute : float array
        Absolute phase of the highest frequency (``frequencies[-1]``), NaN where unknown.
    wrapped, modulation : sequences of float arrays of ``absolute``'s shape
        Wrapped phase (any 2 pi representation) and fringe amplitude B of every frequency, lowest
        first; the highest's wrapped phase is not read (``absolute`` holds it). A NaN in a lower
        frequency's maps makes the fused phase NaN there (a phase needs all its frames).
    frequencies : sequence of float
        Fringe counts, lowest first, the highest last (need not be whole).
    steps : sequence of int
        Phase steps J of each frequency (>= 3).
    sigma_i : float
        Camera noise standard deviation (grey levels), for the agreement test and ``sigma``.
    out, sigma_out : float32 arrays, optional
        Where to write the fused phase (may be ``absolute`` itself) and its sigma.

    Returns
    -------
    FusedPhase
        The phase is NaN where ``absolute`` is, or where no frequency has modulation.
    """
    count = len(frequencies)
    if not (len(wrapped) == len(modulation) == len(steps) == count) or count == 0:
        raise ValueError(
            f"wrapped, modulation, steps: expected {count} entries each (one per frequency), found "
            f"{len(wrapped)}, {len(modulation)}, {len(steps)}"
        )
    top = float(frequencies[-1])
    base = np.asarray(absolute, dtype=np.float32)
    unit, bound, noise_unit = weight_unit(sigma_i)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        top_weight = _scaled_square(modulation[-1], steps[-1] * unit)  # w_K = J_K B_K^2
        total, shift, agreeing = top_weight, None, None  # sum_k w_k; sum_k w_k (Phi_K^(k) - Phi_K)
        for k in range(count - 1):
            weight, offset, agrees = _lower_frequency(
                base, wrapped[k], modulation[k], steps[k] * unit, top / float(frequencies[k]), top_weight, bound
            )
            total = np.add(top_weight, weight) if shift is None else np.add(total, weight, out=total)
            offset *= weight
            shift = offset if shift is None else np.add(shift, offset, out=shift)
            agreeing = agrees if agreeing is None else np.logical_and(agreeing, agrees, out=agreeing)
        if shift is None:  # one frequency: nothing to combine
            total = total.copy()
            phase = base.copy() if out is None else out
            if out is not None and out is not base:
                np.copyto(out, base)
        else:
            shift /= total
            phase = np.add(base, shift, out=out if out is not None else shift)
        sigma = np.divide(_constant(noise_unit), total, out=sigma_out if sigma_out is not None else total)
        _sqrt_into(sigma)
    if agreeing is None:
        return FusedPhase(phase, sigma, 0)
    finite = base.size - int(np.count_nonzero(np.isnan(base)))
    return FusedPhase(phase, sigma, finite - int(np.count_nonzero(agreeing)))


def weight_unit(sigma_i: float) -> tuple[float, float, float]:
    """The unit u the weights are taken in, the agreement bound c^2 2 sigma_I^2 u and the noise 2 sigma_I^2 u.

    Weights in units of 1 / (c^2 2 sigma_I^2) make the agreement bound their plain sum (one product
    fewer per frequency). Below :data:`_MIN_SCALED_BOUND` (sigma_I ~1e-4 grey, far under 8-bit rounding)
    the scaled products could overflow float32: the weights stay unscaled and the bound is multiplied.
    """
    noise = 2.0 * float(sigma_i) ** 2
    agreement = AGREEMENT_SIGMAS**2 * noise
    unit = 1.0 / agreement if agreement >= _MIN_SCALED_BOUND else 1.0
    return unit, agreement * unit, noise * unit


def _scaled_square(values: np.ndarray, scale: float) -> np.ndarray:
    """``scale`` x values^2 as a new float32 array: OpenCV's scaled product, one pass instead of two."""
    v = np.ascontiguousarray(values, dtype=np.float32)
    out = np.empty(v.shape, dtype=np.float32)
    if v.size:
        flat = v.reshape(-1)
        _cv2().multiply(flat, flat, out.reshape(-1), scale=float(scale))
    return out


def _sqrt_into(values: np.ndarray) -> None:
    """Square root of a float32 array in place (OpenCV's vectorised root: about half numpy's time, the same
    correctly rounded values)."""
    if values.size and values.flags.c_contiguous:
        flat = values.reshape(-1)
        _cv2().sqrt(flat, flat)
    else:
        np.sqrt(values, out=values)


@functools.cache
def _cv2() -> Any:
    """The cv2 module (a dependency), imported on first use."""
    import cv2

    return cv2


def _constant(value: float) -> np.ndarray:
    """A float32 scalar as a 0-d array: numpy's ufuncs take it several times faster than a NumPy scalar."""
    return np.array(value, dtype=np.float32)


def _lower_frequency(
    base: np.ndarray,
    wrapped: np.ndarray,
    modulation: np.ndarray,
    steps: float,
    ratio: float,
    top_weight: np.ndarray,
    bound_scale: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Weight (0 where it disagrees), offset Phi_K^(k) - Phi_K and agreement of one lower frequency.

    ``ratio`` = f_K / f_k; ``steps`` = J_k u and ``top_weight`` = w_K = J_K B_K^2 u in the weights'
    unit u; ``bound_scale`` = c^2 2 sigma_I^2 u. The agreement test
    ``offset^2 <= c^2 2 sigma_I^2 (1 / w_k + 1 / w_K)`` is evaluated without reciprocals as
    ``offset^2 w_k w_K <= c^2 2 sigma_I^2 u (w_k + w_K)`` (numpy's masked copies cost ten products);
    with u = 1 / (c^2 2 sigma_I^2) the bound is the plain sum.
    """
    phi = np.asarray(wrapped, dtype=np.float32)
    # (phi_k - Phi_K / r) / 2 pi wrapped to [-1/2, 1/2] turns: its absolute phase's offset, unwrapped with Phi_K's
    turns = np.multiply(phi, _INVERSE_TWO_PI)
    offset = np.multiply(base, _constant(1.0 / (TWO_PI * ratio)))
    np.subtract(turns, offset, out=offset)
    np.rint(offset, out=turns)
    offset -= turns
    offset *= _constant(TWO_PI * ratio)  # in radians of the highest frequency
    weight = _scaled_square(modulation, steps / ratio**2)  # w_k = J_k B_k^2 (f_k / f_K)^2
    square = np.multiply(offset, offset, out=turns)
    agrees = np.less(square, _PI_SQUARED)  # under half a fringe of the highest frequency
    square *= weight
    square *= top_weight
    bound = np.add(weight, top_weight)
    if bound_scale != 1.0:
        bound *= _constant(bound_scale)
    agrees &= np.less_equal(square, bound)  # NaN compares False
    weight *= agrees
    return weight, offset, agrees
