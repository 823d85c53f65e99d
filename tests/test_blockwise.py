"""Blockwise kernels: same result whatever the block size or thread count; errors surface."""

from __future__ import annotations

import numpy as np
import pytest

from processing import _blockwise
from processing.phase_shift import phase_shift
from processing.temporal import unwrap_two_frequency


@pytest.fixture
def threads(monkeypatch: pytest.MonkeyPatch):
    def set_threads(count: int) -> None:
        monkeypatch.setattr(_blockwise, "THREADS", count)

    return set_threads


def _kernel(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return a * b, (a > b)


@pytest.mark.parametrize("block", [1, 7, 100, 1000, 5000])
@pytest.mark.parametrize("count", [1, 2, 3])
def test_blocks_and_threads_give_the_elementwise_result(threads, block: int, count: int) -> None:
    threads(count)
    rng = np.random.default_rng(block)
    a, b = rng.normal(size=1234), rng.normal(size=1234)
    product, greater = _blockwise.blockwise(_kernel, [a, b], (np.float64, np.bool_), block=block)
    np.testing.assert_array_equal(product, a * b)
    np.testing.assert_array_equal(greater, a > b)
    assert product.dtype == np.float64 and greater.dtype == np.bool_


def test_stacks_are_cut_along_the_last_axis(threads) -> None:
    threads(2)
    stack = np.arange(3 * 50, dtype=np.float64).reshape(3, 50)
    (total,) = _blockwise.blockwise(lambda s: (s.sum(axis=0),), [stack], (np.float64,), block=8)
    np.testing.assert_array_equal(total, stack.sum(axis=0))


def test_kernel_error_is_raised_after_all_parts_finish(threads) -> None:
    threads(2)
    calls = []

    def failing(a: np.ndarray) -> tuple[np.ndarray]:
        calls.append(a.size)
        if a[0] >= 500:
            raise ValueError("late block")
        return (a,)

    with pytest.raises(ValueError, match="late block"):
        _blockwise.blockwise(failing, [np.arange(1000.0)], (np.float64,), block=100)
    assert sum(calls) >= 500


def test_processing_results_do_not_depend_on_threads(threads) -> None:
    rng = np.random.default_rng(0)
    stack = rng.integers(0, 255, (6, 200, 300), dtype=np.uint8)
    phi1, phi2 = rng.uniform(-np.pi, np.pi, (2, 200, 300))
    results = []
    for count in (1, 2):
        threads(count)
        ps = phase_shift(stack)
        unwrapped = unwrap_two_frequency(phi1, phi2, 7, 8)
        results.append((ps.phase, ps.modulation, unwrapped.phase, unwrapped.orders, unwrapped.valid))
    for single, multi in zip(*results):
        np.testing.assert_array_equal(single, multi)


def test_thread_count_from_environment(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("FPP_THREADS", "3")
    assert _blockwise._thread_count() == 3
    monkeypatch.setenv("FPP_THREADS", "0")
    assert _blockwise._thread_count() == 1
    monkeypatch.setenv("FPP_THREADS", "many")
    with pytest.raises(ValueError, match="FPP_THREADS"):
        _blockwise._thread_count()
    monkeypatch.delenv("FPP_THREADS")
    assert _blockwise._thread_count() == 1


def test_forked_child_gets_a_working_pool(threads) -> None:
    """multiprocessing's fork start method copies the pool object without its threads."""
    import multiprocessing

    if "fork" not in multiprocessing.get_all_start_methods():
        pytest.skip("no fork start method on this platform")
    threads(2)
    stack = np.random.default_rng(1).integers(0, 255, (4, 150, 150), dtype=np.uint8)
    expected = phase_shift(stack).phase  # starts the pool in the parent
    context = multiprocessing.get_context("fork")
    with context.Pool(1) as pool:
        result = pool.apply_async(_child_phase, (stack,))
        np.testing.assert_array_equal(result.get(timeout=60), expected)


def _child_phase(stack: np.ndarray) -> np.ndarray:
    _blockwise.THREADS = 2
    return phase_shift(stack).phase
