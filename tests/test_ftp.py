"""Fourier-transform profilometry against analytic carriers and a simulated scan."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.phase.ftp import detect_carrier, ftp_amplitude, ftp_phase
from processing.phase.shifting import phase_shift

SHAPE = (96, 256)
CARRIER = 1.0 / 16.0  # cycles per pixel
EDGE = 24  # FTP's window leaks at the image borders; compare the interior


def _wrap(x: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * x))


def _object_phase(amplitude: float = 1.0) -> np.ndarray:
    """A smooth bump, slowly varying compared with the carrier (its local frequency shift stays
    well inside the band)."""
    y, x = np.mgrid[0 : SHAPE[0], 0 : SHAPE[1]]
    return amplitude * np.exp(-((x - 128.0) ** 2 + (y - 48.0) ** 2) / (2 * 40.0**2))


def _fringes(phi: np.ndarray, background: float = 100.0, modulation: float = 60.0) -> np.ndarray:
    x = np.arange(SHAPE[1])[None, :]
    return background + modulation * np.cos(2 * np.pi * CARRIER * x + phi)


@pytest.mark.parametrize("window", ["hann", "tukey", "rect"])
def test_recovers_carrier_plus_object_phase(window: str) -> None:
    obj = _object_phase()
    x = np.arange(SHAPE[1])[None, :]
    phase, amplitude = ftp_phase(_fringes(obj), carrier=CARRIER, window=window)
    error = _wrap(phase - (2 * np.pi * CARRIER * x + obj))[:, EDGE:-EDGE]
    assert np.sqrt(np.mean(error**2)) < 0.02
    assert np.max(np.abs(error)) < 0.06
    assert np.median(np.abs(amplitude[:, EDGE:-EDGE] - 60.0)) < 2.0
    assert phase.dtype == np.float64 and np.all(phase >= -np.pi) and np.all(phase < np.pi)


def test_carrier_detection_and_axis() -> None:
    image = _fringes(_object_phase())
    assert detect_carrier(image) == pytest.approx(CARRIER, abs=0.002)
    detected, _ = ftp_phase(image)
    given, _ = ftp_phase(image, carrier=CARRIER)
    assert np.max(np.abs(_wrap(detected - given))[:, EDGE:-EDGE]) < 0.05
    transposed, _ = ftp_phase(image.T, carrier=CARRIER, axis=0)
    np.testing.assert_allclose(transposed.T, given, atol=1e-9)


def test_negative_carrier_for_decreasing_phase() -> None:
    obj = _object_phase()
    x = np.arange(SHAPE[1])[None, :]
    image = 100.0 + 60.0 * np.cos(-2 * np.pi * CARRIER * x + obj)
    phase, _ = ftp_phase(image, carrier=-CARRIER)
    error = _wrap(phase - (-2 * np.pi * CARRIER * x + obj))[:, EDGE:-EDGE]
    assert np.max(np.abs(error)) < 0.06
    wrong_sign, _ = ftp_phase(image, carrier=CARRIER)  # the test can fail: sign matters
    assert np.max(np.abs(_wrap(wrong_sign - (-2 * np.pi * CARRIER * x + obj))[:, EDGE:-EDGE])) > 1.0


def test_noise_and_narrow_band() -> None:
    """A narrower band rejects more noise on a flat object."""
    rng = np.random.default_rng(7)
    image = _fringes(np.zeros(SHAPE)) + rng.normal(0.0, 6.0, SHAPE)
    x = np.arange(SHAPE[1])[None, :]
    rms = []
    for bandwidth in (0.8, 0.3):
        phase, _ = ftp_phase(image, carrier=CARRIER, bandwidth=bandwidth)
        rms.append(np.sqrt(np.mean(_wrap(phase - 2 * np.pi * CARRIER * x)[:, EDGE:-EDGE] ** 2)))
    assert rms[1] < rms[0] < 0.1


def test_agrees_with_phase_shifting_on_simulated_scan() -> None:
    """One frame of a simulated sphere-cap scan: FTP matches 4-step phase shifting."""
    base = synth.RigGeometry()
    geometry = replace(base.with_camera(256, 96), pixel_mm=base.pixel_mm * 4)
    heights = scenes.sphere_cap(96, 256, geometry.pixel_mm, radius_mm=300.0, max_height_mm=40.0)
    mapping = synth.projector_coordinates(heights, geometry)
    stack = synth.render_stack(
        synth.sinusoid_patterns([16], 4), mapping, geometry, synth.Appearance(snr_db=40.0), np.random.default_rng(1)
    )
    reference = phase_shift(stack).phase
    phase, _ = ftp_phase(stack[0])
    error = _wrap(phase - reference)[:, EDGE:-EDGE]
    assert np.sqrt(np.mean(error**2)) < 0.1  # FTP's usual accuracy on a curved object
    assert np.median(np.abs(error)) < 0.05


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"image": np.zeros((4, 4, 4))}, "image"),
        ({"image": np.full(SHAPE, np.nan)}, "image"),
        ({"carrier": 0.0}, "carrier"),
        ({"carrier": 0.7}, "carrier"),
        ({"bandwidth": 0.0}, "bandwidth"),
        ({"bandwidth": 1.5}, "bandwidth"),
        ({"window": "kaiser"}, "window"),
        ({"axis": 2}, "axis"),
    ],
)
def test_bad_input_names_the_argument(kwargs: dict, match: str) -> None:
    arguments = {"image": _fringes(np.zeros(SHAPE))} | kwargs
    with pytest.raises(ValueError, match=match):
        ftp_phase(**arguments)


def test_fringe_parts_recover_phase_background_and_modulation() -> None:
    """ftp_fringe_parts on an analytic fringe: phase, amplitude, background within stated tolerances (issue 9)."""
    from processing.phase.ftp import ftp_fringe_parts

    height, width, f0 = 64, 256, 1 / 16
    x = np.arange(width)[None, :].repeat(height, axis=0)
    phi = 2 * np.pi * f0 * x
    image = 100.0 + 40.0 * np.cos(phi)
    image[:, 96:160] = 100.0  # no fringes here: invalid
    parts = ftp_fringe_parts(image, f0, axis=1)
    inner = (slice(None), slice(16, 64))
    np.testing.assert_allclose(np.angle(np.exp(1j * (parts.phase - phi)))[inner], 0.0, atol=1e-2)
    np.testing.assert_allclose(parts.amplitude[inner], 40.0, rtol=0.02)
    np.testing.assert_allclose(parts.background[inner], 100.0, atol=1e-6)
    assert parts.valid[inner].all() and not parts.valid[:, 120:136].any()


@pytest.mark.parametrize("axis", [0, 1])
def test_amplitude_alone_in_float32_matches_the_double_precision_one(axis: int) -> None:
    """ftp_amplitude (the live view's modulation map) is ftp_phase's amplitude to float32 precision,
    and both are the analytic modulation in the interior."""
    image = _fringes(_object_phase(2.0))
    image = image if axis == 1 else image.T.copy()
    _, expected = ftp_phase(image, axis=axis)
    amplitude = ftp_amplitude(image.astype(np.float32), axis=axis)
    assert amplitude.dtype == np.float32
    np.testing.assert_allclose(amplitude, expected, rtol=1e-4, atol=1e-3)
    inner = amplitude[:, EDGE:-EDGE] if axis == 1 else amplitude[EDGE:-EDGE, :]
    assert np.median(np.abs(inner - 60.0)) < 2.0  # the modulation the fringes were made with
