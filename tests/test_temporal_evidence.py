"""Changes of fringe orders judged against the lower frequencies' wrapped phases (processing.correction.temporal_evidence)."""

from __future__ import annotations

import numpy as np

from processing.angles import wrap_to_pi
from processing.correction.temporal_evidence import (
    confusable_shift,
    keep_temporally_supported,
    lower_frequency_misfit,
    noise_weights,
    separable_shift,
    snap_to_lower_frequencies,
)

TWO_PI = 2.0 * np.pi
TOP = 17.0  # a 13/17 pair: one order shifts the 13 prediction by 1.48 rad


def _scene(
    noise: float = 0.03, seed: int = 0, shape: tuple[int, int] = (60, 80)
) -> tuple[np.ndarray, np.ndarray, list[tuple[float, np.ndarray]]]:
    """True absolute phase at TOP with a step of one fringe and a bit (a hidden edge), its valid mask and the
    noisy wrapped phase at 13 (the top phase is kept noise-free: its wrapped part is what every map shares)."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    truth = TWO_PI * cols / 12.0 + 0.01 * rows
    truth[20:40, 30:60] += TWO_PI + 0.3
    low = wrap_to_pi(truth * 13.0 / TOP + rng.normal(0.0, noise, shape))
    return truth, np.ones(shape, dtype=bool), [(13.0, low)]


def test_the_misfit_is_noise_with_the_true_orders_and_the_shift_squared_one_order_off() -> None:
    truth, valid, lower = _scene(noise=0.0)
    assert np.allclose(lower_frequency_misfit(truth, TOP, lower), 0.0, atol=1e-18)
    off = lower_frequency_misfit(truth + TWO_PI, TOP, lower)
    np.testing.assert_allclose(off, wrap_to_pi(np.full(1, TWO_PI * 13.0 / TOP))[0] ** 2, rtol=1e-9)


def test_a_change_the_lower_frequency_contradicts_goes_back() -> None:
    """The spatial proposal pooled across the step (one order off on the raised patch); the measurement had it right."""
    truth, valid, lower = _scene()
    proposed = truth.copy()
    proposed[20:26, 30:36] -= 3 * TWO_PI  # three orders off on part of the patch: the snap cannot reach it
    phase, unresolved, counts = keep_temporally_supported(proposed, truth, valid, TOP, lower)
    np.testing.assert_array_equal(phase, truth)
    assert counts["reverted"] == 1 and not unresolved.any()


def test_a_change_of_noisy_measured_orders_is_left_to_the_neighbours() -> None:
    """Where the lower frequency is as noisy as the shift, measured and proposed orders fit it alike: no verdict."""
    truth, valid, lower = _scene(noise=1.2, seed=3)
    measured = truth.copy()
    measured[5:9, 5:9] += TWO_PI  # wrong temporal orders the spatial proposal fixed
    phase, unresolved, counts = keep_temporally_supported(truth, measured, valid, TOP, lower)
    np.testing.assert_array_equal(phase, truth)
    assert counts["undecidable"] == 1 and counts["reverted"] == 0 and not unresolved.any()


def test_right_changes_stand_where_the_measured_orders_misfit() -> None:
    """Temporal errors that do not fit the lower frequency (an outlier there), fixed by the proposal: kept."""
    truth, valid, lower = _scene()
    measured = truth.copy()
    measured[50:53, 10:14] += 4 * TWO_PI  # 13 x 4 orders = 52: the 13 prediction shifts by 2.22 rad
    phase, _unresolved, counts = keep_temporally_supported(truth, measured, valid, TOP, lower)
    np.testing.assert_array_equal(phase, truth)
    assert counts["reverted"] == 0


def test_a_proposal_one_order_off_moves_to_the_order_the_lower_frequency_fits() -> None:
    truth, valid, lower = _scene()
    measured = truth.copy()
    measured[20:40, 30:60] += 5 * TWO_PI  # the temporal orders were wrong on the patch...
    proposed = truth.copy()
    proposed[20:40, 30:60] -= TWO_PI  # ...and the spatial proposal is one order off there
    snapped, moved = snap_to_lower_frequencies(proposed, measured, valid, TOP, lower)
    np.testing.assert_array_equal(snapped, truth)
    assert moved == 20 * 30


def test_the_snap_leaves_orders_the_lower_frequency_cannot_tell_apart() -> None:
    """29/32: one order shifts the 29 prediction by 0.59 rad, below the shift the snap needs."""
    rows, cols = np.mgrid[0:40, 0:50].astype(np.float64)
    truth = TWO_PI * cols / 9.0
    lower = [(29.0, wrap_to_pi(truth * 29.0 / 32.0))]
    proposed = truth - TWO_PI
    measured = truth + 11 * TWO_PI
    snapped, moved = snap_to_lower_frequencies(proposed, measured, np.ones(truth.shape, bool), 32.0, lower)
    assert moved == 0 and snapped is proposed


def test_a_proposal_two_orders_off_moves_where_one_order_is_too_small_a_shift() -> None:
    """29/32 beside an edge: the proposal two orders off (1.18 rad at 29) goes back to the order the 29 phase fits,
    whether the measured orders were right or eleven orders off (0.2 rad: the pair's own ambiguity)."""
    rng = np.random.default_rng(5)
    rows, cols = np.mgrid[0:40, 0:50].astype(np.float64)
    truth = TWO_PI * cols / 9.0 + 0.01 * rows
    lower = [(29.0, wrap_to_pi(truth * 29.0 / 32.0 + rng.normal(0.0, 0.07, truth.shape)))]
    measured = truth.copy()
    measured[:, 25:] -= 11 * TWO_PI  # nine orders from the proposal there: 0.98 rad, a change nothing judges
    proposed = truth.copy()
    proposed[10:14, 20:30] -= 2 * TWO_PI  # straddles the right and the wrong measured orders
    proposed[30:33, 5:9] += 2 * TWO_PI
    snapped, moved = snap_to_lower_frequencies(proposed, measured, np.ones(truth.shape, bool), 32.0, lower)
    np.testing.assert_allclose(snapped, truth, rtol=0.0, atol=1e-9)
    assert moved == 4 * 10 + 3 * 4


def _ramp_with_lower(
    top: float, lows: tuple[float, ...], noise: float, seed: int, shape: tuple[int, int] = (50, 70)
) -> tuple[np.ndarray, np.ndarray, list[tuple[float, np.ndarray]]]:
    """A ramp of absolute phase at ``top``, its valid mask and the noisy wrapped phases at ``lows``."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    truth = TWO_PI * cols / 11.0 + 0.02 * rows
    lower = [(f, wrap_to_pi(truth * f / top + rng.normal(0.0, noise, shape))) for f in lows]
    return truth, np.ones(shape, dtype=bool), lower


def test_a_wrong_piece_of_one_shift_goes_back_inside_a_blob_of_right_changes() -> None:
    """64/58/53: the proposal fixes a patch whose measured orders were three off, and pooled the one-pixel column
    beside it eight orders off (onto a step's far side); the column's measured orders were right. The patch's
    evidence outweighs the column's over their blob, so the blob stands as a whole; the column's piece of shift +8
    (1.6 and 2.4 rad at 58 and 53) is judged on its own and goes back."""
    truth, valid, lower = _ramp_with_lower(64.0, (58.0, 53.0), noise=0.05, seed=11)
    measured = truth.copy()
    measured[20:30, 30:40] += 3 * TWO_PI
    proposed = truth.copy()
    proposed[20:30, 40] += 8 * TWO_PI
    phase, unresolved, counts = keep_temporally_supported(proposed, measured, valid, 64.0, lower)
    np.testing.assert_array_equal(phase, truth)
    assert counts["reverted"] == 0 and counts["piece_pixels_reverted"] == 10 and not unresolved.any()


def test_a_piece_whose_measured_orders_an_order_near_the_proposal_would_fit_as_well_is_reported() -> None:
    """29/32: the measured orders of the column are eleven off, where the 29 phase predicts within 0.2 rad of the
    truth's, and the proposal two off. The 29 phase fits the measured orders better than the proposal (1.38 rad apart),
    but also fits the order two from the proposal as well as the measured one: nothing tells the measured orders
    from the truth, so the column keeps the proposal and is reported unresolved instead of sent eleven orders off."""
    truth, valid, lower = _ramp_with_lower(32.0, (29.0,), noise=0.03, seed=12)
    measured = truth.copy()
    measured[20:30, 30:40] += 5 * TWO_PI  # fixed by the proposal: 2.95 rad at 29
    measured[20:30, 40] += 11 * TWO_PI
    proposed = truth.copy()
    proposed[20:30, 40] -= 2 * TWO_PI
    phase, unresolved, counts = keep_temporally_supported(proposed, measured, valid, 32.0, lower)
    np.testing.assert_array_equal(phase, proposed)
    column = np.zeros(valid.shape, dtype=bool)
    column[20:30, 40] = True
    np.testing.assert_array_equal(unresolved, column)
    assert counts["piece_pixels_reverted"] == 0 and counts["piece_pixels_unresolved"] == 10


def test_a_piece_whose_measured_orders_a_neighbours_order_fits_as_well_takes_that_order() -> None:
    """32/29/27 with 0.25 and 0.45 rad of noise at 29 and 27: the column's measured orders are 31 off, which shifts
    the lower phases' predictions from the truth's by 0.59 and 0.98 rad, too little against that noise to judge (the
    lower phases there lie a little nearer the measured orders' prediction: what made temporal unwrapping pick
    them); the proposal is three off. The lower frequencies contradict the proposal, but cannot tell the measured
    orders from the order continuing the column's neighbours on both sides, which they fit within the noise: the
    column takes that order instead of going back 31 orders off."""
    rng = np.random.default_rng(13)
    rows, cols = np.mgrid[0:50, 0:70].astype(np.float64)
    truth = TWO_PI * cols / 11.0 + 0.02 * rows
    valid = np.ones(truth.shape, dtype=bool)
    measured = truth.copy()
    measured[20:30, 30:40] += 5 * TWO_PI  # fixed by the proposal: 2.9 and 1.4 rad at 29 and 27
    column = np.zeros(valid.shape, dtype=bool)
    column[20:30, 40] = True
    measured[column] -= 31 * TWO_PI
    lower = []
    for f, sd in ((29.0, 0.25), (27.0, 0.45)):
        low = truth * f / 32.0 + rng.normal(0.0, sd, truth.shape)
        low[column] = truth[column] * f / 32.0 + 0.55 * wrap_to_pi(np.full(10, -31 * TWO_PI * f / 32.0))
        lower.append((f, wrap_to_pi(low)))
    proposed = truth.copy()
    proposed[column] -= 3 * TWO_PI
    phase, unresolved, counts = keep_temporally_supported(proposed, measured, valid, 32.0, lower)
    np.testing.assert_allclose(phase, truth, rtol=0.0, atol=1e-9)
    assert not unresolved.any() and counts["piece_pixels_reverted"] == 10


def test_separable_shifts_take_the_misfit_noise_from_the_phase_noise_not_from_the_chosen_orders() -> None:
    """10 orders of 32 move the 29-fringe prediction by 0.39 rad: under the 1 rad a blob is judged by (confusable
    whatever the noise), 4.6 misfit deviations at 0.063 rad of phase noise and 1.8 at 0.16 rad. At 0.16 rad the
    misfit of orders chosen to fit (each pixel's best of 0, +-11 and +-21 orders) is under half its true noise."""
    rng = np.random.default_rng(5)
    lower = [(29.0, np.zeros(1))]
    orders = np.array([10.0])
    assert confusable_shift(orders, 32.0, lower, [1.0 / 0.03**2])[0]
    assert separable_shift(orders, 32.0, lower, 0.063)[0]
    assert not separable_shift(orders, 32.0, lower, 0.16)[0]
    assert not separable_shift(np.array([0.0]), 32.0, lower, 0.01)[0]
    truth = np.tile(np.linspace(0.0, 60.0, 400), (50, 1))
    phase = truth + rng.normal(0.0, 0.16, truth.shape)
    wrapped_29 = np.mod(truth * 29.0 / 32.0 + rng.normal(0.0, 0.16, truth.shape), TWO_PI)
    candidates = np.stack([phase + TWO_PI * k for k in (0.0, 11.0, -11.0, 21.0, -21.0)])
    fits = lower_frequency_misfit(candidates, 32.0, [(29.0, wrapped_29[None])])
    chosen = np.take_along_axis(candidates, np.argmin(fits, axis=0)[None], axis=0)[0]
    weight = noise_weights(chosen, np.ones(truth.shape, bool), 32.0, [(29.0, wrapped_29)])[0]
    assert 1.0 / np.sqrt(weight) < 0.5 * 0.16 * np.hypot(1.0, 29.0 / 32.0)  # the chosen orders' misfit: too small
