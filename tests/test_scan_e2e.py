"""`rig scan` end to end on the simulated rig: devices -> capture on disk -> height map of the scene.

The rig scans the flat reference plane, then the object, with the same patterns; the calibration
is the simulated rig's exact geometry (what ``rig calibrate`` would estimate). Processing must
give back the simulated scene's heights.
"""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from cli_steps import scan_and_process

from rig.cli import COMMAND_MODULES, main
from rig.config import load_config
from rig.hardware.simulated import geometry_from_config, scene_height
from rig.store.capture import read_capture

# pylon reads PYLON_CAMEMU when pypylon first loads (see tests/test_camera_pylon.py).
os.environ.setdefault("PYLON_CAMEMU", "1")


@pytest.fixture
def small_rig(simulated_rig_toml):
    """A 160x120 camera at 35 dB and a 228x285 projector: quick, and enough for three frequencies."""
    return simulated_rig_toml((228, 285), (160, 120), snr_db=35)


# Expected error from the camera noise alone: at 35 dB the noise is ~2.3 DN against a fringe
# amplitude of 100 DN, so 4-step phase has sigma ~0.016 rad per scan, 0.023 rad for object minus
# reference; at 32 fringes (0.0625 cycles/mm on the plane, d0 = 250 mm, l0 = 1000 mm) one radian
# is ~10 mm of height: rms ~0.24 mm. Tolerances leave room for quantisation and the steep rim.
RMS_ERROR_MM = 0.4
P99_ERROR_MM = 1.2
MEDIAN_ERROR_MM = 0.3
MIN_VALID_FRACTION = 0.95  # of the pixels the projector reaches in both scans


def test_scan_without_arguments_writes_a_complete_capture(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["scan"]) == 0
    (capture_dir,) = tmp_path.glob("capture-*")
    capture = read_capture(capture_dir)  # verifies every sha256
    assert capture.complete and capture.scene == "object"
    assert capture.shape == (768, 1024) and capture.projector_size == (912, 1140)
    assert len(capture.patterns) == len(capture.frames) == 12
    assert [f["trigger_index"] for f in capture.frames] == list(range(12))
    assert capture.manifest["simulation"]["scene"] == "hemisphere"
    image = capture.load_frame(0)
    assert image.dtype == np.uint8 and image.std() > 10  # fringes, not a blank frame


def test_scan_reference_then_object_processes_to_the_scene_heights(tmp_path, small_rig, exact_calibration):
    config_path = tmp_path / "rig.toml"
    config_path.write_text(small_rig)
    config = load_config(config_path)
    geometry = geometry_from_config(config)

    calibration = exact_calibration(config_path, tmp_path / "calibration")
    capture = tmp_path / "object"
    out = tmp_path / "processed"
    scan_and_process(config_path, capture, calibration, out)

    assert read_capture(capture).complete
    height = np.load(out / "height.npy")
    truth = scene_height(config, "object", geometry)
    assert height.shape == truth.shape
    from mock_devices.synth import projector_coordinates

    lit = projector_coordinates(truth, geometry).lit & projector_coordinates(np.zeros_like(truth), geometry).lit
    valid = np.isfinite(height) & lit
    assert valid.sum() >= MIN_VALID_FRACTION * lit.sum()
    error = np.abs(height[valid] - truth[valid])
    assert np.sqrt(np.mean(error**2)) < RMS_ERROR_MM
    assert np.percentile(error, 99) < P99_ERROR_MM
    assert truth.max() > 50  # the scene is not trivially flat
    report = json.loads((out / "report.json").read_text())
    assert report  # written by the processing step


@pytest.mark.skipif("process" not in COMMAND_MODULES, reason="`rig process` is not registered in rig/cli.py")
def test_rig_process_reads_what_rig_scan_wrote(tmp_path, small_rig, exact_calibration):
    config_path = tmp_path / "rig.toml"
    config_path.write_text(small_rig.replace('scene = "hemisphere"', 'scene = "steps"'))
    config = load_config(config_path)
    geometry = geometry_from_config(config)
    calibration = exact_calibration(config_path, tmp_path / "calibration")
    assert main(["scan", "--config", str(config_path), "-o", str(tmp_path / "object")]) == 0
    assert (
        main(["process", str(tmp_path / "object"), "--calibration", str(calibration), "-o", str(tmp_path / "out")]) == 0
    )
    height = np.load(tmp_path / "out" / "height.npy")
    truth = scene_height(config, "object", geometry)
    valid = np.isfinite(height)
    assert valid.mean() > MIN_VALID_FRACTION * 0.9  # the staircase's risers cast shadows
    assert np.median(np.abs(height[valid] - truth[valid])) < MEDIAN_ERROR_MM


def test_missing_calibration_stops_before_scanning(tmp_path, capsys):
    args = ["scan", "-o", str(tmp_path / "c"), "--calibration", str(tmp_path / "nope"), "--process"]
    assert main(args) == 1
    err = capsys.readouterr().err.strip()
    assert err.startswith("rig scan: error: ") and "nope" in err and "\n" not in err
    assert not list(tmp_path.glob("c*"))  # nothing scanned


def test_bad_config_is_one_line_and_exit_1(tmp_path, capsys):
    config_path = tmp_path / "rig.toml"
    config_path.write_text("[camera]\nexposure_us = 0\n")
    assert main(["scan", "--config", str(config_path), "-o", str(tmp_path / "c")]) == 1
    err = capsys.readouterr().err.strip()
    assert err == f"rig scan: error: {config_path}: [camera] exposure_us: expected a positive number, found 0"
    assert not (tmp_path / "c").exists()


PYLON_RIG = """
[projector]
backend = "gl-offscreen"
size = [96, 120]
[camera]
backend = "pylon"             # no serial: the first camera, pylon's emulator here
size = [64, 48]
exposure_us = 2000
[trigger]
backend = "software"
[scan]
frequencies = [1]
steps = 3
fetch_timeout_s = 5.0
"""


def test_scan_with_a_real_backend_pylon_emulator(tmp_path):
    """The real-device path of `rig scan`: pylon driver (against pylon's emulator), GL projector, software trigger.

    The emulator has no trigger counter, so frames are matched to triggers by frame id.
    """
    pylon = pytest.importorskip("pypylon.pylon", reason="pypylon is not installed (optional extra 'pylon')")
    devices = pylon.TlFactory.GetInstance().EnumerateDevices()
    if not any(d.GetDeviceClass() == "BaslerCamEmu" for d in devices) or len(devices) != sum(
        d.GetDeviceClass() == "BaslerCamEmu" for d in devices
    ):
        pytest.skip("needs pylon's camera emulator as the only camera (PYLON_CAMEMU set before pypylon loads)")
    config_path = tmp_path / "rig.toml"
    config_path.write_text(PYLON_RIG)
    assert main(["scan", "--config", str(config_path), "-o", str(tmp_path / "capture")]) == 0
    capture = read_capture(tmp_path / "capture")
    assert capture.shape == (48, 64) and capture.projector_size == (96, 120)
    assert [f["frame_id"] for f in capture.frames] == [0, 1, 2]
    assert all(f["exposure_us"] == pytest.approx(2000, rel=0.05) for f in capture.frames)
    assert capture.manifest["devices"]["camera"] != "simulated camera"


def test_gamma_lut_from_the_config_linearises_the_projector(tmp_path, small_rig):
    """A projector with gamma 2.2, pre-corrected by the LUT the config names, behaves like a linear one."""
    np.save(tmp_path / "lut.npy", np.linspace(0.0, 1.0, 256) ** (1 / 2.2))
    linear = small_rig.replace("snr_db = 35", 'snr_db = "none"').replace(
        "frequencies = [1, 8, 32]", "frequencies = [8]"
    )
    rigs = {  # [simulation] is the last table: appended keys land there
        "linear": linear,
        "gamma": linear + "gamma = 2.2\n",
        "corrected": linear.replace("size = [228, 285]\n", 'size = [228, 285]\ngamma_lut = "lut.npy"\n', 1)
        + "gamma = 2.2\n",
    }
    frames = {}
    for name, text in rigs.items():
        (tmp_path / f"{name}.toml").write_text(text)
        assert (
            main(
                ["scan", "--config", str(tmp_path / f"{name}.toml"), "--scene", "reference", "-o", str(tmp_path / name)]
            )
            == 0
        )
        frames[name] = read_capture(tmp_path / name).load_frames().astype(float)
    assert np.abs(frames["corrected"] - frames["linear"]).mean() < 1.5  # DN: 8-bit framebuffer and camera
    assert np.abs(frames["gamma"] - frames["linear"]).mean() > 10
