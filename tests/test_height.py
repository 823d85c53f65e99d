"""Thesis eq. 1.15 (phase to height) and its inverse, error metrics and point clouds."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from mock_devices import scenes, synth
from processing.geometry.height import height_to_phase, nmse, phase_mse, phase_to_height, point_cloud

L0, D0, F0 = 1000.0, 250.0, 0.0125


def test_sign_convention_raised_point_has_negative_phase_difference() -> None:
    """d0 > 0: a point towards the camera (h > 0) has dPhi < 0, and eq. 1.15 maps it back to h > 0."""
    dphi = height_to_phase(np.array([10.0]), L0, D0, F0)
    assert dphi[0] < 0
    assert phase_to_height(dphi, L0, D0, F0)[0] == pytest.approx(10.0)
    assert phase_to_height(np.array([-1.0]), L0, D0, F0)[0] > 0
    # Opposite baseline: the sign of dPhi flips, the height does not.
    flipped = height_to_phase(np.array([10.0]), L0, -D0, F0)
    assert flipped[0] == pytest.approx(-dphi[0])
    assert phase_to_height(flipped, L0, -D0, F0)[0] == pytest.approx(10.0)


def test_eq_1_15_value() -> None:
    """h = l0 dPhi / (dPhi - 2 pi f0 d0) at h = 100 mm: dPhi = -2 pi 0.0125 250 100 / 900."""
    dphi = -2 * np.pi * F0 * D0 * 100.0 / (L0 - 100.0)
    assert height_to_phase(np.array(100.0), L0, D0, F0) == pytest.approx(dphi)
    assert L0 * dphi / (dphi - 2 * np.pi * F0 * D0) == pytest.approx(100.0)
    assert phase_to_height(np.array(dphi), L0, D0, F0) == pytest.approx(100.0)


def test_round_trip() -> None:
    heights = np.linspace(-200.0, 900.0, 1001).reshape(7, 143)
    back = phase_to_height(height_to_phase(heights, L0, D0, F0), L0, D0, F0)
    np.testing.assert_allclose(back, heights, atol=1e-9)


def test_float32_round_trip_within_its_rounding() -> None:
    heights = np.linspace(-200.0, 900.0, 1001).reshape(7, 143)
    dphi = height_to_phase(heights, L0, D0, F0)
    back = phase_to_height(dphi.astype(np.float32), L0, D0, F0, dtype=np.float32)
    assert back.dtype == np.float32
    # float32 dPhi (relative 6e-8) and arithmetic: a few 1e-7 of the height and of l0.
    np.testing.assert_allclose(back, heights, rtol=1e-6, atol=1e-6 * L0)
    with pytest.raises(ValueError, match="dtype"):
        phase_to_height(dphi, L0, D0, F0, dtype=np.int32)


def test_simulated_plane_recovered_from_true_phases() -> None:
    """The synthesiser's projector coordinates of a 20 mm plane give 20 mm through eq. 1.15."""
    base = synth.RigGeometry()
    geometry = replace(base.with_camera(64, 48), pixel_mm=base.pixel_mm * 16)
    f = geometry.f0_frequency
    reference = synth.projector_coordinates(scenes.flat(48, 64, geometry.pixel_mm), geometry)
    plane = synth.projector_coordinates(scenes.flat(48, 64, geometry.pixel_mm, level_mm=20.0), geometry)
    dphi = synth.true_absolute_phase(plane, geometry, f) - synth.true_absolute_phase(reference, geometry, f)
    assert np.all(dphi[plane.lit] < 0)
    heights = phase_to_height(dphi, geometry.l0_mm, geometry.d0_mm, geometry.f0_per_mm)
    np.testing.assert_allclose(heights[plane.lit], 20.0, atol=1e-9)


@pytest.mark.parametrize(
    ("l0", "d0", "f0", "match"),
    [(0.0, D0, F0, "l0_mm"), (L0, 0.0, F0, "d0_mm"), (L0, np.inf, F0, "d0_mm"), (L0, D0, -1.0, "f0_per_mm")],
)
def test_bad_geometry_names_the_argument(l0: float, d0: float, f0: float, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        phase_to_height(np.zeros(3), l0, d0, f0)
    with pytest.raises(ValueError, match=match):
        height_to_phase(np.zeros(3), l0, d0, f0)


def test_height_at_or_above_pupils_refused() -> None:
    with pytest.raises(ValueError, match="height_mm"):
        height_to_phase(np.array([L0]), L0, D0, F0)


def test_nmse_and_phase_mse() -> None:
    truth = np.array([[1.0, -2.0], [3.0, 4.0]])
    assert nmse(1.1 * truth, truth) == pytest.approx(0.01)
    assert nmse(truth, truth) == 0.0
    mask = np.array([[True, False], [False, False]])
    assert nmse(np.array([[2.0, 99.0], [99.0, 99.0]]), truth, mask) == pytest.approx(1.0)
    estimate = truth + np.array([[np.nan, 1.0], [1.0, 1.0]])  # NaN pixels are ignored
    assert phase_mse(estimate, truth) == pytest.approx(1.0)
    assert nmse(estimate, truth) == pytest.approx(3.0 / (4.0 + 9.0 + 16.0))


@pytest.mark.parametrize(
    ("estimate", "truth", "mask", "match"),
    [
        (np.zeros(3), np.zeros(4), None, "shape"),
        (np.zeros(3), np.zeros(3), None, "truth"),
        (np.ones(3), np.ones(3), np.zeros(3, bool), "mask"),
    ],
)
def test_metric_errors(estimate, truth, mask, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        nmse(estimate, truth, mask)


def test_point_cloud_geometry() -> None:
    heights = np.full((3, 5), 100.0)
    heights[0, 0] = np.nan
    mask = np.ones((3, 5), bool)
    mask[2, 4] = False
    points = point_cloud(heights, pixel_mm=0.5, l0_mm=L0, mask=mask)
    assert points.shape == (13, 3)
    rows, cols = np.nonzero(mask & np.isfinite(heights))
    scale = 0.5 * (L0 - 100.0) / L0  # lateral size of a pixel at h = 100 mm
    np.testing.assert_allclose(points[:, 0], (cols - 2.0) * scale)
    np.testing.assert_allclose(points[:, 1], (rows - 1.0) * scale)
    np.testing.assert_allclose(points[:, 2], 100.0)
    shifted = point_cloud(heights, 0.5, L0, mask=mask, center=(0.0, 0.0))
    np.testing.assert_allclose(shifted[:, 0], cols * scale)
    with pytest.raises(ValueError, match="height_mm"):
        point_cloud(np.zeros(4), 0.5, L0)
