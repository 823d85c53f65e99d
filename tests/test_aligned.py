"""processing._aligned: arrays on a 64-byte boundary, for OpenCV's alignment-dependent rounding."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from processing._aligned import ALIGNMENT, aligned_empty


@pytest.mark.parametrize(("shape", "dtype"), [(7, np.float32), ((3, 5), np.int32), ((2, 3, 4), np.uint8)])
def test_aligned_empty_is_aligned_contiguous_and_of_its_shape(shape, dtype) -> None:
    for _ in range(8):  # several allocations: numpy alone places them on 16-byte boundaries
        array = aligned_empty(shape, dtype)
        assert array.ctypes.data % ALIGNMENT == 0 and array.flags.c_contiguous and array.flags.writeable
        assert array.shape == ((shape,) if isinstance(shape, int) else shape) and array.dtype == dtype


def test_magnitude_into_aligned_outputs_does_not_depend_on_the_allocation() -> None:
    """The reason for the module: OpenCV's magnitude into outputs 16 bytes off a 32-byte boundary rounds its
    first elements differently; into aligned outputs the values are the same wherever they are."""
    rng = np.random.default_rng(3)
    cos_part, sin_part = (rng.normal(0.0, 50.0, 4096).astype(np.float32) for _ in range(2))
    raw = np.empty(4096 + 64, dtype=np.float32)
    start = (-raw.ctypes.data % 64) // 4
    outputs = [raw[start + offset : start + offset + 4096] for offset in (0, 4, 8, 12)]  # 0, 16, 32, 48 bytes
    results = []
    for out in outputs:
        cv2.magnitude(cos_part, sin_part, out)
        results.append(out.copy())
    aligned = [aligned_empty(4096) for _ in range(4)]
    for out in aligned:
        cv2.magnitude(cos_part, sin_part, out)
    assert all(np.array_equal(out, results[0]) for out in aligned)  # the 64-byte-aligned result
    exact = np.hypot(cos_part.astype(np.float64), sin_part.astype(np.float64))
    for result in results:
        assert np.max(np.abs(result - exact) / np.spacing(exact.astype(np.float32))) <= 2.0  # either way within 2 ulp


def test_an_empty_aligned_array_has_its_shape() -> None:
    assert aligned_empty(0).shape == (0,) and aligned_empty((0, 3), np.int32).shape == (0, 3)
