"""processing.quantiles.percentile against numpy's percentile, bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from processing.quantiles import percentile


def _samples(rng: np.random.Generator):
    for size in (1, 2, 3, 7, 100, 16001):
        for dtype in (np.float32, np.float64):
            yield rng.random(size).astype(dtype)
            yield rng.integers(0, 4, size).astype(dtype)  # ties everywhere
            yield (rng.standard_normal(size) * 1e3).astype(dtype)


@pytest.mark.parametrize("q", [0.0, 1.0, 37.3, 50.0, 95.0, 99.0, 100.0])
def test_equals_numpy_bit_for_bit(q: float) -> None:
    rng = np.random.default_rng(7)
    for sample in _samples(rng):
        expected = float(np.percentile(sample, q))
        assert percentile(sample.copy(), q) == expected, (sample.dtype, sample.size, q)


def test_reorders_only_the_sample_given() -> None:
    sample = np.array([5.0, 1.0, 4.0, 2.0, 3.0])
    assert percentile(sample, 50.0) == 3.0
    assert sorted(sample.tolist()) == [1.0, 2.0, 3.0, 4.0, 5.0]  # same values, possibly reordered


@pytest.mark.parametrize(
    ("sample", "q", "message"),
    [(np.zeros(0), 50.0, "non-empty"), (np.zeros((2, 2)), 50.0, "one-dimensional"), (np.zeros(3), 101.0, "q")],
)
def test_refuses_what_it_cannot_take(sample: np.ndarray, q: float, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        percentile(sample, q)
