"""`rig process --denoise rpca --correction ...`: the RPCA stages inside the product, recorded in report.json."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rig.cli import main
from rig.commands.process import register  # noqa: F401  (the command must exist)


def run_process(capture, calibration, out, *extra: str) -> dict:
    assert main(["process", str(capture), "--calibration", str(calibration), "-o", str(out), "-q", *extra]) == 0
    return json.loads((out / "report.json").read_text())


def height_rms(out, scan) -> float:
    height = np.load(out / "height.npy")
    valid = np.isfinite(height) & scan.lit
    return float(np.sqrt(np.mean((height[valid] - scan.height_mm[valid]) ** 2)))


def test_default_correction_is_auto_and_is_recorded(small_capture, small_scan, tmp_path) -> None:
    report = run_process(small_capture.capture, small_capture.calibration, tmp_path / "auto")
    none = run_process(small_capture.capture, small_capture.calibration, tmp_path / "none", "--correction", "none")
    for scene in ("object", "reference"):
        info = report["stage_info"][scene]["correction"]
        assert info["method"] == "auto"
        assert info["iterations"] > 0 and info["rank"] >= 1 and info["seconds"] >= 0
        assert "tau" in info["parameters"]
        assert "correction" in report["timings_s"][scene]
    assert none["stage_info"]["object"].get("correction") is None
    # how much of the map auto could not settle: in the report, matching the correction's own entry
    unresolved = report["stage_info"]["object"]["correction"]["unresolved"]
    assert report["unresolved_fraction"] == unresolved["fraction"]
    assert 0 <= unresolved["fraction"] <= 1 and len(unresolved["regions"]) <= 20
    assert "unresolved_fraction" not in none
    # the capture's lower frequencies reach auto (the fused pass keeps their wrapped phases for it)
    evidence = report["stage_info"]["object"]["correction"]["evidence"]
    assert {"kept", "reverted", "unresolved", "undecidable", "moved_one_order", "spikes_mended"} <= set(evidence)
    # the unresolved pixels are a file when there are any, inside the valid mask, as many as reported
    if unresolved["pixels"]:
        mask = np.load(tmp_path / "auto" / "unresolved.npy")
        assert report["files"]["unresolved"] == "unresolved.npy"
        assert mask.dtype == bool and not (mask & ~np.load(tmp_path / "auto" / "mask.npy")).any()
        assert int(mask.sum()) <= unresolved["pixels"]
    else:
        assert "unresolved" not in report["files"]
    # auto never makes the heights worse than no correction (64 fringes over 160 px: steep phase).
    assert height_rms(tmp_path / "auto", small_scan) <= height_rms(tmp_path / "none", small_scan)


@pytest.mark.parametrize("method", ["rpca-phase", "rpca-orders", "vote"])
def test_each_method_runs_through_the_pipeline(small_capture, tmp_path, method: str) -> None:
    report = run_process(small_capture.capture, small_capture.calibration, tmp_path / method, "--correction", method)
    info = report["stage_info"]["object"]["correction"]
    assert info["method"] == method and "parameters" in info and "seconds" in info


def test_rpca_denoising_stage_is_recorded_and_parameters_reach_it(small_capture, small_scan, tmp_path) -> None:
    report = run_process(
        small_capture.capture,
        small_capture.calibration,
        tmp_path / "den",
        "--denoise",
        "rpca",
        "--correction",
        "none",
        "--param",
        "stable=true",
    )
    info = report["stage_info"]["object"]["denoise"]
    assert info["method"] == "rpca" and info["parameters"] == {"stable": True}
    assert len(info["iterations"]) == len(info["rank"]) == 12  # 3 frequencies x 4 steps
    assert height_rms(tmp_path / "den", small_scan) < 1.0


def test_unresolved_orders_are_named_in_a_note_and_the_summary_line(capsys, tmp_path) -> None:
    from types import SimpleNamespace

    from rig.commands.process import print_summary
    from rig.pipeline.corrections import _note_unresolved

    state = SimpleNamespace(name="object", notes=[])
    info = {"method": "auto", "unresolved": {"pixels": 300, "fraction": 0.0125, "regions": [[10, 20, 29, 39, 300]]}}
    _note_unresolved(state, info)  # type: ignore[arg-type]
    assert state.notes == [
        "--correction auto: fringe orders unresolved on 1.25% of the object (300 pixels in 1 regions; largest at "
        "rows 10..29, columns 20..39): the measured orders are kept there; see report.json stage_info"
    ]
    _note_unresolved(state, {"method": "auto", "unresolved": {"pixels": 0, "fraction": 0.0, "regions": []}})
    assert len(state.notes) == 1
    report = {"valid_fraction": 0.9, "methods": {"unwrap": "two-frequency"}, "notes": [], "unresolved_fraction": 0.0125}
    print_summary(report, tmp_path / "out")
    assert "fringe orders unresolved on 1.25%" in capsys.readouterr().err
