"""Both fringe axes with the reference-plane model: the default axis, --axis both, and one-axis calibrations.

A simulated reference-plane rig whose baseline is turned 80 degrees from x towards y (mostly
vertical): the row fringes (y) see d0 sin 80 = 0.98 d0 of it, the column fringes (x) d0 cos 80 =
0.17 d0. Both axes have fringes 14.25 projector pixels wide (64 across 912 columns, 80 across 1140
rows), so the same phase noise is 5.7x more height along x. The calibration is the rig's exact one,
fitted on both axes (``axes``) or, as before, on one.
"""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from calibration.errors import CalibrationError
from calibration.plane_axes import height_per_projector_pixel_mm, plane_axes, sensitivity_rad_per_mm
from calibration.store import read_calibration, write_calibration
from rig.errors import ProcessingError
from rig.hardware.synthesis import (
    demo_geometry,
    simulate_scan,
    sinusoid_patterns,
    write_simulated_scan,
)
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.result import build_report
from rig.pipeline.run import process

BASELINE_ANGLE_DEG = 80.0
PATTERNS = sinusoid_patterns((1, 8, 64), 4, "x") + sinusoid_patterns((1, 10, 80), 4, "y")


def vertical_rig_scan(tmp_path: Path, seed: int, axes: tuple[str, ...] = ("x", "y")):
    """A hemisphere under fringes on both axes, on the mostly vertical rig, and its exact calibration."""
    geometry = replace(demo_geometry(160, 120), baseline_angle_deg=BASELINE_ANGLE_DEG)
    scan = simulate_scan("hemisphere", geometry=geometry, patterns=PATTERNS, seed=seed)
    scan.calibrated_axes = axes
    return scan, write_simulated_scan(scan, tmp_path / "scan")


def height_rms(result, scan) -> float:
    error = np.where(result.mask & scan.lit, result.height - scan.height_mm, np.nan)
    assert np.count_nonzero(np.isfinite(error)) > 0.9 * np.count_nonzero(scan.lit)
    return float(np.sqrt(np.nanmean(error**2)))


@pytest.mark.parametrize("seed", [11, 12])
def test_the_default_takes_the_more_sensitive_axis_and_says_why(tmp_path: Path, seed: int) -> None:
    scan, paths = vertical_rig_scan(tmp_path, seed)
    runs = {
        axis: process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis=axis))
        for axis in (None, "x", "y")
    }
    report = build_report(runs[None])
    assert report["methods"]["fringe_axis"] == "y"
    assert "larger sensitivity" in report["methods"]["axis_choice"]
    rms = {axis: height_rms(result, scan) for axis, result in runs.items()}
    assert rms[None] == rms["y"]  # the same run
    # tan 80 = 5.7x the sensitivity: the phase noise alone gives y 1/5.7 of x's error (5.6-5.75 on
    # seeds 11-14 and 21-25); at least 1/4
    assert rms["y"] < rms["x"] / 4, rms
    sensitivity = runs[None].object.info["sensitivity_rad_per_mm"]
    assert sensitivity["y"] / sensitivity["x"] == pytest.approx(np.tan(np.deg2rad(BASELINE_ANGLE_DEG)), rel=0.01)


def test_the_weaker_axis_asked_for_is_warned_about_with_its_height_per_projector_pixel(tmp_path: Path) -> None:
    _, paths = vertical_rig_scan(tmp_path, seed=13)
    columns = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis="x"))
    rows = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis="y"))
    per_pixel = columns.object.info["depth_per_projector_pixel_mm"]
    assert per_pixel["x"] / per_pixel["y"] == pytest.approx(np.tan(np.deg2rad(BASELINE_ANGLE_DEG)), rel=0.01)
    assert any("--axis x: ill-conditioned" in note and f"{per_pixel['x']:.3g} mm" in note for note in columns.notes)
    assert not any("ill-conditioned" in note for note in rows.notes)


def test_both_axes_fuse_the_two_heights_by_inverse_variance(tmp_path: Path) -> None:
    scan, paths = vertical_rig_scan(tmp_path, seed=14)
    both = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis="both"))
    rows = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis="y"))
    columns = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis="x"))
    assert build_report(both)["methods"]["fringe_axis"] == "both"
    assert both.object.info["axis_fusion"]["both_axes_pixels"] > 0.9 * np.count_nonzero(both.mask)
    rms = {name: height_rms(r, scan) for name, r in (("both", both), ("x", columns), ("y", rows))}
    # weights 1 : 1/5.7^2 predict sqrt(1 / (1 + 1 / 32.2)) = 0.985 of y's error (0.982-0.987 on seeds
    # 11-14 and 21-25): the x axis adds a little, never takes away
    assert rms["both"] <= 0.995 * rms["y"], rms
    assert not any("not used; choose them with --axis" in note for note in both.notes)
    assert both.uncertainty is not None
    keep = both.mask & scan.lit
    ratio = np.sqrt(np.mean(((both.height - scan.height_mm)[keep] / both.uncertainty[keep]) ** 2))
    assert 1 / 1.5 <= ratio <= 1.5


def test_a_calibration_fitted_on_one_axis_keeps_it_and_refuses_both(tmp_path: Path) -> None:
    scan, paths = vertical_rig_scan(tmp_path, seed=15, axes=("x",))
    result = process(paths.capture, paths.calibration, ProcessOptions(correction="none"))
    report = build_report(result)
    assert report["methods"]["fringe_axis"] == "x"
    assert "the only one it converts (it holds no fit along y)" in report["methods"]["axis_choice"]
    with pytest.raises(ProcessingError, match=r"--axis both: .* converts fringes along x only"):
        process(paths.capture, paths.calibration, ProcessOptions(axis="both"))


def test_a_calibration_naming_no_axis_keeps_the_first_captured(tmp_path: Path) -> None:
    """Calibrations written before ``fringe_axis`` existed: the first axis in the capture, as before."""
    _, paths = vertical_rig_scan(tmp_path, seed=16, axes=())
    result = process(paths.capture, paths.calibration, ProcessOptions(correction="none"))
    assert build_report(result)["methods"]["fringe_axis"] == "x"
    with pytest.raises(ProcessingError, match="--axis both: .*names no fitted axis"):
        process(paths.capture, paths.calibration, ProcessOptions(axis="both"))


def test_the_sensitivity_formula_matches_the_simulated_phase_of_a_raised_plane() -> None:
    """S = 2 pi f0 |d0| / l0 and dh/du against the phase the simulator gives a plane 0.5 mm up."""
    from mock_devices import synth
    from rig.hardware.synthesis import exact_calibration

    geometry = replace(demo_geometry(64, 48), baseline_angle_deg=BASELINE_ANGLE_DEG)
    planes = plane_axes(exact_calibration(geometry, axes=("x", "y")))
    flat = synth.projector_coordinates(np.zeros(geometry.camera_shape), geometry)
    raised = synth.projector_coordinates(np.full(geometry.camera_shape, 0.5), geometry)
    for axis, moved, extent, frequency in (
        ("x", raised.u - flat.u, geometry.projector_width, 64),
        ("y", raised.v - flat.v, geometry.projector_height, 80),
    ):
        phase_per_mm = float(np.median(np.abs(moved))) * 2 * np.pi * frequency / extent / 0.5
        assert sensitivity_rad_per_mm(planes[axis], frequency) == pytest.approx(phase_per_mm, rel=0.002)
        per_pixel = height_per_projector_pixel_mm(planes[axis], extent)
        assert per_pixel == pytest.approx(0.5 / float(np.median(np.abs(moved))), rel=0.002)


def test_a_malformed_axes_entry_is_refused_in_one_line(tmp_path: Path) -> None:
    _, paths = vertical_rig_scan(tmp_path, seed=17)
    calibration = read_calibration(paths.calibration)
    calibration.extra["axes"]["y"]["d0_mm"] = "far"
    write_calibration(paths.calibration, calibration)
    with pytest.raises(
        CalibrationError, match=r"calibration.json: axes.y.d0_mm: expected a non-zero number, found 'far'"
    ):
        process(paths.capture, paths.calibration, ProcessOptions(correction="none"))


def test_a_session_with_fringes_on_both_axes_fits_each_axis(tmp_path: Path) -> None:
    """`rig calibrate --from` on a stored reference-plane session of the vertical rig: each axis's own d0 and f0."""
    from mock_devices import synth
    from rig.calibrate.session import CalibrationPlan, compute
    from rig.store.capture import write_capture

    geometry = replace(demo_geometry(160, 120), baseline_angle_deg=BASELINE_ANGLE_DEG)
    projector = {"width": geometry.projector_width, "height": geometry.projector_height}
    appearance = synth.Appearance(ambient=0.05, snr_db=35.0)
    rng = np.random.default_rng(18)
    cal = tmp_path / "cal"

    def store(height: float, where: Path, scene: str) -> None:
        mapping = synth.projector_coordinates(np.full(geometry.camera_shape, height), geometry)
        frames = synth.render_stack(PATTERNS, mapping, geometry, appearance, rng)
        write_capture(where, frames, PATTERNS, projector, scene=scene)

    store(0.0, cal / "reference", "reference")
    for height in (25, 50, 100, 150):
        store(float(height), cal / "planes" / f"plane-at-{height}mm", f"plane-at-{height}mm")
    plan = CalibrationPlan(board=None, board_views=0, pixel_mm=geometry.pixel_mm)
    (cal / "session.json").write_text(json.dumps(plan.to_json()))
    report = compute(cal)
    axes = read_calibration(cal).extra["axes"]
    for axis in ("x", "y"):
        assert axes[axis]["d0_mm"] == pytest.approx(geometry.baseline_share(axis), rel=0.02)
        frequency = axes[axis]["f0_frequency"]
        assert axes[axis]["f0_per_mm"] == pytest.approx(geometry.per_mm_along(axis, frequency), rel=0.01)
    assert any("rig process takes the larger by default" in line for line in report.lines)
    # and processing a scan with it takes the rows
    scan = simulate_scan("hemisphere", geometry=geometry, patterns=PATTERNS, seed=19)
    paths = write_simulated_scan(scan, tmp_path / "scan")
    result = process(paths.capture, cal, ProcessOptions(correction="none"))
    assert build_report(result)["methods"]["fringe_axis"] == "y"
    assert height_rms(result, scan) < 0.2
