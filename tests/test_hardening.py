"""Issue 10 reproducers, one test per class: data loss, containment, one-line errors, limits, commits."""

from __future__ import annotations

import json
import os
import stat
import struct
import threading
import zlib
from pathlib import Path

import numpy as np
import pytest
from cli_steps import assert_one_line, run

from mock_devices.camera import CameraFaults
from rig.cli import main
from rig.errors import CaptureError
from rig.store import files
from rig.store.capture import CaptureWriter, read_capture

PATTERNS = [{"kind": "sinusoid", "axis": "x", "frequency": 1, "steps": 3, "step": j} for j in range(3)]
CAMERA = {"width": 16, "height": 12, "bit_depth": 8}
PROJECTOR = {"width": 32, "height": 24}


def write_small(path: Path, overwrite: bool = False) -> None:
    with CaptureWriter(path, CAMERA, PROJECTOR, PATTERNS, overwrite=overwrite) as writer:
        for i in range(3):
            writer.add_frame(i, np.full((12, 16), 10 * i, np.uint8))


# 1. --overwrite replaces only what this program wrote -------------------------------------------


@pytest.mark.parametrize(
    "argv",
    [
        ("scan", "-o", "{d}", "--overwrite"),
        ("simulate", "-o", "{d}", "--size", "32x24", "--overwrite"),
        ("calibrate", "-o", "{d}", "--overwrite"),
        ("demo", "-o", "{d}", "--size", "32x24", "-q"),
        ("process", "{cap}", "-o", "{d}", "-q"),
    ],
)
def test_overwrite_never_replaces_a_foreign_directory(capsys, tmp_path, small_capture, argv) -> None:
    precious = tmp_path / "d"
    precious.mkdir()
    (precious / "thesis.tex").write_text("years of work")
    code, err = run(capsys, *(a.format(d=precious, cap=small_capture.capture) for a in argv))
    assert_one_line(code, err, "not written by this program")
    assert (precious / "thesis.tex").read_text() == "years of work"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d", "scan"]  # no leftover staging directory


def test_overwrite_replaces_a_capture_atomically(tmp_path) -> None:
    target = tmp_path / "cap"
    write_small(target)
    write_small(target, overwrite=True)
    assert read_capture(target).complete
    assert [p.name for p in tmp_path.iterdir()] == ["cap"]
    assert stat.S_IMODE(target.stat().st_mode) == 0o777 & ~files._umask()  # not 0700 (item 9)


# 2. concurrent writers: one wins, the other is told -------------------------------------------


def test_concurrent_commits_never_delete_a_capture(tmp_path) -> None:
    target = tmp_path / "cap"
    first = CaptureWriter(target, CAMERA, PROJECTOR, PATTERNS)
    second = CaptureWriter(target, CAMERA, PROJECTOR, PATTERNS)
    with first:
        with pytest.raises(CaptureError, match="appeared while writing"):
            with second:
                for i in range(3):
                    second.add_frame(i, np.full((12, 16), 200, np.uint8))
                for i in range(3):
                    first.add_frame(i, np.full((12, 16), 100, np.uint8))
                first.__exit__(None, None, None)  # the first commits while the second still writes
                first.temp_path = None
    assert read_capture(target).load_frame(0)[0, 0] == 100
    (loser,) = tmp_path.glob("cap.incomplete-*")
    assert read_capture(loser, salvage=True).complete is False  # kept, visibly uncommitted


def test_racing_commits_from_threads_have_exactly_one_winner(tmp_path) -> None:
    target = tmp_path / "out"
    stagings = []
    for i in range(8):
        staging = files.make_staging(target, CaptureError)
        (staging / "report.json").write_text(json.dumps({"program": "fpp-rig test", "i": i}))
        stagings.append(staging)
    outcomes: list[str] = []

    def commit(staging: Path) -> None:
        try:
            files.commit_directory(staging, target, ("output",), False, CaptureError)
            outcomes.append("won")
        except CaptureError:
            outcomes.append("lost")

    threads = [threading.Thread(target=commit, args=(s,)) for s in stagings]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert sorted(outcomes) == ["lost"] * 7 + ["won"]


# 3./4. containment: links, FIFOs, absolute and '..' paths --------------------------------------


def test_output_is_never_written_through_a_planted_link(capsys, tmp_path, small_capture) -> None:
    out = tmp_path / "out"
    assert run(capsys, "process", small_capture.capture, "-o", out, "-q")[0] == 0
    victim = tmp_path / "victim.txt"
    victim.write_text("safe")
    (out / "report.json.tmp").symlink_to(victim)
    assert run(capsys, "process", small_capture.capture, "-o", out, "-q", "--overwrite")[0] == 0
    assert victim.read_text() == "safe" and not (out / "report.json.tmp").exists()


def test_frames_linked_outside_the_capture_are_refused(capsys, small_capture) -> None:
    frames = small_capture.capture / "frames"
    os.rename(frames, frames.with_name("elsewhere"))
    frames.symlink_to("/etc")
    assert_one_line(*run(capsys, "info", small_capture.capture), "leads outside")


def test_a_fifo_frame_is_refused_at_once(capsys, small_capture) -> None:
    frame = small_capture.capture / "frames" / "000.png"
    frame.unlink()
    os.mkfifo(frame)
    assert_one_line(*run(capsys, "info", small_capture.capture), "expected a regular file, found a FIFO")


@pytest.mark.parametrize("reference", ["/abs/reference", "../../reference"])
def test_calibration_reference_must_be_relative_and_inside(capsys, small_capture, reference) -> None:
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data["reference"] = reference
    path.write_text(json.dumps(data))
    code, err = run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    assert_one_line(code, err, "reference: expected a path relative to the calibration directory")


def test_calibration_reference_linking_outside_is_refused(capsys, tmp_path, small_capture) -> None:
    reference = small_capture.calibration / "reference"
    os.rename(reference, tmp_path / "moved")
    reference.symlink_to(tmp_path / "moved")
    code, err = run(capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-q")
    assert_one_line(code, err, "leads outside")


@pytest.mark.parametrize("name", ["/etc/passwd", "../../x.png"])
def test_import_pattern_file_names_stay_in_the_folder(capsys, tmp_path, name) -> None:
    folder = tmp_path / "images"
    folder.mkdir()
    spec = tmp_path / "spec.json"
    spec.write_text(json.dumps({"patterns": [{"kind": "flat", "level": 1}], "files": [name]}))
    code, err = run(capsys, "import", folder, "--patterns", f"@{spec}", "-o", tmp_path / "cap")
    assert_one_line(code, err, "files[0]")


# 5. tracebacks that are now one line ---------------------------------------------------------


@pytest.mark.parametrize("where", ["/proc/x/out", "{file}", "{file}/below"])
def test_unwritable_outputs_fail_before_computing(capsys, tmp_path, small_capture, where) -> None:
    file = tmp_path / "afile"
    file.write_text("x")
    out = where.format(file=file)
    for argv in (
        ("process", small_capture.capture, "-o", out, "-q"),
        ("simulate", "-o", out, "--size", "32x24"),
        ("calibrate", "-o", out, "-q"),
    ):
        assert_one_line(*run(capsys, *argv))
    assert file.read_text() == "x"


def test_singular_phase_shifts_name_the_patterns(capsys, small_capture) -> None:
    path = small_capture.capture / "capture.json"
    manifest = json.loads(path.read_text())
    for pattern in manifest["patterns"]:
        pattern["shift_rad"] = 0.0
    path.write_text(json.dumps(manifest))
    assert_one_line(*run(capsys, "process", small_capture.capture, "-q"), "patterns[0]", "cannot compute a phase")


@pytest.mark.parametrize(
    "text",
    ["[" * 100000 + "]" * 100000, '{"format": ' + "7" * 5000 + "}", '{"a": NaN}'],
    ids=["nesting", "digits", "nan"],
)
def test_hostile_json_is_one_line(capsys, small_capture, text) -> None:
    (small_capture.capture / "capture.json").write_text(text)
    assert_one_line(*run(capsys, "info", small_capture.capture), "capture.json")


@pytest.mark.parametrize(
    "toml,fragment",
    [
        ("[scan]\nfrequencies = [1, 1e308]\n", "frequencies"),
        ("[trigger]\nbaudrate = 9223372036854775807\n", "baudrate"),
        ("[camera]\nsize = [100000, 100000]\n", "size"),
        ("[scan]\nsteps = " + "9" * 5000 + "\n", "not valid TOML"),
        ("a = " + "[" * 5000 + "]" * 5000 + "\n", "not valid TOML"),
    ],
    ids=["frequency", "baudrate", "size", "digits", "nesting"],
)
def test_absurd_config_values_are_one_line(capsys, tmp_path, toml, fragment) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(toml)
    assert_one_line(*run(capsys, "scan", "--config", config, "-o", tmp_path / "c"), fragment)
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize("name", ["a\0b", "x" * 5000], ids=["nul", "long"])
def test_impossible_file_names_are_one_line(capsys, small_capture, name) -> None:
    assert_one_line(*run(capsys, "process", small_capture.capture, "-o", name, "-q"))
    assert_one_line(*run(capsys, "info", name))


def test_bad_parameter_value_is_one_line(capsys, small_capture) -> None:
    code, err = run(
        capsys, "process", small_capture.capture, "--correction", "auto", "--param", "max_residual=abc", "-q"
    )
    assert_one_line(code, err, "max_residual" if "max_residual" in err else "abc")


def test_import_opencv_on_a_file_that_is_not_opencv(capsys, tmp_path) -> None:
    for content in (b"hello\n", b"%YAML:1.0\n[[[[", b"\x89PNG\r\n"):
        source = tmp_path / "cal.yml"
        source.write_bytes(content)
        code, err = run(
            capsys, "calibrate", "--import-opencv", source, "--projector-size", "10x10", "-o", tmp_path / "c"
        )
        assert_one_line(code, err, "cal.yml")
    assert not (tmp_path / "c").exists()


# 6. sizes are checked before allocation ------------------------------------------------------


def _png_header(width: int, height: int) -> bytes:
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + struct.pack(">I", 13) + b"IHDR" + ihdr + struct.pack(">I", zlib.crc32(b"IHDR" + ihdr))


def test_image_header_is_checked_before_decoding(capsys, tmp_path) -> None:
    folder = tmp_path / "images"
    folder.mkdir()
    (folder / "0.png").write_bytes(_png_header(32000, 32000) + bytes(2000))
    assert_one_line(*run(capsys, "import", folder, "--patterns", "flat:1", "-o", tmp_path / "c"), "32000x32000")


def test_limits_are_overridable_from_the_environment(monkeypatch) -> None:
    monkeypatch.setenv("RIG_MAX_IMAGE_SIDE", "100")
    with pytest.raises(CaptureError, match="RIG_MAX_IMAGE_SIDE"):
        files.decode_image(_png_header(200, 10), "x.png", CaptureError)
    monkeypatch.setenv("RIG_MAX_IMAGE_SIDE", "lots")
    with pytest.raises(ValueError, match="RIG_MAX_IMAGE_SIDE"):
        files.limits()


def test_simulate_size_beyond_the_limit_is_refused(capsys, tmp_path) -> None:
    assert_one_line(*run(capsys, "simulate", "-o", tmp_path / "s", "--size", "100000x100000"), "RIG_MAX_IMAGE_SIDE")


# 8. commit windows -------------------------------------------------------------------------


def test_uncommitted_directory_claiming_completeness_is_refused(tmp_path) -> None:
    write_small(tmp_path / "cap")
    killed = tmp_path / "cap2.incomplete-abc123"  # what a kill just before the rename leaves
    os.rename(tmp_path / "cap", killed)
    assert json.loads((killed / "capture.json").read_text())["complete"] is True
    with pytest.raises(CaptureError, match="never committed"):
        read_capture(killed)
    assert read_capture(killed, salvage=True).complete


def test_interrupted_replacement_says_where_the_old_capture_is(tmp_path) -> None:
    write_small(tmp_path / "cap")
    os.rename(tmp_path / "cap", tmp_path / "cap.replaced-xyz")  # a kill between two renames
    with pytest.raises(CaptureError, match=r"previous version at .*cap\.replaced-xyz"):
        read_capture(tmp_path / "cap")


# 9. minor ----------------------------------------------------------------------------------


def test_absurd_l0_gives_no_infinity(capsys, tmp_path, small_capture) -> None:
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data["l0_mm"] = 1e308
    path.write_text(json.dumps(data))
    out = tmp_path / "o"
    code, err = run(
        capsys, "process", small_capture.capture, "--calibration", small_capture.calibration, "-o", out, "-q"
    )
    if code == 0:
        assert np.isfinite(np.load(out / "height.npy")[np.load(out / "mask.npy")]).all()
        assert "Infinity" not in (out / "report.json").read_text()
    else:
        assert_one_line(code, err, "no pixel has a finite height")


def test_truncated_png_prints_only_the_error(capfd, small_capture) -> None:
    frame = small_capture.capture / "frames" / "000.png"
    data = frame.read_bytes()[:300]
    frame.write_bytes(data)
    path = small_capture.capture / "capture.json"
    manifest = json.loads(path.read_text())
    import hashlib

    manifest["frames"][0]["sha256"] = hashlib.sha256(data).hexdigest()
    path.write_text(json.dumps(manifest))
    code = main(["info", str(small_capture.capture)])
    err = capfd.readouterr().err
    assert code == 1 and len(err.strip().splitlines()) == 1 and "WARN" not in err, err


# 10. a camera whose first frame after every start is bad --------------------------------------


@pytest.mark.parametrize("faults", [CameraFaults(timeout_on={0}), CameraFaults(stale={0}), CameraFaults(drop={0})])
def test_retries_make_progress_past_a_bad_first_frame(tmp_path, faults) -> None:
    from test_acquisition import scan

    result, _rig = scan(tmp_path, "software", camera_faults=faults)
    assert read_capture(result.path).complete and result.attempts > len(result.frames)
