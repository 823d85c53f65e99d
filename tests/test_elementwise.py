"""abs_difference: numpy's |a - b| bit for bit, through OpenCV where it applies."""

import numpy as np
import pytest

from processing.elementwise import abs_difference


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_neighbour_steps_match_numpy_bit_for_bit(dtype):
    rng = np.random.default_rng(3)
    phase = (rng.normal(size=(67, 131)) * 40.0).astype(dtype)
    phase[rng.random(phase.shape) < 0.05] = np.nan
    phase[0, :3] = [np.inf, -np.inf, 0.0]
    for after, before in ((phase[:, 1:], phase[:, :-1]), (phase[1:], phase[:-1])):  # strided views
        expected = np.abs(np.subtract(after, before))
        got = abs_difference(after, before)
        assert got.dtype == expected.dtype and got.shape == expected.shape
        assert np.array_equal(got, expected, equal_nan=True)
        assert np.array_equal(np.signbit(got), np.signbit(expected))


def test_other_inputs_take_numpy():
    a, b = np.array([1.0, np.nan, -2.5]), np.array([3.0, 1.0, 0.5])  # 1-D
    assert np.array_equal(abs_difference(a, b), [2.0, np.nan, 3.0], equal_nan=True)
    mixed = abs_difference(np.ones((2, 2), np.float32), np.zeros((2, 2)))  # two dtypes: numpy's promotion
    assert mixed.dtype == np.float64 and np.array_equal(mixed, np.ones((2, 2)))
