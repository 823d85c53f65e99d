"""The projector-only alignment grid (kind "grid"): its maths, its validation, and its refusal in captures.

The shader is checked against the same numpy rendering with the other kinds (tests/contracts.py
PATTERNS); the console's live view of it is in tests/test_console_api.py.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from drivers.projector import validate_pattern as projector_validate
from processing.projection.patterns import CAPTURE_KINDS, Grid, PatternError, parse_pattern, pattern_image
from rig.errors import CaptureError
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.store.capture import read_capture, validate_pattern


def test_grid_lines_and_crosshair_run_through_the_centre_pixel() -> None:
    """20 x 14 projector, centre pixel (10, 7): lines every 5 px through it, a 3 px crosshair on it."""
    image = pattern_image({"kind": "grid", "pitch_px": 5, "line_px": 1, "crosshair_px": 3}, (20, 14))
    lit_cols = {0, 5, 10, 15} | {9, 10, 11}
    lit_rows = {2, 7, 12} | {6, 7, 8}
    expected = np.zeros((14, 20), dtype=np.float32)
    expected[sorted(lit_rows), :] = 1.0
    expected[:, sorted(lit_cols)] = 1.0
    np.testing.assert_array_equal(image, expected)


def test_wide_lines_are_centred_on_their_position_and_levels_are_used() -> None:
    grid = Grid(pitch_px=8, line_px=3, crosshair_px=0, level=0.75, background=0.25)
    row = pattern_image(grid, (32, 4))[0]
    # centre column 16; lines of 3 px around 16 + 8k: columns 0..1 (of -1..1), 7..9, 15..17, 23..25, 31 (of 31..33)
    lit = {0, 1, 7, 8, 9, 15, 16, 17, 23, 24, 25, 31}
    assert {int(c) for c in np.flatnonzero(row == 0.75)} == lit
    assert np.all(row[[c for c in range(32) if c not in lit]] == 0.25)


@pytest.mark.parametrize(
    ("entry", "key", "message"),
    [
        ({"kind": "grid"}, "pitch_px", "pitch_px: missing"),
        ({"kind": "grid", "pitch_px": 1}, "pitch_px", "expected an integer >= 2, found 1"),
        ({"kind": "grid", "pitch_px": 8, "line_px": 8}, "line_px", "expected 1 .. 7 (pitch_px = 8), found 8"),
        ({"kind": "grid", "pitch_px": 8, "crosshair_px": -1}, "crosshair_px", "expected an integer >= 0, found -1"),
        ({"kind": "grid", "pitch_px": 8, "level": "white"}, "level", "expected a finite number, found 'white'"),
    ],
)
def test_grid_validation_names_the_key(entry: dict, key: str, message: str) -> None:
    with pytest.raises(PatternError) as info:
        parse_pattern(entry)
    assert info.value.key == key and message in str(info.value)
    with pytest.raises(ValueError, match=f"pattern 'grid'.*{key}"):
        projector_validate(entry)


def test_grid_round_trips_and_writes_only_what_differs_from_its_defaults() -> None:
    entry = {"kind": "grid", "pitch_px": 64, "line_px": 2, "note": "kept"}
    assert parse_pattern(entry).to_dict() == entry
    assert Grid(pitch_px=32).to_dict() == {"kind": "grid", "pitch_px": 32}
    assert Grid(pitch_px=32, crosshair_px=0).to_dict() == {"kind": "grid", "pitch_px": 32, "crosshair_px": 0}


def test_a_capture_naming_the_grid_is_refused_with_one_clear_line(tmp_path: Path) -> None:
    with pytest.raises(CaptureError) as info:
        validate_pattern("capture.json", 2, {"kind": "grid", "pitch_px": 32})
    message = str(info.value)
    assert message.startswith("capture.json: patterns[2].kind: 'grid' is a projector-only alignment pattern")
    assert f"expected one of {', '.join(CAPTURE_KINDS)}" in message and "grid" not in CAPTURE_KINDS

    result = simulate_scan("hemisphere", demo_geometry(32, 24), [{"kind": "flat", "level": 1.0}], seed=1)
    capture = write_simulated_scan(result, tmp_path / "scan").capture
    manifest = json.loads((capture / "capture.json").read_text())
    manifest["patterns"][0] = {"kind": "grid", "pitch_px": 16}
    (capture / "capture.json").write_text(json.dumps(manifest))
    with pytest.raises(CaptureError, match=r"capture\.json: patterns\[0\]\.kind: 'grid' is a projector-only"):
        read_capture(capture)
