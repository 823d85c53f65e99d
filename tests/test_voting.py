"""Ding's row voting ([119]) and the shadow filling that precedes the RPCA corrections."""

from __future__ import annotations

import numpy as np
import pytest

from processing.correction.shadow_fill import fill_shadows
from processing.correction.voting import majority_per_label, segment_labels, vote_row_orders

TWO_PI = 2.0 * np.pi


def ramp(rows: int = 20, cols: int = 200, fringes: float = 6.0) -> tuple[np.ndarray, np.ndarray]:
    """A true absolute phase rising along rows (slightly different per row) and its wrapped phase."""
    x = np.linspace(0.0, TWO_PI * fringes, cols)
    phase = x[None, :] + np.linspace(0.0, 1.0, rows)[:, None]
    return phase, np.angle(np.exp(1j * phase))


def test_voting_removes_isolated_order_errors() -> None:
    truth, wrapped = ramp()
    rng = np.random.default_rng(0)
    measured = truth.copy()
    wrong = rng.random(truth.shape) < 0.05
    measured[wrong] += TWO_PI * rng.choice([-2, -1, 1, 2], int(wrong.sum()))
    corrected = vote_row_orders(measured, wrapped)
    np.testing.assert_allclose(corrected, truth, atol=1e-9)


def test_voting_keeps_a_segment_whose_majority_is_wrong() -> None:
    # The method's known limit (thesis 1.2.3.2): a segment mostly wrong stays wrong.
    truth, wrapped = ramp(rows=1)
    labels = segment_labels(wrapped, np.ones(wrapped.shape, dtype=bool))
    segment = labels[0] == labels[0, 100]
    measured = truth.copy()
    measured[0, segment] += TWO_PI
    corrected = vote_row_orders(measured, wrapped)
    np.testing.assert_allclose(corrected[0, segment], truth[0, segment] + TWO_PI)


def test_short_segments_take_the_order_of_their_neighbours() -> None:
    truth, wrapped = ramp(rows=1)
    # Noise pulls the second pixel of a fringe back across the wrap point: it and the pixel
    # before it become one-pixel segments. Its measured order is also wrong.
    j = int(np.flatnonzero(np.abs(np.diff(wrapped[0])) > np.pi)[2]) + 2
    noisy_truth = truth.copy()
    noisy_truth[0, j] -= 0.4
    wrapped_noisy = np.angle(np.exp(1j * noisy_truth))
    assert np.abs(np.diff(wrapped_noisy[0, j - 2 : j + 2])).min() > np.pi  # three jumps in a row
    measured = noisy_truth.copy()
    measured[0, j] += TWO_PI * 7
    corrected = vote_row_orders(measured, wrapped_noisy)
    np.testing.assert_allclose(corrected, noisy_truth, atol=1e-9)
    plain = vote_row_orders(measured, wrapped_noisy, min_segment=1)
    assert plain[0, j] - noisy_truth[0, j] == pytest.approx(TWO_PI * 7)


def test_voting_respects_the_mask_and_segments_stop_at_shadows() -> None:
    truth, wrapped = ramp()
    mask = np.ones(truth.shape, dtype=bool)
    mask[:, 50:60] = False
    measured = np.where(mask, truth, np.nan)
    corrected = vote_row_orders(measured, wrapped, mask)
    assert np.isnan(corrected[:, 50:60]).all()
    np.testing.assert_allclose(corrected[mask], truth[mask], atol=1e-9)
    labels = segment_labels(wrapped, mask)
    assert (labels[:, 50:60] == -1).all()
    assert not np.intersect1d(labels[:, :50], labels[:, 60:]).size


def test_majority_per_label_breaks_ties_towards_the_larger_value() -> None:
    labels = np.array([0, 0, 0, 1, 1, 2, 2, 2, 2])
    values = np.array([3, 3, 4, -1, 5, 7, 7, 8, 8])
    np.testing.assert_array_equal(majority_per_label(labels, values), [3, 5, 8])


def test_voting_bad_input_names_the_argument() -> None:
    truth, wrapped = ramp()
    with pytest.raises(ValueError, match="^wrapped_phase:"):
        vote_row_orders(truth, wrapped[:, :-1])
    with pytest.raises(ValueError, match="^mask:"):
        vote_row_orders(truth, wrapped, np.zeros(truth.shape, dtype=bool))
    with pytest.raises(ValueError, match="^absolute_phase:"):
        vote_row_orders(np.full(truth.shape, np.nan), wrapped, np.ones(truth.shape, dtype=bool))


def test_fill_shadows_interpolates_linearly_along_rows() -> None:
    truth, _ = ramp()
    mask = np.ones(truth.shape, dtype=bool)
    mask[3:7, 20:40] = False
    mask[:, :5] = False  # row starts: constant extension
    filled = fill_shadows(np.where(mask, truth, np.nan), mask)
    np.testing.assert_allclose(filled[3:7, 20:40], truth[3:7, 20:40], atol=1e-9)
    np.testing.assert_allclose(filled[:, :5], np.repeat(truth[:, 5:6], 5, axis=1))
    assert np.array_equal(filled[mask], truth[mask])


def test_fill_shadows_uses_nearest_pixel_for_empty_rows() -> None:
    image = np.arange(30.0).reshape(5, 6)
    mask = np.ones(image.shape, dtype=bool)
    mask[2] = False
    filled = fill_shadows(image, mask)
    assert np.isfinite(filled).all()
    assert set(filled[2]) <= set(image[1]) | set(image[3])
    nearest = fill_shadows(image, mask, method="nearest")
    assert np.isfinite(nearest).all()


def test_fill_shadows_bad_input_names_the_argument() -> None:
    with pytest.raises(ValueError, match="^mask:"):
        fill_shadows(np.ones((4, 4)), np.zeros((4, 4), dtype=bool))
    with pytest.raises(ValueError, match="^mask:"):
        fill_shadows(np.ones((4, 4)), np.ones((3, 4), dtype=bool))
    with pytest.raises(ValueError, match="^image:"):
        fill_shadows(np.ones(4))
    with pytest.raises(ValueError, match="^method:"):
        fill_shadows(np.ones((4, 4)), method="cubic")
