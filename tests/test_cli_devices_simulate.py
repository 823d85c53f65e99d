"""`rig devices` and `rig simulate`: what they print and write, and one-line errors."""

from __future__ import annotations

import json

import numpy as np
import pytest

from calibration.store import read_calibration
from mock_devices.dlp_usb import FakeDlpc350Backend
from mock_devices.scenes import make_scene
from rig.cli import main
from rig.hardware.probes import format_probe, probe_dlp
from rig.store.capture import read_capture


def test_devices_lists_every_family_and_the_simulated_rig(capsys):
    assert main(["devices", "--no-opencv"]) == 0
    out = capsys.readouterr().out
    for title in (
        "Basler (pylon) cameras",
        "Serial ports (trigger box)",
        "DLP projectors (USB)",
        "Off-screen rendering",
        "Simulated rig",
    ):
        assert title in out
    assert "simulated-serial" in out and "gl-offscreen" in out


def test_devices_finds_a_lightcrafter_on_usb():
    probe = probe_dlp(backend=FakeDlpc350Backend())
    assert [(f.backend, f.address) for f in probe.found] == [("dlp4500", "bus 1 address 7")]
    assert "DLP LightCrafter 4500 (0451:6401)" in format_probe(probe)


def test_simulate_writes_capture_calibration_and_truth(tmp_path):
    out = tmp_path / "sim"
    args = [
        "simulate",
        "-o",
        str(out),
        "--size",
        "96x72",
        "--scene",
        "steps",
        "--frequencies",
        "1",
        "8",
        "--steps",
        "4",
        "--snr-db",
        "none",
    ]
    assert main(args) == 0
    capture = read_capture(out / "object")
    reference = read_capture(out / "calibration" / "reference")
    assert capture.shape == reference.shape == (72, 96)
    assert [(p["frequency"], p["step"]) for p in capture.patterns] == [(f, j) for f in (1, 8) for j in range(4)]
    assert reference.scene == "reference"
    calibration = read_calibration(out / "calibration")
    assert calibration.pixel_mm == pytest.approx(409.6 / 96)
    truth = np.load(out / "truth-height.npy")
    np.testing.assert_allclose(truth, make_scene("steps", 72, 96, 409.6 / 96), atol=1e-4)
    # noiseless: the object differs from the reference exactly where the scene is raised
    differs = np.any(capture.load_frames() != reference.load_frames(), axis=0)
    assert differs[truth > 0].mean() > 0.9 and differs[truth == 0].mean() < 0.05


def test_simulate_takes_patterns_from_a_json_file(tmp_path):
    patterns = [{"kind": "gray", "axis": "x", "bit": b, "bits": 3} for b in range(3)]
    (tmp_path / "patterns.json").write_text(json.dumps(patterns))
    out = tmp_path / "sim"
    assert main(["simulate", "-o", str(out), "--size", "64x48", "--patterns", str(tmp_path / "patterns.json")]) == 0
    assert [p["bit"] for p in read_capture(out / "object").patterns] == [0, 1, 2]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--steps", "2"], "command line: [scan] steps: expected an integer 3..64, found 2"),
        (["--snr-db", "loud"], "--snr-db: expected a number in dB or 'none', found 'loud'"),
        (["--scene", "teapot"], "rig config: [simulation] scene: expected one of flat, sphere-cap"),
        (["--patterns", "missing.json"], "missing.json: patterns file not found"),
    ],
)
def test_simulate_bad_values_are_one_line(tmp_path, capsys, args, message):
    assert main(["simulate", "-o", str(tmp_path / "sim"), "--size", "64x48", *args]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("rig simulate: error: ") and message in err
    assert not (tmp_path / "sim").exists()
