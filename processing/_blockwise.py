"""Run an elementwise numpy kernel over blocks of pixels.

A chain of numpy operations on full 1024 x 768 float64 images allocates a fresh 6 MB temporary
per operation and streams every one through main memory. Cutting the pixels into blocks of a few
thousand keeps the temporaries in the CPU cache and in the allocator's small-block pool; only the
outputs are allocated at full size. The loop is over blocks (about fifty per megapixel), never
over pixels.

Sharing the blocks between threads was tried and dropped: numpy releases the GIL inside its
loops, but with blocks this small the threads spent their time handing the GIL over (two threads
used 40 % more CPU for no shorter wall time on the 2-core development machine, idle or loaded).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

BLOCK = 16384  # pixels per block: float64 temporaries of 128 KiB stay in L2


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
        ``kernel(*blocks) -> tuple`` of one array per output, each of the block's length.
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
    for start in range(0, pixels, block):
        window = slice(start, min(start + block, pixels))
        results = kernel(*(x[..., window] for x in inputs))
        for out, result in zip(outputs, results):
            out[window] = result
    return outputs
