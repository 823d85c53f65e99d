"""auto's arbitration between its kept fringe orders and its low-rank surface's (processing.correction.surface_orders).

Analytic maps where the answer is known: a patch of wrong kept orders L has right, a patch standing a
whole number of fringes proud that L smoothed away (the lower frequencies keep it), and a one-pixel-wide
column beside a step that either order fits as well (unresolved without lower frequencies, decided by
them with).
"""

from __future__ import annotations

import numpy as np

from processing.angles import wrap_to_pi
from processing.correction.surface_orders import arbitrate_low_rank_orders

TWO_PI = 2.0 * np.pi
SHAPE = (30, 50)
F_HIGH, F_LOW = 17.0, 13.0
# 1 / noise variance of the lower frequency's phase (0.05 rad standard deviation)
WEIGHTS = [1.0 / 0.05**2]


def _ramp() -> np.ndarray:
    return np.tile(np.linspace(0.0, 40.0, SHAPE[1]), (SHAPE[0], 1))


def _lower(truth: np.ndarray) -> list[tuple[float, np.ndarray]]:
    return [(F_LOW, wrap_to_pi(truth * F_LOW / F_HIGH))]


def test_a_patch_of_wrong_kept_orders_takes_the_surface_orders() -> None:
    truth = _ramp()
    kept = truth.copy()
    kept[10:13, 20:23] -= 2 * TWO_PI
    valid = np.ones(SHAPE, dtype=bool)
    out, unresolved, moved = arbitrate_low_rank_orders(kept, truth + 0.3, valid, F_HIGH, _lower(truth), WEIGHTS)
    np.testing.assert_allclose(out, truth)
    assert moved == 9 and not unresolved.any()


def test_a_patch_a_whole_number_of_fringes_proud_stays_where_the_lower_frequencies_see_it() -> None:
    """L smoothed the patch away: its orders leave no break, the kept ones a ring of them; the 13-fringe
    phase says the patch is real, so the kept orders stay."""
    background = _ramp()
    truth = background.copy()
    truth[10:16, 20:26] += 3 * TWO_PI
    valid = np.ones(SHAPE, dtype=bool)
    out, unresolved, moved = arbitrate_low_rank_orders(truth, background, valid, F_HIGH, _lower(truth), WEIGHTS)
    np.testing.assert_array_equal(out, truth)
    assert moved == 0 and not unresolved.any()
    # without the lower frequencies the breaks alone decide, and L's orders win
    out, _, moved = arbitrate_low_rank_orders(truth, background, valid)
    assert moved == 36
    np.testing.assert_allclose(out, background)


def _column_beside_a_step() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat halves 4 rad apart; the column between them fits either side as well: (on the right side's
    order, on the left side's, L = the left side's)."""
    right = np.zeros(SHAPE)
    right[:, 25:] = 4.0
    left = right.copy()
    left[:, 25] -= TWO_PI
    surface = np.zeros(SHAPE)
    surface[:, 26:] = 4.0
    return right, left, surface


def test_a_column_either_order_fits_is_unresolved_and_the_kept_order_stays() -> None:
    right, _, surface = _column_beside_a_step()
    valid = np.ones(SHAPE, dtype=bool)
    out, unresolved, moved = arbitrate_low_rank_orders(right, surface, valid)
    np.testing.assert_array_equal(out, right)
    assert moved == 0
    assert unresolved[:, 25].all() and unresolved.sum() == SHAPE[0]


def test_a_tie_the_lower_frequencies_clearly_decide_takes_their_side() -> None:
    kept, truth, surface = _column_beside_a_step()
    valid = np.ones(SHAPE, dtype=bool)
    out, unresolved, moved = arbitrate_low_rank_orders(kept, surface, valid, F_HIGH, _lower(truth), WEIGHTS)
    np.testing.assert_allclose(out, truth)
    assert moved == SHAPE[0] and not unresolved.any()
    # and where they say the kept order is right, it stays, decided: not unresolved
    out, unresolved, moved = arbitrate_low_rank_orders(kept, surface, valid, F_HIGH, _lower(kept), WEIGHTS)
    np.testing.assert_array_equal(out, kept)
    assert moved == 0 and not unresolved.any()
