"""Fringe orders that put the absolute phase outside the pattern: moved back by the period no frequency sees.

The absolute phase of a sinusoid is 2 pi f u / W (the projector coordinate u in radians; capture
format), so every lit pixel lies in [0, 2 pi f). Temporal unwrapping does not know this: where the
beat or the lower frequency's phase is off (a shadow's edge, low contrast), it can land a whole
number of *invisible periods* away, P = 2 pi f / g orders of the highest frequency with g the
greatest common divisor of the integer frequencies. A shift of P moves every lower frequency's
prediction by whole turns, so the lower frequencies fit it exactly as well as the truth and no
temporal evidence can object; for coprime frequencies P is the pattern's whole range, so such a
pixel is always out of range (measured on develop cases of the drawn family: blobs of a few hundred
pixels 32 orders off at 32/29/27, which every later step of ``auto`` kept).

A pixel beyond the range by any amount moves by the fewest whole periods that bring it in. The
measured orders stay, blob by blob, only where they leave fewer order breaks with the neighbours than
the moved ones (:func:`~processing.correction.order_evidence.keep_supported_changes`): a pixel just
beyond the range's end by noise, or a capture whose phase convention is off by a constant, continues
its neighbours as measured and stays. Where the neighbours cannot tell (an island beside a shadow,
as many breaks either way), the range decides: the measured orders cannot be right.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from processing.correction.order_evidence import changed_orders, keep_supported_changes

TWO_PI = 2.0 * np.pi


def invisible_period(frequency: float, lower_frequencies: Sequence[float]) -> float | None:
    """The phase shift (rad) at ``frequency`` that moves every lower frequency's prediction by whole turns:
    2 pi f / gcd(all frequencies); None unless every frequency is a whole number of fringes."""
    frequencies = [float(frequency), *(float(f) for f in lower_frequencies)]
    if not all(f > 0 and f.is_integer() for f in frequencies):
        return None
    divisor = 0
    for f in frequencies:
        divisor = math.gcd(divisor, int(f))
    return TWO_PI * (int(frequency) // divisor)


def folded_into_range(phase: np.ndarray, valid: np.ndarray, frequency: float, period: float) -> np.ndarray:
    """``phase`` with each valid pixel outside [0, 2 pi ``frequency``) moved by the fewest whole ``period`` s
    that bring it in (NaN elsewhere untouched); the same array where none lies outside."""
    top = TWO_PI * float(frequency)
    with np.errstate(invalid="ignore"):
        outside = valid & ((phase < 0.0) | (phase >= top))
    if not outside.any():
        return phase
    at = np.flatnonzero(outside)
    values = np.ravel(phase)[at]
    # below 0: up by ceil(-v / P) periods; from the top on: down by floor((v - top) / P) + 1
    turns = np.where(values < 0.0, np.ceil(-values / period), -np.floor((values - top) / period) - 1.0)
    out = phase.copy()
    out.reshape(-1)[at] = values + turns * period
    return out


def keep_range_folds(
    phase: np.ndarray, valid: np.ndarray, frequency: float, lower_frequencies: Sequence[float]
) -> tuple[np.ndarray, int]:
    """``phase`` with the out-of-range pixels folded back where their neighbours support it; how many moved.

    Without an invisible period (non-integer frequencies), or with nothing out of range, ``phase`` itself.
    """
    period = invisible_period(frequency, lower_frequencies)
    if period is None:
        return phase, 0
    folded = folded_into_range(phase, valid, frequency, period)
    if folded is phase:
        return phase, 0
    # the measured orders stay only where they leave fewer breaks: out of range they cannot be right, so a
    # blob the neighbours cannot judge (an island beside a shadow, as many breaks either way) is folded
    kept, _ = keep_supported_changes(phase, folded, valid)
    return kept, int(np.count_nonzero(changed_orders(kept, phase, valid)))
