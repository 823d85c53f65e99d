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

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

TWO_PI = 2.0 * np.pi
AGREEMENT_SIGMAS = 4.0  # a lower frequency further than this from the highest (in sigma of the difference) is left out


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
) -> FusedPhase:
    """The inverse-variance weighted absolute phase of every frequency, in the highest's units.

    Parameters
    ----------
    absolute : float array
        Absolute phase of the highest frequency (``frequencies[-1]``), NaN where unknown.
    wrapped, modulation : sequences of float arrays of ``absolute``'s shape
        Wrapped phase (any 2 pi representation) and fringe amplitude B of every frequency, lowest
        first; the highest's wrapped phase is not read (``absolute`` holds it).
    frequencies : sequence of float
        Fringe counts, lowest first, the highest last (need not be whole).
    steps : sequence of int
        Phase steps J of each frequency (>= 3).
    sigma_i : float
        Camera noise standard deviation (grey levels), for the agreement test and ``sigma``.
    out : float32 array, optional
        Where to write the fused phase (may be ``absolute`` itself).

    Returns
    -------
    FusedPhase
    """
    count = len(frequencies)
    if not (len(wrapped) == len(modulation) == len(steps) == count) or count == 0:
        raise ValueError(
            f"wrapped, modulation, steps: expected {count} entries each (one per frequency), found "
            f"{len(wrapped)}, {len(modulation)}, {len(steps)}"
        )
    top = float(frequencies[-1])
    base = np.asarray(absolute, dtype=np.float32)
    noise = np.float32(2.0 * float(sigma_i) ** 2)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        b_top = np.asarray(modulation[-1], dtype=np.float32)
        total = np.multiply(b_top, b_top, dtype=np.float32)
        total *= np.float32(steps[-1])  # w_K = J_K B_K^2
        shift = np.zeros_like(base)  # sum_k w_k (Phi_K^(k) - Phi_K)
        disagree = np.zeros(base.shape, dtype=bool)
        for k in range(count - 1):
            ratio = top / float(frequencies[k])
            weight, offset = _lower_frequency(base, wrapped[k], modulation[k], steps[k], ratio, total, noise)
            disagree |= weight == 0
            shift += weight * offset
            total += weight
        fused = np.divide(shift, total, out=shift)
        np.nan_to_num(fused, copy=False, nan=0.0, posinf=0.0, neginf=0.0)  # no usable weight: Phi_K itself
        phase = np.add(base, fused, out=out if out is not None else None, dtype=np.float32)
        sigma = np.sqrt(np.divide(noise, total, out=total), out=total)
    finite = np.isfinite(base)
    return FusedPhase(phase, sigma, int(np.count_nonzero(disagree & finite)))


def _lower_frequency(
    base: np.ndarray,
    wrapped: np.ndarray,
    modulation: np.ndarray,
    steps: int,
    ratio: float,
    top_weight: np.ndarray,
    noise: np.float32,
) -> tuple[np.ndarray, np.ndarray]:
    """Weight (0 where it disagrees or is unknown) and offset Phi_K^(k) - Phi_K of one lower frequency.

    ``ratio`` = f_K / f_k; ``top_weight`` = J_K B_K^2 (the agreement test's other variance).
    """
    phi = np.asarray(wrapped, dtype=np.float32)
    scale = np.float32(1.0 / ratio)
    # its absolute phase, unwrapped with the highest's: phi + 2 pi rint((Phi_K / r - phi) / 2 pi), scaled by r
    expected = base * scale
    order = np.subtract(expected, phi)
    order *= np.float32(1.0 / TWO_PI)
    np.rint(order, out=order)
    order *= np.float32(TWO_PI)
    order += phi
    order -= expected
    offset = np.multiply(order, np.float32(ratio), out=order)  # Phi_K^(k) - Phi_K, in the highest's units
    b = np.asarray(modulation, dtype=np.float32)
    weight = np.multiply(b, b, dtype=np.float32)
    weight *= np.float32(steps * scale * scale)  # J_k B_k^2 (f_k / f_K)^2
    # agreement: offset^2 <= c^2 var(difference) = c^2 noise (1 / w_k + 1 / w_K), and |offset| < pi
    spread = np.reciprocal(weight)
    spread += np.reciprocal(top_weight)
    spread *= np.float32(AGREEMENT_SIGMAS**2) * noise
    np.minimum(spread, np.float32(np.pi**2), out=spread)
    agrees = np.square(offset) <= spread  # NaN (unknown phase or modulation) compares False
    np.copyto(weight, np.float32(0.0), where=~agrees)
    np.copyto(offset, np.float32(0.0), where=~agrees)
    return weight, offset
