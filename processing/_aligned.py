"""Arrays whose data starts on a 64-byte boundary, for OpenCV kernels whose rounding depends on it.

OpenCV's ``magnitude`` computes the elements before its output's first 32-byte boundary on a
scalar path that rounds differently from its vector loop (1 ulp, measured on AVX2). numpy places a
new array on a 16-byte boundary, so half the time a map's first elements depended on where the
allocator put it: the same frames gave maps that differed in the last bit from run to run and
between a batch worker and ``rig process``. Outputs allocated here take the vector loop
throughout.
"""

from __future__ import annotations

import math

import numpy as np

ALIGNMENT = 64  # bytes: a cache line, and a multiple of every SIMD width OpenCV uses


def aligned_empty(shape: int | tuple[int, ...], dtype: type | np.dtype = np.float32) -> np.ndarray:
    """An uninitialised C-contiguous array of ``shape`` whose data starts on an :data:`ALIGNMENT` boundary."""
    dims = (shape,) if isinstance(shape, int) else tuple(shape)
    itemsize = np.dtype(dtype).itemsize
    size = math.prod(dims) * itemsize
    raw = np.empty(size + ALIGNMENT, dtype=np.uint8)
    start = -raw.ctypes.data % ALIGNMENT
    return raw[start : start + size].view(dtype).reshape(dims)
