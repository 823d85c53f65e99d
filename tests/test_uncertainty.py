"""The noise estimate, the predicted phase and height sigma, and the uncertainty outputs.

Tolerances: the noise estimate from ~16k sampled pixels has a relative standard error under 1 %
(J >= 4) and a few % (three steps, median absolute deviation); 5 % and 10 % leave room. The
predicted height sigma on the simulated rig (seeds 21 and 22, not those the correction gain was
developed on) must match the observed error within a factor 1.5 (issue target).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from mock_devices import synth
from processing.geometry.uncertainty import (
    GAIN_SAMPLES,
    combined_phase_sigma,
    correction_gain,
    noise_sigma,
    phase_sigma,
)
from processing.phase.shifting import phase_shift
from rig.cli import main
from rig.hardware.synthesis import demo_appearance, demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process
from rig.store.result_files import read_ply_points, write_ply


def _fringes(steps: int, sigma: float, seed: int, shape: tuple[int, int] = (240, 320)) -> tuple[np.ndarray, np.ndarray]:
    """Frames of a tilted fringe with modulation varying 20..100 and noise ``sigma``; and the true phase."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : shape[0], 0 : shape[1]]
    phase = 2 * np.pi * cols / 16.0
    modulation = 20.0 + 80.0 * rows / shape[0]
    shifts = 2 * np.pi * np.arange(steps) / steps
    frames = 120.0 + modulation * np.cos(phase[None] + shifts[:, None, None])
    return frames + rng.normal(0.0, sigma, frames.shape), modulation


@pytest.mark.parametrize("steps", [4, 6, 9])
def test_the_fit_residual_gives_the_noise(steps: int) -> None:
    frames, _ = _fringes(steps, 3.0, seed=steps)
    assert noise_sigma(frames, [list(range(steps))]) == pytest.approx(3.0, rel=0.05)


def test_three_steps_give_the_noise_from_neighbours() -> None:
    frames, _ = _fringes(3, 3.0, seed=5)
    assert noise_sigma(frames, [[0, 1, 2]], axis="x") == pytest.approx(3.0, rel=0.10)


def test_predicted_phase_sigma_matches_the_phase_scatter() -> None:
    steps, sigma = 6, 4.0
    frames, modulation = _fringes(steps, sigma, seed=7)
    phase = phase_shift(frames).phase
    truth = np.mod(2 * np.pi * np.arange(frames.shape[2]) / 16.0, 2 * np.pi)
    error = np.angle(np.exp(1j * (phase - truth[None, :])))
    predicted = phase_sigma(modulation, noise_sigma(frames, [list(range(steps))]), steps)
    for band in (slice(20, 40), slice(200, 220)):  # low and high modulation
        observed = np.sqrt(np.mean(error[band] ** 2))
        assert observed == pytest.approx(float(np.median(predicted[band])), rel=0.1)


def test_a_correction_that_removes_half_the_noise_power_has_gain_sqrt_half() -> None:
    rng = np.random.default_rng(3)
    sigma = np.full((200, 200), 0.1)
    noise_kept, noise_removed = rng.normal(0, 0.1 / np.sqrt(2), (2, 200, 200))
    before = noise_kept + noise_removed
    gain = correction_gain(before, noise_kept, sigma, np.ones((200, 200), bool))
    assert gain == pytest.approx(np.sqrt(0.5), rel=0.05)


def test_the_gain_of_a_full_size_map_comes_from_its_masked_subsample() -> None:
    # 768 x 1024 is above GAIN_SAMPLES pixels: the spread is taken over a strided subsample, whose mask must
    # stay aligned with it. Outside the mask the correction moved the phase by 5 sigma: were those pixels read,
    # the removed share would exceed 1 and the gain fall to MIN_CORRECTION_GAIN.
    rng = np.random.default_rng(5)
    shape = (768, 1024)
    sigma = np.full(shape, 0.1, dtype=np.float32)
    noise_kept, noise_removed = rng.normal(0, 0.1 / np.sqrt(2), (2, *shape)).astype(np.float32)
    before = noise_kept + noise_removed
    after = noise_kept.copy()
    mask = np.ones(shape, bool)
    mask[:, ::3] = False  # a third of the columns, interleaved with the subsample's stride
    after[~mask] += np.float32(0.5) * np.sign(rng.normal(size=int((~mask).sum()))).astype(np.float32)
    assert GAIN_SAMPLES < mask.size
    gain = correction_gain(before, after, sigma, mask)
    assert gain == pytest.approx(np.sqrt(0.5), rel=0.02)


def test_the_gain_refuses_maps_of_another_shape_naming_them() -> None:
    before = np.zeros((4, 5))
    with pytest.raises(ValueError, match=r"sigma_phi: expected the shape \(4, 5\) of before, found \(5, 4\)"):
        correction_gain(before, before, np.ones((5, 4)), np.ones((4, 5), bool))


def _scan(snr_db: float, seed: int):
    return simulate_scan(
        "hemisphere",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((1, 8, 64), 6),
        appearance=demo_appearance(snr_db),
        seed=seed,
    )


@pytest.mark.parametrize(
    ("snr_db", "seed", "corrections"),
    [(10.0, 21, ("none",)), (20.0, 21, ("none", "auto")), (30.0, 22, ("none", "auto")), (40.0, 21, ("none", "auto"))],
)
def test_predicted_height_sigma_matches_the_simulated_error(
    tmp_path: Path, snr_db: float, seed: int, corrections: tuple[str, ...]
) -> None:
    """At 10 dB the auto correction's noise gain is not resolved (docs/uncertainty.md): uncorrected only."""
    scan = _scan(snr_db, seed)
    paths = write_simulated_scan(scan, tmp_path / "scan")
    for correction in corrections:
        result = process(paths.capture, paths.calibration, ProcessOptions(correction=correction))
        assert result.uncertainty is not None
        keep = result.mask & scan.lit
        error = result.height[keep] - scan.height_mm[keep]
        sigma = result.uncertainty[keep].astype(np.float64)
        inliers = np.abs(error) < 6 * sigma
        assert inliers.mean() > (0.8 if snr_db < 15 else 0.97)  # fringe-order slips at 10 dB are not noise
        ratio = np.sqrt(np.mean((error[inliers] / sigma[inliers]) ** 2))
        assert 1 / 1.5 <= ratio <= 1.5, (correction, ratio)


def test_max_sigma_keeps_the_pixels_under_the_bound(tmp_path: Path) -> None:
    """A dark band (reflectivity 0.12) that the 0.2 ratio drops is kept; a darker one (0.03) is too noisy."""
    reflectivity = np.ones((240, 320))
    reflectivity[:, 200:260] = 0.12
    reflectivity[:, 260:] = 0.03
    scan = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((1, 8, 64), 6),
        appearance=synth.Appearance(reflectivity=reflectivity, ambient=0.1, gain=200.0, snr_db=40.0),
        seed=25,
    )
    paths = write_simulated_scan(scan, tmp_path / "scan")
    plain = process(paths.capture, paths.calibration, ProcessOptions(correction="none", min_modulation_ratio=0.2))
    default = process(paths.capture, paths.calibration, ProcessOptions(correction="none"))
    bounded = process(  # the bound in mm alone, without the default one in radians
        paths.capture, paths.calibration, ProcessOptions(correction="none", max_sigma=1.0, max_phase_sigma=None)
    )
    assert bounded.uncertainty is not None and bounded.height is not None
    assert np.all(bounded.uncertainty[bounded.mask] <= 1.0)
    assert np.all(np.isnan(bounded.height[~bounded.mask]))
    dark, darker = scan.lit[:, 200:260], scan.lit[:, 260:]
    assert plain.mask[:, 200:260][dark].mean() < 0.05  # the ratio rule drops the dark band
    assert bounded.mask[:, 200:260][dark].mean() > 0.9  # the noise rule keeps it
    assert default.mask[:, 200:260][dark].mean() > 0.9  # and so does the default (the noise rule in radians)
    assert default.object.info["validity"]["rule"] == "noise"
    assert bounded.mask[:, 260:][darker].mean() < 0.1
    assert bounded.object.info["above_max_sigma"] > 0
    error = bounded.height[:, 200:260][bounded.mask[:, 200:260]] - scan.height_mm[:, 200:260][bounded.mask[:, 200:260]]
    assert np.sqrt(np.mean(error**2)) < 1.0


def test_a_max_sigma_no_pixel_meets_is_refused_naming_the_bound(capsys, tmp_path: Path) -> None:
    """Not "no pixel has a finite height with this calibration": the bound removed them, and the line says so."""
    paths = write_simulated_scan(_scan(30.0, 24), tmp_path / "scan")
    out = tmp_path / "out"
    argv = ["process", str(paths.capture), "--calibration", str(paths.calibration), "-o", str(out), "-q"]
    assert main([*argv, "--max-sigma", "1e-6"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].count("--max-sigma 1e-06 mm") == 1, err
    smallest = float(err[0].split("smallest ")[1].split(" mm")[0])
    assert smallest > 1e-6  # the smallest predicted sigma, above the bound
    assert "finite height" not in err[0] and not out.exists()
    assert main([*argv, "--max-sigma", str(smallest * 1.01)]) == 0  # just above it: some pixels are kept


def test_outputs_carry_the_uncertainty(capsys, tmp_path: Path) -> None:
    scan = _scan(30.0, 24)
    paths = write_simulated_scan(scan, tmp_path / "scan")
    out = tmp_path / "out"
    assert main(["process", str(paths.capture), "--calibration", str(paths.calibration), "-o", str(out), "-q"]) == 0
    capsys.readouterr()
    uncertainty, mask = np.load(out / "uncertainty.npy"), np.load(out / "mask.npy")
    assert uncertainty.dtype == np.float32 and uncertainty.shape == mask.shape
    assert np.all(np.isnan(uncertainty[~mask])) and np.all(np.isfinite(uncertainty[mask]))
    report = json.loads((out / "report.json").read_text())
    figures = report["uncertainty_mm"]
    assert figures["median"] == pytest.approx(float(np.median(uncertainty[mask])), rel=1e-6)
    assert figures["p95"] >= figures["median"] > 0
    assert report["files"]["uncertainty"] == "uncertainty.npy"
    header = (out / "points.ply").read_bytes().split(b"end_header")[0].decode()
    assert "property float sigma" in header
    assert len(read_ply_points(out / "points.ply")) == int(mask.sum())


def test_the_ply_sigma_property_round_trips(tmp_path: Path) -> None:
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    sigma = np.array([0.1, 0.2, 0.3, 0.4], dtype=np.float32)
    path = write_ply(tmp_path / "p.ply", points, np.arange(4, dtype=np.uint8), sigma=sigma)
    data = path.read_bytes()
    body = data[data.index(b"end_header\n") + len(b"end_header\n") :]
    record = np.frombuffer(body, dtype=[("xyz", "<f4", (3,)), ("rgb", "u1", (3,)), ("sigma", "<f4")])
    np.testing.assert_array_equal(record["sigma"], sigma)
    np.testing.assert_array_equal(read_ply_points(path), points)


def test_the_default_measures_a_dark_flat_target_as_well_as_its_noise_allows(tmp_path: Path) -> None:
    """Half a plane at reflectivity 0.12 (modulation ~12 grey levels at 8 bit): the issue's dark board.

    Target: >= 85 % of it measured; accuracy unchanged: the bright half as under the former rule,
    the dark half's plane error what its predicted sigma says (within the model's factor 1.5).
    """
    reflectivity = np.ones((240, 320))
    reflectivity[:, 160:] = 0.12
    scan = simulate_scan(
        "flat",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((1, 8, 64), 6),
        appearance=synth.Appearance(reflectivity=reflectivity, ambient=0.1, gain=200.0, snr_db=35.0),
        seed=63,
    )
    paths = write_simulated_scan(scan, tmp_path / "scan")
    former = process(paths.capture, paths.calibration, ProcessOptions(correction="none", min_modulation_ratio=0.2))
    default = process(paths.capture, paths.calibration, ProcessOptions(correction="none"))
    assert default.height is not None and default.uncertainty is not None and former.height is not None
    dark, bright = (slice(None), slice(160, None)), (slice(None), slice(0, 160))
    assert former.mask[dark][scan.lit[dark]].mean() < 0.05
    assert default.mask[dark][scan.lit[dark]].mean() >= 0.85
    np.testing.assert_array_equal(default.mask[bright], former.mask[bright])
    np.testing.assert_allclose(default.height[bright], former.height[bright], equal_nan=True)
    keep = default.mask[dark] & scan.lit[dark]
    error = (default.height - scan.height_mm)[dark][keep]
    predicted = float(np.median(default.uncertainty[dark][keep]))
    assert 1 / 1.5 <= np.sqrt(np.mean(error**2)) / predicted <= 1.5


def test_combined_phase_sigma_is_within_two_ulp_of_the_float64_value() -> None:
    rng = np.random.default_rng(5)
    first = rng.lognormal(-3.0, 1.5, 50_001).astype(np.float32)  # an odd length: the vector loop's tail too
    second = rng.lognormal(-3.0, 1.5, 50_001).astype(np.float32)
    first[:3], second[:3] = [np.nan, 0.0, 3.0], [1.0, np.nan, 4.0]
    combined = combined_phase_sigma(first.reshape(1, -1), second.reshape(1, -1))[0]
    exact = np.hypot(first.astype(np.float64), second.astype(np.float64))
    assert combined.dtype == np.float32 and np.isnan(combined[:2]).all() and combined[2] == 5.0
    assert np.max(np.abs(combined[3:] - exact[3:]) / np.spacing(exact[3:].astype(np.float32))) <= 2.0
    with pytest.raises(ValueError, match="second"):
        combined_phase_sigma(first, second[:-1])
