"""The fused float32 pass against analytic truth, and against the float64 stage functions it replaces."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.phase.shifting import phase_shift, sample_stride, shadow_mask
from processing.unwrap import fused_pass
from processing.unwrap.fused_pass import ANGLE_TOLERANCE, fringe_pass, modulation_thresholds, wrapped_angle
from processing.unwrap.temporal import (
    unwrap_heterodyne,
    unwrap_hierarchical,
    unwrap_three_frequency,
    unwrap_two_frequency,
)

TWO_PI = 2.0 * np.pi
BACKENDS = [pytest.param(True, id="opencv"), pytest.param(False, id="numpy")]


def _angle_tolerance(opencv: bool) -> float:
    """The pass's angle error bound: OpenCV's, or float32 rounding where numpy's angles are exact (and fast here)."""
    return ANGLE_TOLERANCE if opencv and not fused_pass.exact_angles_are_fast() else 1e-6


def _circular_gap(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    gap = np.abs(np.asarray(a, dtype=np.float64) - b) % TWO_PI
    return np.minimum(gap, TWO_PI - gap)


def _scan(frequencies, steps=6, snr_db=40.0, seed=0, scene="hemisphere"):
    """Frames (all frequencies, lowest first), truth mapping and geometry of a small simulated scan."""
    base = synth.RigGeometry()
    geometry = replace(base.with_camera(160, 120), pixel_mm=base.pixel_mm * base.camera_width / 160)
    heights = scenes.make_scene(scene, geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    mapping = synth.projector_coordinates(heights, geometry)
    stack = synth.render_stack(
        synth.sinusoid_patterns(frequencies, steps),
        mapping,
        geometry,
        synth.Appearance(ambient=0.05, snr_db=snr_db),
        np.random.default_rng(seed),
    )
    groups = [list(range(i * steps, (i + 1) * steps)) for i in range(len(frequencies))]
    return stack, groups, mapping, geometry


# ----------------------------------------------------------------------------- the angle kernel


@pytest.mark.parametrize("opencv", BACKENDS)
def test_wrapped_angle_within_stated_tolerance_of_float64_arctan2(opencv: bool) -> None:
    rng = np.random.default_rng(3)
    c = rng.normal(0.0, 100.0, 200_000)
    s = rng.normal(0.0, 100.0, 200_000)
    # Axes, the +-0 and tiny negative sines that round to 2 pi, very unequal magnitudes.
    c[:8] = [1.0, -1.0, 0.0, 0.0, 1.0, 1.0, -1.0, 1e-30]
    s[:8] = [0.0, 0.0, 1.0, -1.0, -1e-30, -1e-9, -1e-30, 5.0]
    angle = wrapped_angle(c, s, opencv=opencv)
    assert angle.dtype == np.float32 and angle.shape == c.shape
    assert angle.min() >= 0.0 and angle.max() < TWO_PI
    exact = np.arctan2(s.astype(np.float32).astype(np.float64), c.astype(np.float32).astype(np.float64))
    gap = _circular_gap(angle, exact)
    assert gap.max() <= _angle_tolerance(opencv)


@pytest.mark.parametrize("fast", [True, False])
def test_the_pass_takes_numpys_exact_angles_only_where_they_are_fast(
    monkeypatch: pytest.MonkeyPatch, fast: bool
) -> None:
    monkeypatch.setattr(fused_pass, "exact_angles_are_fast", lambda: fast)
    stack, groups, _, _ = _scan([7, 8], snr_db=30.0)
    fused = fringe_pass(stack, groups, [7, 8], "two-frequency")
    exact = phase_shift(stack[6:].astype(np.float64)).phase
    gap = _circular_gap(fused.wrapped[0], exact)[fused.modulated]
    assert fused.wrapped[0].max() < TWO_PI
    if fast:  # float32 rounding of the exact angle
        assert gap.max() <= 1e-6
    else:  # OpenCV's approximation: within its bound, but not that close
        assert 1e-6 < gap.max() <= ANGLE_TOLERANCE


def test_wrapped_angle_keeps_nan_and_refuses_mismatched_shapes() -> None:
    angle = wrapped_angle(np.array([np.nan, 1.0]), np.array([1.0, 0.0]))
    assert np.isnan(angle[0]) and angle[1] == 0.0
    with pytest.raises(ValueError, match="sin_part"):
        wrapped_angle(np.ones(3), np.ones(4))


# ----------------------------------------------------------------------------- against the stage functions


def _stage_functions(stack, groups, frequencies, method, min_ratio=0.2):
    """What rig process computed stage by stage: phase_shift + shadow_mask per group, then the method."""
    results = [phase_shift(stack[g]) for g in groups]
    valid = np.ones(stack.shape[1:], dtype=bool)
    for r in results:
        valid &= shadow_mask(r.modulation, r.background, min_ratio=min_ratio)
    phis = [r.phase for r in results]
    ints = [int(f) for f in frequencies]
    if method == "two-frequency":
        unwrapped = unwrap_two_frequency(phis[-2], phis[-1], ints[-2], ints[-1])
    elif method == "three-frequency":
        unwrapped = unwrap_three_frequency(phis[-3:], ints[-3:])
    elif method == "hierarchical":
        unwrapped = unwrap_hierarchical(phis, ints)
    else:
        unwrapped = unwrap_heterodyne(phis, ints)
    return results, valid, unwrapped


CASES = [
    ("two-frequency", [7, 8]),
    ("two-frequency", [5, 6, 11]),  # the two highest of three, as rig process picks them
    ("three-frequency", [6, 10, 15]),
    ("hierarchical", [1, 8, 64]),
    ("heterodyne", [16, 15]),
    ("heterodyne", [64, 58, 53]),
]


@pytest.mark.parametrize("opencv", BACKENDS)
@pytest.mark.parametrize(("method", "frequencies"), CASES)
def test_matches_stage_functions_and_truth(method: str, frequencies: list[int], opencv: bool) -> None:
    frequencies = sorted(frequencies)
    stack, groups, mapping, geometry = _scan(frequencies, steps=4 if method != "two-frequency" else 6)
    fused = fringe_pass(stack, groups, frequencies, method, opencv=opencv)
    separate, modulated, unwrapped = _stage_functions(stack, groups, frequencies, method)
    valid = modulated & unwrapped.valid
    top = frequencies[-1]
    assert fused.phase_frequency == top
    assert fused.phase.dtype == np.float32 and fused.orders.dtype == np.int32
    # The mask: the same test with float32 modulation; at most a pixel or two sits on a threshold.
    assert np.mean(fused.valid != valid) < 1e-3
    assert not (fused.valid & ~fused.modulated).any()
    assert np.mean(fused.modulated != modulated) < 1e-3
    both = fused.valid & valid & mapping.lit
    assert both.mean() > 0.9
    np.testing.assert_array_equal(fused.orders[both], unwrapped.orders[both])
    tolerance = 2 * ANGLE_TOLERANCE if opencv else 1e-4  # float32 of an absolute phase up to 2 pi 64
    np.testing.assert_allclose(fused.phase[both], unwrapped.phase[both], atol=tolerance)
    assert np.isnan(fused.phase[~fused.modulated]).all() and np.isfinite(fused.phase[fused.modulated]).all()
    # Analytic truth: the absolute phase of the projector column each pixel sees.
    truth = synth.true_absolute_phase(mapping, geometry, top)
    assert np.abs(fused.phase[both] - truth[both]).max() < 0.3
    # Kept maps: the highest frequency's wrapped phase, modulation and background.
    assert fused.kept == [len(frequencies) - 1]
    high = separate[-1]
    assert _circular_gap(fused.wrapped[0], high.phase).max() <= ANGLE_TOLERANCE
    np.testing.assert_allclose(fused.modulation[0], high.modulation, rtol=1e-5, atol=1e-3)
    np.testing.assert_allclose(fused.background[0], high.background, rtol=1e-5, atol=1e-3)
    fraction = fused.phase[both] / TWO_PI - fused.orders[both]  # phase = 2 pi (order + turns in [0, 1))
    assert fraction.min() > -1e-5 and fraction.max() < 1.0 + 1e-5


def test_opencv_and_numpy_paths_agree_and_threads_change_nothing() -> None:
    stack, groups, _, _ = _scan([7, 8], snr_db=30.0)
    a = fringe_pass(stack, groups, [7, 8], "two-frequency", opencv=True)
    b = fringe_pass(stack, groups, [7, 8], "two-frequency", opencv=False)
    c = fringe_pass(stack, groups, [7, 8], "two-frequency", opencv=True, threads=3)
    lit = a.valid & b.valid
    assert np.mean(a.valid != b.valid) < 1e-3
    np.testing.assert_array_equal(a.orders[lit], b.orders[lit])
    np.testing.assert_allclose(a.phase[lit], b.phase[lit], atol=ANGLE_TOLERANCE)
    # Threads see the same blocks; BLAS may still round a product differently (buffer alignment).
    np.testing.assert_array_equal(a.valid, c.valid)
    np.testing.assert_array_equal(a.orders, c.orders)
    np.testing.assert_allclose(a.phase, c.phase, rtol=1e-6)
    np.testing.assert_allclose(a.modulation[0], c.modulation[0], rtol=1e-6)


def test_integer_frames_bound_with_opencv_as_float_frames_do_with_numpy() -> None:
    """uint8 frames take OpenCV's min and max for the angle and mask bounds (no NaN possible); the same values
    as float32 frames, which keep numpy's NaN-propagating bounds."""
    stack, groups, _, _ = _scan([7, 8], snr_db=20.0)
    kwargs = {"keep_all": True, "fuse_noise": 2.0, "min_ratio": 0.8}  # a bound that decides many pixels
    integer = fringe_pass(stack, groups, [7, 8], "two-frequency", **kwargs)
    floating = fringe_pass(stack.astype(np.float32), groups, [7, 8], "two-frequency", **kwargs)
    assert 0.05 < np.mean(~integer.modulated) < 0.95  # the mask's bound decides pixels either way
    np.testing.assert_array_equal(integer.modulated, floating.modulated)
    np.testing.assert_array_equal(integer.valid, floating.valid)
    for a, b in zip(integer.wrapped, floating.wrapped, strict=True):
        assert a.max() < TWO_PI and b.max() < TWO_PI
        np.testing.assert_allclose(a, b, rtol=1e-6)  # BLAS may round a block's product in the last bit
    np.testing.assert_allclose(integer.phase, floating.phase, rtol=1e-6)


def test_brightness_and_no_orders_keep_the_same_phase_and_one_map_for_two() -> None:
    stack, groups, _, _ = _scan([7, 8], snr_db=30.0)
    full = fringe_pass(stack, groups, [7, 8], "two-frequency", keep_all=True)
    lean = fringe_pass(stack, groups, [7, 8], "two-frequency", keep_all=True, orders=False, brightness=True)
    assert lean.orders is None and lean.modulation == [] and lean.background == []
    assert full.brightness == [] and len(lean.brightness) == 2
    # Two passes: BLAS may round a block's product differently in the last bit (buffer alignment).
    for bright, background, modulation in zip(lean.brightness, full.background, full.modulation, strict=True):
        np.testing.assert_allclose(bright, background + modulation, rtol=1e-6)
    np.testing.assert_allclose(lean.phase, full.phase, rtol=1e-6)
    np.testing.assert_array_equal(lean.valid, full.valid)
    for a, b in zip(lean.wrapped, full.wrapped, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-6)


def test_large_image_uses_several_blocks_and_threads_share_them(monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of 16k pixels with a partial last one: the same result as the stage functions everywhere."""
    monkeypatch.setattr(fused_pass, "BLOCK", 16384)  # several blocks on a small image
    stack, groups, _, _ = _scan([7, 8])
    tall = np.concatenate([stack] * 3, axis=1)  # 360 x 160 = 57600 pixels: 3 full blocks and a partial one
    fused = fringe_pass(tall, groups, [7, 8], "two-frequency", threads=2)
    _, modulated, unwrapped = _stage_functions(tall, groups, [7, 8], "two-frequency")
    valid = modulated & unwrapped.valid
    both = fused.valid & valid
    np.testing.assert_array_equal(fused.orders[both], unwrapped.orders[both])
    assert np.mean(fused.valid != valid) < 1e-3


def test_threads_give_the_same_maps_bit_for_bit() -> None:
    """Whichever thread takes a block, its maps are the same to the last bit (the buffers OpenCV's magnitude
    writes are aligned: processing._aligned), over several blocks, a partial one and the fusion."""
    stack, groups, _, _ = _scan([7, 8], snr_db=30.0)
    tall = np.concatenate([stack] * 40, axis=1)  # 768k pixels, as a 1024 x 768 camera: 11 full blocks and a partial
    kwargs = {"keep_all": True, "fuse_noise": 2.0}
    one = fringe_pass(tall, groups, [7, 8], "two-frequency", threads=1, **kwargs)
    for _ in range(3):
        two = fringe_pass(tall, groups, [7, 8], "two-frequency", threads=2, **kwargs)
        for name in ("phase", "valid", "modulated", "sigma"):
            np.testing.assert_array_equal(getattr(two, name), getattr(one, name), err_msg=name)
        for name in ("wrapped", "modulation", "background"):
            for a, b in zip(getattr(two, name), getattr(one, name), strict=True):
                np.testing.assert_array_equal(a, b, err_msg=name)


def test_arbitrary_shifts_interleaved_frames_and_keep_all() -> None:
    rng = np.random.default_rng(5)
    phi = rng.uniform(-np.pi, np.pi, (40, 50))
    shifts = np.array([0.1, 1.9, 2.5, 4.4, 5.0])
    frames = 120.0 + 80.0 * np.cos(phi[None] + shifts[:, None, None])
    # Two identical groups whose frames are interleaved with each other (frame indices not contiguous).
    stack = np.empty((10, 40, 50), dtype=np.float64)
    stack[0::2], stack[1::2] = frames, frames
    fused = fringe_pass(stack, [[0, 2, 4, 6, 8], [1, 3, 5, 7, 9]], [3, 3], None, shifts=[shifts, shifts], keep_all=True)
    assert fused.phase is None and fused.orders is None and fused.kept == [0, 1]
    np.testing.assert_array_equal(fused.modulated, fused.valid)
    for wrapped in fused.wrapped:
        assert _circular_gap(wrapped, phi).max() <= ANGLE_TOLERANCE
    np.testing.assert_allclose(fused.modulation[1], 80.0, rtol=1e-5)
    np.testing.assert_allclose(fused.background[0], 120.0, rtol=1e-6)
    assert fused.valid.all()


def test_nan_frames_and_dark_pixels_are_invalid() -> None:
    stack, groups, _, _ = _scan([7, 8])
    frames = stack.astype(np.float32)
    frames[3, 10, 20] = np.nan
    frames[:, 50, 60] = 0.0  # no light at all
    fused = fringe_pass(frames, groups, [7, 8], "two-frequency")
    assert not fused.valid[10, 20] and np.isnan(fused.phase[10, 20])
    assert not fused.valid[50, 60]


def test_threshold_matches_shadow_mask_definition() -> None:
    """0.3 x the 99th percentile of the modulation over shadow_mask's own regular subsample."""
    stack, groups, _, _ = _scan([7, 8], scene="steps")
    fused = fringe_pass(stack, groups, [7, 8], "two-frequency", min_ratio=0.3)
    for g, threshold in zip(groups, fused.thresholds):
        modulation = phase_shift(stack[g]).modulation
        sample = modulation.reshape(-1)[:: sample_stride(modulation.shape)]
        assert threshold == pytest.approx(0.3 * np.percentile(sample, 99.0), rel=1e-5)


def test_thresholds_computed_apart_give_the_same_pass() -> None:
    """modulation_thresholds (the pipeline runs it beside the noise estimate) is the pass's own derivation."""
    stack, groups, _, _ = _scan([15, 16], scene="steps", snr_db=25.0)
    shifts = [np.linspace(0.0, TWO_PI, 6, endpoint=False) + 0.3] * 2
    apart = modulation_thresholds(stack, groups, shifts, min_ratio=0.25)
    inside = fringe_pass(stack, groups, [15, 16], "two-frequency", shifts=shifts, min_ratio=0.25, fuse_noise=1.5)
    given = fringe_pass(
        stack, groups, [15, 16], "two-frequency", shifts=shifts, min_ratio=0.25, fuse_noise=1.5, thresholds=apart
    )
    assert apart == inside.thresholds == given.thresholds
    for name in ("phase", "sigma", "valid", "modulated"):
        np.testing.assert_array_equal(getattr(given, name), getattr(inside, name))
    with pytest.raises(ValueError, match="thresholds"):
        fringe_pass(stack, groups, [15, 16], "two-frequency", thresholds=apart[:1])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"groups": [[0, 1]]}, "groups\\[0\\]"),
        ({"groups": [[0, 1, 2, 99]]}, "groups\\[0\\]"),
        ({"groups": []}, "groups"),
        ({"frequencies": [7.5], "method": "hierarchical"}, "whole fringe counts"),
        ({"method": "hierarchical"}, "frequencies"),  # needs the unit frequency and another
        ({"frequencies": [7, 8]}, "frequencies"),
        ({"method": "spiral"}, "method"),
        ({"min_ratio": 1.5}, "min_ratio"),
        ({"shifts": [None, None]}, "shifts"),
        ({"threads": 0}, "threads"),
    ],
)
def test_bad_arguments_name_themselves(kwargs: dict, match: str) -> None:
    stack, _, _, _ = _scan([8], steps=4)
    arguments = {"frames": stack, "groups": [[0, 1, 2, 3]], "frequencies": [8], "method": None}
    arguments.update(kwargs)
    with pytest.raises(ValueError, match=match):
        fringe_pass(**arguments)


def test_two_dimensional_frames_refused() -> None:
    with pytest.raises(ValueError, match="frames"):
        fringe_pass(np.zeros((4, 5)), [[0, 1, 2]], [1])
