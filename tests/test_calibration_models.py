"""Per-pixel polynomial model, the model dispatch, and the three models compared on a pinhole rig.

On the pinhole projector-camera simulation (mock_devices.stereo_synth) eq. 1.15 does not hold: a
flat plane's phase difference varies across the view. The reference-plane fit must flag that,
the per-pixel polynomial must absorb it, and the stereo model must not care.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.errors import CalibrationError
from calibration.geometry import fit_f0, fit_l0_d0
from calibration.models import height_from_phase, needs_reference, points_from_phase
from calibration.polynomial import fit_polynomial
from calibration.store import Calibration, read_calibration, write_calibration
from mock_devices.stereo_synth import Scene, calibration_fields, demo_rig, demo_scene, trace

FREQUENCY = 64
PLANE_MM = 600.0
HEIGHTS = (20.0, 40.0, 60.0, 80.0)
RIG = demo_rig(96, 80)


def exact_phase(scene: Scene) -> tuple[np.ndarray, np.ndarray]:
    points, mapping = trace(RIG, scene)
    return np.where(mapping.lit, 2 * np.pi * FREQUENCY * mapping.u / RIG.projector.width, np.nan), points


@pytest.fixture(scope="module")
def planes():
    reference, _ = exact_phase(Scene(plane_distance=PLANE_MM))
    deltas = [exact_phase(Scene(plane_distance=PLANE_MM - h))[0] - reference for h in HEIGHTS]
    obj, points = exact_phase(demo_scene())
    return reference, deltas, obj, PLANE_MM - points[..., 2]


def test_reference_plane_fit_flags_a_rig_that_breaks_eq_1_15(planes):
    reference, deltas, _, _ = planes
    f0 = fit_f0(reference, PLANE_MM / RIG.camera.matrix[0, 0])
    with pytest.raises(CalibrationError, match="does not\nfollow eq. 1.15|not flat or not level"):
        fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm)


def test_polynomial_absorbs_what_eq_1_15_misses(planes, tmp_path):
    reference, deltas, obj, truth = planes
    model = fit_polynomial(HEIGHTS, deltas, FREQUENCY, degree=3)
    assert model.residual_rms_mm < 0.01
    on_object = truth > 0.5
    error = model.height(obj - reference) - truth
    assert float(np.sqrt(np.nanmean(error[on_object] ** 2))) < 0.01
    # the ideal model fitted anyway is worse by orders of magnitude on the same object
    f0 = fit_f0(reference, PLANE_MM / RIG.camera.matrix[0, 0])
    fit = fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm, flatness_tolerance_mm=None)
    from processing.geometry.height import phase_to_height

    ideal = phase_to_height(obj - reference, fit.l0_mm, fit.d0_mm, f0.f0_per_mm) - truth
    assert np.sqrt(np.nanmean(ideal[on_object] ** 2)) > 20 * np.sqrt(np.nanmean(error[on_object] ** 2))
    # stored beside calibration.json and dispatched by model name
    cal = Calibration(model="polynomial", reference="reference", pixel_mm=0.5, extra=model.save(tmp_path))
    cal.extra.pop("model")
    write_calibration(tmp_path, cal)
    again = read_calibration(tmp_path)
    assert needs_reference(again)
    height = height_from_phase(again, obj, reference, FREQUENCY)
    assert np.allclose(height, model.height(obj - reference), equal_nan=True)
    # a phase at half the frequency means half the phase difference for the same height
    assert np.allclose(height_from_phase(again, obj / 2, reference / 2, FREQUENCY / 2), height, equal_nan=True)
    points, heights = points_from_phase(again, obj, reference, FREQUENCY)
    assert points.shape == (*obj.shape, 3) and np.allclose(points[..., 2], heights, equal_nan=True)


def test_stereo_model_through_the_dispatch(planes, tmp_path):
    _, _, obj, truth = planes
    cal = Calibration(model="stereo", extra={**calibration_fields(RIG), "plane": [0.0, 0.0, -1.0, PLANE_MM]})
    cal.extra.pop("model")
    write_calibration(tmp_path, cal)
    again = read_calibration(tmp_path)
    assert not needs_reference(again)
    height = height_from_phase(again, obj, None, FREQUENCY)
    assert np.nanmax(np.abs(height - truth)) < 1e-4


def test_reference_plane_model_through_the_dispatch():
    cal = Calibration(
        l0_mm=1000.0, d0_mm=250.0, f0_per_mm=0.0125, f0_frequency=8.0, pixel_mm=0.5, reference="reference"
    )
    delta = np.full((4, 6), -0.5)
    points, height = points_from_phase(cal, delta, np.zeros((4, 6)), 8.0)
    expected = 1000.0 * -0.5 / (-0.5 - 2 * np.pi * 0.0125 * 250.0)
    assert np.allclose(height, expected)
    assert points[0, 0, 0] == pytest.approx(-2.5 * 0.5 * (1000.0 - expected) / 1000.0)
    with pytest.raises(CalibrationError, match="needs the reference-plane phase"):
        height_from_phase(cal, delta, None, 8.0)


def test_bad_polynomial_input(planes, tmp_path):
    _, deltas, _, _ = planes
    with pytest.raises(CalibrationError, match="degree-3 polynomial needs at least 3 distinct heights"):
        fit_polynomial(HEIGHTS[:2], deltas[:2], FREQUENCY, degree=3)
    with pytest.raises(CalibrationError, match="did not move|no phase change"):
        fit_polynomial(HEIGHTS[:3], [np.zeros_like(d) for d in deltas[:3]], FREQUENCY, degree=2)
    with pytest.raises(CalibrationError, match="singular"):
        fit_polynomial((20.0, 40.0, 60.0), [deltas[0]] * 3, FREQUENCY, degree=2)  # three heights, one phase
    cal = Calibration(
        model="polynomial",
        reference="reference",
        pixel_mm=0.5,
        extra={"polynomial": {"file": "missing.npy", "degree": 3, "phase_frequency": 64}},
    )
    write_calibration(tmp_path, cal)
    with pytest.raises(CalibrationError, match="missing.npy: missing"):
        height_from_phase(read_calibration(tmp_path), deltas[0], deltas[0], FREQUENCY)
    with pytest.raises(CalibrationError, match="model: expected one of"):
        height_from_phase(Calibration(model="mystery"), deltas[0], deltas[0], FREQUENCY)


def test_plane_points_of_kept_pixels_follow_the_lateral_formula() -> None:
    """X = (x - cx) pixel_mm (l0 - h) / l0, Y likewise, Z = h, for the masked pixels in C order."""
    from calibration.models import plane_points, plane_points_finite
    from calibration.store import Calibration

    cal = Calibration(l0_mm=1000.0, d0_mm=250.0, f0_per_mm=0.0125, f0_frequency=8.0, pixel_mm=0.4)
    h = np.random.default_rng(2).uniform(-50.0, 150.0, (6, 9)).astype(np.float32)
    mask = np.random.default_rng(3).random(h.shape) < 0.6
    rows, cols = np.nonzero(mask)
    scale = 0.4 * (1000.0 - h[rows, cols].astype(np.float64)) / 1000.0
    expected = np.column_stack([(cols - 4.0) * scale, (rows - 2.5) * scale, h[rows, cols]])
    points = plane_points(cal, h, mask)
    assert points.dtype == np.float32
    np.testing.assert_allclose(points, expected, rtol=1e-6, atol=1e-4)
    np.testing.assert_array_equal(plane_points(cal, h).reshape(6, 9, 3)[mask], points)
    huge = h.copy()
    huge[0, 0] = 3e38  # finite in float32, but its lateral coordinates are not
    assert not plane_points_finite(Calibration(l0_mm=1e-3, pixel_mm=1e6), huge)[0, 0]
    assert plane_points_finite(cal, h).all()
