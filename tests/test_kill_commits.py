"""SIGKILL `rig scan` and `rig process` at seeded random moments; check what issue 10 promises.

After any kill: a capture at the named path is complete and verifies, a directory left beside it
is visibly uncommitted (refused without salvage), and a processing output directory holds either
the complete old or the complete new result.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rig.errors import CaptureError
from rig.store.capture import read_capture

REPO = Path(__file__).resolve().parents[1]
KILLS = 4  # per test; delays drawn from a fixed seed
SMALL_RIG = """
[camera]
size = [64, 48]
[projector]
size = [96, 120]
[scan]
frequencies = [1, 8]
steps = 4
"""


def _start(*argv: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    return subprocess.Popen(
        [sys.executable, "-m", "rig.cli", *argv], cwd=cwd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE
    )


def _kill_after(process: subprocess.Popen, delay_s: float) -> None:
    try:
        process.wait(timeout=delay_s)
    except subprocess.TimeoutExpired:
        process.send_signal(signal.SIGKILL)
        process.wait()


def _delays(seed: int, low: float, high: float) -> list[float]:
    return list(np.random.default_rng(seed).uniform(low, high, KILLS))


def test_killed_scans_never_leave_a_capture_claiming_completeness(tmp_path) -> None:
    (tmp_path / "rig.toml").write_text(SMALL_RIG)
    for n, delay in enumerate(_delays(10, 0.3, 2.5)):
        target = tmp_path / f"cap{n}"
        _kill_after(_start("scan", "--config", "rig.toml", "-o", target.name, cwd=tmp_path), delay)
        if target.exists():
            assert read_capture(target).complete  # verified: every frame's checksum
        for left in tmp_path.glob(f"{target.name}.incomplete-*"):
            with pytest.raises(CaptureError):
                read_capture(left)  # never passes for a capture without --salvage
    assert not list(tmp_path.glob("*.replaced-*"))


def test_killed_overwrite_keeps_the_old_or_the_new_capture(tmp_path) -> None:
    (tmp_path / "rig.toml").write_text(SMALL_RIG)
    target = tmp_path / "cap"
    assert _start("scan", "--config", "rig.toml", "-o", "cap", cwd=tmp_path).wait() == 0
    for delay in _delays(11, 0.3, 2.5):
        _kill_after(_start("scan", "--config", "rig.toml", "-o", "cap", "--overwrite", cwd=tmp_path), delay)
        assert read_capture(target).complete


def _assert_complete_output(out: Path) -> str:
    report = json.loads((out / "report.json").read_text())
    for name in report["files"].values():
        assert (out / name).is_file(), name
    height = np.load(out / "height.npy") if "height" in report["files"] else None
    phase = np.load(out / "phase.npy")
    assert height is None or height.shape == phase.shape
    return report["calibration"] or "none"


def test_killed_processing_leaves_the_old_or_the_new_result(tmp_path, small_capture) -> None:
    out = tmp_path / "out"
    assert _start("process", str(small_capture.capture), "-o", str(out), "-q", cwd=tmp_path).wait() == 0
    seen = {_assert_complete_output(out)}
    for delay in _delays(12, 0.3, 2.0):
        _kill_after(
            _start(
                "process",
                str(small_capture.capture),
                "--calibration",
                str(small_capture.calibration),
                "-o",
                str(out),
                "-q",
                cwd=tmp_path,
            ),
            delay,
        )
        seen.add(_assert_complete_output(out))
    assert "none" in seen


OLD_HEIGHTS, NEW_HEIGHTS = "25,50,100,150", "20,40,80,120"


def _complete_calibration(cal: Path) -> str:
    """The plane heights of the complete calibration at ``cal`` (every capture in it verifies)."""
    from calibration.store import read_calibration

    calibration = read_calibration(cal)
    assert calibration.reference_path is not None and read_capture(calibration.reference_path).complete
    heights = json.loads((cal / "session.json").read_text())["heights_mm"]
    planes = sorted(cal.glob("planes/*"))
    assert len(planes) == len(heights) and all(read_capture(plane).complete for plane in planes)
    assert calibration.extra["heights_mm"] == heights  # calibration.json was fitted to these very captures
    return ",".join(f"{h:g}" for h in heights)


def test_killed_calibrate_overwrite_keeps_the_old_or_the_new_calibration(tmp_path) -> None:
    (tmp_path / "rig.toml").write_text(SMALL_RIG)
    common = ("calibrate", "--config", "rig.toml", "-o", "cal", "--board", "none", "--pixel-mm", "1.6", "-q")
    assert _start(*common, "--heights", OLD_HEIGHTS, cwd=tmp_path).wait() == 0
    seen = {_complete_calibration(tmp_path / "cal")}
    for delay in _delays(13, 0.3, 3.0):
        _kill_after(_start(*common, "--heights", NEW_HEIGHTS, "--overwrite", cwd=tmp_path), delay)
        seen.add(_complete_calibration(tmp_path / "cal"))
    assert OLD_HEIGHTS in seen and seen <= {OLD_HEIGHTS, NEW_HEIGHTS}
    assert _start(*common, "--heights", NEW_HEIGHTS, "--overwrite", cwd=tmp_path).wait() == 0
    assert _complete_calibration(tmp_path / "cal") == NEW_HEIGHTS


def test_killed_calibrate_from_leaves_no_empty_staging_folder(tmp_path) -> None:
    """Issue 22: `rig calibrate --from DIR -o OTHER` used to create OTHER's staging folder before
    computing, so every kill during the computation left an empty `OTHER.incomplete-*` behind."""
    (tmp_path / "rig.toml").write_text(SMALL_RIG)
    common = ("calibrate", "--config", "rig.toml", "-o", "cal", "--board", "none", "--pixel-mm", "1.6", "-q")
    assert _start(*common, "--heights", OLD_HEIGHTS, cwd=tmp_path).wait() == 0
    for n, delay in enumerate(_delays(14, 1.0, 2.5)):
        _kill_after(_start("calibrate", "--from", "cal", "-o", f"other{n}", "-q", cwd=tmp_path), delay)
        assert not [p.name for p in tmp_path.glob(f"other{n}.incomplete-*") if not any(p.iterdir())]
        if (tmp_path / f"other{n}").exists():  # committed whole: the calibration and its reference
            from calibration.store import read_calibration

            calibration = read_calibration(tmp_path / f"other{n}")
            assert calibration.reference_path is not None and read_capture(calibration.reference_path).complete
