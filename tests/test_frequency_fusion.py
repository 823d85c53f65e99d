"""Every frequency in the absolute phase: the inverse-variance fusion against seeded simulations.

The predicted gain is sqrt(w_K / sum_k w_k), w_k = J_k B_k^2 (f_k / f_K)^2 (the module's docstring).
On ~100k pixels the RMS error is known to about 0.3 %; the tolerances (5 % on the ratio of the
fused to the highest frequency's error, 10 % through the whole pipeline with heights and a
reference plane) leave room for the estimated noise and modulation the weights use.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mock_devices import synth
from processing.geometry.uncertainty import noise_sigma
from processing.phase.frequency_fusion import fuse_frequencies
from processing.phase.shifting import phase_shift
from processing.unwrap.fused_pass import ANGLE_TOLERANCE, fringe_pass
from processing.unwrap.temporal import unwrap_two_frequency
from rig.hardware.synthesis import demo_appearance, demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process

SHAPE = (200, 512)


def _ramp(frequencies, steps, amplitudes, sigma: float, seed: int):
    """Frames of each frequency across a ramp of projector columns, noise ``sigma``; the true column in turns."""
    rng = np.random.default_rng(seed)
    u = np.broadcast_to(np.linspace(0.0, 1.0, SHAPE[1], endpoint=False), SHAPE)
    frames = []
    for f, j, b in zip(frequencies, steps, amplitudes, strict=True):
        shifts = 2 * np.pi * np.arange(j) / j
        clean = 128.0 + b * np.cos(2 * np.pi * f * u[None] + shifts[:, None, None])
        frames.append(clean + rng.normal(0.0, sigma, clean.shape))
    return frames, u


def _wrapped_error(phase: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * (phase - truth)))


@pytest.mark.parametrize(
    ("frequencies", "steps", "amplitudes", "seed"),
    [
        ((15, 16), (6, 6), (90.0, 90.0), 31),  # a two-frequency pair: nearly equal weights
        ((15, 16), (4, 8), (60.0, 90.0), 32),  # unequal step counts and modulations
    ],
)
def test_fused_error_falls_by_the_predicted_factor(frequencies, steps, amplitudes, seed: int) -> None:
    sets, u = _ramp(frequencies, steps, amplitudes, sigma=3.0, seed=seed)
    results = [phase_shift(frames) for frames in sets]
    top = unwrap_two_frequency(results[0].phase, results[1].phase, *frequencies)
    stack = np.concatenate(sets)
    groups = [list(range(steps[0])), list(range(steps[0], sum(steps)))]
    sigma_i = noise_sigma(stack, groups)
    fused = fuse_frequencies(
        top.phase, [r.phase for r in results], frequencies, [r.modulation for r in results], steps, sigma_i
    )
    truth = 2 * np.pi * frequencies[-1] * u
    alone = np.sqrt(np.mean(_wrapped_error(top.phase, truth) ** 2))
    combined = np.sqrt(np.mean(_wrapped_error(fused.phase, truth) ** 2))
    weights = [j * b**2 * (f / frequencies[-1]) ** 2 for f, j, b in zip(frequencies, steps, amplitudes, strict=True)]
    predicted = np.sqrt(weights[-1] / sum(weights))
    assert combined / alone == pytest.approx(predicted, rel=0.05)
    # the predicted sigma of the fused phase is its observed scatter
    assert float(np.median(fused.sigma)) == pytest.approx(combined, rel=0.05)
    assert fused.disagreeing < 1e-4 * top.phase.size  # 6 sigma: none by chance; a few pixels of uint8 rounding


def test_a_lower_frequency_that_disagrees_is_left_out() -> None:
    """A region where the low frequency's phase is off by a third of a fringe keeps the highest's phase."""
    frequencies, steps = (15, 16), (6, 6)
    sets, u = _ramp(frequencies, steps, (90.0, 90.0), sigma=3.0, seed=33)
    results = [phase_shift(frames) for frames in sets]
    top = unwrap_two_frequency(results[0].phase, results[1].phase, *frequencies)
    low = results[0].phase.copy()
    low[:50] += 2.0  # rad at f = 15: a systematic error of the low set (a specular spot, a shadow edge)
    fused = fuse_frequencies(
        top.phase, [low, results[1].phase], frequencies, [r.modulation for r in results], steps, 3.0
    )
    np.testing.assert_allclose(fused.phase[:50], top.phase[:50], atol=1e-4)  # float32 of the same value
    assert fused.disagreeing >= 50 * SHAPE[1]
    truth = 2 * np.pi * 16 * u
    assert np.abs(_wrapped_error(fused.phase[:50], truth[:50])).max() < 0.2  # not pulled towards the slip


def test_the_fused_pass_fuses_as_the_function_does() -> None:
    frequencies, steps = (15, 16), (6, 6)
    sets, _ = _ramp(frequencies, steps, (90.0, 90.0), sigma=3.0, seed=34)
    stack = np.clip(np.rint(np.concatenate(sets)), 0, 255).astype(np.uint8)
    groups = [list(range(6)), list(range(6, 12))]
    plain = fringe_pass(stack, groups, list(frequencies), "two-frequency", keep_all=True, opencv=False)
    fused = fringe_pass(stack, groups, list(frequencies), "two-frequency", keep_all=True, fuse_noise=3.0)
    assert plain.sigma is None and fused.sigma is not None
    expected = fuse_frequencies(plain.phase, plain.wrapped, frequencies, plain.modulation, steps, 3.0)
    both = plain.valid & fused.valid
    assert both.mean() > 0.99
    np.testing.assert_allclose(fused.phase[both], expected.phase[both], atol=4 * ANGLE_TOLERANCE)
    np.testing.assert_allclose(fused.sigma[both], expected.sigma[both], rtol=1e-3)
    assert abs(fused.disagreeing - expected.disagreeing) <= 5


def _height_rms(result, scan) -> float:
    keep = result.mask & scan.lit
    return float(np.sqrt(np.mean((result.height[keep] - scan.height_mm[keep]) ** 2)))


def test_the_pipeline_heights_gain_what_the_weights_predict(tmp_path: Path) -> None:
    """Two-frequency capture (15, 16) through rig process: height error falls to ~sqrt(1 / (1 + (15/16)^2))."""
    scan = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((15, 16), 6),
        appearance=demo_appearance(30.0),
        seed=35,
    )
    paths = write_simulated_scan(scan, tmp_path / "scan")
    alone = process(
        paths.capture, paths.calibration, ProcessOptions(correction="none", params={"frequency_fusion": False})
    )
    fused = process(paths.capture, paths.calibration, ProcessOptions(correction="none"))
    assert "frequency_fusion" in fused.object.info and "frequency_fusion" not in alone.object.info
    assert fused.object.info["frequency_fusion"]["frequencies"] == [15.0, 16.0]
    predicted = np.sqrt(1.0 / (1.0 + (15.0 / 16.0) ** 2))  # equal steps; modulation nearly equal at 15 and 16
    assert _height_rms(fused, scan) / _height_rms(alone, scan) == pytest.approx(predicted, rel=0.1)
    assert alone.uncertainty is not None and fused.uncertainty is not None
    both = alone.mask & fused.mask
    ratio = float(np.median(fused.uncertainty[both] / alone.uncertainty[both]))
    assert ratio == pytest.approx(predicted, rel=0.05)  # the uncertainty map follows the fused variance
