"""processing.correction.phase_rpca.block_means: the valid pixels' mean of each block, bit for bit numpy's sum."""

from __future__ import annotations

import numpy as np
import pytest

from processing.correction.phase_rpca import block_means


def _reference(values: np.ndarray, valid: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """The block means as numpy's multi-axis sum of the padded float32 map computes them."""
    rows, cols = values.shape
    down, across = -(-rows // factor), -(-cols // factor)
    data = np.zeros((down * factor, across * factor), dtype=np.float32)
    count = np.zeros(data.shape, dtype=np.float32)
    data[:rows, :cols] = np.where(valid, values, 0.0)
    count[:rows, :cols] = valid
    sums = data.reshape(down, factor, across, factor).sum(axis=(1, 3))
    counts = count.reshape(down, factor, across, factor).sum(axis=(1, 3))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, sums / counts, 0.0).astype(np.float32), counts > 0


@pytest.mark.parametrize("factor", [2, 3, 4])
def test_block_means_equal_numpys_block_sums_bit_for_bit(factor: int) -> None:
    rng = np.random.default_rng(factor)
    for shape in ((61, 94), (64, 96), (7, 5)):
        values = rng.normal(0.0, 1.0, shape) * 10.0 ** rng.uniform(-3.0, 3.0, shape) + 100.0 * rng.random()
        values[rng.random(shape) < 0.05] = -0.0
        valid = rng.random(shape) > 0.2
        valid[: 2 * factor, : 2 * factor] = False  # whole blocks without a valid pixel: 0 and False
        values[~valid] = np.nan  # never read
        means, inside = block_means(values, valid, factor)
        expected, expected_inside = _reference(values, valid, factor)
        assert means.dtype == np.float32 and np.array_equal(inside, expected_inside)
        assert means.tobytes() == expected.tobytes()
        assert not inside[:2, :2].any() and (means[:2, :2] == 0).all()


def test_block_means_are_the_means_of_the_valid_pixels() -> None:
    values = np.arange(16.0).reshape(4, 4)
    valid = np.ones((4, 4), dtype=bool)
    valid[0, 0] = False
    means, inside = block_means(values, valid, 2)
    assert inside.all()
    np.testing.assert_allclose(
        means, [[(1 + 4 + 5) / 3, (2 + 3 + 6 + 7) / 4], [(8 + 9 + 12 + 13) / 4, (10 + 11 + 14 + 15) / 4]]
    )
