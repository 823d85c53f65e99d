"""Changes of fringe orders judged blob by blob against the measured orders (processing.correction.order_evidence)."""

from __future__ import annotations

import numpy as np
import pytest

from processing.correction import order_evidence
from processing.correction.order_evidence import (
    breaks_per_blob,
    keep_supported_changes,
    label_blobs,
    mend_spikes,
    unresolved_summary,
)

TWO_PI = 2.0 * np.pi


def _ramp(shape: tuple[int, int] = (60, 80), period_px: float = 20.0) -> np.ndarray:
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]].astype(np.float64)
    return TWO_PI * cols / period_px + 0.02 * rows


def test_a_change_that_removes_breaks_is_kept() -> None:
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    measured = truth.copy()
    measured[10:13, 20:23] += TWO_PI  # a blob of wrong temporal orders
    measured[40, 50] -= 2 * TWO_PI  # and a lone one
    phase, unresolved = keep_supported_changes(truth, measured, valid)
    np.testing.assert_array_equal(phase, truth)
    assert not unresolved.any()


def test_a_change_that_adds_breaks_is_undone() -> None:
    """A proposal wrong by one fringe on a patch the measurement had right (pooling across a step)."""
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    proposed = truth.copy()
    proposed[30:40, 10:25] -= TWO_PI
    proposed[5, 5] += TWO_PI  # beside a right change elsewhere
    measured = truth.copy()
    measured[5, 5] += TWO_PI
    measured[50, 60] += TWO_PI  # a wrong order the proposal fixed
    proposed[50, 60] = truth[50, 60]
    phase, unresolved = keep_supported_changes(proposed, measured, valid)
    np.testing.assert_array_equal(phase[30:40, 10:25], truth[30:40, 10:25])
    assert phase[50, 60] == truth[50, 60]
    assert not unresolved.any()


def test_an_island_no_edge_can_judge_is_unresolved_and_kept_as_measured() -> None:
    """A patch cut off by invalid pixels: one fringe up or down leaves no break either way."""
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    valid[18:42, 28:52] = False
    valid[22:38, 32:48] = True  # the island, a ring of invalid pixels around it
    proposed = truth.copy()
    proposed[22:38, 32:48] += TWO_PI
    phase, unresolved = keep_supported_changes(proposed, truth, valid)
    np.testing.assert_array_equal(phase, truth)
    assert unresolved.sum() == 16 * 16 and unresolved[22:38, 32:48].all()
    summary = unresolved_summary(unresolved, valid)
    assert summary["pixels"] == 256
    assert summary["fraction"] == round(256 / valid.sum(), 6)
    assert summary["regions"] == [[22, 32, 37, 47, 256]]


def test_breaks_count_each_edge_of_a_blob_once() -> None:
    phase = np.zeros((5, 5))
    phase[2, 2] = TWO_PI
    labels = np.zeros((5, 5), dtype=np.int32)
    labels[2, 2] = 1
    counts = breaks_per_blob(phase, np.ones((5, 5), dtype=bool), labels, 2)
    assert counts[1] == 4


@pytest.mark.parametrize("pairs_per_gather", [1, 10**9])  # every pair gathered; the whole map stepped
def test_breaks_per_blob_counts_as_a_pixel_by_pixel_count(
    monkeypatch: pytest.MonkeyPatch, pairs_per_gather: int
) -> None:
    rng = np.random.default_rng(5)
    shape = (40, 50)
    phase = rng.normal(0.0, 1.5, shape) + TWO_PI * rng.integers(-1, 2, shape)
    phase[rng.random(shape) < 0.05] = np.nan
    valid = rng.random(shape) > 0.1
    count, labels = label_blobs(rng.random(shape) < 0.3)
    monkeypatch.setattr(order_evidence, "_GATHER_BELOW", pairs_per_gather)
    counts = breaks_per_blob(phase, valid, labels, count)
    expected = np.zeros(count, dtype=np.int64)
    for y, x in np.ndindex(shape):
        for y2, x2 in ((y, x + 1), (y + 1, x)):
            if y2 >= shape[0] or x2 >= shape[1] or not (valid[y, x] and valid[y2, x2]):
                continue
            a, b = labels[y, x], labels[y2, x2]
            if (a or b) and abs(phase[y2, x2] - phase[y, x]) > np.pi:  # NaN: no break
                expected[a] += 1
                if b != a:
                    expected[b] += 1
    np.testing.assert_array_equal(counts, expected)


def test_nothing_changed_nothing_unresolved() -> None:
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    phase, unresolved = keep_supported_changes(truth, truth.copy(), valid)
    assert phase is truth and not unresolved.any()
    assert unresolved_summary(unresolved, valid) == {"pixels": 0, "fraction": 0.0, "regions": []}


def test_a_lone_order_spike_takes_the_order_of_its_neighbours() -> None:
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    spiky = truth.copy()
    spiky[20, 30] -= 11 * TWO_PI
    spiky[0, 5] += TWO_PI  # on the border: three neighbours only, left alone
    mended, count = mend_spikes(spiky, valid)
    assert count == 1
    assert abs(mended[20, 30] - truth[20, 30]) < 1e-9
    np.testing.assert_array_equal(mended[0, 5], spiky[0, 5])


def test_a_spike_at_the_corner_of_a_step_takes_the_order_the_misfit_prefers() -> None:
    """Two neighbours on each side of a step of six fringes: either side is as well supported."""
    rows, cols = np.mgrid[0:20, 0:20].astype(np.float64)
    truth = 0.05 * cols + np.where(cols > rows, 6 * TWO_PI, 0.0)  # the step runs along the diagonal
    valid = np.ones(truth.shape, dtype=bool)
    spiky = truth.copy()
    spiky[10, 11] -= 11 * TWO_PI  # above the diagonal: up and right neighbours on its side
    upper = truth[10, 11]
    mended, count = mend_spikes(spiky, valid, lambda values, where: np.abs(values - upper))
    assert count == 1 and mended[10, 11] == upper
    lower_side = truth[10, 11] - 6 * TWO_PI
    mended, _ = mend_spikes(spiky, valid, lambda values, where: np.abs(values - lower_side))
    assert abs(mended[10, 11] - lower_side) < 1e-9


def test_a_pixel_with_one_continuous_neighbour_is_no_spike() -> None:
    truth = _ramp()
    valid = np.ones(truth.shape, dtype=bool)
    pair = truth.copy()
    pair[30, 40:42] += TWO_PI  # two wrong pixels side by side: each has one neighbour that agrees
    mended, count = mend_spikes(pair, valid)
    assert count == 0 and mended is pair
