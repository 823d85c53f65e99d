"""The speckle single shot (thesis ch. 2.3) through the product: config, `rig simulate`, `rig scan`, `rig process`.

Scenes are the simulated rig's hemisphere (about 100 mm high) on a 256 x 192 camera (1.6 mm per
pixel on the plane), one `speckle-sinusoid` frame of 16 fringes, 35 dB camera noise, the exact
calibration of the simulated rig. Measured on this set-up (noise seeds 0-2 of `rig simulate`,
and `rig scan`): 98 % of the pixels valid, median height error 0.09-0.14 mm, 81-82 % of the valid
pixels within 1 mm, 4 % off by more than 5 mm; those lie on and within ~6 pixels of the
hemisphere's rim, where the band-limited FTP phase smears the edge. Here one radian of phase is
~20 mm of height (16 fringes, d0 250 mm, l0 1000 mm) and no pixel had a wrong fringe order (none
off by half an order, ~64 mm), so the tolerances below bound the phase error of the product path.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from cli_steps import scan_and_process

from mock_devices import synth
from rig.cli import main
from rig.config import load_config, parse_config
from rig.errors import ConfigError
from rig.hardware.simulated import appearance_from_config, geometry_from_config, scene_height
from rig.store.capture import read_capture, validate_pattern

MEDIAN_ERROR_MM = 0.25
WITHIN_1MM = 0.75  # share of valid pixels within 1 mm of the truth
ORDER_SLIPS = 0.07  # share of valid pixels off by more than 5 mm
MIN_VALID = 0.9  # share of the pixels the projector reaches in both scenes

SPECKLE_RIG = """
[camera]
size = [256, 192]
[scan]
pattern_set = "speckle"
speckle_seed = 7
[simulation]
scene = "hemisphere"
snr_db = 35
"""


def _height_errors(height: np.ndarray, truth: np.ndarray, lit: np.ndarray) -> tuple[float, np.ndarray]:
    valid = np.isfinite(height) & lit
    return valid.sum() / lit.sum(), np.abs(height[valid] - truth[valid])


def _assert_heights(height: np.ndarray, truth: np.ndarray, lit: np.ndarray) -> None:
    valid_share, error = _height_errors(height, truth, lit)
    assert valid_share > MIN_VALID
    assert np.median(error) < MEDIAN_ERROR_MM
    assert np.mean(error < 1.0) > WITHIN_1MM
    assert np.mean(error > 5.0) < ORDER_SLIPS
    assert truth.max() > 50  # not trivially flat


def _assert_single_shot_info(info: dict, role: str) -> None:
    single = info["single_shot"]
    assert single["role"] == role
    assert "single shot" in single["method"]
    assert single["parameters"]["frequency"] == 16
    assert single["iterations"] >= 1 and single["rank"] >= 1
    assert single["seconds"] > 0


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    root = tmp_path_factory.mktemp("speckle") / "sim"
    assert (
        main(["simulate", "-o", str(root), "--pattern-set", "speckle", "--size", "256x192", "--scene", "hemisphere"])
        == 0
    )
    return root


def test_simulated_speckle_capture_is_processed_single_shot(simulated, tmp_path):
    capture = read_capture(simulated / "object")
    assert [p["kind"] for p in capture.patterns] == ["speckle-sinusoid"]
    assert read_capture(simulated / "calibration" / "reference").patterns == capture.patterns
    out = tmp_path / "out"
    assert (
        main(["process", str(simulated / "object"), "--calibration", str(simulated / "calibration"), "-o", str(out)])
        == 0
    )

    truth = np.load(simulated / "truth-height.npy")
    config = parse_config({"camera": {"size": [256, 192]}})
    geometry = geometry_from_config(config)
    lit = synth.projector_coordinates(truth.astype(np.float64), geometry).lit
    lit &= synth.projector_coordinates(np.zeros_like(truth, dtype=np.float64), geometry).lit
    _assert_heights(np.load(out / "height.npy"), truth, lit)

    report = json.loads((out / "report.json").read_text())
    assert report["methods"]["unwrap"] == "single-shot"
    assert report["methods"]["wrapped_phase"] == "single-shot"
    _assert_single_shot_info(report["stage_info"]["object"], "object")
    _assert_single_shot_info(report["stage_info"]["reference"], "reference")
    assert report["stage_info"]["object"]["single_shot"]["parameters"]["patch"] == 27
    assert set(report["stage_info"]["object"]["single_shot"]["timings_s"]) >= {"rpca", "ftp", "correlation", "voting"}


def test_single_shot_parameters_come_from_param(simulated, tmp_path):
    out = tmp_path / "out"
    assert (
        main(
            [
                "process",
                str(simulated / "object"),
                "--calibration",
                str(simulated / "calibration"),
                "-o",
                str(out),
                "--param",
                "patch=21",
                "--param",
                "vote=false",
                "--correction",
                "none",
            ]
        )
        == 0
    )
    info = json.loads((out / "report.json").read_text())["stage_info"]
    for role in ("object", "reference"):
        assert info[role]["single_shot"]["parameters"]["patch"] == 21
        assert info[role]["single_shot"]["parameters"]["vote"] is False


def test_single_shot_without_calibration_is_one_line(simulated, tmp_path, capsys):
    code = main(["process", str(simulated / "object"), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == 1
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("process ")]
    assert len(lines) == 1 and "Traceback" not in err
    assert "speckle-sinusoid" in lines[0] and "--calibration" in lines[0]


def test_denoising_a_single_shot_is_refused(simulated, tmp_path, capsys):
    code = main(
        [
            "process",
            str(simulated / "object"),
            "--calibration",
            str(simulated / "calibration"),
            "-o",
            str(tmp_path / "out"),
            "--denoise",
            "rpca",
        ]
    )
    err = capsys.readouterr().err
    assert code == 1 and "Traceback" not in err
    assert "--denoise rpca: not for a speckle-sinusoid (single-shot) capture" in err


def test_config_speckle_pattern_set():
    config = parse_config(
        {
            "scan": {
                "pattern_set": "speckle",
                "speckle_frequency": 12,
                "speckle_seed": 3,
                "speckle_dot_px": 2,
                "speckle_gain": 0.25,
                "axis": "y",
            }
        }
    )
    (pattern,) = config.scan.patterns()
    validate_pattern("config", 0, pattern)
    assert pattern == {
        "kind": "speckle-sinusoid",
        "axis": "y",
        "frequency": 12,
        "steps": 1,
        "step": 0,
        "seed": 3,
        "dot_px": 2,
        "speckle_gain": 0.25,
    }
    assert parse_config({}).scan.patterns()[0]["kind"] == "sinusoid"
    with pytest.raises(ConfigError, match=r"\[scan\] pattern_set: expected one of"):
        parse_config({"scan": {"pattern_set": "single"}})
    with pytest.raises(ConfigError, match=r"\[scan\] speckle_gain: expected a number in \[0, 1\], found 1.5"):
        parse_config({"scan": {"speckle_gain": 1.5}})


def test_rig_scan_projects_the_speckle_pattern(tmp_path):
    # Noiseless, so that the rendered frame can be compared with processing.projection.patterns' definition.
    config_path = tmp_path / "rig.toml"
    config_path.write_text(SPECKLE_RIG.replace("snr_db = 35", 'snr_db = "none"'))
    config = load_config(config_path)
    assert main(["scan", "--config", str(config_path), "--scene", "reference", "-o", str(tmp_path / "ref")]) == 0
    capture = read_capture(tmp_path / "ref")
    assert capture.complete and len(capture.frames) == 1
    (pattern,) = capture.patterns
    assert pattern == {
        "kind": "speckle-sinusoid",
        "axis": "x",
        "frequency": 16,
        "steps": 1,
        "step": 0,
        "seed": 7,
        "dot_px": 3,
        "speckle_gain": 0.3,
    }
    geometry = geometry_from_config(config)
    mapping = synth.projector_coordinates(np.zeros((geometry.camera_height, geometry.camera_width)), geometry)
    expected = synth.render_frame(pattern, mapping, geometry, appearance_from_config(config), np.random.default_rng(0))
    frame = capture.load_frame(0).astype(np.float64)
    diff = np.abs(frame - expected)
    assert frame.std() > 20  # fringes and speckle, not a blank frame
    assert np.median(diff) <= 1.0
    assert np.mean(diff <= 2.0) > 0.8
    # The GL rasteriser and numpy's floor disagree only on which dot a pixel sampled right at a dot
    # edge belongs to: every larger difference lies within half a projector pixel of one.
    dot = pattern["dot_px"]
    edge_u = np.abs(mapping.u / dot - np.round(mapping.u / dot)) * dot < 0.5
    edge_v = np.abs(mapping.v / dot - np.round(mapping.v / dot)) * dot < 0.5
    assert np.all((edge_u | edge_v)[diff > 2.0])


def test_rig_scan_speckle_then_process(tmp_path, exact_calibration):
    config_path = tmp_path / "rig.toml"
    config_path.write_text(SPECKLE_RIG)
    config = load_config(config_path)
    geometry = geometry_from_config(config)
    calibration = exact_calibration(config_path, tmp_path / "calibration")
    out = tmp_path / "processed"
    scan_and_process(config_path, tmp_path / "object", calibration, out)
    truth = scene_height(config, "object", geometry)
    lit = (
        synth.projector_coordinates(truth, geometry).lit
        & synth.projector_coordinates(np.zeros_like(truth), geometry).lit
    )
    _assert_heights(np.load(out / "height.npy"), truth, lit)
    report = json.loads((out / "report.json").read_text())
    _assert_single_shot_info(report["stage_info"]["object"], "object")


def test_calibrate_then_scan_the_speckle_reference_then_single_shots(tmp_path):
    # The user path: rig calibrate with phase shifting (l0, d0, f0 are fitted from absolute
    # phases), then the reference plane again under the speckle pattern into the calibration's
    # reference capture; single shots are then processed against it with the fitted geometry.
    speckle = tmp_path / "speckle.toml"
    speckle.write_text(SPECKLE_RIG)
    shifting = tmp_path / "shifting.toml"
    shifting.write_text(SPECKLE_RIG.replace('pattern_set = "speckle"', "frequencies = [1, 8, 32]"))
    calibration = tmp_path / "calibration"
    assert main(["calibrate", "--config", str(shifting), "-o", str(calibration), "-q"]) == 0
    assert (
        main(
            [
                "scan",
                "--config",
                str(speckle),
                "--scene",
                "reference",
                "-o",
                str(calibration / "reference"),
                "--overwrite",
            ]
        )
        == 0
    )
    out = tmp_path / "processed"
    scan_and_process(speckle, tmp_path / "object", calibration, out)
    config = load_config(speckle)
    geometry = geometry_from_config(config)
    truth = scene_height(config, "object", geometry)
    lit = (
        synth.projector_coordinates(truth, geometry).lit
        & synth.projector_coordinates(np.zeros_like(truth), geometry).lit
    )
    _assert_heights(np.load(out / "height.npy"), truth, lit)
