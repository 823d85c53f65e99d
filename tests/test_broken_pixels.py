"""Pixels breaking with three or four neighbours (processing.correction.broken_pixels), on analytic maps."""

from __future__ import annotations

import numpy as np

from processing.angles import wrap_to_pi
from processing.correction.broken_pixels import mend_broken_pixels
from processing.correction.temporal_evidence import lower_frequency_misfit

TWO_PI = 2.0 * np.pi
SHAPE = (24, 32)


def _step() -> np.ndarray:
    """A ramp with a step of 10 rad (more than a fringe) between columns 15 and 16."""
    phase = np.tile(np.linspace(0.0, 6.0, SHAPE[1]), (SHAPE[0], 1))
    phase[:, 16:] += 10.0
    return phase


def test_a_run_beside_a_step_mends_and_the_step_stays() -> None:
    truth = _step()
    kept = truth.copy()
    kept[8:12, 15] += 8 * TWO_PI  # a run of four along the edge, eight orders off: no pixel of it is a spike
    out, moved = mend_broken_pixels(kept, np.ones(SHAPE, dtype=bool))
    np.testing.assert_allclose(out, truth)
    assert moved == 4


def _misfit(truth: np.ndarray, f_high: float, f_low: float):
    lower = wrap_to_pi(truth * f_low / f_high)

    def misfit(values: np.ndarray, where: np.ndarray) -> np.ndarray:
        return lower_frequency_misfit(values, f_high, [(f_low, lower[where])])

    return misfit


def test_the_lower_frequencies_veto_a_move_they_fit_worse() -> None:
    """A one-pixel-wide column standing two fringes proud, real: its neighbours would pull it down, the lower
    frequency's phase (13 of 17 fringes) says it is where it is."""
    truth = np.tile(np.linspace(0.0, 6.0, SHAPE[1]), (SHAPE[0], 1))
    truth[4:20, 10] += 2 * TWO_PI
    valid = np.ones(SHAPE, dtype=bool)
    out, moved = mend_broken_pixels(truth, valid, _misfit(truth, 17.0, 13.0))
    np.testing.assert_array_equal(out, truth)
    assert moved == 0
    # without the lower frequency the neighbours alone decide (and are wrong here)
    _, moved = mend_broken_pixels(truth, valid)
    assert moved > 0


def test_pixels_beside_a_shadow_or_the_border_with_three_neighbours_off_mend() -> None:
    """Beside a shadow and on the map's edge a pixel has three valid neighbours: a fringe or more off all three is
    the same evidence as three of four."""
    truth = _step()
    valid = np.ones(SHAPE, dtype=bool)
    valid[5:15, 20:24] = False  # a shadow
    kept = truth.copy()
    kept[8, 19] -= 11 * TWO_PI  # beside the shadow: left, up and down valid, all eleven orders away
    kept[0, 5] += TWO_PI  # on the top edge: three neighbours
    kept[SHAPE[0] - 1, 8] -= 2 * TWO_PI  # on the bottom edge
    kept[13, 18:20] += TWO_PI  # a pair ending at the shadow: the pixel beside it breaks with two of three ...
    out, moved = mend_broken_pixels(kept, valid, _misfit(truth, 17.0, 13.0))
    np.testing.assert_allclose(out[valid], truth[valid])
    assert moved == 5  # ... and with three once its partner has moved


def test_a_pixel_beside_a_shadow_off_two_of_its_three_neighbours_stays() -> None:
    """One valid neighbour continuing it is as many as a neighbour's order would have after a move: no evidence."""
    truth = _step()
    valid = np.ones(SHAPE, dtype=bool)
    valid[5:15, 20:24] = False
    kept = truth.copy()
    kept[5:15, 19] += TWO_PI  # a column along the shadow: each pixel continues the ones above and below it
    out, moved = mend_broken_pixels(kept, valid)
    assert moved == 0
    np.testing.assert_array_equal(out, kept)


def test_next_to_what_another_step_moved_only_those_neighbours_are_judged() -> None:
    """A column along a shadow that another step sent back all but one pixel of: judged next to the moved pixels,
    the one left breaks with all three neighbours and mends; a broken pixel elsewhere is not looked at."""
    truth = _step()
    valid = np.ones(SHAPE, dtype=bool)
    valid[5:15, 20:24] = False
    kept = truth.copy()
    kept[10, 19] += TWO_PI  # the column's one pixel left
    kept[2, 5] += 2 * TWO_PI  # elsewhere, broken with all four neighbours
    moved_by_another = np.zeros(SHAPE, dtype=bool)
    moved_by_another[5:15, 19] = True
    moved_by_another[10, 19] = False
    out, moved = mend_broken_pixels(kept, valid, _misfit(truth, 17.0, 13.0), next_to=moved_by_another)
    assert moved == 1
    assert np.isclose(out[10, 19], truth[10, 19]) and out[2, 5] == kept[2, 5]


def test_orders_a_whole_lower_frequency_cycle_apart_fit_alike_and_the_neighbours_decide() -> None:
    """36 orders of 36 fringes are 6 whole cycles of 6: the lower frequency fits both orders alike, up to rounding
    in the last digits, which must not veto the move the neighbours support."""
    truth = _step() * 3.0
    kept = truth.copy()
    kept[8, 3:7] -= 36 * TWO_PI  # a run of four, no pixel of it a spike
    kept[15, 20:24] += 36 * TWO_PI
    out, moved = mend_broken_pixels(kept, np.ones(SHAPE, dtype=bool), _misfit(truth, 36.0, 6.0))
    np.testing.assert_allclose(out, truth)
    assert moved == 8
