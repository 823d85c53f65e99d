"""Phase differences wrapped into [-pi, pi): the arithmetic every order test shares."""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi
_INV_TWO_PI = 1.0 / TWO_PI


def wrap_to_pi(x: np.ndarray) -> np.ndarray:
    """``x`` wrapped into [-pi, pi), as ``np.mod(x + pi, 2 pi) - pi`` (to rounding) at a quarter of its cost.

    ``np.mod`` of floats computes an exact remainder (about 14 ns a value here); a floor of the
    scaled value is 3-4x faster and differs only by the rounding of the last bit.
    """
    out = np.multiply(x, _INV_TWO_PI)
    out += 0.5
    np.floor(out, out=out)
    out *= -TWO_PI
    out += x
    return out
