"""Changed pixels go back to their measured order where it continues the settled surface around them.

Counting order breaks cannot place a pixel at the corner of a height step of a fringe and a half, or on a
line along a steep slope: one order off, such a pixel breaks with as many neighbours as with its right order
(a corner pixel touches as many far-side pixels as near-side ones). Its phase can: on at least one side
the surface it lies on continues through it, and a linear extrapolation of two pixels on that side
(``2 phi(p + d) - phi(p + 2 d)``) predicts its phase within the noise, while the other order lies a whole fringe
from that prediction and, across a step of a fraction ``s`` of a fringe off a whole one, ``s`` fringes from the
far side's.

Only pixels whose kept order differs from the measured one by one or two orders are judged, and pixels further
off only where the lower frequencies tell the two orders apart (``telling``): a change they cannot see (11 orders
of 32 at 29, 7 of 25 at 18) is what the close pairs' dense errors make, and there the measured order is as
likely the wrong one. They are judged against
extrapolations from settled pixels (kept order = measured order, or moved back here), so a blob of
changed pixels mends from its rim, up to :data:`PASSES` passes. The pixel beyond the settled neighbour need
only continue it (within pi): where its measured order slipped but its kept one is right, it still carries the
surface's slope (a strip a few pixels wide along a step, its pixels' measured orders slipping at random, has
few pairs of settled pixels in a row).
A pixel moves back only where the measured order's nearest extrapolation lies within :data:`TOLERANCE_RAD`
and nearer than the kept order's by :data:`MARGIN_RAD` (or by three noise deviations of an extrapolation where
that is less: :func:`continuation_margin`), and, with the lower frequencies, where their misfit
favours the measured order by more than half its expected shift: two weak pieces of evidence agreeing. Where
both orders continue a side (a step of about a whole fringe: the kept order continues one side as well as the
measured order the other) the margin never holds; there, if the phase noise alone tells the two orders'
lower-frequency predictions apart (``separable``), a measured order continuing its side at least as well goes
back on the lower frequencies' word.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from processing.correction.order_evidence import neighbours_at
from processing.correction.temporal_evidence import Z_MARGIN
from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi
# Passes over the pixels still judged: a blob mends from its rim inward, a pass per ring.
PASSES = 8
# The measured order's nearest extrapolation must lie within this (about pi / 2: half the way to a break; the
# extrapolation's noise is sqrt(6) times the phase noise, 0.3 rad at 15 dB)...
TOLERANCE_RAD = 1.6
# ... and nearer than the kept order's by this much.
MARGIN_RAD = 0.5
# Pixels kept within this many orders of the measured one are judged (one or two orders: the close pairs'
# ambiguity); pixels further off only where the lower frequencies tell the orders apart.
MAX_ORDERS = 2.5


def continuation_margin(sigma: float) -> float:
    """The margin for phase noise ``sigma`` (rad): :data:`MARGIN_RAD`, or :data:`~processing.correction.
    temporal_evidence.Z_MARGIN` standard deviations of an extrapolation's residual (``sqrt(6) sigma``: a second
    difference) where that is less. A pixel whose kept order continues its own side lies within the noise of that
    side's extrapolation, so the measured order's must beat it by more than the noise; at high SNR that is far
    less than half a radian, and a step a twentieth of a fringe off a whole one (0.3 rad) is seen."""
    return float(min(MARGIN_RAD, Z_MARGIN * np.sqrt(6.0) * sigma))


def extrapolations(
    phase: np.ndarray, settled: np.ndarray, beyond: np.ndarray, ys: np.ndarray, xs: np.ndarray
) -> np.ndarray:
    """(4, n): ``2 phase(p + d) - phase(p + 2 d)`` for each 4-direction ``d`` where the pixel next to ``p`` is
    ``settled``, the one beyond it in ``beyond`` and the two lie within pi of each other (continuous), else NaN."""
    near = neighbours_at(phase, settled, ys, xs)
    far = neighbours_at(phase, beyond, ys, xs, reach=2)
    with np.errstate(invalid="ignore"):
        continuous = np.abs(near - far) <= np.pi  # NaN (unsettled or off the map): False
    return np.where(continuous, 2.0 * near - far, np.nan)


def nearest_residual(values: np.ndarray, predicted: np.ndarray) -> np.ndarray:
    """Smallest |value - prediction| over the directions (inf where none is available)."""
    with np.errstate(invalid="ignore"):
        residual = np.abs(predicted - values[None, :])
    return np.where(np.isnan(residual), np.inf, residual).min(axis=0)


def restore_continued_orders(
    kept: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    shift: Callable[[np.ndarray], np.ndarray] | None = None,
    telling: Callable[[np.ndarray], np.ndarray] | None = None,
    margin: float = MARGIN_RAD,
    separable: Callable[[np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, int]:
    """``kept`` with changed pixels back on their measured order where it continues the settled surface;
    how many moved. ``misfit(values, where)``: the lower frequencies' misfit as in
    :func:`~processing.correction.broken_pixels.mend_broken_pixels`; ``shift(delta_orders)``: its expected
    increase for an order change (both optional, together); ``telling(delta_orders)``: whether they tell orders
    that far apart from each other (with both others only: pixels beyond :data:`MAX_ORDERS` are judged where it
    says so); ``margin``: how much nearer than the kept order's the measured order's extrapolation must lie
    (default :data:`MARGIN_RAD`; :func:`continuation_margin` gives it from the phase noise);
    ``separable(delta_orders)``: whether the phase noise alone tells the orders apart (with ``misfit`` and
    ``shift``): there a measured order that continues a settled side at least as well as the kept order continues
    one goes back without the margin, the lower frequencies deciding the tie.

    Examples
    --------
    A ramp raised 1.4 fringes above row 3 and right of column 6, with three pixels at the inner corner kept one
    order up (each breaks with as many neighbours as on its measured order):

    >>> import numpy as np
    >>> truth = np.tile(np.linspace(0.0, 3.0, 10), (8, 1))
    >>> truth[:3, :] += 1.4 * 2 * np.pi
    >>> truth[3:, 6:] += 1.4 * 2 * np.pi
    >>> kept = truth.copy()
    >>> kept[3, 4:6] += 2 * np.pi
    >>> kept[4, 5] += 2 * np.pi
    >>> out, moved = restore_continued_orders(kept, truth, np.ones((8, 10), bool))
    >>> bool(np.allclose(out, truth)), moved
    (True, 3)
    """
    delta = abs_difference(kept, measured)
    with np.errstate(invalid="ignore"):
        changed = valid & (delta > np.pi)
        todo = changed & (delta < MAX_ORDERS * TWO_PI)
    if telling is not None and misfit is not None and shift is not None:
        far = np.flatnonzero(changed & ~todo)
        orders = np.rint((kept.reshape(-1)[far] - measured.reshape(-1)[far]) / TWO_PI)
        todo.reshape(-1)[far[telling(orders)]] = True
    if not todo.any():
        return kept, 0
    out, settled = kept.copy(), valid & ~changed
    ys, xs = np.nonzero(todo)
    total = 0
    for _ in range(PASSES):
        moved = _judge(out, measured, settled, ys, xs, misfit, shift, margin, valid, separable)
        if not moved.any():
            break
        out[ys[moved], xs[moved]] = measured[ys[moved], xs[moved]]
        settled[ys[moved], xs[moved]] = True
        total += int(np.count_nonzero(moved))
        ys, xs = ys[~moved], xs[~moved]
    return out, total


def _judge(
    out: np.ndarray,
    measured: np.ndarray,
    settled: np.ndarray,
    ys: np.ndarray,
    xs: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None,
    shift: Callable[[np.ndarray], np.ndarray] | None,
    margin: float,
    valid: np.ndarray,
    separable: Callable[[np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """Which of the pixels (row-major) go back to their measured order this pass: the measured order continues
    a settled side within :data:`TOLERANCE_RAD`, by ``margin`` better than the kept one (or, where ``separable``
    says so, at least as well), and the lower frequencies' misfit (when given) grows by more than half the
    expected shift with the kept order."""
    # the pixel beyond a settled neighbour need only continue it: a changed pixel there whose kept order is right
    # (its measured one a noise slip) still carries the surface's slope
    predicted = extrapolations(out, settled, valid, ys, xs)
    here, back = out[ys, xs], measured[ys, xs]
    r_kept, r_back = nearest_residual(here, predicted), nearest_residual(back, predicted)
    move = (r_back < TOLERANCE_RAD) & (r_back + margin < r_kept)
    if misfit is None or shift is None:
        return move
    orders = np.rint((here - back) / TWO_PI)
    if separable is not None:  # a tie the continuation cannot break, where the lower frequencies can
        move |= (r_back < TOLERANCE_RAD) & (r_back <= r_kept) & separable(orders)
    if move.any():
        where = np.zeros(settled.shape, dtype=bool)
        where[ys, xs] = True  # ys, xs are row-major: the mask's order
        fits = misfit(np.vstack([here, back]), where)
        move &= fits[0] - fits[1] > 0.5 * shift(orders)
    return move
