"""Run an elementwise numpy kernel over blocks of pixels, on up to a few threads.

A chain of numpy operations on full 1024 x 768 float64 images allocates a fresh 6 MB temporary
per operation and streams every one through main memory. Cutting the pixels into blocks of a few
thousand keeps the temporaries in the CPU cache and in the allocator's small-block pool; only the
outputs are allocated at full size. The loop is over blocks (about fifty per megapixel), never
over pixels.

numpy releases the GIL inside its loops, so the blocks can be shared between the calling thread
and a small pool: ``FPP_THREADS`` (environment) sets the number of threads, default 1 (no pool).
On the shared 2-core development machine a second thread bought nothing: with blocks this small
the threads mostly wait for each other's GIL hand-over and the other core is seldom idle (see
benchmarks/bench_pipeline.py, which times both). On a machine with idle cores, try 2-4.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor

import numpy as np

BLOCK = 16384  # pixels per block: float64 temporaries of 128 KiB stay in L2


def _thread_count() -> int:
    configured = os.environ.get("FPP_THREADS")
    if configured is None:
        return 1
    try:
        return max(1, int(configured))
    except ValueError:
        raise ValueError(f"FPP_THREADS: expected a positive integer, found {configured!r}") from None


THREADS = _thread_count()
_pool: ThreadPoolExecutor | None = None
_pool_lock = threading.Lock()


def _executor() -> ThreadPoolExecutor:
    global _pool
    with _pool_lock:
        if _pool is None:
            _pool = ThreadPoolExecutor(max_workers=max(1, THREADS - 1), thread_name_prefix="fpp-blockwise")
        return _pool


def _forget_pool_after_fork() -> None:
    """A forked child inherits the pool object but not its threads: start a fresh one there."""
    global _pool, _pool_lock
    _pool = None
    _pool_lock = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool_after_fork)


def blockwise(
    kernel: Callable[..., tuple[np.ndarray, ...]],
    inputs: Sequence[np.ndarray],
    out_dtypes: Sequence[type | np.dtype],
    block: int = BLOCK,
) -> tuple[np.ndarray, ...]:
    """Apply ``kernel`` to consecutive blocks along the last (pixel) axis of every input.

    Parameters
    ----------
    kernel : callable
        ``kernel(*blocks) -> tuple`` of one array per output, each of the block's length. It
        must not share state between calls (blocks may run concurrently).
    inputs : sequence of arrays
        Arrays whose last axis runs over the same P pixels (e.g. (P,) maps, (N, P) stacks).
    out_dtypes : sequence of dtypes
        dtype of each (P,) output.
    block : int
        Pixels per block.

    Returns
    -------
    outputs : tuple of (P,) arrays
    """
    pixels = inputs[0].shape[-1]
    outputs = tuple(np.empty(pixels, dtype=dtype) for dtype in out_dtypes)
    starts = range(0, pixels, block)

    def run(part: Sequence[int]) -> None:
        for start in part:
            window = slice(start, min(start + block, pixels))
            results = kernel(*(x[..., window] for x in inputs))
            for out, result in zip(outputs, results):
                out[window] = result

    threads = min(THREADS, len(starts))
    if threads <= 1:
        run(starts)
        return outputs
    # Contiguous runs of blocks, one per thread; the calling thread takes the first.
    bounds = np.linspace(0, len(starts), threads + 1).astype(int)
    parts = [starts[bounds[i] : bounds[i + 1]] for i in range(threads)]
    futures = [_executor().submit(run, part) for part in parts[1:]]
    try:
        run(parts[0])
    finally:
        for future in futures:  # wait for every part, re-raising the first error
            future.result()
    return outputs
