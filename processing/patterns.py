"""What each pattern kind of capture-format.md projects, as numpy maths.

This module is the single definition of the projected intensities: the moderngl shaders, the
synthesiser and the simulated camera are all checked against it. Intensities are in [0, 1],
before the projector's gamma. The projector pixel coordinate ``u`` runs along the pattern's
``axis`` over ``0 .. W`` (``W`` the projector width for ``"x"``, its height for ``"y"``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

PATTERN_KINDS = ("sinusoid", "speckle-sinusoid", "gray", "flat")

# Keys of a pattern entry that change what is projected: two captures are comparable only if
# these agree pattern by pattern (provenance and other extra keys may differ).
PROJECTION_KEYS = (
    "kind", "axis", "frequency", "steps", "step", "offset", "amplitude", "phase_rad", "shift_rad",
    "bit", "bits", "inverted", "level", "seed", "dot_px", "speckle_gain",
)


def sinusoid_shift(pattern: Mapping[str, Any]) -> float:
    """Phase shift of one sinusoid frame in radians: ``shift_rad`` if given, else 2 pi j / J."""
    if "shift_rad" in pattern:
        return float(pattern["shift_rad"])
    return 2.0 * np.pi * int(pattern["step"]) / int(pattern["steps"])


def sinusoid_intensity(pattern: Mapping[str, Any], u: np.ndarray, extent: float) -> np.ndarray:
    """Intensity of a ``sinusoid`` pattern at projector coordinate ``u`` along its axis.

    Parameters
    ----------
    pattern : mapping
        A ``sinusoid`` entry of capture.json (``frequency``, ``steps``, ``step``; optional
        ``offset``, ``amplitude``, ``phase_rad``, ``shift_rad``).
    u : array
        Projector coordinate in pixels along the pattern's axis.
    extent : float
        Projector size ``W`` along the axis, in pixels.

    Returns
    -------
    array like ``u``: offset + amplitude cos(2 pi f u / W + phase_rad + shift).
    """
    offset = float(pattern.get("offset", 0.5))
    amplitude = float(pattern.get("amplitude", 0.5))
    phase = 2.0 * np.pi * float(pattern["frequency"]) * np.asarray(u, dtype=np.float64) / extent
    phase += float(pattern.get("phase_rad", 0.0)) + sinusoid_shift(pattern)
    return offset + amplitude * np.cos(phase)


def gray_stripe_index(u: np.ndarray, extent: float, bits: int) -> np.ndarray:
    """Index of the Gray-code stripe (0 .. 2**bits - 1) that projector coordinate ``u`` lies in."""
    stripes = 1 << bits
    return np.clip(np.floor(np.asarray(u, dtype=np.float64) * stripes / extent), 0, stripes - 1).astype(np.int64)


def gray_intensity(pattern: Mapping[str, Any], u: np.ndarray, extent: float) -> np.ndarray:
    """Intensity (0 or 1) of one Gray-code bit plane; ``bit`` 0 is the most significant.

    The projector width is cut into ``2**bits`` stripes; stripe ``s`` carries Gray code
    ``s ^ (s >> 1)``. ``inverted`` gives the complementary (negative) image.
    """
    bits = int(pattern["bits"])
    bit = int(pattern["bit"])
    stripe = gray_stripe_index(u, extent, bits)
    gray = stripe ^ (stripe >> 1)
    value = ((gray >> (bits - 1 - bit)) & 1).astype(np.float64)
    return 1.0 - value if pattern.get("inverted", False) else value


def pattern_intensity(
    pattern: Mapping[str, Any], u: np.ndarray, v: np.ndarray, projector_size: tuple[int, int]
) -> np.ndarray:
    """Projected intensity in [0, 1] of any pattern kind at projector pixel coordinates (u, v).

    Parameters
    ----------
    pattern : mapping
        One entry of capture.json's ``patterns``.
    u, v : arrays of equal shape
        Projector column and row coordinates in pixels (pixel centres at k + 0.5).
    projector_size : (width, height)
        Projector resolution in pixels.
    """
    kind = pattern.get("kind")
    width, height = projector_size
    axis = pattern.get("axis", "x")
    if axis not in ("x", "y"):
        raise ValueError(f"pattern axis: expected 'x' or 'y', found {axis!r}")
    coord, extent = (u, width) if axis == "x" else (v, height)
    if kind == "sinusoid":
        return sinusoid_intensity(pattern, coord, extent)
    if kind == "gray":
        return gray_intensity(pattern, coord, extent)
    if kind == "flat":
        return np.full(np.shape(u), float(pattern["level"]))
    if kind == "speckle-sinusoid":
        from processing.speckle import speckle_sinusoid_intensity

        return speckle_sinusoid_intensity(pattern, u, v, projector_size)
    raise ValueError(f"pattern kind: expected one of {', '.join(PATTERN_KINDS)}, found {kind!r}")


def pattern_image(pattern: Mapping[str, Any], projector_size: tuple[int, int]) -> np.ndarray:
    """The full projector frame of a pattern, (height, width) float32 in [0, 1], sampled at pixel centres."""
    width, height = projector_size
    u = np.arange(width, dtype=np.float64) + 0.5
    v = np.arange(height, dtype=np.float64) + 0.5
    uu, vv = np.meshgrid(u, v)
    return pattern_intensity(pattern, uu, vv, projector_size).astype(np.float32)

