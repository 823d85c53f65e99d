"""Partly lit views: calibration fits use lit, modulated pixels only; previews and summaries name what they show.

The simulated rig's footprint is set by ``[simulation] f0_per_mm``: footprint width on the plane =
f0_frequency / f0_per_mm (default 512 mm, 1.25 x the 409.6 mm view); 8 / 0.0266667 = 300 mm
covers only 73 % of the view, the camera sees the unlit plane around it.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest
from cli_steps import calibrate_on_plane
from realdata import import_eye, import_eye_calibration, needs_real_data, process_eye

from rig.cli import main
from rig.store.result_files import colour_map

PARTLY_LIT = """
[projector]
size = [320, 400]
[camera]
size = [320, 240]
[scan]
frequencies = [1, 8, 32]
steps = 4
[simulation]
scene = "hemisphere"
snr_db = 35
f0_per_mm = 0.0266667
"""


def test_partly_lit_view_calibrates_within_half_a_percent(tmp_path, capsys) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(PARTLY_LIT)
    # the pixel size is given: this test is about the phase fits (f0, l0, d0) on a partly lit view
    assert calibrate_on_plane(config, tmp_path / "cal", 1.28) == 0, capsys.readouterr().err
    cal = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    f0_at_32 = 0.0266667 * 32 / 8
    assert cal["f0_per_mm"] * 8 / cal["f0_frequency"] == pytest.approx(0.0266667, rel=0.005)
    assert cal["f0_per_mm"] == pytest.approx(f0_at_32, rel=0.005)
    assert cal["l0_mm"] == pytest.approx(1000.0, rel=0.005)  # 975.7 when the footprint's edge entered the fits
    assert cal["d0_mm"] == pytest.approx(250.0, rel=0.005)


@pytest.mark.parametrize(
    "f0_per_mm, tolerance", [(0.0266667, 0.005), (0.015625, 0.0015)], ids=["partly-lit", "fully-lit"]
)
def test_default_calibration_with_board_views(tmp_path, capsys, f0_per_mm, tolerance) -> None:
    """The default session (board on the plane and six tilted views) on a partly lit view: corners
    beyond or at the footprint's edge are left out, so no spurious lens distortion is fitted and the
    board on the plane gives the true pixel size (before: 0.288 px reprojection, a "significant"
    distortion undistorted into every fit, pixel 1.2888 mm, l0 993.7 mm, d0 259.4 mm)."""
    config = tmp_path / "rig.toml"
    config.write_text(PARTLY_LIT.replace("f0_per_mm = 0.0266667", f"f0_per_mm = {f0_per_mm}"))
    assert main(["calibrate", "--config", str(config), "-o", str(tmp_path / "cal"), "-q"]) == 0, capsys.readouterr().err
    cal = json.loads((tmp_path / "cal" / "calibration.json").read_text())
    assert not cal["distortion_significant"] and cal["reprojection_rms_px"] < 0.1  # the simulated lens is a pinhole
    assert cal["pixel_mm"] == pytest.approx(1.28, rel=tolerance)
    assert cal["f0_per_mm"] == pytest.approx(f0_per_mm * 32 / 8, rel=tolerance)
    assert cal["l0_mm"] == pytest.approx(1000.0, rel=tolerance)
    assert cal["d0_mm"] == pytest.approx(250.0, rel=tolerance)


@needs_real_data
def test_stereo_summary_says_depth_and_preview_has_an_invalid_legend(tmp_path, capsys) -> None:
    import_eye_calibration(tmp_path / "cal")
    import_eye(tmp_path / "eye", "--projector-width", "1920")
    capsys.readouterr()
    process_eye(tmp_path, "--correction", "none")
    err = capsys.readouterr().err
    assert ", depth " in err and ", height " not in err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["quantity"] == "depth" and report["preview"]["shows"] == "depth"
    preview = cv2.imread(str(tmp_path / "out" / "preview.png"))
    panel = preview[:, 1280:]
    grey = tuple(int(v) for v in colour_map(np.full((1, 1), np.nan), 0.0, 1.0)[0, 0])
    assert (np.all(panel == grey, axis=2)).sum() >= 50  # the legend's swatch of the invalid colour


def test_scan_process_prints_the_process_summary(tmp_path, capsys, simulated_rig_toml) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(simulated_rig_toml((320, 400), (160, 120), 35.0))
    assert calibrate_on_plane(config, tmp_path / "cal", 2.56) == 0
    capsys.readouterr()
    assert (
        main(
            [
                "scan",
                "--config",
                str(config),
                "-o",
                str(tmp_path / "part"),
                "--calibration",
                str(tmp_path / "cal"),
                "--process",
            ]
        )
        == 0
    )
    err = capsys.readouterr().err
    assert "part-processed: valid " in err and ", height " in err and " points" in err
