"""Blockwise kernels: same result whatever the block size; processing results independent of it."""

from __future__ import annotations

import numpy as np
import pytest

from processing import _blockwise
from processing.phase.shifting import phase_shift
from processing.unwrap.temporal import unwrap_two_frequency


def _kernel(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return a * b, (a > b)


@pytest.mark.parametrize("block", [1, 7, 100, 1000, 5000])
def test_any_block_size_gives_the_elementwise_result(block: int) -> None:
    rng = np.random.default_rng(block)
    a, b = rng.normal(size=1234), rng.normal(size=1234)
    product, greater = _blockwise.blockwise(_kernel, [a, b], (np.float64, np.bool_), block=block)
    np.testing.assert_array_equal(product, a * b)
    np.testing.assert_array_equal(greater, a > b)
    assert product.dtype == np.float64 and greater.dtype == np.bool_


def test_stacks_are_cut_along_the_last_axis() -> None:
    stack = np.arange(3 * 50, dtype=np.float64).reshape(3, 50)
    (total,) = _blockwise.blockwise(lambda s: (s.sum(axis=0),), [stack], (np.float64,), block=8)
    np.testing.assert_array_equal(total, stack.sum(axis=0))


def test_processing_results_do_not_depend_on_the_block(monkeypatch: pytest.MonkeyPatch) -> None:
    rng = np.random.default_rng(0)
    stack = rng.integers(0, 255, (6, 200, 300), dtype=np.uint8)
    phi1, phi2 = rng.uniform(-np.pi, np.pi, (2, 200, 300))
    results = []
    for block in (_blockwise.BLOCK, 999):
        monkeypatch.setattr(_blockwise.blockwise, "__defaults__", (block,))
        ps = phase_shift(stack)
        unwrapped = unwrap_two_frequency(phi1, phi2, 7, 8)
        results.append((ps.phase, ps.modulation, unwrapped.phase, unwrapped.orders, unwrapped.valid))
    for default, small in zip(*results):
        np.testing.assert_array_equal(default, small)
