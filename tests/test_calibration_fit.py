"""A calibration that does not fit the capture is refused with one line: field, values, likely cause, fix.

Simulated captures (the conftest scan) with their calibration edited the way real mistakes edit
it, a stereo calibration for a small imported capture, and the real eye of ``../shared/real-data``
imported without ``--projector-width`` (skipped cleanly when that folder is absent).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
from realdata import import_eye, import_eye_calibration, needs_real_data

from rig.cli import main


def _one_line_error(capsys, *argv: object) -> str:
    code = main([str(a) for a in argv])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("process ")]
    assert code == 1, err
    assert len(lines) == 1 and "Traceback" not in err, err
    return lines[0]


def _edit(path: Path, **changes: object) -> None:
    data = json.loads(path.read_text())
    data.update(changes)
    path.write_text(json.dumps(data))


def test_fringe_axis_other_than_the_calibrations_is_refused(capsys, small_capture, tmp_path) -> None:
    _edit(small_capture.calibration / "calibration.json", fringe_axis="y")
    line = _one_line_error(
        capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", tmp_path / "out"
    )
    assert "fringe axis: x does not fit" in line and "fringe_axis y" in line and "--axis y" in line
    assert not (tmp_path / "out").exists()


def test_distances_in_metres_are_refused(capsys, small_capture, tmp_path) -> None:
    _edit(small_capture.calibration / "calibration.json", l0_mm=1.0)
    line = _one_line_error(
        capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", tmp_path / "out"
    )
    assert "l0_mm: 1 mm is implausibly short" in line and "metres" in line and "(1000)" in line


def test_reference_with_other_frequencies_names_the_cause(capsys, small_capture, tmp_path) -> None:
    manifest = small_capture.calibration / "reference" / "capture.json"
    data = json.loads(manifest.read_text())
    for pattern in data["patterns"]:
        if pattern.get("frequency") == 64:
            pattern["frequency"] = 32
    manifest.write_text(json.dumps(data))
    line = _one_line_error(
        capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", tmp_path / "out"
    )
    assert "the reference capture does not fit this capture" in line and "likely cause" in line and "fix:" in line


def _fringe_capture(tmp_path: Path, projector_width: int | None) -> Path:
    folder = tmp_path / "images"
    folder.mkdir()
    x = np.arange(64)
    for k in range(4):
        row = 120 + 100 * np.cos(2 * np.pi * 4 * x / 64 + 2 * np.pi * k / 4)
        cv2.imwrite(str(folder / f"{k}.png"), np.rint(np.tile(row, (48, 1))).astype(np.uint8))
    out = tmp_path / "capture"
    extra = [] if projector_width is None else ["--projector-width", str(projector_width)]
    assert main(["import", str(folder), "--patterns", "sin:f=4,steps=4", "-o", str(out), *extra]) == 0
    return out


def _stereo_calibration(tmp_path: Path, projector: tuple[int, int], translation: list[float]) -> Path:
    cal = tmp_path / "cal"
    cal.mkdir()
    fields = {
        "format": "fpp-calibration",
        "version": 1,
        "model": "stereo",
        "camera_matrix": [[100, 0, 32], [0, 100, 24], [0, 0, 1]],
        "distortion": [],
        "projector_matrix": [[150, 0, projector[0] / 2], [0, 150, projector[1] / 2], [0, 0, 1]],
        "projector_distortion": [],
        "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        "translation_mm": translation,
        "camera_size": [64, 48],
        "projector_size": list(projector),
    }
    (cal / "calibration.json").write_text(json.dumps(fields))
    return cal


def test_stereo_projector_width_mismatch_says_which_import_option_fixes_it(capsys, tmp_path) -> None:
    capture = _fringe_capture(tmp_path, projector_width=None)  # the importer's default: the image width, 64
    capsys.readouterr()
    cal = _stereo_calibration(tmp_path, (128, 48), [-100.0, 0.0, 0.0])
    line = _one_line_error(capsys, "process", capture, "--calibration", cal, "-o", tmp_path / "out")
    assert "projector width: 64 px does not fit" in line and "projector_size 128x48" in line
    assert "re-import it with --projector-width 128" in line


def test_stereo_translation_in_metres_is_refused(capsys, tmp_path) -> None:
    capture = _fringe_capture(tmp_path, projector_width=64)
    capsys.readouterr()
    cal = _stereo_calibration(tmp_path, (64, 48), [-0.1, 0.0, 0.0])
    line = _one_line_error(capsys, "process", capture, "--calibration", cal, "-o", tmp_path / "out")
    assert "translation_mm: baseline 0.1 mm is implausibly short" in line and "multiply translation_mm by 1000" in line


@needs_real_data
def test_real_eye_imported_without_projector_width_is_refused(capsys, tmp_path) -> None:
    import_eye_calibration(tmp_path / "cal")
    import_eye(tmp_path / "eye")
    capsys.readouterr()
    line = _one_line_error(
        capsys, "process", tmp_path / "eye", "--calibration", tmp_path / "cal", "-o", tmp_path / "out"
    )
    assert "projector width: 1280 px does not fit" in line and "re-import it with --projector-width 1920" in line
    import_eye(tmp_path / "small", "--projector-width", "1920", "--downsample", "2")
    capsys.readouterr()
    line = _one_line_error(
        capsys, "process", tmp_path / "small", "--calibration", tmp_path / "cal", "-o", tmp_path / "out"
    )
    assert "camera: 640x512 does not fit" in line and "camera_size 1280x1024" in line and "--downsample" in line
