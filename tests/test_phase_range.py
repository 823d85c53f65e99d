"""Orders outside the pattern's range [0, 2 pi f), moved back by the period no lower frequency sees."""

import numpy as np
import pytest

from processing.angles import wrap_to_pi
from processing.correction.phase_range import folded_into_range, invisible_period, keep_range_folds
from processing.correction.registry import correct_auto

TWO_PI = 2.0 * np.pi


@pytest.mark.parametrize(
    ("frequency", "lower", "orders"),
    [(32, (29, 27), 32), (25, (18,), 25), (36, (6, 1), 36), (64, (58, 53), 64), (32, (16, 8), 4)],
)
def test_the_period_moves_every_lower_frequency_by_whole_turns(frequency, lower, orders):
    period = invisible_period(frequency, lower)
    assert period == pytest.approx(TWO_PI * orders)
    for f_low in lower:  # the lower frequency's prediction moves by whole turns: invisible to it
        turns = period * f_low / frequency / TWO_PI
        assert turns == pytest.approx(round(turns))


def test_no_period_without_whole_fringe_counts():
    assert invisible_period(32.5, (29,)) is None
    assert invisible_period(32, (29.25,)) is None


def test_out_of_range_values_move_by_the_fewest_periods():
    valid = np.ones((1, 6), dtype=bool)
    phase = TWO_PI * np.array([[0.1, 32.1, -0.2, 65.0, 31.9, -33.5]])
    folded = folded_into_range(phase, valid, 32, TWO_PI * 32)
    np.testing.assert_allclose(folded / TWO_PI, [[0.1, 0.1, 31.8, 1.0, 31.9, 30.5]], atol=1e-12)
    # a period shorter than the range (frequencies sharing a factor): the nearest in-range value
    np.testing.assert_allclose(
        folded_into_range(TWO_PI * np.array([[33.0]]), valid[:, :1], 32, TWO_PI * 4) / TWO_PI, 29.0
    )
    inside = TWO_PI * np.array([[0.1, 31.9]])
    assert folded_into_range(inside, valid[:, :2], 32, TWO_PI * 32) is inside  # nothing outside: no copy


def _ramp(rows: int = 60, cols: int = 90, start: float = 0.05, stop: float = 6.0) -> np.ndarray:
    """A smooth absolute phase at 32 fringes, ``start`` to ``stop`` fringes across the map (rad)."""
    return TWO_PI * np.broadcast_to(np.linspace(start, stop, cols), (rows, cols)).copy()


def test_a_blob_a_whole_range_off_goes_back():
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    measured = truth.copy()
    measured[20:30, 0:12] += TWO_PI * 32  # at the pattern's start: 32 orders off, as a failed beat leaves it
    kept, moved = keep_range_folds(measured, valid, 32, (29, 27))
    assert moved == 120
    np.testing.assert_allclose(kept, truth, atol=1e-9)


def test_a_phase_offset_by_a_constant_stays():
    """A capture whose convention is off by 0.4 rad: the first columns lie below 0 but continue their
    neighbours, so folding them would break the surface: nothing moves."""
    measured = _ramp(start=0.0) - 0.4
    valid = np.ones(measured.shape, dtype=bool)
    assert (measured < 0).any()
    kept, moved = keep_range_folds(measured, valid, 32, (29, 27))
    assert moved == 0
    assert np.array_equal(kept, measured)


@pytest.mark.parametrize("share_off", [0.6, 1.0])
def test_auto_returns_an_island_whose_measured_orders_lie_outside_the_pattern(share_off):
    """An island beside the map's border, a shadow around it, where temporal unwrapping put ``share_off`` of the
    pixels 32 orders up (the lower frequencies fit them as well as the truth). Without step 0 the island's pooled
    order is the wrong one (all 600 pixels off at 60 %, nothing for the neighbours to judge at 100 %)."""
    rng = np.random.default_rng(7)
    truth = _ramp(rows=96, cols=128, start=0.05, stop=9.0)
    valid = np.ones(truth.shape, dtype=bool)
    valid[28:62, 0:23] = False
    valid[30:60, 0:20] = True
    noise = 0.02
    wrapped = wrap_to_pi(truth + rng.normal(0.0, noise, truth.shape))
    measured = truth - wrap_to_pi(truth) + wrapped  # the true orders on the noisy wrapped phase
    off = np.zeros(truth.shape, dtype=bool)
    off[30:60, 0:20] = rng.random((30, 20)) < share_off
    measured[off] += TWO_PI * 32
    lower = [(f, wrap_to_pi(truth * f / 32 + rng.normal(0.0, noise, truth.shape))) for f in (29.0, 27.0)]
    out, info = correct_auto(measured, wrapped, mask=valid, frequency=32.0, lower_wrapped=lower)
    assert info["evidence"]["range_folded"] == np.count_nonzero(off)
    assert int(np.count_nonzero(valid & (np.abs(out - truth) > np.pi))) == 0
    assert info["orders_changed"] >= np.count_nonzero(off)  # counted against the phase as given
