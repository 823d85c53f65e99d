"""The rig config file: defaults, the shipped examples, and one clear line for every bad field."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

from rig.config import RigConfig, load_config
from rig.errors import ConfigError
from rig.hardware.simulated import geometry_from_config, scene_height

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "rig.toml"
    path.write_text(text)
    return path


def test_no_file_is_the_simulated_rig():
    config = load_config(None)
    assert config.simulated
    assert (config.projector.backend, config.camera.backend, config.trigger.backend) == (
        "gl-offscreen",
        "simulated",
        "simulated-serial",
    )
    assert len(config.scan.patterns()) == 12


def test_simulated_example_spells_out_the_defaults():
    config = load_config(EXAMPLES / "simulated-rig.toml")
    assert dataclasses.replace(config, source=None) == RigConfig()


def test_lab_example_names_real_backends():
    config = load_config(EXAMPLES / "rig.toml")
    assert (config.projector.backend, config.camera.backend, config.trigger.backend) == ("dlp4500", "pylon", "serial")
    assert config.camera.serial == "40012345"
    assert config.trigger.port == "/dev/ttyACM0"


def test_values_are_read(tmp_path):
    config = load_config(
        write(
            tmp_path,
            """
            [projector]
            size = [320, 240]
            [camera]
            size = [128, 96]
            exposure_us = 500
            [scan]
            frequencies = [1, 4, 16]
            steps = 4
            axis = "y"
            gray_bits = 3
            retries = 0
            [simulation]
            snr_db = "none"
            scene = "steps"
            """,
        )
    )
    assert config.projector.size == (320, 240)
    assert (config.camera.width, config.camera.height, config.camera.exposure_us) == (128, 96, 500.0)
    assert config.simulation.snr_db is None
    assert config.pixel_mm() == pytest.approx(409.6 / 128)
    patterns = config.scan.patterns()
    assert len(patterns) == 3 * 4 + 3 * 2
    assert patterns[4] == {"kind": "sinusoid", "axis": "y", "frequency": 4, "steps": 4, "step": 0}
    assert patterns[-1] == {"kind": "gray", "axis": "y", "bit": 2, "bits": 3, "inverted": True}


def test_a_real_camera_defaults_to_its_software_trigger(tmp_path):
    config = load_config(write(tmp_path, '[camera]\nbackend = "opencv"\nindex = 1\n'))
    assert (config.camera.backend, config.camera.index, config.trigger.backend) == ("opencv", 1, "software")


def test_gamma_lut_resolves_against_the_config_folder(tmp_path):
    (tmp_path / "lut.npy").write_bytes(b"")
    config = load_config(write(tmp_path, '[projector]\ngamma_lut = "lut.npy"\n'))
    assert config.projector.gamma_lut == tmp_path / "lut.npy"


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ('[camera]\nexposure_us = "fast"\n', "[camera] exposure_us: expected a positive number, found 'fast'"),
        ("[camera]\nexposure_us = -5\n", "[camera] exposure_us: expected a positive number, found -5"),
        (
            '[camera]\nbackend = "usb"\n',
            "[camera] backend: expected one of 'simulated', 'opencv', 'pylon', found 'usb'",
        ),
        ("[camera]\nexposur_us = 5\n", "[camera] exposur_us: unknown key; expected one of backend, exposure_us"),
        ("[projector]\nsize = [912]\n", "[projector] size: expected [width, height] in pixels"),
        ("[projector]\nsize = [0, 10]\n", "[projector] size: expected [width, height] in pixels"),
        ('[projector]\ngamma_lut = "missing.npy"\n', "[projector] gamma_lut: expected an existing file"),
        ('[trigger]\nbackend = "serial"\n', "[trigger] port: expected a serial port or pyserial URL"),
        (
            '[trigger]\nbackend = "serial"\nport = "/dev/ttyACM0"\n',
            "[trigger] backend: expected 'simulated-serial' or 'software' with the simulated camera",
        ),
        ("[trigger]\nbaudrate = 0\n", "[trigger] baudrate: expected an integer 1..12000000, found 0"),
        ("[scan]\nsteps = 2\n", "[scan] steps: expected an integer 3..64, found 2"),
        ("[scan]\nsteps = 6.0\n", "[scan] steps: expected an integer 3..64, found 6.0"),
        (
            "[scan]\nfrequencies = []\n",
            "[scan] frequencies: expected a non-empty list of positive numbers up to 16384, found []",
        ),
        ("[scan]\nfrequencies = [8, 8]\n", "[scan] frequencies: expected distinct frequencies"),
        ("[scan]\nretries = true\n", "[scan] retries: expected an integer 0..20, found True"),
        ('[scan]\naxis = "z"\n', "[scan] axis: expected one of 'x', 'y', found 'z'"),
        ("[scan]\nfetch_timeout_s = inf\n", "[scan] fetch_timeout_s: expected a positive number, found inf"),
        ("[simulation]\nd0_mm = 0\n", "[simulation] d0_mm: expected a non-zero number, found 0"),
        ('[simulation]\nsnr_db = "loud"\n', "[simulation] snr_db: expected a number in dB or \"none\", found 'loud'"),
        ('[projector]\nbackend = "window"\n', "[projector] backend: expected 'gl-offscreen' with the simulated camera"),
        (
            '[camera]\nbackend = "opencv"\n[trigger]\nbackend = "simulated-serial"\n',
            "[trigger] backend: expected 'software' or 'serial' with camera backend 'opencv'",
        ),
        ("[cameras]\nindex = 0\n", "[cameras]: unknown section; expected one of projector, camera"),
        ("camera = 3\n", "[camera]: expected a table, found 3"),
        ("[camera\n", "not valid TOML"),
    ],
)
def test_bad_field_is_one_clear_line(tmp_path, text, expected):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(str(path))
    assert expected in message


def test_unknown_scene_is_refused_by_the_simulated_rig_in_one_line(tmp_path):
    """The scenes are the simulation's (rig.hardware): the config names one, the simulated rig checks it."""
    path = write(tmp_path, '[simulation]\nscene = "teapot"\n')
    config = load_config(path)
    with pytest.raises(ConfigError) as info:
        scene_height(config, "object", geometry_from_config(config))
    message = str(info.value)
    assert "\n" not in message and message.startswith(f"{path}: [simulation] scene: expected one of flat, sphere-cap")


def test_missing_file_is_named(tmp_path):
    with pytest.raises(ConfigError, match="nope.toml: rig config file not found"):
        load_config(tmp_path / "nope.toml")


def test_directory_instead_of_file(tmp_path):
    with pytest.raises(ConfigError, match="expected a rig config file, found a directory"):
        load_config(tmp_path)


@pytest.mark.parametrize(
    ("content", "expected"),
    [
        ("0.0\n0.5\n2.0\n", "gamma LUT: expected at least 2 drive levels in [0, 1], found 3 values in [0.0, 2.0]"),
        ("0.5\n", "gamma LUT: expected at least 2 drive levels in [0, 1], found 1 values"),
        ("zero\none\n", "cannot read the gamma LUT ([projector] gamma_lut)"),
    ],
)
def test_bad_gamma_lut_file_is_one_line(tmp_path, content, expected):
    from rig.hardware.assembly import load_gamma_lut

    (tmp_path / "lut.txt").write_text(content)
    config = load_config(write(tmp_path, '[projector]\ngamma_lut = "lut.txt"\n'))
    with pytest.raises(ConfigError) as info:
        load_gamma_lut(config)
    assert str(info.value).startswith(str(tmp_path / "lut.txt")) and expected in str(info.value)
    assert "\n" not in str(info.value)
