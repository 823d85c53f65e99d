"""Fringe sampling density: spatial corrections are skipped where fringes are too dense for them."""

from __future__ import annotations

import numpy as np
import pytest

from processing.sampling import SPATIAL_STEP_LIMIT_RAD, fringe_step_rad, undersampled_for_spatial_methods
from rig import api
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.run import ProcessResult


@pytest.mark.parametrize("period_px", [1.25, 2.0, 3.0, 10.0, 40.0])
@pytest.mark.parametrize("axis", [0, 1])
def test_step_is_the_true_phase_step_even_above_nyquist(period_px: float, axis: int) -> None:
    rows, cols = np.mgrid[0:40, 0:60].astype(np.float64)
    phase = 2 * np.pi * (cols if axis == 1 else rows) / period_px + 0.3
    valid = np.ones_like(phase, dtype=bool)
    valid[5:9, 10:30] = False
    phase[~valid] = np.nan
    step = fringe_step_rad(phase, valid, axis)
    assert step == pytest.approx(2 * np.pi / period_px, rel=1e-9)
    assert undersampled_for_spatial_methods(step) == (2 * np.pi / period_px > SPATIAL_STEP_LIMIT_RAD)


def test_no_valid_neighbours_and_bad_input() -> None:
    assert np.isnan(fringe_step_rad(np.zeros((3, 3)), np.eye(3, dtype=bool), 1))
    with pytest.raises(ValueError, match="valid"):
        fringe_step_rad(np.zeros((3, 3)), np.ones((2, 3), dtype=bool), 1)
    with pytest.raises(ValueError, match="axis"):
        fringe_step_rad(np.zeros((3, 3)), np.ones((3, 3), dtype=bool), 2)


def _nmse(result: ProcessResult, truth: np.ndarray) -> float:
    valid = result.mask & np.isfinite(result.height)
    return float(np.sum((result.height[valid] - truth[valid]) ** 2) / np.sum(truth[valid] ** 2))


def test_auto_leaves_undersampled_fringes_alone(tmp_path) -> None:
    """64 fringes seen by a 64 px camera (about 1.2 px per fringe): temporal unwrapping is right,
    but every spatial correction compares aliased neighbours; auto made the heights 3000x worse."""
    scan = simulate_scan("hemisphere", geometry=demo_geometry(64, 48), seed=3)
    paths = write_simulated_scan(scan, tmp_path / "tiny")
    truth = np.load(paths.truth)
    none = api.process(paths.capture, paths.calibration, api.ProcessOptions(correction="none"))
    auto = api.process(paths.capture, paths.calibration)
    assert _nmse(auto, truth) == pytest.approx(_nmse(none, truth), rel=1e-6)
    assert "too dense" in auto.report["stage_info"]["object"]["correction"]["skipped"]
    assert any("auto skipped" in note for note in auto.report["notes"])
    vote = api.process(paths.capture, paths.calibration, api.ProcessOptions(correction="vote"))
    assert any("unreliable" in note for note in vote.report["notes"])


def test_step_ignores_wrong_orders_on_most_pixels() -> None:
    """Fringes 36 px apart (the issue's case at frequency 25) with 60 % of the pixels carrying wrong
    orders of 1 - 7 fringes either way (two-frequency look-up errors): the median step of the
    unwrapped phase measured the errors (about 2 pi per pixel, "0.1 px apart") and switched
    corrections off; the wrapped steps give the fringes' true step."""
    rng = np.random.default_rng(20)
    rows, cols = np.mgrid[0:300, 0:400].astype(np.float64)
    period_px = 36.0
    truth = 2 * np.pi * cols / period_px + 0.01 * rows
    wrong = rng.random(truth.shape) < 0.6
    errors = rng.integers(1, 8, truth.shape) * rng.choice([-1, 1], truth.shape)
    phase = truth + 2 * np.pi * np.where(wrong, errors, 0) + rng.normal(0.0, 0.05, truth.shape)
    valid = np.ones_like(phase, dtype=bool)
    head, tail = phase[:, :-1], phase[:, 1:]
    unwrapped_median = float(np.median(np.abs(tail - head)))
    assert undersampled_for_spatial_methods(unwrapped_median)  # what the earlier guard saw
    step = fringe_step_rad(phase, valid, axis=1)
    assert step == pytest.approx(2 * np.pi / period_px, rel=0.05)
    assert not undersampled_for_spatial_methods(step)
