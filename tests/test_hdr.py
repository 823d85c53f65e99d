"""Shiny and dark parts in one scan (issue 25): exposure fusion, the exposure assistant, captures at
several exposures, and the CLI's exposure options."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_steps import assert_one_line, run

from mock_devices.synth import Sensor
from processing.phase.exposure_fusion import NoiseModel, fuse_exposures, noise_model
from processing.phase.shifting import phase_shift
from rig import api
from rig.acquisition.exposure_plan import (
    MAX_EXPOSURES,
    TARGET_COVERAGE,
    Reflectance,
    choose_exposures,
    ladder,
    usable,
)
from rig.config import parse_config
from rig.errors import CaptureError, ConfigError
from rig.hardware.synthesis import Appearance, demo_geometry, simulate_scan, write_simulated_scan
from rig.store.capture import read_capture, write_capture
from rig.store.exposures import exposure_sets, with_exposures
from rig.store.results import EXPOSURE

STEPS = 4
SHIFTS = 2 * np.pi * np.arange(STEPS) / STEPS
TOP = 255.0


def fringe_stack(rate_a: np.ndarray, rate_b: np.ndarray, phi: np.ndarray, times: list[float], noise: NoiseModel, rng):
    """(E, J, H, W) 8-bit frames I = t (a + b cos(phi + delta_j)) with the noise model's noise, clipped at 255."""
    out = []
    for t in times:
        clean = t * (rate_a + rate_b * np.cos(phi[None] + SHIFTS[:, None, None]))
        noisy = clean + rng.standard_normal(clean.shape) * np.sqrt(noise.variance(clean))
        out.append(np.clip(np.rint(noisy), 0, TOP))
    return np.stack(out).astype(np.uint8)


# --------------------------------------------------------------------------- fusion


def test_fusion_recovers_the_phase_where_single_exposures_saturate_or_drown_in_noise() -> None:
    """Three bands of reflectance (specular, matte, dark), each usable at one exposure only."""
    rng = np.random.default_rng(7)
    rows, cols = 60, 90
    phi = np.tile(np.linspace(-3.0, 3.0, cols), (rows, 1))
    scale = np.ones((rows, cols))
    scale[:, :30], scale[:, 60:] = 16.0, 1 / 16  # specular left, dark right (grey per unit time at t = 1)
    noise = NoiseModel(read=0.15, shot=0.025)
    times = [1 / 16, 1.0, 16.0]
    stack = fringe_stack(100 * scale, 80 * scale, phi, times, noise, rng)
    fused = fuse_exposures(stack, times, [list(range(STEPS))], noise, saturation=TOP)
    result = phase_shift(fused.frames, shifts=SHIFTS)
    error = np.angle(np.exp(1j * (result.phase - phi)))
    # every band: the phase within 6 sigma of the prediction sqrt(2/J) / B (unit noise after fusion)
    predicted = np.sqrt(2 / STEPS) / result.modulation
    assert np.all(np.abs(error) < 6 * predicted)
    # the saturated band draws on the short exposure alone, the dark band mostly on the long one
    assert np.all(fused.dominant[:, :30] == 0) and np.all(fused.used[:, :30] == 1)
    assert np.all(fused.dominant[:, 60:] == 2)
    # unit noise: the phase error over many pixels has the predicted spread (within 15 %)
    ratio = np.std(error / predicted)
    assert 0.85 < ratio < 1.15, ratio


def test_fusion_weights_follow_each_exposure_noise() -> None:
    """Two unsaturated exposures: inverse-variance fusion beats each alone by the predicted factor."""
    rng = np.random.default_rng(3)
    rows, cols = 80, 80
    phi = rng.uniform(-np.pi, np.pi, (rows, cols))
    noise = NoiseModel(read=4.0, shot=0.0)  # read noise only: weights t^2, the long exposure worth 4x
    times = [1.0, 2.0]
    stack = fringe_stack(np.full((rows, cols), 40.0), np.full((rows, cols), 30.0), phi, times, noise, rng)
    fused = fuse_exposures(stack, times, [list(range(STEPS))], noise, saturation=TOP)
    errors = {}
    for name, frames in (("short", stack[0]), ("long", stack[1]), ("fused", fused.frames)):
        phase = phase_shift(frames.astype(np.float64), shifts=SHIFTS).phase
        errors[name] = np.std(np.angle(np.exp(1j * (phase - phi))))
    # phase variance ∝ var / (t b)^2: short 4/900, long 4/3600; fused 1 / (900/4 + 3600/4)
    expected = {"short": np.sqrt(2 / STEPS * 4 / 30**2), "long": np.sqrt(2 / STEPS * 4 / 60**2)}
    expected["fused"] = np.sqrt(2 / STEPS / (30**2 / 4 + 60**2 / 4))
    for name, value in errors.items():
        assert value == pytest.approx(expected[name], rel=0.1), name
    assert np.all(fused.dominant == 1)


def test_pixels_saturated_at_every_exposure_have_no_modulation() -> None:
    stack = np.full((2, STEPS, 3, 3), 255, dtype=np.uint8)
    fused = fuse_exposures(stack, [1.0, 2.0], [list(range(STEPS))], NoiseModel(1.0, 0.0), saturation=TOP)
    assert np.all(fused.frames == 0) and np.all(fused.dominant == -1) and np.all(fused.used == 0)


def test_noise_model_is_estimated_from_the_frames() -> None:
    rng = np.random.default_rng(11)
    truth = NoiseModel(read=0.5, shot=0.05)
    phi = rng.uniform(-np.pi, np.pi, (120, 120))
    level = np.tile(np.linspace(5, 120, 120), (120, 1))
    stack = fringe_stack(level, 0.6 * level, phi, [1.0, 1.8], truth, rng)
    found = noise_model(stack, [list(range(STEPS))], [SHIFTS], TOP)
    assert found.shot == pytest.approx(truth.shot, rel=0.15)
    assert found.read == pytest.approx(truth.read + 1 / 12, abs=0.25)  # quantisation adds 1/12


def test_fusion_refuses_what_does_not_fit() -> None:
    stack = np.zeros((2, STEPS, 2, 2), dtype=np.uint8)
    with pytest.raises(ValueError, match="exposures_us"):
        fuse_exposures(stack, [1.0], [list(range(STEPS))], NoiseModel(1, 0))
    with pytest.raises(ValueError, match="groups"):
        fuse_exposures(stack, [1.0, 2.0], [[0, 1]], NoiseModel(1, 0))
    with pytest.raises(ValueError, match="stack"):
        fuse_exposures(stack[0], [1.0, 2.0], [list(range(STEPS))], NoiseModel(1, 0))


# --------------------------------------------------------------------------- the assistant


def reflectance(white: list[float], count: list[int]) -> Reflectance:
    """Populations of pixels with white rates (grey per us), black 0, full contrast, all lit."""
    rates = np.concatenate([np.full(n, w) for w, n in zip(white, count)])
    return Reflectance(rates, np.zeros_like(rates), np.ones_like(rates), np.ones(rates.size, dtype=bool))


def test_a_matte_scene_needs_one_exposure_the_configured_one() -> None:
    found = reflectance([0.015, 0.02], [500, 500])  # 150 .. 200 grey at 10 000 us
    chosen, coverage, reached = choose_exposures(found, ladder(10_000, (20, 1e6), 1e6), TOP, 10_000)
    assert chosen == (10_000.0,) and coverage == 1.0 and reached


def test_shiny_matte_and_dark_need_three_exposures_that_each_cover_their_part() -> None:
    found = reflectance([0.2, 0.02, 0.0005], [100, 700, 200])  # specular, matte, dark
    candidates = ladder(10_000, (20, 1e6), 1e6)
    chosen, coverage, reached = choose_exposures(found, candidates, TOP, 10_000)
    assert len(chosen) == 3 and reached and coverage >= TARGET_COVERAGE
    for rate in (0.2, 0.02, 0.0005):  # each population usable at one of the chosen exposures
        one = reflectance([rate], [1])
        assert any(usable(one, e, TOP)[0] for e in chosen), rate


def test_an_unreachable_range_is_said_not_guessed() -> None:
    found = reflectance([0.2, 0.02, 0.000001], [300, 400, 300])  # the dark third needs > the longest exposure
    chosen, coverage, reached = choose_exposures(found, ladder(10_000, (20, 50_000), 50_000), TOP, 10_000)
    assert not reached and len(chosen) <= MAX_EXPOSURES and coverage < TARGET_COVERAGE
    assert max(chosen) <= 50_000


def test_candidates_stay_inside_the_camera_limits() -> None:
    candidates = ladder(10_000, (500, 40_000), 1e6)
    assert min(candidates) == 500 and max(candidates) == 40_000
    with pytest.raises(CaptureError, match="no exposure"):
        ladder(10_000, (500, 40_000), 100)


# --------------------------------------------------------------------------- captures at several exposures


def test_capture_with_exposures_round_trips_and_old_captures_read_unchanged(tmp_path: Path) -> None:
    base = [{"kind": "sinusoid", "axis": "x", "frequency": 8, "steps": 3, "step": j} for j in range(3)]
    patterns = with_exposures(base, [2000, 8000])
    frames = np.zeros((6, 4, 5), dtype=np.uint8)
    write_capture(tmp_path / "hdr", frames, patterns, {"width": 64, "height": 48})
    write_capture(tmp_path / "old", frames[:3], base, {"width": 64, "height": 48})
    sets = exposure_sets(read_capture(tmp_path / "hdr").pattern_models)
    assert sets.exposures_us == (2000.0, 8000.0) and sets.indices == ((0, 1, 2), (3, 4, 5))
    assert [p.to_dict() for p in sets.base] == base
    manifest = json.loads((tmp_path / "hdr" / "capture.json").read_text())
    assert manifest["version"] == 1 and manifest["patterns"][3]["exposure_us"] == 8000
    old = exposure_sets(read_capture(tmp_path / "old").pattern_models)
    assert not old.multiple and len(old.base) == 3


@pytest.mark.parametrize(
    ("exposures", "message"),
    [
        ([2000, 8000, 2000, 8000, 2000, 8000], "each exposure's patterns together"),
        ([2000, 2000, 2000, 8000, 8000, None], "on every pattern"),
    ],
)
def test_exposures_out_of_structure_are_refused_in_one_line(tmp_path: Path, exposures, message: str) -> None:
    base = [{"kind": "sinusoid", "axis": "x", "frequency": 8, "steps": 3, "step": j % 3} for j in range(6)]
    write_capture(tmp_path / "bad", np.zeros((6, 4, 5), dtype=np.uint8), base, {"width": 64, "height": 48})
    manifest_path = tmp_path / "bad" / "capture.json"
    manifest = json.loads(manifest_path.read_text())  # another tool's capture.json: the writer refuses these
    manifest["patterns"] = [{**p, **({"exposure_us": e} if e else {})} for p, e in zip(base, exposures)]
    manifest_path.write_text(json.dumps(manifest))
    with pytest.raises(CaptureError, match=message):
        read_capture(tmp_path / "bad")


@pytest.fixture(scope="module")
def hdr_scan(tmp_path_factory):
    """The shiny-and-dark scene at 160 x 120 with the sensor model, at 1500, 10 000 and 80 000 us."""
    geometry = demo_geometry(160, 120)
    appearance = Appearance(ambient=0.1, gain=200.0, snr_db=None, sensor=Sensor())
    scan = simulate_scan(
        "shiny-and-dark", geometry=geometry, appearance=appearance, seed=5, exposures_us=[1500, 10_000, 80_000]
    )
    single = simulate_scan("shiny-and-dark", geometry=geometry, appearance=appearance, seed=5)
    root = tmp_path_factory.mktemp("hdr")
    return scan, write_simulated_scan(scan, root / "hdr"), single, write_simulated_scan(single, root / "single")


def test_an_hdr_capture_processes_with_a_single_exposure_reference(hdr_scan, tmp_path: Path) -> None:
    scan, paths, single, single_paths = hdr_scan
    on_object = (scan.height_mm > 0) & scan.lit
    report = api.process_to(paths.capture, tmp_path / "out", paths.calibration)
    assert report["files"]["exposure"] == EXPOSURE
    assert report["stage_info"]["object"]["exposures"]["exposures_us"] == [1500.0, 10000.0, 80000.0]
    exposure = np.load(tmp_path / "out" / EXPOSURE)
    mask = np.load(tmp_path / "out" / "mask.npy")
    assert np.all(np.isnan(exposure[~mask])) and set(np.unique(exposure[mask])) <= {1500.0, 10000.0, 80000.0}
    height = np.load(tmp_path / "out" / "height.npy")
    hdr_valid = (mask & on_object).sum() / on_object.sum()
    one = api.process(single_paths.capture, single_paths.calibration)
    one_valid = (one.mask & on_object).sum() / on_object.sum()
    assert hdr_valid >= 0.98 and one_valid < 0.9, (hdr_valid, one_valid)
    error = (height - scan.height_mm)[mask & on_object]
    assert np.sqrt(np.mean(error**2)) < 0.15  # mm; the shiny dome's highlight and the dark block included
    # the uncertainty follows from the fused frames' unit noise: predicted and actual errors agree within 2x
    sigma = np.load(tmp_path / "out" / "uncertainty.npy")[mask & on_object]
    assert 0.5 < np.sqrt(np.mean(error**2)) / np.sqrt(np.mean(sigma**2)) < 2.0


# --------------------------------------------------------------------------- configuration and CLI


def test_config_exposures() -> None:
    assert parse_config({"scan": {"exposures_us": [2000, 8000]}}).scan.exposures_us == (2000.0, 8000.0)
    with pytest.raises(ConfigError, match=r"\[scan\] exposures_us: expected distinct exposure times"):
        parse_config({"scan": {"exposures_us": [2000, 2000]}})
    with pytest.raises(ConfigError, match=r"\[scan\] exposures_us: expected a positive number"):
        parse_config({"scan": {"exposures_us": [2000, -1]}})


@pytest.mark.parametrize(
    ("argv", "fragments"),
    [
        (["--exposures", "2000,abc"], ("--exposures", "'2000,abc'", "microseconds")),
        (["--exposures", "0,8000"], ("--exposures", "positive", "'0,8000'")),
        (["--exposures", "2000,2000"], ("--exposures", "distinct")),
        (["--exposures", "2000", "--hdr", "auto"], ("--hdr auto and --exposures",)),
        (["--exposures", "10,2000000"], ("outside", "limits")),
    ],
)
def test_bad_exposures_are_one_line_and_exit_1(capsys, tmp_path: Path, argv: list[str], fragments) -> None:
    code, err = run(capsys, "scan", "-o", tmp_path / "capture", *argv)
    assert_one_line(code, err, *fragments)
    assert not (tmp_path / "capture").exists()


def test_scan_at_several_exposures_on_the_simulated_rig(capsys, tmp_path: Path, simulated_rig_toml) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(simulated_rig_toml((912, 1140), (96, 72), 35))
    code, _ = run(capsys, "scan", "--config", config, "-o", tmp_path / "capture", "--exposures", "2500,10000")
    assert code == 0
    manifest = json.loads((tmp_path / "capture" / "capture.json").read_text())
    frames = manifest["frames"]
    assert len(frames) == 2 * 12  # frequencies 1, 8, 32 x 4 steps at each exposure
    assert [f["exposure_us"] for f in frames] == [2500.0] * 12 + [10000.0] * 12  # what the camera reported
    assert [p["exposure_us"] for p in manifest["patterns"]] == [2500] * 12 + [10000] * 12


def test_hdr_auto_prints_what_it_chose_and_why(capsys, tmp_path: Path, simulated_rig_toml) -> None:
    config = tmp_path / "rig.toml"
    text = simulated_rig_toml((912, 1140), (96, 72), 35).replace('"hemisphere"', '"shiny-and-dark"')
    config.write_text(text + "full_well_e = 10000\n")
    code, err = run(capsys, "scan", "--config", config, "-o", tmp_path / "capture", "--hdr", "auto")
    assert code == 0
    lines = [line for line in err.splitlines() if line.startswith("exposure assistant:")]
    assert "predicted usable" in lines[0] and "alone" in lines[0]
    plan = json.loads((tmp_path / "capture" / "capture.json").read_text())["exposure_plan"]
    assert 1 <= len(plan["exposures_us"]) <= 3 and len(lines) == 1 + len(plan["exposures_us"])
    sets = exposure_sets(read_capture(tmp_path / "capture").pattern_models)
    assert list(sets.exposures_us if sets.multiple else plan["exposures_us"]) == plan["exposures_us"]


def test_import_describes_a_folder_of_several_exposures(capsys, tmp_path: Path, hdr_scan) -> None:
    import cv2

    scan, _, _, _ = hdr_scan
    folder = tmp_path / "images"
    folder.mkdir()
    for i, image in enumerate(scan.object_frames):
        cv2.imwrite(str(folder / f"{i}.png"), image)
    argv = ["import", folder, "--patterns", "sin:f=1/8/64,steps=4", "-o", tmp_path / "capture"]
    argv += ["--projector-width", 912, "--projector-height", 1140]
    code, err = run(capsys, *argv, "--exposures", "1500,10000,80000")
    assert code == 0 and "3 exposures (1500, 10000, 80000 us) of 12 patterns each" in err
    sets = exposure_sets(read_capture(tmp_path / "capture").pattern_models)
    assert sets.exposures_us == (1500.0, 10000.0, 80000.0)
    code, err = run(capsys, *argv[:-4], "-o", tmp_path / "other", "--exposures", "1500,10000")
    assert_one_line(code, err, "24 files at 2 exposures", "found 36 images")


def test_sensor_noise_grows_with_the_signal_and_clips_at_the_full_well() -> None:
    """Shot noise of variance S / (e- per grey) plus read noise; the top grey level is saturation."""
    sensor = Sensor(full_well_e=10_000.0, read_noise_e=8.0)
    per_dn = sensor.electrons_per_dn(8)
    rng = np.random.default_rng(2)
    for level in (5.0, 50.0, 200.0):
        noisy = sensor.add_noise(np.full(200_000, level, dtype=np.float64), 8, rng)
        assert np.var(noisy) == pytest.approx(level / per_dn + (8.0 / per_dn) ** 2, rel=0.03)
    from mock_devices.synth import Appearance as SynthAppearance
    from mock_devices.synth import ProjectorMap, expose

    lit = np.ones((4, 4), dtype=bool)
    mapping = ProjectorMap(u=np.zeros((4, 4)), v=np.zeros((4, 4)), lit=lit)
    bright = expose(np.ones((4, 4)), mapping, SynthAppearance(gain=400.0, sensor=sensor), rng)
    assert bright.dtype == np.uint8 and np.all(bright == 255)


def test_camera_exposure_limits_are_enforced(tmp_path: Path) -> None:
    from mock_devices.camera import SimulatedCamera
    from mock_devices.synth import RigGeometry

    geometry = RigGeometry(camera_width=32, camera_height=24)
    camera = SimulatedCamera(None, geometry, exposure_limits_us=(100.0, 50_000.0))
    with camera:
        assert camera.exposure_limits_us == (100.0, 50_000.0)
        camera.exposure_us = 40_000
        with pytest.raises(ValueError, match="100 .. 50000 us"):
            camera.exposure_us = 60_000
        assert camera.exposure_us == 40_000


def test_the_example_config_of_shiny_and_dark_parts_loads() -> None:
    from rig.config import load_config

    config = load_config(Path(__file__).resolve().parent.parent / "examples" / "shiny-and-dark.toml")
    assert config.simulation.scene == "shiny-and-dark" and config.simulation.full_well_e == 10_000
    assert config.scan.exposures_us == ()  # --hdr auto or --exposures choose them
