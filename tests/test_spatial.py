"""Quality-guided spatial unwrapping against a known continuous phase (up to 2 pi k per region)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.phase.shifting import phase_shift, quality_map, shadow_mask
from processing.unwrap.spatial import phase_derivative_variance, unwrap_quality_guided

TWO_PI = 2.0 * np.pi
SHAPE = (90, 120)


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * x))


def _surface() -> np.ndarray:
    """A tilted paraboloid spanning about 8 periods, gradient below 1 rad per pixel."""
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]].astype(float)
    return 0.25 * x + 0.0015 * ((x - 60.0) ** 2 + (y - 40.0) ** 2) + 1.0


def _assert_equal_up_to_2pi(unwrapped: np.ndarray, truth: np.ndarray, region: np.ndarray, atol: float) -> None:
    difference = unwrapped[region] - truth[region]
    offset = np.median(difference)
    assert abs(offset / TWO_PI - np.rint(offset / TWO_PI)) < 0.05, "offset is not a multiple of 2 pi"
    assert np.max(np.abs(difference - TWO_PI * np.rint(offset / TWO_PI))) < atol


def test_noise_free_surface_exact() -> None:
    truth = _surface()
    unwrapped = unwrap_quality_guided(_wrap(truth))
    _assert_equal_up_to_2pi(unwrapped, truth, np.ones(SHAPE, bool), 1e-9)


@pytest.mark.parametrize("quality", ["variance", "modulation"])
def test_noisy_surface_with_quality(quality: str) -> None:
    rng = np.random.default_rng(11)
    truth = _surface()
    modulation = np.ones(SHAPE)
    noise = rng.normal(0.0, 0.15, SHAPE)
    # A very noisy patch: a good quality map routes the paths around it.
    noise[30:45, 70:85] = rng.uniform(-np.pi, np.pi, (15, 15))
    modulation[30:45, 70:85] = 0.05
    wrapped = _wrap(truth + noise)
    unwrapped = unwrap_quality_guided(wrapped, quality=modulation if quality == "modulation" else None)
    outside = np.ones(SHAPE, bool)
    outside[28:47, 68:87] = False
    # Right order everywhere outside the patch: error = the added noise only.
    _assert_equal_up_to_2pi(unwrapped, truth, outside, 5 * 0.15)


def test_mask_with_isolated_regions() -> None:
    """A masked band splits the image: each side right up to its own 2 pi k, NaN in the band."""
    truth = _surface()
    mask = np.ones(SHAPE, bool)
    mask[:, 55:60] = False
    mask[10:20, 10:20] = False  # a hole inside the left region
    unwrapped = unwrap_quality_guided(_wrap(truth), mask=mask)
    assert np.all(np.isnan(unwrapped[~mask]))
    assert not np.isnan(unwrapped[mask]).any()
    left, right = mask.copy(), mask.copy()
    left[:, 55:] = False
    right[:, :60] = False
    _assert_equal_up_to_2pi(unwrapped, truth, left, 1e-9)
    _assert_equal_up_to_2pi(unwrapped, truth, right, 1e-9)


def test_nan_pixels_are_excluded_and_single_pixels_survive() -> None:
    truth = _surface()
    wrapped = _wrap(truth)
    wrapped[5, 5] = np.nan
    mask = np.ones(SHAPE, bool)
    mask[0:3, 0:3] = False
    mask[1, 1] = True  # an isolated single pixel: its own region
    unwrapped = unwrap_quality_guided(wrapped, mask=mask)
    assert np.isnan(unwrapped[5, 5])
    assert unwrapped[1, 1] == pytest.approx(wrapped[1, 1])
    region = mask & np.isfinite(wrapped)
    region[0:3, 0:3] = False
    _assert_equal_up_to_2pi(unwrapped, truth, region, 1e-9)


def test_simulated_scan_single_frequency() -> None:
    """Sphere cap at 16 fringes: spatial unwrapping of the lit pixels matches the absolute phase."""
    base = synth.RigGeometry()
    geometry = replace(base.with_camera(128, 96), pixel_mm=base.pixel_mm * 8)
    heights = scenes.sphere_cap(96, 128, geometry.pixel_mm)
    mapping = synth.projector_coordinates(heights, geometry)
    stack = synth.render_stack(
        synth.sinusoid_patterns([16], 4),
        mapping,
        geometry,
        synth.Appearance(ambient=0.05, snr_db=35.0),
        np.random.default_rng(2),
    )
    result = phase_shift(stack)
    valid = shadow_mask(result.modulation, result.background)
    unwrapped = unwrap_quality_guided(
        result.phase, quality=quality_map(result.modulation, result.background), mask=valid
    )
    truth = synth.true_absolute_phase(mapping, geometry, 16)
    _assert_equal_up_to_2pi(unwrapped, truth, valid & mapping.lit, 0.3)


def test_phase_derivative_variance() -> None:
    y, x = np.mgrid[0:40, 0:50].astype(float)
    ramp = _wrap(0.9 * x - 0.4 * y)  # linear phase, wraps included: zero variance
    assert np.max(phase_derivative_variance(ramp)) < 1e-6  # sqrt of round-off in var
    noisy = ramp.copy()
    noisy[15:25, 20:30] = np.random.default_rng(0).uniform(-np.pi, np.pi, (10, 10))
    z = phase_derivative_variance(noisy, window=5)
    assert z[20, 25] > 1.0 and z[5, 5] < 1e-6


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"phi": np.zeros((3, 4, 5))}, "phi"),
        ({"mask": np.ones((3, 3), bool)}, "mask"),
        ({"mask": np.ones(SHAPE)}, "mask"),
        ({"quality": np.ones((2, 2))}, "quality"),
        ({"quality_kind": "residues"}, "quality_kind"),
    ],
)
def test_bad_input_names_the_argument(kwargs: dict, match: str) -> None:
    arguments = {"phi": np.zeros(SHAPE)} | kwargs
    with pytest.raises(ValueError, match=match):
        unwrap_quality_guided(**arguments)
    with pytest.raises(ValueError, match="window"):
        phase_derivative_variance(np.zeros(SHAPE), window=4)


def test_remove_region_offsets_takes_each_regions_nearest_multiple_of_two_pi() -> None:
    """Two regions off by 2 pi k from the reference (plus a small true difference) come back to it (issue 9)."""
    from processing.unwrap.spatial import remove_region_offsets

    rng = np.random.default_rng(5)
    truth = 0.3 * rng.standard_normal((20, 30))
    delta = np.full((20, 30), np.nan)
    delta[:, :12] = truth[:, :12] + 2 * np.pi * 3
    delta[:, 15:] = truth[:, 15:] - 2 * np.pi * 2
    out = remove_region_offsets(delta)
    np.testing.assert_allclose(out[:, :12], truth[:, :12], atol=1e-12)
    np.testing.assert_allclose(out[:, 15:], truth[:, 15:], atol=1e-12)
    assert np.isnan(out[:, 12:15]).all()
    assert np.isnan(remove_region_offsets(np.full((3, 3), np.nan))).all()
