"""Fringe orders pooled over 2-D fringe regions: seeded phase maps with known orders."""

from __future__ import annotations

import numpy as np

from processing.fringe_regions import fill_from_neighbours, fringe_regions, pool_region_orders, region_cut

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
