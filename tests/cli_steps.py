"""CLI steps that several tests take on the simulated rig."""

from __future__ import annotations

from pathlib import Path

from rig.cli import main


def calibrate_on_plane(config: Path, out: Path, pixel_mm: float) -> int:
    """`rig calibrate` without a board (the pixel size given): the exit status, for the caller to assert."""
    argv = ["calibrate", "--config", str(config), "-o", str(out), "--board", "none"]
    return main([*argv, "--pixel-mm", f"{pixel_mm:g}", "-q"])


def scan_and_process(config: Path, capture: Path, calibration: Path, out: Path) -> None:
    """`rig scan --process`: the object into ``capture``, processed with ``calibration`` into ``out``."""
    argv = ["scan", "--config", str(config), "-o", str(capture), "--calibration", str(calibration)]
    assert main([*argv, "--process", "--process-output", str(out)]) == 0


def run(capsys, *argv: object) -> tuple[int, str]:
    """`rig ARGV` in this process: the exit status and what it wrote on stderr."""
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def assert_one_line(code: int, err: str, *fragments: str) -> None:
    """A user error: exit status 1, one error line containing every fragment, no traceback."""
    lines = [line for line in err.splitlines() if ": error:" in line]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
