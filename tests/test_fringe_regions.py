"""Fringe orders pooled over 2-D fringe regions: seeded phase maps with known orders."""

from __future__ import annotations

import numpy as np
import pytest

from processing.angles import wrap_to_pi
from processing.correction import region_orders
from processing.correction.region_orders import (
    _beyond_wrapped,
    _window_majority,
    fill_from_neighbours,
    fringe_regions,
    neighbour_steps_at,
    order_break_pixels,
    pool_region_orders,
    region_cut,
)

TWO_PI = 2.0 * np.pi


def _measured(truth: np.ndarray, noise: float, wrong: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(absolute, wrapped) of ``truth`` with phase noise and a fraction of orders off by +-7 or +-18."""
    rng = np.random.default_rng(seed)
    wrapped = np.mod(truth + rng.normal(0.0, noise, truth.shape), TWO_PI)
    orders = np.rint((truth - wrapped) / TWO_PI)
    bad = rng.random(truth.shape) < wrong
    orders[bad] += rng.choice([-18, -7, 7, 18], size=int(bad.sum()))
    return wrapped + TWO_PI * orders, wrapped


def _wrong(phase: np.ndarray, truth: np.ndarray, valid: np.ndarray) -> int:
    return int(np.count_nonzero(valid & (np.abs(phase - truth) > np.pi)))


def test_pooling_recovers_every_order_of_a_plane_with_40_percent_wrong() -> None:
    truth = np.add.outer(np.linspace(0.0, 2.0, 120), np.linspace(0.0, 60.0, 160))  # ~10 fringes
    absolute, wrapped = _measured(truth, 0.12, 0.4, seed=1)
    valid = np.ones(truth.shape, dtype=bool)
    assert _wrong(absolute, truth, valid) > 0.35 * truth.size
    pooled = pool_region_orders(absolute, wrapped, valid)
    assert _wrong(pooled, truth, valid) == 0
    # Only orders move: the measured wrapped phase is kept.
    np.testing.assert_allclose(np.mod(pooled, TWO_PI), wrapped, atol=1e-9)


def test_a_hidden_edge_keeps_both_orders() -> None:
    # A block whose top is 3 periods + 0.3 rad above the floor: no wrapped jump marks its edge,
    # so the floor and the block share regions; each side must keep its own order.
    truth = np.add.outer(np.zeros(96), np.linspace(0.0, 40.0, 128))
    truth[30:70, 50:90] += 3 * TWO_PI + 0.3
    absolute, wrapped = _measured(truth, 0.1, 0.3, seed=2)
    valid = np.ones(truth.shape, dtype=bool)
    assert _wrong(absolute, truth, valid) > 0.25 * truth.size
    pooled = pool_region_orders(absolute, wrapped, valid)
    assert _wrong(pooled, truth, valid) <= 0.01 * truth.size  # pixels along the block's outline at most


def test_steep_fringes_raise_the_cut_and_still_pool() -> None:
    # 2.5 rad per pixel (64 fringes over 160 px): every neighbour differs by more than pi / 2.
    truth = np.add.outer(np.zeros(40), np.arange(160) * 2.5)
    absolute, wrapped = _measured(truth, 0.05, 0.2, seed=3)
    valid = np.ones(truth.shape, dtype=bool)
    assert region_cut(wrapped, valid) == np.pi
    pooled = pool_region_orders(absolute, wrapped, valid)
    assert _wrong(pooled, truth, valid) < 0.2 * _wrong(absolute, truth, valid)


def test_shadows_stay_nan_and_regions_do_not_cross_them() -> None:
    truth = np.add.outer(np.zeros(64), np.linspace(0.0, 30.0, 96))
    absolute, wrapped = _measured(truth, 0.1, 0.25, seed=4)
    valid = np.ones(truth.shape, dtype=bool)
    valid[:, 40:44] = False
    absolute[~valid] = np.nan
    pooled = pool_region_orders(absolute, wrapped, valid)
    assert np.isnan(pooled[~valid]).all() and np.isfinite(pooled[valid]).all()
    assert _wrong(pooled, truth, valid) == 0
    core, labels, _ = fringe_regions(wrapped, valid, np.pi / 2)
    assert not core[~valid].any()
    assert not set(np.unique(labels[:, :40])) - {0} & set(np.unique(labels[:, 44:])) - {0}


def test_fill_takes_the_order_of_the_neighbour_nearest_in_wrapped_phase() -> None:
    wrapped = np.array([[6.1, 0.1, 0.2]])
    phase = np.array([[6.1 + TWO_PI * 2, np.nan, 0.2 + TWO_PI * 3]])
    out = fill_from_neighbours(phase.copy(), wrapped, np.ones(wrapped.shape, dtype=bool))
    assert out[0, 1] == 0.1 + TWO_PI * 3  # continuous with 0.2 (same fringe), not with 6.1


def _brute_window_majority(orders, labels, rows, cols, radius):
    """Per-pixel reference: count the window's same-region orders one by one (ties: the smaller)."""
    winners, support = [], []
    height, width = orders.shape
    for y, x in zip(rows, cols, strict=True):
        counts: dict[int, int] = {}
        for yy in range(max(0, y - radius), min(height, y + radius + 1)):
            for xx in range(max(0, x - radius), min(width, x + radius + 1)):
                if labels[yy, xx] == labels[y, x]:
                    counts[int(orders[yy, xx])] = counts.get(int(orders[yy, xx]), 0) + 1
        best = max(counts.values())
        winners.append(min(k for k, v in counts.items() if v == best))
        support.append(best)
    return np.array(winners), np.array(support)


@pytest.mark.parametrize("count_cells", [region_orders._COUNT_CELLS, 0])  # counting the votes; sorting them
def test_window_majority_matches_a_per_pixel_count_with_ties_borders_and_regions(
    count_cells: int, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(region_orders, "_COUNT_CELLS", count_cells)
    rng = np.random.default_rng(3)
    orders = rng.integers(-3, 4, size=(23, 31)).astype(np.int32)  # many ties in a 5 x 5 window
    labels = (rng.random((23, 31)) < 0.7).astype(np.int32) + (np.arange(31) >= 15).astype(np.int32) * 2
    rows, cols = np.nonzero(labels > 0)
    winners, support = _window_majority(orders, labels, rows, cols, radius=2)
    expected_winners, expected_support = _brute_window_majority(orders, labels, rows, cols, 2)
    np.testing.assert_array_equal(support, expected_support)
    np.testing.assert_array_equal(winners, expected_winners)


def test_beyond_wrapped_equals_the_wrapped_test_everywhere() -> None:
    values = np.random.default_rng(4).uniform(-4.5 * np.pi, 4.5 * np.pi, size=(200, 300))
    values[0, :5] = [1.2, -1.2, np.nextafter(1.2, 2.0), np.pi, np.nan]
    np.testing.assert_array_equal(_beyond_wrapped(values, 1.2), np.abs(wrap_to_pi(values)) > 1.2)


def test_neighbour_steps_at_pixels_count_what_the_full_map_test_sees() -> None:
    rng = np.random.default_rng(5)
    phase = np.cumsum(rng.normal(0.0, 0.3, size=(40, 50)), axis=1)
    phase[rng.random(phase.shape) < 0.05] += 2 * np.pi  # order errors
    valid = rng.random(phase.shape) > 0.1
    rows, cols = np.nonzero(np.ones(phase.shape, dtype=bool))
    breaks, continues = neighbour_steps_at(phase, valid, rows, cols)
    full = order_break_pixels(np.where(valid, phase, np.nan))
    np.testing.assert_array_equal(breaks > 0, full.reshape(-1))
    # every valid 4-neighbour of a valid pixel is one or the other; an invalid pixel counts none
    padded = np.pad(valid, 1)
    neighbours = padded[:-2, 1:-1].astype(int) + padded[2:, 1:-1] + padded[1:-1, :-2] + padded[1:-1, 2:]
    np.testing.assert_array_equal(breaks + continues, np.where(valid, neighbours, 0).reshape(-1))


def test_fill_writes_into_a_non_contiguous_map() -> None:
    wrapped = np.tile(np.linspace(0.0, 1.0, 8), (6, 1))
    phase = np.asfortranarray(wrapped + 2 * np.pi * 3)
    phase[2:4, 3:5] = np.nan
    filled = fill_from_neighbours(phase, wrapped, np.ones(phase.shape, dtype=bool))
    assert filled is phase and np.isfinite(phase).all()
    np.testing.assert_allclose(phase, wrapped + 2 * np.pi * 3)
