"""The real captures of ``../shared/real-data`` and the CLI steps that several tests take on them.

Tests that need the folder mark themselves ``needs_real_data`` and skip cleanly without it.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from rig.cli import main

REAL_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "real-data"
EYE = REAL_DATA / "slmaster-eye"
needs_real_data = pytest.mark.skipif(not REAL_DATA.is_dir(), reason=f"real data not present at {REAL_DATA}")
EYE_PATTERNS = "sin:f=32,steps=12,phase=pi; gray:bits=6"
KAMINO = REAL_DATA / "kamino410-mugs" / "object1"
# 1920 x 1080 display: 200/3-px and 100-px fringes (28.8 and 19.2 fringes along x, 16.2 and 10.8 along y),
# shifts -120, 0, +120 degrees; OpenCV's GrayCodePattern of 100-px cells, column bits then row bits, each
# plane followed by its inverse; white; black (tests/realdata.py's README section of ../shared/real-data)
KAMINO_SHIFTS = "shifts=-120/0/120deg"
KAMINO_PATTERNS = (
    f"sin:f=28.8,{KAMINO_SHIFTS}; sin:f=19.2,{KAMINO_SHIFTS}; "
    f"sin:f=16.2,{KAMINO_SHIFTS},axis=y; sin:f=10.8,{KAMINO_SHIFTS},axis=y; "
    "gray:bits=5,period=100,inverted=interleaved; gray:bits=4,period=100,inverted=interleaved,axis=y; white; black"
)
KAMINO_DISPLAY = ("--projector-width", "1920", "--projector-height", "1080")


def import_eye_calibration(out: Path) -> None:
    """`rig calibrate --import-opencv` the eye's stereo calibration (1920x1024 projector) into ``out``."""
    argv = ["calibrate", "--import-opencv", str(EYE / "caliInfo.yml"), "--projector-size", "1920x1024"]
    assert main([*argv, "--pixel-centre", "0", "-o", str(out)]) == 0


def import_eye(out: Path, *options: str) -> None:
    """`rig import` the eye's left camera into ``out`` with its pattern spec and the given options."""
    assert main(["import", str(EYE / "L"), "--patterns", EYE_PATTERNS, *options, "-o", str(out)]) == 0


def process_eye(root: Path, *options: str) -> None:
    """`rig process` ``root/eye`` with the calibration ``root/cal`` into ``root/out``."""
    argv = ["process", str(root / "eye"), "--calibration", str(root / "cal"), "-o", str(root / "out")]
    assert main([*argv, *options]) == 0
