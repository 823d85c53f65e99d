"""`rig process`, `rig info`, `rig demo`: round trip against the simulated truth, and bad inputs.

Round-trip tolerance: the conftest scan (160x120, 2.56 mm pixels, hemisphere 102 mm high, 4-step
fringes at 1/8/64 periods, 35 dB SNR, 8-bit) must come back with an RMS height error below
0.5 mm and every valid lit pixel within 3 mm of the truth (phase noise ~0.03 rad at 64 periods
is ~0.15 mm; pixels on the steep rim carry the largest error).
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from calibration.store import read_calibration
from mock_devices import synth
from rig.cli import main
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions, choose_unwrap, group_patterns
from rig.pipeline.run import process
from rig.store.capture import write_capture
from rig.store.result_files import read_ply_points

REPO = Path(__file__).resolve().parents[1]


def _run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def _assert_one_line_error(code: int, err: str, *fragments: str) -> None:
    assert code == 1
    lines = [line for line in err.splitlines() if line.strip() and not line.startswith("process ")]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


# ------------------------------------------------------------------ round trip


def test_process_recovers_the_scene_heights(capsys, small_capture, small_scan, tmp_path) -> None:
    out = tmp_path / "out"
    code, stdout, _ = _run(
        capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", out, "--json", "-q"
    )
    assert code == 0
    summary = json.loads(stdout)
    assert summary["unwrap"] == "hierarchical"
    height = np.load(out / "height.npy")
    mask = np.load(out / "mask.npy")
    assert height.dtype == np.float32 and mask.dtype == bool and height.shape == small_scan.height_mm.shape
    assert np.all(np.isnan(height[~mask])) and np.all(np.isfinite(height[mask]))
    valid = mask & small_scan.lit
    assert valid.mean() > 0.9
    error = height[valid] - small_scan.height_mm[valid]
    assert np.sqrt(np.mean(error**2)) < 0.5
    assert np.max(np.abs(error)) < 3.0


def test_outputs_follow_the_format(capsys, small_capture, small_scan, tmp_path) -> None:
    out = tmp_path / "out"
    assert (
        _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", out, "-q")[0]
        == 0
    )
    mask = np.load(out / "mask.npy")
    phase = np.load(out / "phase.npy")
    truth = synth.true_absolute_phase(small_scan.object_map, small_scan.geometry, 64)
    assert phase.dtype == np.float64
    assert np.nanmax(np.abs(phase[mask] - truth[mask])) < 0.5  # absolute phase, not just wrapped
    points = read_ply_points(out / "points.ply")
    assert points.shape == (mask.sum(), 3)
    np.testing.assert_allclose(points[:, 2], np.load(out / "height.npy")[mask], atol=1e-4)
    preview = cv2.imread(str(out / "preview.png"))
    assert preview.shape[0] == mask.shape[0] and preview.shape[1] > mask.shape[1]  # image + scale bar
    report = json.loads((out / "report.json").read_text())
    for stage in ("load", "undistort", "denoise", "phase", "correction"):
        assert report["timings_s"]["object"][stage] >= 0 and report["timings_s"]["reference"][stage] >= 0
    assert report["methods"]["unwrap"] == "hierarchical" and report["methods"]["frequencies"] == [1, 8, 64]
    assert report["valid_fraction"] == pytest.approx(mask.mean())
    assert report["versions"]["fpp-rig"]


def test_without_calibration_writes_phase_and_skips_height(capsys, small_capture, tmp_path) -> None:
    out = tmp_path / "phase-only"
    code, _, err = _run(capsys, "process", small_capture.capture, "-o", out, "-q")
    assert code == 0 and "height, points and height preview skipped" in err
    assert not (out / "height.npy").exists() and not (out / "points.ply").exists()
    wrapped = np.load(out / "wrapped.npy")
    assert wrapped.shape == (3, 120, 160)
    assert np.all((wrapped >= -np.pi) & (wrapped < np.pi))
    report = json.loads((out / "report.json").read_text())
    assert report["wrapped_frequencies"] == [1, 8, 64] and report["preview"]["shows"] == "phase"


@pytest.mark.parametrize(
    "frequencies,expected",
    [
        ((16,), "spatial"),
        ((1, 8, 64), "hierarchical"),
        ((5, 8), "two-frequency"),
        ((64, 58, 53), "heterodyne"),
        ((6, 10, 15), "three-frequency"),
    ],
)
def test_automatic_unwrap_choice(frequencies, expected) -> None:
    groups = group_patterns(synth.sinusoid_patterns(frequencies, 4))
    assert choose_unwrap(groups, "x") == expected


def test_automatic_choice_refuses_what_nothing_fits() -> None:
    from rig.errors import ProcessingError

    with pytest.raises(
        ProcessingError, match=r"frequencies \[4, 8\]: no automatic unwrapping method fits; choose one with --unwrap"
    ):
        choose_unwrap(group_patterns(synth.sinusoid_patterns((4, 8), 4)), "x")


def _scan_with(tmp_path: Path, patterns: list[dict], scene: str = "hemisphere", width: int = 160, height: int = 120):
    scan = simulate_scan(scene, geometry=demo_geometry(width, height), patterns=patterns, seed=3)
    return scan, write_simulated_scan(scan, tmp_path / "scan")


def _height_error(scan, result) -> np.ndarray:
    valid = result.mask & scan.lit
    assert valid.mean() > 0.8
    return result.height[valid] - scan.height_mm[valid]


@pytest.mark.parametrize(
    "bits,frequency,extra",
    [(4, 16, "none"), (5, 16, "none"), (5, 16, "inverted"), (5, 16, "flats")],
    ids=["plain", "complementary", "complementary+inverted", "complementary+flats"],
)
def test_gray_code_plus_phase_shifting(tmp_path, bits, frequency, extra) -> None:
    gray = [{"kind": "gray", "axis": "x", "bit": b, "bits": bits} for b in range(bits)]
    if extra == "inverted":
        gray += [dict(g, inverted=True) for g in gray]
    elif extra == "flats":
        gray += [{"kind": "flat", "level": 1.0}, {"kind": "flat", "level": 0.0}]
    scan, paths = _scan_with(tmp_path, synth.sinusoid_patterns((frequency,), 4) + gray)
    result = process(paths.capture, paths.calibration)
    assert result.object.unwrapped.method == "gray"
    error = _height_error(scan, result)
    assert np.median(np.abs(error)) < 0.5  # orders right almost everywhere (plain Gray code slips at edges)
    if bits == 5:
        assert np.mean(np.abs(error) < 3.0) > 0.99


def test_two_frequency_with_phase_offset_and_custom_shifts(tmp_path) -> None:
    """phase_rad and shift_rad (non-uniform shifts) are honoured when computing the wrapped phase."""
    patterns = []
    for f in (5, 8):
        for j, shift in enumerate((0.0, 1.9, 4.0, 5.1)):
            patterns.append(
                {
                    "kind": "sinusoid",
                    "axis": "x",
                    "frequency": f,
                    "steps": 4,
                    "step": j,
                    "phase_rad": np.pi,
                    "shift_rad": shift,
                }
            )
    scan, paths = _scan_with(tmp_path, patterns)
    result = process(paths.capture, paths.calibration)
    assert result.object.unwrapped.method == "two-frequency"
    assert np.sqrt(np.mean(_height_error(scan, result) ** 2)) < 2.0


def test_spatial_unwrapping_single_frequency(tmp_path) -> None:
    scan, paths = _scan_with(tmp_path, synth.sinusoid_patterns((8,), 4))
    result = process(paths.capture, paths.calibration)
    assert result.object.unwrapped.method == "spatial" and not result.object.unwrapped.absolute
    assert any("spatial unwrapping" in note for note in result.notes)
    assert np.median(np.abs(_height_error(scan, result))) < 1.0


def test_single_frame_uses_fourier_transform_profilometry(tmp_path) -> None:
    scan, paths = _scan_with(tmp_path, [{"kind": "sinusoid", "axis": "x", "frequency": 16, "steps": 1, "step": 0}])
    result = process(paths.capture, paths.calibration)
    assert result.object.unwrapped.method == "ftp"
    assert np.median(np.abs(_height_error(scan, result))) < 1.0  # FTP blurs edges; the bulk is right


def test_lens_distortion_of_the_calibration_is_removed(small_capture, small_scan, tmp_path) -> None:
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    matrix = [[100.0, 0.0, 79.5], [0.0, 100.0, 59.5], [0.0, 0.0, 1.0]]
    path.write_text(json.dumps(dict(data, camera_matrix=matrix, distortion=[0.0, 0.0, 0.0, 0.0, 0.0])))
    plain = process(small_capture.capture, small_capture.calibration, ProcessOptions(undistort=False))
    identity = process(small_capture.capture, small_capture.calibration)
    assert identity.object.info.get("undistorted") and not plain.object.info.get("undistorted")
    np.testing.assert_allclose(identity.height, plain.height, atol=1e-3, equal_nan=True)  # zero distortion: same
    path.write_text(json.dumps(dict(data, camera_matrix=matrix, distortion=[-0.3, 0.0, 0.0, 0.0, 0.0])))
    barrel = process(small_capture.capture, small_capture.calibration)
    changed = np.isfinite(barrel.height) & np.isfinite(plain.height)
    assert np.mean(np.abs(barrel.height[changed] - plain.height[changed]) > 1.0) > 0.01  # the remap moved the object


# ------------------------------------------------------------------ bad inputs: one line, exit 1


def test_missing_capture_json(capsys, tmp_path) -> None:
    (tmp_path / "empty").mkdir()
    code, _, err = _run(capsys, "process", tmp_path / "empty", "-q")
    _assert_one_line_error(code, err, "rig process: error:", "capture.json: missing")


def test_checksum_mismatch_is_one_line_naming_the_file(capsys, small_capture) -> None:
    manifest = json.loads((small_capture.capture / "capture.json").read_text())
    frame = small_capture.capture / manifest["frames"][5]["file"]
    frame.write_bytes(frame.read_bytes()[:-10] + b"0123456789")
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    _assert_one_line_error(code, err, str(frame), "checksum mismatch")


def test_incomplete_capture_is_refused_unless_salvaged(capsys, small_capture, tmp_path) -> None:
    manifest_path = small_capture.capture / "capture.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["complete"] = False
    manifest_path.write_text(json.dumps(manifest))
    code, _, err = _run(capsys, "process", small_capture.capture, "-q", "-o", tmp_path / "o")
    _assert_one_line_error(code, err, "complete: expected true, found false")
    assert _run(capsys, "process", small_capture.capture, "-q", "--salvage", "-o", tmp_path / "o")[0] == 0


def test_calibration_without_its_reference_capture(capsys, small_capture) -> None:
    import shutil

    shutil.rmtree(small_capture.reference)
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    _assert_one_line_error(code, err, "calibration.json: reference: no capture at")


def test_reference_captured_with_other_patterns(capsys, small_capture, tmp_path) -> None:
    import shutil

    other = simulate_scan("flat", geometry=demo_geometry(160, 120), patterns=synth.sinusoid_patterns((1, 8, 64), 3))
    shutil.rmtree(small_capture.reference)
    projector = {"width": other.geometry.projector_width, "height": other.geometry.projector_height}
    write_capture(small_capture.reference, other.reference_frames, other.patterns, projector, scene="reference")
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    _assert_one_line_error(code, err, "reference capture does not fit", "patterns: expected the 12 patterns", "found 9")


def test_calibration_for_another_camera_size(capsys, small_capture, tmp_path) -> None:
    bigger = simulate_scan("flat", geometry=demo_geometry(200, 120))
    paths = write_simulated_scan(bigger, tmp_path / "other")
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", paths.calibration, "-q")
    _assert_one_line_error(
        code, err, "reference capture does not fit", "camera size: expected 160x120", "found 200x120"
    )


def test_calibration_with_unknown_version_or_model(capsys, small_capture) -> None:
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    path.write_text(json.dumps(dict(data, version=7)))
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    _assert_one_line_error(code, err, "calibration.json: version: expected 1", "found 7")
    path.write_text(json.dumps(dict(data, model="mystery")))
    code, _, err = _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    _assert_one_line_error(code, err, "model: expected one of reference-plane, polynomial, stereo, found 'mystery'")


def test_speckle_capture_without_calibration_is_one_line(capsys, tmp_path) -> None:
    frames = np.zeros((1, 32, 48), np.uint8)
    pattern = {
        "kind": "speckle-sinusoid",
        "axis": "x",
        "frequency": 8,
        "steps": 1,
        "step": 0,
        "seed": 1,
        "dot_px": 3,
        "speckle_gain": 0.3,
    }
    write_capture(tmp_path / "c", frames, [pattern], {"width": 96, "height": 64})
    code, _, err = _run(capsys, "process", tmp_path / "c", "-q")
    _assert_one_line_error(
        code, err, "speckle-sinusoid (single-shot) capture takes its fringe orders from a reference-plane capture"
    )


def test_subprocess_error_has_no_traceback(tmp_path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "rig.cli", "process", str(tmp_path / "nothing")],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 1
    assert done.stderr.strip().splitlines()[-1].startswith("rig process: error:") and "Traceback" not in done.stderr
    assert "capture directory not found" in done.stderr


# ------------------------------------------------------------------ rig info, rig demo


def test_info_describes_and_verifies(capsys, small_capture) -> None:
    code, out, _ = _run(capsys, "info", small_capture.capture)
    assert code == 0
    assert "object capture, complete" in out and "camera 160x120 8-bit" in out
    assert "sinusoid x: frequency 64, 4 steps" in out and "12 patterns, 12 frames, all verified" in out
    code, out, _ = _run(capsys, "info", small_capture.capture, "--json")
    assert json.loads(out)["extra_keys"] == ["simulation"]


def test_info_fails_on_a_bad_frame(capsys, small_capture) -> None:
    manifest = json.loads((small_capture.capture / "capture.json").read_text())
    frame = small_capture.capture / manifest["frames"][0]["file"]
    frame.unlink()
    code, _, err = _run(capsys, "info", small_capture.capture)
    _assert_one_line_error(code, err, "rig info: error:", "frame file missing (pattern 0)")


def test_demo_reports_a_small_height_error(capsys, tmp_path) -> None:
    out = tmp_path / "demo"
    code, stdout, _ = _run(capsys, "demo", "-o", out, "--size", "160x120", "--json", "-q")
    assert code == 0
    summary = json.loads(stdout)
    assert summary["height_error_mm"]["rms"] < 0.5
    for name in ("height", "points", "preview", "report"):
        assert Path(summary["files"][name]).is_file()
    assert read_calibration(out / "scan" / "calibration").l0_mm == 1000.0
    # a second run replaces its own earlier output, but never a foreign directory
    assert _run(capsys, "demo", "-o", out, "--size", "160x120", "-q")[0] == 0
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "thesis.tex").write_text("precious")
    code, _, err = _run(capsys, "demo", "-o", foreign, "-q")
    _assert_one_line_error(code, err, "not written by this program")
    assert (foreign / "thesis.tex").exists()


def test_rerun_without_calibration_leaves_no_stale_height(capsys, small_capture, tmp_path) -> None:
    out = tmp_path / "out"
    assert (
        _run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", out, "-q")[0]
        == 0
    )
    assert (out / "height.npy").exists()
    assert _run(capsys, "process", small_capture.capture, "-o", out, "-q", "--overwrite")[0] == 0
    assert not (out / "height.npy").exists() and not (out / "points.ply").exists() and (out / "wrapped.npy").exists()
    code, _, err = _run(capsys, "process", small_capture.capture, "-o", small_capture.capture, "-q")
    _assert_one_line_error(code, err, "exists and is a capture directory")
