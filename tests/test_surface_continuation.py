"""Step 6c: pixels kept one or two orders off go back where the measured order continues the settled surface."""

import numpy as np
import pytest

from processing.correction.surface_continuation import MARGIN_RAD, continuation_margin, restore_continued_orders

TWO_PI = 2.0 * np.pi


def _raised_corner(step_fringes: float) -> np.ndarray:
    """A ramp (0 - 3 rad across 12 columns) raised ``step_fringes`` above row 4 and right of column 7."""
    truth = np.tile(np.linspace(0.0, 3.0, 12), (10, 1))
    truth[:4, :] += step_fringes * TWO_PI
    truth[4:, 7:] += step_fringes * TWO_PI
    return truth


def _corner_kept_one_up(truth: np.ndarray) -> np.ndarray:
    kept = truth.copy()
    kept[4, 5:7] += TWO_PI  # the inner corner's pixels, each touching as many far-side pixels as near-side ones
    kept[5, 6] += TWO_PI
    return kept


def test_a_corner_of_a_step_of_one_and_a_half_fringes_goes_back():
    truth = _raised_corner(1.4)
    out, moved = restore_continued_orders(_corner_kept_one_up(truth), truth, np.ones(truth.shape, bool))
    assert moved == 3
    np.testing.assert_array_equal(out, truth)


def test_a_step_of_a_whole_fringe_stays_undecided():
    """Across a step of one whole fringe the kept order continues the far side as well as the measured one
    continues the near side: nothing tells them apart, nothing moves."""
    truth = _raised_corner(1.0)
    kept = _corner_kept_one_up(truth)
    out, moved = restore_continued_orders(kept, truth, np.ones(truth.shape, bool))
    assert moved == 0
    np.testing.assert_array_equal(out, kept)


def test_the_lower_frequencies_can_veto():
    truth = _raised_corner(1.4)
    kept = _corner_kept_one_up(truth)
    valid = np.ones(truth.shape, bool)

    def favours_kept(values: np.ndarray, where: np.ndarray) -> np.ndarray:
        return np.vstack([np.zeros(values.shape[1]), np.ones(values.shape[1])])  # kept fits, measured does not

    def favours_measured(values: np.ndarray, where: np.ndarray) -> np.ndarray:
        return np.vstack([np.ones(values.shape[1]), np.zeros(values.shape[1])])

    def shift(delta: np.ndarray) -> np.ndarray:
        return np.full(delta.shape, 1.0)

    assert restore_continued_orders(kept, truth, valid, favours_kept, shift)[1] == 0
    assert restore_continued_orders(kept, truth, valid, favours_measured, shift)[1] == 3


def test_changes_of_many_orders_are_not_judged():
    truth = _raised_corner(1.4)
    kept = truth.copy()
    kept[4, 5:7] += 3 * TWO_PI  # a wrong temporal order fixed by an earlier step looks like this
    out, moved = restore_continued_orders(kept, truth, np.ones(truth.shape, bool))
    assert moved == 0 and out is kept


def test_changes_of_many_orders_are_judged_where_the_lower_frequencies_tell_them_apart() -> None:
    """Three orders off at a step's corner (pooled from the far side), measured right: back where the lower
    frequencies tell the orders apart and favour the measured one; left where they cannot tell them apart (the
    close pairs' ambiguous shifts, where the measured order is as likely wrong)."""
    truth = _raised_corner(1.4)
    kept = truth.copy()
    kept[4, 5:7] += 3 * TWO_PI
    kept[5, 6] += 3 * TWO_PI
    valid = np.ones(truth.shape, bool)

    def favours_measured(values: np.ndarray, where: np.ndarray) -> np.ndarray:
        return np.vstack([np.ones(values.shape[1]), np.zeros(values.shape[1])])

    def shift(delta: np.ndarray) -> np.ndarray:
        return np.full(delta.shape, 1.0)

    seen: list[np.ndarray] = []

    def tells(orders: np.ndarray) -> np.ndarray:
        seen.append(orders)
        return np.ones(orders.shape, bool)

    out, moved = restore_continued_orders(kept, truth, valid, favours_measured, shift, tells)
    assert moved == 3 and np.all(np.abs(np.concatenate(seen)) == 3)
    np.testing.assert_array_equal(out, truth)
    blind = lambda orders: np.zeros(orders.shape, bool)  # noqa: E731
    assert restore_continued_orders(kept, truth, valid, favours_measured, shift, blind)[1] == 0
    assert restore_continued_orders(kept, truth, valid, None, None, tells)[1] == 0  # never without the evidence


def test_the_margin_shrinks_with_the_noise_so_a_step_near_a_whole_fringe_is_seen_at_high_snr() -> None:
    """A step of 1.05 fringes: the corner kept one order up continues the far side within 0.31 rad, the measured
    order the near side exactly. 0.5 rad of margin leaves it; at 0.02 rad of phase noise (3 deviations of a second
    difference: 0.15 rad) it goes back. At 0.15 rad of noise the margin stays 0.5 rad."""
    truth = _raised_corner(1.05)
    kept = _corner_kept_one_up(truth)
    valid = np.ones(truth.shape, bool)
    assert restore_continued_orders(kept, truth, valid)[1] == 0
    assert continuation_margin(0.02) == pytest.approx(3.0 * np.sqrt(6.0) * 0.02)
    assert continuation_margin(0.15) == MARGIN_RAD
    out, moved = restore_continued_orders(kept, truth, valid, margin=continuation_margin(0.02))
    assert moved == 3
    np.testing.assert_array_equal(out, truth)


def test_a_changed_pixel_beyond_a_settled_neighbour_carries_the_slope() -> None:
    # A column kept one order off on the map's edge: no side but the right one continues it, and there the pixel
    # beyond the settled neighbour keeps its (right) order against a measured slip of 3 orders.
    truth = np.tile(0.3 * np.arange(8.0), (5, 1))
    kept = truth.copy()
    kept[:, 0] += TWO_PI
    measured = truth.copy()
    measured[:, 2] += 3 * TWO_PI
    out, moved = restore_continued_orders(kept, measured, np.ones(truth.shape, dtype=bool))
    assert moved == 5
    np.testing.assert_array_equal(out[:, 0], truth[:, 0])
    np.testing.assert_array_equal(out[:, 2], truth[:, 2])  # the slipped pixel is not judged: 3 orders off


def test_a_tie_the_continuation_cannot_break_goes_to_the_lower_frequencies_where_the_noise_tells_the_orders_apart() -> (
    None
):
    """Across a step of one whole fringe both orders continue a side equally well; where the phase noise alone
    separates the two orders' lower-frequency predictions, their misfit decides (no margin asked)."""
    truth = _raised_corner(1.0)
    kept = _corner_kept_one_up(truth)
    valid = np.ones(truth.shape, bool)

    def favours(measured: bool):
        def misfit(values: np.ndarray, where: np.ndarray) -> np.ndarray:
            rows = [np.ones(values.shape[1]), np.zeros(values.shape[1])]
            return np.vstack(rows if measured else rows[::-1])

        return misfit

    def shift(delta: np.ndarray) -> np.ndarray:
        return np.full(delta.shape, 1.0)

    def separable(orders: np.ndarray) -> np.ndarray:
        return np.ones(orders.shape, bool)

    def inseparable(orders: np.ndarray) -> np.ndarray:
        return np.zeros(orders.shape, bool)

    out, moved = restore_continued_orders(kept, truth, valid, favours(True), shift, separable=separable)
    assert moved == 3
    np.testing.assert_array_equal(out, truth)
    assert restore_continued_orders(kept, truth, valid, favours(False), shift, separable=separable)[1] == 0
    assert restore_continued_orders(kept, truth, valid, favours(True), shift, separable=inseparable)[1] == 0
