"""Step 6d: islands that one order shift the lower frequencies cannot see joins to the surface around them."""

import numpy as np
import pytest

from processing.correction import order_islands
from processing.correction.order_islands import level_islands
from processing.correction.temporal_evidence import confusable_shift, lower_frequency_misfit

TWO_PI = 2.0 * np.pi


def _ramp(rows: int = 40, cols: int = 60) -> np.ndarray:
    """A smooth surface: 0 - 30 rad across the columns (0.5 rad a pixel), a gentle tilt down the rows."""
    return np.linspace(0.0, 30.0, cols)[None, :] + np.linspace(0.0, 4.0, rows)[:, None]


def _everywhere(value: bool):  # noqa: ANN202 - a test's stand-in for the lower frequencies or the vote
    return lambda shifts: np.full(np.shape(shifts), value)


def _all_undecided(kept: np.ndarray) -> np.ndarray:
    return np.ones(kept.shape, dtype=bool)


def test_an_island_eleven_orders_off_joins_the_surface() -> None:
    truth = _ramp()
    kept = truth.copy()
    kept[10:20, 15:30] += 11 * TWO_PI  # a fringe region whose vote settled on the 29/32 pair's ambiguous order
    out, moved = level_islands(kept, np.ones(truth.shape, bool), _everywhere(True), _all_undecided)
    assert moved == 150
    np.testing.assert_allclose(out, truth, atol=1e-9)


def test_with_the_capture_lower_frequency_only_its_blind_shifts_move() -> None:
    """29/32 with 0.1 rad of phase noise: 11 and 21 orders move the 29-fringe prediction by 0.2 rad (confusable),
    5 orders by 2.9 rad (seen)."""
    truth = _ramp()
    lower = [(29.0, np.zeros(truth.shape))]

    def confusable(shifts: np.ndarray) -> np.ndarray:
        return confusable_shift(shifts, 32.0, lower, [1.0 / 0.1**2])  # the weight: one over the noise variance

    for orders, expected in ((11, 150), (-21, 150), (5, 0)):
        kept = truth.copy()
        kept[10:20, 15:30] += orders * TWO_PI
        assert level_islands(kept, np.ones(truth.shape, bool), confusable, _all_undecided)[1] == expected, orders


def test_an_object_the_lower_frequency_places_stays_where_it_fits() -> None:
    """A block truly 9 orders above its surround (29/32: a shift of 0.98 rad, under the per-pixel bounds) stays
    where the lower frequency's misfit says it fits (without the misfit, the breaks alone would level it); a block
    kept 9 orders off a surface without a step comes down."""
    rng = np.random.default_rng(3)
    surface = _ramp()
    surface[10:20, 15:30] += 9 * TWO_PI + 0.3  # a real step: 0.3 rad from the whole shift, within CLOSE_RAD
    lower_wrapped = np.mod(surface * 29.0 / 32.0 + rng.normal(0.0, 0.1, surface.shape), TWO_PI)
    lower = [(29.0, lower_wrapped)]

    def confusable(shifts: np.ndarray) -> np.ndarray:
        return confusable_shift(shifts, 32.0, lower, [1.0 / 0.1**2])

    def misfit(values: np.ndarray, at: np.ndarray) -> np.ndarray:
        return lower_frequency_misfit(values, 32.0, [(29.0, lower_wrapped.reshape(-1)[at])])

    valid = np.ones(surface.shape, bool)
    assert confusable(np.array([9.0]))[0]
    assert level_islands(surface, valid, confusable, _all_undecided)[1] == 150  # the breaks alone level it
    out, moved = level_islands(surface, valid, confusable, _all_undecided, misfit)
    assert moved == 0 and out is surface
    truth = _ramp()  # no step: the block kept 9 orders off, where the shift lowers the misfit
    lower_wrapped[:] = np.mod(truth * 29.0 / 32.0 + rng.normal(0.0, 0.1, truth.shape), TWO_PI)
    off = truth.copy()
    off[10:20, 15:30] += 9 * TWO_PI
    out, moved = level_islands(off, valid, confusable, _all_undecided, misfit)
    assert moved == 150
    np.testing.assert_allclose(out, truth, atol=1e-9)


def test_an_island_whose_measured_orders_vouch_for_it_stays() -> None:
    """Where the vote decides the kept orders (a real edge, its measured orders agreeing), nothing moves."""
    truth = _ramp()
    kept = truth.copy()
    kept[10:20, 15:30] += 11 * TWO_PI
    out, moved = level_islands(kept, np.ones(truth.shape, bool), _everywhere(True), lambda k: np.zeros(k.shape, bool))
    assert moved == 0 and out is kept


def test_an_island_too_small_for_any_vote_to_decide_moves_whatever_the_vote() -> None:
    """Below 9 pixels (Z_MARGIN squared) no sign test can vouch for the kept orders: 8 pixels move with a vote said
    to decide them, 9 do not."""
    truth = _ramp()
    decided = lambda k: np.zeros(k.shape, bool)  # noqa: E731
    assert order_islands.TOO_FEW_TO_VOTE == 9
    for rows, expected in ((2, 8), (3, 0)):
        kept = truth.copy()
        kept[10 : 10 + rows, 15 : 15 + (4 if rows == 2 else 3)] += 11 * TWO_PI  # 2 x 4 and 3 x 3
        out, moved = level_islands(kept, np.ones(truth.shape, bool), _everywhere(True), decided)
        assert moved == expected, rows
        if expected:
            np.testing.assert_allclose(out, truth, atol=1e-9)


def test_shifts_of_one_or_two_orders_are_left_to_the_pixel_steps() -> None:
    truth = _ramp()
    for orders in (1, -2):
        kept = truth.copy()
        kept[10:20, 15:30] += orders * TWO_PI
        assert level_islands(kept, np.ones(truth.shape, bool), _everywhere(True), _all_undecided)[1] == 0
    assert order_islands.MIN_ORDERS == 3


def test_the_larger_side_stays_and_a_step_off_every_whole_shift_stays() -> None:
    """Half the map 11 orders up: neither side is an island of the other's surface (the smaller moves only
    towards a larger one, so the larger half stays); a block raised 11.4 orders (a real step, 2.5 rad off the
    nearest whole shift) is not within reach of any shift."""
    truth = _ramp()
    valid = np.ones(truth.shape, bool)
    halves = truth.copy()
    halves[:, 35:] += 11 * TWO_PI
    out, moved = level_islands(halves, valid, _everywhere(True), _all_undecided)
    assert moved == 40 * 25
    np.testing.assert_allclose(out, truth, atol=1e-9)  # the smaller half (25 of 60 columns) came down
    raised = truth.copy()
    raised[10:20, 15:30] += 11.4 * TWO_PI
    assert level_islands(raised, valid, _everywhere(True), _all_undecided)[1] == 0


def test_an_island_inside_an_island_comes_down_in_passes() -> None:
    """An island 22 orders up inside one 11 up: the outer joins the surface, then the inner joins it."""
    truth = _ramp()
    kept = truth.copy()
    kept[5:35, 10:50] += 11 * TWO_PI
    kept[15:25, 20:40] += 11 * TWO_PI
    out, moved = level_islands(kept, np.ones(truth.shape, bool), _everywhere(True), _all_undecided)
    np.testing.assert_allclose(out, truth, atol=1e-9)
    assert moved == 30 * 40


@pytest.mark.parametrize("gap", [True, False])
def test_invalid_pixels_neither_join_nor_move(gap: bool) -> None:
    """An island cut off by a shadow all round has no broken pair: nothing to judge it by."""
    truth = _ramp()
    kept = truth.copy()
    kept[10:20, 15:30] += 11 * TWO_PI
    valid = np.ones(truth.shape, bool)
    if gap:
        valid[9:21, 14:31] = False
        valid[10:20, 15:30] = True
    out, moved = level_islands(kept, valid, _everywhere(True), _all_undecided)
    assert moved == (0 if gap else 150)
