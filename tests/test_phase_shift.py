"""N-step phase shifting, shadow mask and quality map against analytic and simulated truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.phase.shifting import (
    PhaseShiftResult,
    phase_shift,
    quality_map,
    root_sum_square,
    shadow_mask,
    shift_weights,
    wrapped_phase,
)

A, B = 120.0, 80.0
SHAPE = (48, 64)


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * x))


def _frames(phi: np.ndarray, shifts: np.ndarray, sigma: float = 0.0, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    frames = A + B * np.cos(phi[None] + shifts[:, None, None])
    return frames + rng.normal(0.0, sigma, frames.shape) if sigma else frames


@pytest.fixture
def phi() -> np.ndarray:
    return np.random.default_rng(42).uniform(-np.pi, np.pi, SHAPE)


@pytest.mark.parametrize("steps", range(3, 13))
def test_uniform_shifts_exact_without_noise(phi: np.ndarray, steps: int) -> None:
    result = phase_shift(_frames(phi, 2 * np.pi * np.arange(steps) / steps))
    assert isinstance(result, PhaseShiftResult)
    assert result.phase.dtype == result.background.dtype == result.modulation.dtype == np.float64
    np.testing.assert_allclose(_wrap(result.phase - phi), 0.0, atol=1e-9)
    np.testing.assert_allclose(result.background, A, atol=1e-9)
    np.testing.assert_allclose(result.modulation, B, atol=1e-9)


@pytest.mark.parametrize("steps", [3, 4, 6, 9, 12])
def test_uniform_shifts_noise_within_theory(phi: np.ndarray, steps: int) -> None:
    """Phase noise of N-step PSP is sigma / B * sqrt(2 / N); allow 5x that as the maximum."""
    sigma = 2.0
    result = phase_shift(_frames(phi, 2 * np.pi * np.arange(steps) / steps, sigma, seed=steps))
    bound = 5.0 * sigma / B * np.sqrt(2.0 / steps)
    assert np.max(np.abs(_wrap(result.phase - phi))) < bound
    assert np.max(np.abs(result.background - A)) < 5.0 * sigma / np.sqrt(steps)
    assert np.max(np.abs(result.modulation - B)) < 5.0 * sigma * np.sqrt(2.0 / steps)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_arbitrary_shifts_least_squares(phi: np.ndarray, seed: int) -> None:
    rng = np.random.default_rng(seed)
    steps = int(rng.integers(4, 9))
    shifts = np.sort(rng.uniform(0, 2 * np.pi, steps))
    shifts[:3] = [0.0, 2.0, 4.0]  # guarantee three well separated shifts
    exact = phase_shift(_frames(phi, shifts), shifts)
    np.testing.assert_allclose(_wrap(exact.phase - phi), 0.0, atol=1e-9)
    np.testing.assert_allclose(exact.modulation, B, atol=1e-9)
    noisy = phase_shift(_frames(phi, shifts, sigma=1.0, seed=seed), shifts)
    assert np.sqrt(np.mean(_wrap(noisy.phase - phi) ** 2)) < 0.03


def test_uniform_weights_match_least_squares() -> None:
    steps = 7
    shifts = 2 * np.pi * np.arange(steps) / steps
    np.testing.assert_allclose(shift_weights(steps), shift_weights(steps, shifts), atol=1e-12)


def test_wrong_shift_model_is_detected(phi: np.ndarray) -> None:
    """Frames shifted by -delta decoded as +delta give the conjugate phase: the test can fail."""
    shifts = 2 * np.pi * np.arange(4) / 4
    result = phase_shift(_frames(phi, -shifts))
    np.testing.assert_allclose(_wrap(result.phase + phi), 0.0, atol=1e-9)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.int32, np.float32])
def test_integer_and_float32_stacks(phi: np.ndarray, dtype: type) -> None:
    frames = _frames(phi, 2 * np.pi * np.arange(6) / 6)
    stack = np.rint(frames).astype(dtype) if np.issubdtype(dtype, np.integer) else frames.astype(dtype)
    # Quantisation to integers: error <= 0.5 DN per frame -> about 0.5 / B * sqrt(2 / N) * 3
    assert np.max(np.abs(_wrap(phase_shift(stack).phase - phi))) < 0.01
    np.testing.assert_array_equal(wrapped_phase(stack), phase_shift(stack).phase)


def test_phase_range_half_open() -> None:
    """phi = pi exactly must come back as -pi (range [-pi, pi))."""
    phi = np.full((2, 3), np.pi)
    for stack in (
        _frames(phi, 2 * np.pi * np.arange(4) / 4),
        np.rint(_frames(phi, 2 * np.pi * np.arange(4) / 4)).astype(np.uint8),
    ):
        phase = phase_shift(stack).phase
        assert np.all(phase >= -np.pi) and np.all(phase < np.pi)
        np.testing.assert_allclose(np.abs(phase), np.pi, atol=1e-6)


def test_block_boundaries_do_not_matter() -> None:
    """A frame larger than one processing block gives the same result as its parts."""
    rng = np.random.default_rng(5)
    phi = rng.uniform(-np.pi, np.pi, (150, 130))  # 19500 pixels: more than one block
    stack = np.rint(_frames(phi, 2 * np.pi * np.arange(5) / 5, sigma=1.0)).astype(np.uint8)
    whole = phase_shift(stack)
    top = phase_shift(stack[:, :75])
    np.testing.assert_array_equal(whole.phase[:75], top.phase)
    np.testing.assert_array_equal(whole.modulation[:75], top.modulation)


@pytest.mark.parametrize(
    ("stack", "shifts", "match"),
    [
        (np.zeros((2, 4, 4)), None, "stack"),
        (np.zeros((4, 4)), None, "stack"),
        (np.zeros((3, 4, 4), dtype=complex), None, "stack"),
        (np.zeros((3, 4, 4), dtype=bool), None, "stack"),
        (np.zeros((4, 4, 4)), np.array([0.0, 1.0, 2.0]), "shifts"),
        (np.zeros((4, 4, 4)), np.array([0.0, np.pi, 0.0, np.pi]), "shifts"),
        (np.zeros((3, 4, 4)), np.array([0.0, 1.0, np.nan]), "shifts"),
    ],
)
def test_bad_input_names_the_argument(stack: np.ndarray, shifts: np.ndarray | None, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        phase_shift(stack, shifts)


def _shadowed_scene(name: str, **params: float):
    geometry = replace(synth.RigGeometry().with_camera(128, 96), pixel_mm=3.2)
    heights = scenes.make_scene(name, 96, 128, geometry.pixel_mm, **params)
    mapping = synth.projector_coordinates(heights, geometry)
    appearance = synth.Appearance(ambient=0.1, snr_db=30.0)
    stack = synth.render_stack(synth.sinusoid_patterns([8], 6), mapping, geometry, appearance, np.random.default_rng(3))
    return mapping, phase_shift(stack)


@pytest.mark.parametrize(("scene", "params"), [("steps", {"step_mm": 40.0, "count": 2}), ("isolated", {})])
def test_shadow_mask_matches_projector_shadows(scene: str, params: dict) -> None:
    mapping, result = _shadowed_scene(scene, **params)
    shadow = ~mapping.lit
    assert shadow.sum() > 50, "scene should cast projector shadows"
    for valid in (shadow_mask(result.modulation, result.background), shadow_mask(result.modulation)):
        assert not valid[shadow].any()
        assert valid[mapping.lit].mean() > 0.99


def test_shadow_mask_dark_surface_needs_background() -> None:
    """A dark but lit surface has low B but high B / A: absolute threshold vs data modulation."""
    b = np.array([[100.0, 10.0, 10.0]])
    a = np.array([[110.0, 11.0, 60.0]])  # lit bright, lit dark, shadow with ambient light
    np.testing.assert_array_equal(shadow_mask(b, a, min_modulation=5.0), [[True, True, False]])
    np.testing.assert_array_equal(shadow_mask(b, min_modulation=5.0), [[True, True, True]])
    np.testing.assert_array_equal(shadow_mask(b, a), [[True, False, False]])  # automatic: 0.2 x p99 of B


def test_shadow_mask_nan_and_bad_arguments() -> None:
    b = np.array([[np.nan, 50.0], [0.0, 40.0]])
    np.testing.assert_array_equal(shadow_mask(b), [[False, True], [False, True]])
    with pytest.raises(ValueError, match="min_ratio"):
        shadow_mask(b, min_ratio=0.0)
    with pytest.raises(ValueError, match="min_modulation"):
        shadow_mask(b, min_modulation=-1.0)
    with pytest.raises(ValueError, match="background"):
        shadow_mask(b, background=np.ones((3, 3)))
    with pytest.raises(ValueError, match="modulation"):
        shadow_mask(np.full((2, 2), np.nan))


def test_quality_map_is_data_modulation() -> None:
    b = np.array([[50.0, 0.0, 80.0, 5.0, np.nan]])
    a = np.array([[100.0, 100.0, 40.0, 0.0, 10.0]])
    np.testing.assert_allclose(quality_map(b, a), [[0.5, 0.0, 1.0, 0.0, 0.0]])
    mapping, result = _shadowed_scene("steps", step_mm=40.0, count=2)
    gamma = quality_map(result.modulation, result.background)
    # Lit: fringe amplitude 0.5 over offset 0.5 + ambient 0.1 -> 0.5 / 0.6; shadow: noise only.
    assert abs(np.median(gamma[mapping.lit]) - 0.5 / 0.6) < 0.02
    assert np.median(gamma[~mapping.lit]) < 0.2


def test_root_sum_square_is_within_one_and_a_half_ulp_of_the_float64_value() -> None:
    rng = np.random.default_rng(21)
    first = (rng.lognormal(-3.0, 2.0, 100_000) * rng.choice([-1.0, 1.0], 100_000)).astype(np.float32)
    second = rng.lognormal(-3.0, 2.0, 100_000).astype(np.float32)
    first[:3], second[:3] = [np.nan, 0.0, 3.0], [1.0, np.nan, 4.0]
    result = root_sum_square(first, second)
    exact = np.hypot(first.astype(np.float64), second.astype(np.float64))
    assert result.dtype == np.float32
    assert np.isnan(result[:2]).all() and result[2] == 5.0
    ulp = np.spacing(exact[3:].astype(np.float32))
    assert np.max(np.abs(result[3:] - exact[3:]) / ulp) <= 1.5  # squares, sum and root each rounded
