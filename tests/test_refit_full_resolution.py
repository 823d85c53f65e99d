"""processing.correction.phase_rpca.refit_full_resolution against an analytic low-rank surface."""

from __future__ import annotations

import numpy as np

from processing.correction.phase_rpca import REFIT_MAX_RANK, decimated_low_rank, refit_full_resolution


def _staircase(rows: int, cols: int) -> np.ndarray:
    """A carrier plus treads along x inside a square: rank 2, edges a block cannot hold."""
    x = np.arange(cols, dtype=np.float64)
    y = np.arange(rows, dtype=np.float64)[:, None]
    carrier = 0.2 * x + 0.01 * y
    inside = (np.abs(y - rows / 2) < rows / 4) & (np.abs(x - cols / 2) < cols / 4)
    treads = np.floor((x - cols / 4) / (cols / 8)) * 1.3
    return carrier + np.where(inside, treads, 0.0)


def test_refit_restores_the_edges_the_block_solve_blurred() -> None:
    rows, cols, sigma = 240, 320, 0.05
    truth = _staircase(rows, cols)
    measured = truth + np.random.default_rng(3).normal(0.0, sigma, truth.shape)
    valid = np.ones(truth.shape, dtype=bool)
    valid[:20, :30] = False  # a shadow: refitted from the interpolated surface, left NaN
    low_rank, result, _ = decimated_low_rank(measured, valid, 4, sigma)
    refit = refit_full_resolution(low_rank, result.low_rank, 4, measured, valid, result.rank, outlier=8 * sigma)
    assert np.isnan(refit[~valid]).all() and np.isfinite(refit[valid]).all()
    block_error = np.sqrt(np.mean((low_rank - truth)[valid] ** 2))
    refit_error = np.sqrt(np.mean((refit - truth)[valid] ** 2))
    assert refit_error < 0.5 * block_error, (refit_error, block_error)
    assert refit_error < 0.5 * sigma  # denoised as well as sharp


def test_refit_leaves_a_high_rank_solution_alone() -> None:
    rng = np.random.default_rng(0)
    measured = rng.normal(size=(128, 128))
    low_rank = measured + 0.1
    blocks = rng.normal(size=(32, 32))
    valid = np.ones(measured.shape, dtype=bool)
    same = refit_full_resolution(low_rank, blocks, 4, measured, valid, REFIT_MAX_RANK + 1, outlier=1.0)
    assert same is low_rank


def test_refit_leaves_a_smooth_noisy_surface_to_the_block_solve() -> None:
    """Where both surfaces fit within the noise, the block surface (a 16-pixel mean) stays: the refit
    chosen by noise alone made a smooth cap noisier (the study's sphere cap at 10 dB)."""
    rows, cols, sigma = 240, 320, 0.3
    y, x = np.mgrid[0:rows, 0:cols].astype(np.float64)
    truth = 0.2 * x + 0.01 * y + 3.0 * np.exp(-((x - cols / 2) ** 2 + (y - rows / 2) ** 2) / (2 * 60.0**2))
    measured = truth + np.random.default_rng(5).normal(0.0, sigma, truth.shape)
    valid = np.ones(truth.shape, dtype=bool)
    low_rank, result, _ = decimated_low_rank(measured, valid, 4, sigma)

    def error(surface: np.ndarray) -> float:
        return float(np.sqrt(np.mean((surface - truth) ** 2)))

    kept = refit_full_resolution(
        low_rank, result.low_rank, 4, measured, valid, result.rank, outlier=8 * sigma, noise=sigma
    )
    blind = refit_full_resolution(low_rank, result.low_rank, 4, measured, valid, result.rank, outlier=8 * sigma)
    assert error(kept) <= 1.02 * error(low_rank), (error(kept), error(low_rank))
    assert np.mean(kept != low_rank) < 0.25  # most pixels keep the block surface
    assert error(blind) > error(kept)  # without the noise margin the refit costs accuracy here
