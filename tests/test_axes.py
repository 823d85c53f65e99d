"""Both fringe axes: the axis choice, each pixel triangulated from both projector coordinates, warnings.

Simulated camera-projector rigs (mock_devices.stereo_synth): a projector on a diagonal baseline
(107, 113, 10 mm), where both axes carry the same depth per projector pixel (3.47 and 3.44 mm) and
the fringes have the same period in projector pixels on both axes (28.5 px: 32 across 912 columns,
24 across 684 rows), so both together should reach 1/sqrt(2) of either alone (the target: <= 0.75x
the best single axis; seeds 41, 42 here, more in benchmarks/validate_axes.py); and the demo rig,
whose baseline is horizontal, so the row fringes carry ~30x more depth per projector pixel than
the column fringes.

Depth errors are compared over the pixels every run measures, without the few where one axis's
fringe order slips at the edge of the projector's image (more than 5 mm off): those are counted
apart; "both" leaves them without a point when the axes disagree.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from calibration.stereo import StereoModel, triangulate
from calibration.store import Calibration, write_calibration
from mock_devices import synth
from mock_devices.stereo_synth import (
    StereoRig,
    aimed_rig,
    calibration_fields,
    demo_rig,
    demo_scene,
    render_frames,
    trace,
)
from processing.geometry.axis_fusion import depth_per_projector_pixel, fuse_points
from rig.errors import ConfigError, ProcessingError
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.result import build_report
from rig.pipeline.run import process
from rig.store.capture import write_capture

FREQUENCIES = {"x": (1, 8, 32), "y": (1, 6, 24)}  # 28.5 projector pixels per period on either axis
DIAGONAL = (107.0, 113.0, 10.0)  # projector centre in the camera frame (mm): both axes equally sensitive
SLIP_MM = 5.0


@dataclass
class StereoScan:
    capture: Path
    calibration: Path
    points: np.ndarray  # true points (H, W, 3)
    lit: np.ndarray


def stereo_scan(tmp_path: Path, rig: StereoRig, seed: int, snr_db: float = 30.0) -> StereoScan:
    """Fringes on both axes of the demo scene, written as a capture, and the rig's exact stereo calibration."""
    points, mapping = trace(rig, demo_scene())
    patterns = [p for axis, f in FREQUENCIES.items() for p in synth.sinusoid_patterns(f, 6, axis)]
    appearance = synth.Appearance(ambient=0.05, snr_db=snr_db)
    frames = render_frames(rig, mapping, patterns, appearance, np.random.default_rng(seed))
    projector = {"width": rig.projector.width, "height": rig.projector.height}
    write_capture(tmp_path / "capture", frames, patterns, projector)
    fields = calibration_fields(rig)
    fields.pop("model")
    write_calibration(tmp_path / "calibration", Calibration(model="stereo", extra=fields))
    return StereoScan(tmp_path / "capture", tmp_path / "calibration", points, mapping.lit)


def depth_error(result, scan: StereoScan) -> np.ndarray:
    """Depth minus the truth (NaN where the run gave no depth or the pixel is unlit)."""
    return np.where(result.mask & scan.lit, result.height - scan.points[..., 2], np.nan)


def depth_rms(results: dict, scan: StereoScan, slip_mm: float = SLIP_MM) -> dict:
    """RMS depth error of each run over the pixels all runs measure without an order slip (``slip_mm`` off)."""
    errors = {name: depth_error(r, scan) for name, r in results.items()}
    keep = np.logical_and.reduce([np.abs(e) < slip_mm for e in errors.values()])  # NaN compares False
    assert keep.mean() > 0.5
    return {name: float(np.sqrt(np.mean(e[keep] ** 2))) for name, e in errors.items()}


@pytest.mark.parametrize("seed", [41, 42])
def test_both_axes_beat_the_best_single_axis(tmp_path: Path, seed: int) -> None:
    scan = stereo_scan(tmp_path, aimed_rig(DIAGONAL, 320, 256), seed)
    results = {
        axis: process(scan.capture, scan.calibration, ProcessOptions(correction="none", axis=axis))
        for axis in ("x", "y")
    }
    both = results["both"] = process(scan.capture, scan.calibration, ProcessOptions(correction="none"))
    report = build_report(both)
    assert report["methods"]["fringe_axis"] == "both"
    assert "camera-projector" in report["methods"]["axis_choice"]
    assert both.object.info["axis_fusion"]["both_axes_pixels"] > 0.9 * np.count_nonzero(both.mask)
    rms = depth_rms(results, scan)
    assert rms["both"] <= 0.75 * min(rms["x"], rms["y"]), rms
    # slips of one axis are not passed on: "both" has none
    assert not np.any(np.abs(depth_error(both, scan)) > SLIP_MM)
    # the predicted sigma follows the fused points
    assert both.uncertainty is not None
    keep = both.mask & scan.lit
    ratio = np.sqrt(np.mean((depth_error(both, scan)[keep] / both.uncertainty[keep]) ** 2))
    assert 1 / 1.5 <= ratio <= 1.5


def test_an_ill_conditioned_axis_asked_for_is_warned_about(tmp_path: Path) -> None:
    """The demo rig's baseline is horizontal: row fringes (y) carry ~30x the depth per projector pixel."""
    scan = stereo_scan(tmp_path, demo_rig(160, 128), seed=43)
    rows = process(scan.capture, scan.calibration, ProcessOptions(correction="none", axis="y"))
    columns = process(scan.capture, scan.calibration, ProcessOptions(correction="none", axis="x"))
    per_pixel = rows.object.info["depth_per_projector_pixel_mm"]
    assert per_pixel["y"] > 10 * per_pixel["x"]
    assert any("--axis y: ill-conditioned" in note and f"{per_pixel['y']:.3g} mm" in note for note in rows.notes)
    assert not any("ill-conditioned" in note for note in columns.notes)
    both = process(scan.capture, scan.calibration, ProcessOptions(correction="none"))
    # both axes weighted by their noise: no worse than the good axis alone, far better than the bad one
    rms = depth_rms({"both": both, "x": columns, "y": rows}, scan, slip_mm=100.0)  # y's noise is mm
    assert rms["both"] <= 1.02 * rms["x"], rms
    assert rms["both"] < 0.2 * rms["y"], rms


def test_depth_per_projector_pixel_matches_a_triangulated_difference() -> None:
    rig = aimed_rig(DIAGONAL, 160, 128)
    points, mapping = trace(rig, demo_scene())
    model = StereoModel.from_fields(calibration_fields(rig))
    model = StereoModel(**{**model.__dict__, "projector_distortion": np.zeros(5)})  # the estimate is pinhole
    per_pixel = depth_per_projector_pixel(points, rig.rotation, rig.translation_mm, rig.projector.matrix)
    for axis, coordinate, extent, estimate in (
        ("x", mapping.u, rig.projector.width, per_pixel[0]),
        ("y", mapping.v, rig.projector.height, per_pixel[1]),
    ):
        phase = np.where(mapping.lit, 2 * np.pi * 16 * coordinate / extent, np.nan)
        step = 2 * np.pi * 16 / extent  # one projector pixel
        moved = triangulate(model, phase + step, 16, axis=axis) - triangulate(model, phase, 16, axis=axis)
        assert estimate == pytest.approx(float(np.nanmedian(np.linalg.norm(moved, axis=-1))), rel=0.05)


def test_fuse_points_is_the_inverse_variance_mean_and_gives_no_point_where_they_disagree() -> None:
    ray = np.array([0.1, -0.2, 1.0])
    first = np.stack([ray * 500.0, ray * 500.0, ray * 500.0, ray * np.nan])[None]
    second = np.stack([ray * 503.0, ray * 600.0, ray * np.nan, ray * 510.0])[None]
    s1, s2 = np.array([[1.0, 1.0, 1.0, 1.0]]), np.array([[2.0, 2.0, 2.0, 2.0]])
    fused = fuse_points([first, second], [s1, s2])
    # pixel 0: weights 1 and 1/4 -> (500 + 503 / 4) / 1.25 = 500.6 along the ray
    np.testing.assert_allclose(fused.points[0, 0], ray * 500.6)
    assert fused.sigma[0, 0] == pytest.approx(1 / np.sqrt(1.25), rel=1e-6)
    assert np.isnan(fused.points[0, 1]).all() and np.isnan(fused.sigma[0, 1])  # 100 |ray| mm apart: undecided
    np.testing.assert_allclose(fused.points[0, 2], ray * 500.0)
    np.testing.assert_allclose(fused.points[0, 3], ray * 510.0)
    assert (fused.combined, fused.alone, fused.disagreeing) == (1, [1, 1], 1)


def test_both_axes_need_a_camera_projector_calibration(tmp_path: Path) -> None:
    from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan

    scan = simulate_scan("hemisphere", geometry=demo_geometry(64, 48), seed=1)
    paths = write_simulated_scan(scan, tmp_path / "scan")
    with pytest.raises(ProcessingError, match="--axis both: .*camera-projector"):
        process(paths.capture, paths.calibration, ProcessOptions(axis="both"))


def test_no_undistort_is_refused_for_a_stereo_calibration_by_the_api(tmp_path: Path) -> None:
    from rig import api

    scan = stereo_scan(tmp_path, demo_rig(96, 80), seed=44)
    with pytest.raises(ConfigError, match="--no-undistort: .*camera-projector"):
        api.process(str(scan.capture), calibration=str(scan.calibration), options=ProcessOptions(undistort=False))
