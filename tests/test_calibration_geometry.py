"""l0 / d0 / f0 calibration on the simulated reference-plane rig, the gauge block, and bad input.

The simulated rig (mock_devices.synth) has known l0, d0, f0 and pixel size; planes and objects are
rendered as 8-bit fringe images at 30 dB SNR and their phase recovered by phase shifting. Fringe
orders come from the true phase (the unwrapping methods are tested elsewhere), so every phase
error left is the rendering noise and quantisation the calibration must cope with.
"""

from __future__ import annotations

import numpy as np
import pytest

from calibration.camera import BoardSpec, detect_board
from calibration.errors import CalibrationError
from calibration.geometry import fit_f0, fit_l0_d0, pixel_mm_from_corners
from calibration.reference import check_same_patterns, phase_frequency
from mock_devices import synth
from mock_devices.board_synth import PinholeCamera, board_pose, chessboard_texture, render_board_view
from processing.geometry.height import phase_to_height
from processing.phase.shifting import phase_shift

FREQUENCY = 16.0
STEPS = 6
GEOMETRY = synth.RigGeometry(
    l0_mm=1000.0,
    d0_mm=250.0,
    f0_per_mm=0.03125,
    f0_frequency=FREQUENCY,
    pixel_mm=3.2,
    camera_width=128,
    camera_height=96,
)
APPEARANCE = synth.Appearance(gain=200.0, ambient=0.05, snr_db=30.0, bit_depth=8)
HEIGHTS = (25.0, 50.0, 100.0, 150.0)  # a translation stage's travel; l0 shows in the curvature


def measured_phase(
    height_mm: np.ndarray, rng: np.random.Generator, appearance=APPEARANCE
) -> tuple[np.ndarray, np.ndarray]:
    """Absolute phase (at FREQUENCY) of a scene from rendered fringes, and the lit mask."""
    mapping = synth.projector_coordinates(height_mm, GEOMETRY)
    frames = synth.render_stack(synth.sinusoid_patterns([FREQUENCY], STEPS), mapping, GEOMETRY, appearance, rng)
    wrapped = phase_shift(frames).phase
    truth = synth.true_absolute_phase(mapping, GEOMETRY, FREQUENCY)
    orders = np.round((np.nan_to_num(truth) - wrapped) / (2 * np.pi))
    return np.where(mapping.lit, wrapped + 2 * np.pi * orders, np.nan), mapping.lit


def plane(level_mm: float) -> np.ndarray:
    return np.full(GEOMETRY.camera_shape, float(level_mm))


def board_pixel_mm(rng: np.random.Generator) -> float:
    """Pixel size from a chessboard lying on the reference plane, seen by the rig's camera."""
    focal = GEOMETRY.l0_mm / GEOMETRY.pixel_mm
    camera = PinholeCamera.simple(GEOMETRY.camera_width, GEOMETRY.camera_height, focal)
    board = BoardSpec("chessboard", (9, 7), 30.0)
    px_per_mm, margin = 2.0, 30.0
    texture = chessboard_texture(board.squares, board.square_mm, px_per_mm, margin)
    rvec, tvec = board_pose(0, 0, 3.0, (0.0, 0.0, GEOMETRY.l0_mm), (270.0, 210.0))
    view = render_board_view(texture, px_per_mm, margin, camera, rvec, tvec, rng=rng)
    found = detect_board(view, board)
    assert found is not None
    return pixel_mm_from_corners(found.image_points, board.inner_corners, board.square_mm)


@pytest.fixture(scope="module")
def calibration_data():
    rng = np.random.default_rng(7)
    reference, ref_lit = measured_phase(plane(0.0), rng)
    planes = [measured_phase(plane(h), rng) for h in HEIGHTS]
    pixel_mm = board_pixel_mm(rng)
    f0 = fit_f0(reference, pixel_mm, mask=ref_lit)
    deltas = [phase - reference for phase, _ in planes]
    fit = fit_l0_d0(HEIGHTS, deltas, f0.f0_per_mm, f0_std_per_mm=f0.f0_std_per_mm)
    return {"reference": reference, "pixel_mm": pixel_mm, "f0": f0, "fit": fit, "deltas": deltas, "rng": rng}


def test_pixel_size_from_chessboard_within_half_percent(calibration_data):
    assert calibration_data["pixel_mm"] == pytest.approx(GEOMETRY.pixel_mm, rel=0.005)


def test_f0_l0_d0_recovered_within_half_percent(calibration_data):
    fit = calibration_data["fit"]
    assert calibration_data["f0"].f0_per_mm == pytest.approx(GEOMETRY.f0_per_mm, rel=0.005)
    assert fit.l0_mm == pytest.approx(GEOMETRY.l0_mm, rel=0.005)
    assert fit.d0_mm == pytest.approx(GEOMETRY.d0_mm, rel=0.005)
    # the stated uncertainties cover the actual errors (within 4 sigma) and residuals are small
    assert abs(fit.l0_mm - GEOMETRY.l0_mm) < 4 * fit.l0_std_mm + 0.5
    assert max(abs(r) for r in fit.residuals_mm) < 0.05
    assert fit.as_fields()["heights_mm"] == list(HEIGHTS)


def test_gauge_block_measured_within_a_tenth_of_a_millimetre(calibration_data):
    fit, f0 = calibration_data["fit"], calibration_data["f0"]
    scene = plane(0.0)
    scene[30:66, 44:84] = 25.0
    phase, lit = measured_phase(scene, calibration_data["rng"])
    height = phase_to_height(phase - calibration_data["reference"], fit.l0_mm, fit.d0_mm, f0.f0_per_mm)
    top = height[34:62, 48:80]
    assert np.isfinite(top).all()
    assert abs(float(np.mean(top)) - 25.0) < 0.1
    assert abs(float(np.mean(height[5:25, 5:40]))) < 0.1  # the plane around it stays at 0


def test_ideal_phases_give_exact_parameters():
    truth = [
        synth.true_absolute_phase(synth.projector_coordinates(plane(h), GEOMETRY), GEOMETRY, FREQUENCY)
        for h in (0.0, *HEIGHTS)
    ]
    fit = fit_l0_d0(HEIGHTS, [p - truth[0] for p in truth[1:]], GEOMETRY.f0_per_mm)
    assert fit.l0_mm == pytest.approx(GEOMETRY.l0_mm, rel=1e-9)
    assert fit.d0_mm == pytest.approx(GEOMETRY.d0_mm, rel=1e-9)
    f0 = fit_f0(truth[0], GEOMETRY.pixel_mm)
    assert f0.f0_per_mm == pytest.approx(GEOMETRY.f0_per_mm, rel=1e-9)


def test_negative_baseline_keeps_its_sign():
    geometry = synth.RigGeometry(
        l0_mm=800.0,
        d0_mm=-150.0,
        f0_per_mm=0.03125,
        f0_frequency=FREQUENCY,
        pixel_mm=3.2,
        camera_width=64,
        camera_height=48,
    )
    truth = [
        synth.true_absolute_phase(synth.projector_coordinates(np.full((48, 64), h), geometry), geometry, FREQUENCY)
        for h in (0.0, 15.0, 30.0, 60.0)
    ]
    fit = fit_l0_d0((15.0, 30.0, 60.0), [p - truth[0] for p in truth[1:]], geometry.f0_per_mm)
    assert fit.d0_mm == pytest.approx(-150.0, rel=1e-9)
    assert fit.l0_mm == pytest.approx(800.0, rel=1e-9)


# --- bad input -------------------------------------------------------------------------------


def test_too_few_heights_is_refused(calibration_data):
    with pytest.raises(CalibrationError, match="at least 3 known heights"):
        fit_l0_d0(HEIGHTS[:2], calibration_data["deltas"][:2], GEOMETRY.f0_per_mm)


def test_mismatched_counts_are_refused(calibration_data):
    with pytest.raises(CalibrationError, match="4 heights but 3 phase maps"):
        fit_l0_d0(HEIGHTS, calibration_data["deltas"][:3], GEOMETRY.f0_per_mm)


def test_plane_that_is_not_flat_is_refused(calibration_data):
    deltas = list(calibration_data["deltas"])
    bumped = deltas[2].copy()
    bumped[:, 64:] -= 0.3  # half the plane ~6 mm higher: a step, not noise
    deltas[2] = bumped
    with pytest.raises(CalibrationError, match=r"plane at 100 mm: heights spread .* not flat"):
        fit_l0_d0(HEIGHTS, deltas, GEOMETRY.f0_per_mm)


def test_equal_heights_are_a_singular_fit(calibration_data):
    with pytest.raises(CalibrationError, match="all equal"):
        fit_l0_d0((50.0, 50.0, 50.0), calibration_data["deltas"][:3], GEOMETRY.f0_per_mm)


def test_unmoved_plane_is_refused(calibration_data):
    deltas = list(calibration_data["deltas"])
    deltas[1] = np.zeros_like(deltas[1])
    with pytest.raises(CalibrationError, match="plane at 50 mm: no phase change"):
        fit_l0_d0(HEIGHTS, deltas, GEOMETRY.f0_per_mm)


def test_zero_height_is_refused(calibration_data):
    with pytest.raises(CalibrationError, match="0 mm is the reference plane"):
        fit_l0_d0((0.0, 50.0, 100.0), calibration_data["deltas"][:3], GEOMETRY.f0_per_mm)


def test_wrong_sign_heights_are_refused(calibration_data):
    with pytest.raises(CalibrationError, match="not a positive distance"):
        fit_l0_d0(tuple(-h for h in HEIGHTS), calibration_data["deltas"], GEOMETRY.f0_per_mm)


def test_flat_reference_phase_has_no_slope():
    with pytest.raises(CalibrationError, match="no phase slope"):
        fit_f0(np.ones((32, 32)), 0.5)


def test_mismatched_patterns_name_the_difference():
    scan = synth.sinusoid_patterns([1, 8], 4)
    other = synth.sinusoid_patterns([1, 16], 4)
    check_same_patterns(scan, [dict(p) for p in scan], "reference", "plane at 20 mm")
    with pytest.raises(CalibrationError, match="plane at 20 mm: pattern 4 frequency = 16 but reference has 8"):
        check_same_patterns(scan, other, "reference", "plane at 20 mm")
    with pytest.raises(CalibrationError, match="3 patterns but reference has 8"):
        check_same_patterns(scan, scan[:3], "reference", "plane at 20 mm")
    assert phase_frequency(other) == 16.0
