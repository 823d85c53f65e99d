"""processing.geometry.plane_model: eq. 1.15's heights, their sigma and the mask in one blocked pass."""

from __future__ import annotations

import numpy as np
import pytest

from processing.geometry.height import phase_to_height
from processing.geometry.plane_model import BLOCK, plane_heights
from processing.geometry.uncertainty import combined_phase_sigma, height_sigma

GEOMETRY = (1000.0, 200.0, 0.05)  # l0, d0 (mm), f0 (fringes / mm)


def _scene(shape: tuple[int, int], dtype: type, seed: int = 0):
    rng = np.random.default_rng(seed)
    reference = np.broadcast_to(np.linspace(0.0, 2 * np.pi * 16, shape[1]), shape).astype(dtype)
    phase = (reference - 3.0 * rng.random(shape)).astype(dtype)
    phase[5:40, 10:60] = np.nan  # a shadow
    valid = np.ones(shape, bool)
    valid[:, :7] = False
    reference_valid = rng.random(shape) > 0.01
    sigmas = [(0.01 + 0.05 * rng.random(shape)).astype(np.float32) for _ in range(2)]
    return phase, reference, valid, reference_valid, sigmas


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_heights_and_mask_are_the_stepwise_ones_bit_for_bit(dtype: type) -> None:
    shape = (300, BLOCK // 256 + 3)  # blocks that do not divide the map
    phase, reference, valid, reference_valid, _ = _scene(shape, dtype)
    out = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, threads=2)
    stepwise = phase_to_height(phase - reference, *GEOMETRY, dtype=dtype).astype(np.float32)
    mask = valid & reference_valid & np.isfinite(stepwise)
    stepwise[~mask] = np.nan
    assert out.height.dtype == np.float32 and out.sigma is None
    np.testing.assert_array_equal(out.mask, mask)
    assert np.array_equal(out.height, stepwise, equal_nan=True)
    assert 0.5 < mask.mean() < 1.0  # the test exercises both sides of the mask


def test_sigma_is_the_analytic_slope_times_the_phase_sigmas_in_quadrature() -> None:
    shape = (200, 333)
    phase, reference, valid, reference_valid, (sigma_obj, sigma_ref) = _scene(shape, np.float32, seed=1)
    out = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, sigma_obj, sigma_ref)
    l0, d0, f0 = GEOMETRY
    c = 2 * np.pi * f0 * d0
    delta = phase.astype(np.float64) - reference.astype(np.float64)
    expected = abs(l0 * c) * np.hypot(sigma_obj, sigma_ref) / (delta - c) ** 2
    assert out.sigma is not None
    np.testing.assert_allclose(out.sigma[out.mask], expected[out.mask], rtol=2e-6)
    assert np.isnan(out.sigma[~out.mask]).all()
    # the other models' way, a forward difference of the model, agrees to its truncation error
    model = lambda p: phase_to_height(p - reference, *GEOMETRY, dtype=np.float32)  # noqa: E731
    difference = height_sigma(model, phase, combined_phase_sigma(sigma_obj, sigma_ref), base=model(phase))
    np.testing.assert_allclose(out.sigma[out.mask], difference[out.mask], rtol=2e-3)


def test_without_a_reference_sigma_the_objects_alone() -> None:
    phase, reference, valid, reference_valid, (sigma_obj, _) = _scene((64, 80), np.float32, seed=2)
    alone = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, sigma_obj)
    doubled = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, sigma_obj, sigma_obj)
    assert alone.sigma is not None and doubled.sigma is not None
    np.testing.assert_allclose(doubled.sigma[alone.mask], np.sqrt(2) * alone.sigma[alone.mask], rtol=1e-6)


def test_threads_give_the_same_maps() -> None:
    phase, reference, valid, reference_valid, (sigma_obj, sigma_ref) = _scene((400, 500), np.float32, seed=3)
    one = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, sigma_obj, sigma_ref, threads=1)
    two = plane_heights(phase, reference, valid, reference_valid, GEOMETRY, sigma_obj, sigma_ref, threads=2)
    for a, b in ((one.height, two.height), (one.sigma, two.sigma), (one.mask, two.mask)):
        assert np.array_equal(a, b, equal_nan=a.dtype != bool)


def test_refuses_maps_of_another_shape_and_a_bad_geometry() -> None:
    phase, reference, valid, reference_valid, _ = _scene((20, 30), np.float32)
    with pytest.raises(ValueError, match="reference_valid: expected the shape"):
        plane_heights(phase, reference, valid, reference_valid[:, :5], GEOMETRY)
    with pytest.raises(ValueError, match="l0_mm"):
        plane_heights(phase, reference, valid, reference_valid, (0.0, 200.0, 0.05))
