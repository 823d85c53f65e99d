"""The reference plane and the calibration planes: same patterns as the scans they serve.

A reference-plane calibration subtracts the plane's absolute phase from the object's pixel by
pixel, so the plane must be captured with exactly the scan's pattern set, and every plane at a
known height likewise. :func:`check_same_patterns` refuses a mismatch naming the first
difference; :func:`phase_frequency` tells which frequency the absolute phase is reported at.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from calibration.errors import CalibrationError
from processing.projection.patterns import PROJECTION_KEYS

#: Name of the reference-plane capture inside a calibration directory.
REFERENCE_DIR = "reference"


def check_same_patterns(
    expected: Sequence[Mapping[str, Any]], found: Sequence[Mapping[str, Any]], expected_name: str, found_name: str
) -> None:
    """Raise CalibrationError unless two pattern lists project the same images in the same order."""
    if len(expected) != len(found):
        raise CalibrationError(
            f"{found_name}: {len(found)} patterns but {expected_name} has {len(expected)}; capture both with the same pattern set"
        )
    for index, (a, b) in enumerate(zip(expected, found)):
        for key in PROJECTION_KEYS:
            if a.get(key) != b.get(key):
                raise CalibrationError(
                    f"{found_name}: pattern {index} {key} = {b.get(key)!r} but {expected_name} has {a.get(key)!r}; "
                    "capture both with the same pattern set"
                )


def phase_frequency(patterns: Sequence[Mapping[str, Any]]) -> float:
    """The highest sinusoid frequency of a pattern set: the absolute phase is reported at it."""
    frequencies = [float(p["frequency"]) for p in patterns if p.get("kind") in ("sinusoid", "speckle-sinusoid")]
    if not frequencies:
        raise CalibrationError("patterns: no sinusoid pattern, cannot calibrate a phase-based model")
    return max(frequencies)
