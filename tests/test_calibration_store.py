"""calibration.json: round trip, extra keys kept, other models carried, one clear error per bad field."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from calibration.errors import CalibrationError
from calibration.store import Calibration, read_calibration, write_calibration

GOOD = {
    "format": "fpp-calibration",
    "version": 1,
    "model": "reference-plane",
    "l0_mm": 1000.0,
    "d0_mm": -250.0,
    "f0_per_mm": 0.0125,
    "f0_frequency": 8,
    "pixel_mm": 0.45,
    "reference": "reference",
    "created_utc": "2026-11-22T10:00:00Z",
}


def _write(tmp_path: Path, data: dict) -> Path:
    directory = tmp_path / "cal"
    directory.mkdir(exist_ok=True)
    (directory / "calibration.json").write_text(json.dumps(data))
    return directory


def test_reads_the_documented_example(tmp_path: Path) -> None:
    cal = read_calibration(_write(tmp_path, GOOD))
    assert (cal.model, cal.l0_mm, cal.d0_mm, cal.pixel_mm) == ("reference-plane", 1000.0, -250.0, 0.45)
    assert cal.reference_path == tmp_path / "cal" / "reference"
    assert cal.per_mm(16) == pytest.approx(0.025)  # frequencies scale linearly from f0_frequency


def test_round_trip_keeps_extra_keys(tmp_path: Path) -> None:
    data = dict(GOOD, camera_matrix=[[1000, 0, 320], [0, 1000, 240], [0, 0, 1]], residuals_mm=[0.01, 0.02], tool="x")
    cal = read_calibration(_write(tmp_path, data))
    cal.l0_mm = 990.0
    written = write_calibration(tmp_path / "out", cal)
    again = json.loads(written.read_text())
    assert again == dict(data, l0_mm=990.0)
    assert read_calibration(tmp_path / "out" / "calibration.json").extra["tool"] == "x"


def test_write_fills_created_time_and_creates_the_directory(tmp_path: Path) -> None:
    cal = Calibration(l0_mm=800, d0_mm=100, f0_per_mm=0.02, f0_frequency=10, pixel_mm=0.3, reference="ref")
    path = write_calibration(tmp_path / "new" / "cal", cal)
    data = json.loads(path.read_text())
    assert data["created_utc"].endswith("Z") and data["format"] == "fpp-calibration" and data["version"] == 1
    assert cal.path == tmp_path / "new" / "cal"


def test_other_models_are_carried_with_their_keys(tmp_path: Path) -> None:
    data = {
        "format": "fpp-calibration",
        "version": 1,
        "model": "polynomial",
        "coefficients": [[1, 2], [3, 4]],
        "order": 3,
    }
    cal = read_calibration(_write(tmp_path, data))
    assert cal.model == "polynomial" and cal.extra == {"coefficients": [[1, 2], [3, 4]], "order": 3}
    write_calibration(tmp_path / "copy", cal)
    assert json.loads((tmp_path / "copy" / "calibration.json").read_text()) == dict(data, created_utc=cal.created_utc)


@pytest.mark.parametrize(
    "change,message",
    [
        ({"format": "calib"}, r"format: expected 'fpp-calibration', found 'calib'"),
        ({"version": 3}, r"version: expected 1 .*found 3"),
        ({"model": ""}, r"model: expected a model name"),
        ({"l0_mm": -1}, r"l0_mm: expected a positive finite number, found -1"),
        ({"d0_mm": 0}, r"d0_mm: expected a non-zero finite number, found 0"),
        ({"f0_per_mm": "0.1"}, r"f0_per_mm: expected a positive finite number, found '0.1'"),
        ({"pixel_mm": None}, r"pixel_mm: expected a positive finite number, found None"),
        ({"reference": None}, r"reference: expected the path of the reference-plane capture"),
    ],
)
def test_bad_fields_are_named(tmp_path: Path, change: dict, message: str) -> None:
    data = {k: v for k, v in dict(GOOD, **change).items() if v is not None}
    with pytest.raises(CalibrationError, match=r"cal/calibration.json: " + message):
        read_calibration(_write(tmp_path, data))


def test_missing_and_malformed_files(tmp_path: Path) -> None:
    with pytest.raises(CalibrationError, match=r"nowhere/calibration.json: missing"):
        read_calibration(tmp_path / "nowhere")
    directory = _write(tmp_path, GOOD)
    (directory / "calibration.json").write_text("{not json")
    with pytest.raises(CalibrationError, match=r"not valid JSON"):
        read_calibration(directory)
