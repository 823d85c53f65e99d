"""Projector gamma: fit from a flat ramp, LUT pre-correction, and phase-error lookup compensation.

The simulated projector has response level ** 2.2; the ripple it leaves in 3-step phase shifting
must shrink when patterns go through the fitted LUT (what ``Projector.set_gamma_lut`` does) or
when the phase goes through a phase-error table learnt on the reference plane.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import CalibrationError
from calibration.gamma import (
    compensate_phase,
    fit_gamma,
    inverse_lut,
    mean_response,
    phase_error_table,
    ramp_patterns,
    ripple_table_from_plane,
    table_from_fields,
)
from drivers.projector import apply_gamma_lut, validate_gamma_lut
from mock_devices import synth
from processing.phase.shifting import phase_shift
from processing.projection.patterns import pattern_intensity

GAMMA = 2.2
GEOMETRY = synth.RigGeometry(pixel_mm=3.2, camera_width=128, camera_height=96)
APPEARANCE = synth.Appearance(gamma=GAMMA, gain=220.0, ambient=0.05, snr_db=40.0, bit_depth=8)
FREQUENCY = 8.0


def wrap(p):
    return np.angle(np.exp(1j * p))


def capture(patterns, lut=None, seed=0, height_mm=None):
    scene = np.zeros(GEOMETRY.camera_shape) if height_mm is None else height_mm
    mapping = synth.projector_coordinates(scene, GEOMETRY)
    rng = np.random.default_rng(seed)
    frames = []
    for pattern in patterns:
        desired = pattern_intensity(pattern, mapping.u, mapping.v, GEOMETRY.projector_size)
        frames.append(synth.expose(apply_gamma_lut(desired, lut), mapping, APPEARANCE, rng))
    return np.stack(frames), mapping


def ripple(lut=None, seed=1):
    """RMS wrapped-phase error of 3-step phase shifting on the plane, and the phases.

    3 steps: the second harmonic a gamma of ~2 adds folds straight into the phase (4 steps are
    blind to it, which is the 'more steps' cure)."""
    frames, mapping = capture(synth.sinusoid_patterns([FREQUENCY], 3), lut, seed)
    measured = phase_shift(frames).phase
    truth = synth.true_absolute_phase(mapping, GEOMETRY, FREQUENCY)
    error = wrap(measured - truth)
    return float(np.sqrt(np.mean((error - error.mean()) ** 2))), measured, truth


@pytest.fixture(scope="module")
def gamma_fit():
    patterns = ramp_patterns(17)
    frames, _ = capture(patterns)
    return fit_gamma([p["level"] for p in patterns], mean_response(frames), saturation=255)


def test_gamma_fitted_from_a_flat_ramp(gamma_fit):
    assert gamma_fit.gamma == pytest.approx(GAMMA, rel=0.02)
    assert gamma_fit.gain == pytest.approx(220.0, rel=0.02)
    assert gamma_fit.offset == pytest.approx(220.0 * 0.05, abs=1.0)


@pytest.mark.parametrize("method", ["model", "empirical"])
def test_lut_pre_correction_removes_the_ripple(gamma_fit, method):
    lut = inverse_lut(gamma_fit, 256, method=method)
    validate_gamma_lut(lut)  # the projector driver accepts it
    assert np.all(np.diff(lut) >= 0)
    # the LUT linearises the model response: response(lut(x)) == x
    x = np.linspace(0, 1, 256)
    assert np.max(np.abs(gamma_fit.normalized_response(lut) - x)) < 0.02
    raw, _, _ = ripple(None)
    corrected, _, _ = ripple(lut)
    assert raw > 0.05  # gamma 2.2 with 3 steps ripples by ~0.1 rad
    assert corrected < raw / 4


def test_phase_error_lookup_compensates_in_processing():
    raw, measured, truth = ripple(None, seed=3)
    table = phase_error_table(measured, truth, bins=64)
    # learnt on one capture, applied to another (different noise)
    _, measured2, truth2 = ripple(None, seed=4)
    compensated = compensate_phase(measured2, table)
    error = wrap(compensated - truth2)
    assert float(np.sqrt(np.mean((error - error.mean()) ** 2))) < raw / 3
    # the ripple of an N-step algorithm under gamma has period 2 pi / N in the phase
    spectrum = np.abs(np.fft.rfft(table.error))
    assert int(np.argmax(spectrum[1:])) + 1 == 3


def test_bad_ramps_are_refused():
    with pytest.raises(CalibrationError, match="at least 5 levels"):
        fit_gamma([0, 0.5, 1], [10, 50, 200])
    with pytest.raises(CalibrationError, match="does not rise"):
        fit_gamma(np.linspace(0, 1, 9), np.full(9, 12.0))
    with pytest.raises(CalibrationError, match="saturates from level 0.75"):
        fit_gamma(np.linspace(0, 1, 5), [10, 40, 120, 255, 255], saturation=255)
    with pytest.raises(CalibrationError, match=r"levels must lie in \[0, 1\]"):
        fit_gamma(np.linspace(0, 2, 5), [10, 40, 120, 200, 250])
    with pytest.raises(CalibrationError, match="phase error table: measured"):
        phase_error_table(np.zeros((10, 10)), np.zeros((10, 11)))


def test_ripple_table_learnt_from_the_plane_itself():
    raw, measured, truth = ripple(None, seed=5)
    absolute = truth + wrap(measured - truth)  # the plane's absolute phase, ripple included
    table, ripple_rms = ripple_table_from_plane(absolute)
    assert ripple_rms == pytest.approx(raw, rel=0.2)  # the table sees the ripple a smooth fit leaves
    _, measured2, truth2 = ripple(None, seed=6)
    error = compensate_phase(truth2 + wrap(measured2 - truth2), table_from_fields(table.as_fields())) - truth2
    assert float(np.sqrt(np.mean((error - error.mean()) ** 2))) < raw / 4
    with pytest.raises(CalibrationError, match="phase_error: expected"):
        table_from_fields({"phase_error_centers": [0, 1]})
