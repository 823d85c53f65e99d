"""The typed pattern model (issue 9): one validation, an exact JSON round trip, used by every layer."""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from realdata import REAL_DATA, needs_real_data

from calibration.jsonfile import write_json_atomic
from drivers.projector import validate_pattern as projector_validate
from processing.projection.patterns import (
    Flat,
    Gray,
    PatternError,
    Sinusoid,
    SpeckleSinusoid,
    parse_pattern,
    pattern_image,
    same_projection,
)
from rig.config import ScanConfig
from rig.errors import CaptureError
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import group_patterns
from rig.store.capture import read_capture, validate_pattern

ROOT = Path(__file__).resolve().parents[1]


def _rewritten_bytes(manifest_path: Path, tmp_path: Path) -> tuple[bytes, bytes]:
    """(capture.json as written, the same manifest with every pattern parsed and written back)."""
    original = manifest_path.read_bytes()
    manifest = json.loads(original)
    manifest["patterns"] = [parse_pattern(p).to_dict() for p in manifest["patterns"]]
    copy = tmp_path / "rewritten.json"
    write_json_atomic(copy, manifest, durable=False)
    return original, copy.read_bytes()


@pytest.mark.parametrize(
    "scan",
    [ScanConfig(frequencies=(1.0, 8.0), steps=3, gray_bits=2), ScanConfig(pattern_set="speckle", speckle_gain=0.25)],
    ids=["phase-shifting+gray", "speckle"],
)
def test_written_capture_round_trips_byte_identical(tmp_path: Path, scan: ScanConfig) -> None:
    patterns = scan.patterns()
    result = simulate_scan("hemisphere", demo_geometry(48, 32), patterns, seed=1)
    paths = write_simulated_scan(result, tmp_path / "scan")
    original, rewritten = _rewritten_bytes(paths.capture / "capture.json", tmp_path)
    assert rewritten == original
    assert read_capture(paths.capture).pattern_models == scan.pattern_models()


@needs_real_data
@pytest.mark.parametrize(
    ("folder", "spec", "options"),
    [
        (
            "slmaster-eye/L",
            "sin:f=32,steps=12,phase=pi; gray:bits=6",
            ["--projector-width", "1920", "--projector-height", "1024"],
        ),
        ("slmaster-david-heterodyne", "sin:f=64/58/53,steps=4", ["--projector-width", "1920"]),
        ("fpp-tools-lens", "sin:f=36,shifts=0/90/180/270deg", ["--glob", "lens_crop_*.jpg", "--shift-sign", "-1"]),
    ],
)
def test_real_data_imports_round_trip_byte_identical(
    tmp_path: Path, folder: str, spec: str, options: list[str]
) -> None:
    from rig.cli import main

    out = tmp_path / "capture"
    assert (
        main(["import", str(REAL_DATA / folder), "--patterns", spec, "-o", str(out), "--downsample", "4", *options])
        == 0
    )
    original, rewritten = _rewritten_bytes(out / "capture.json", tmp_path)
    assert rewritten == original


_numbers = st.floats(min_value=-10, max_value=10, allow_nan=False) | st.integers(-10, 10)
_extra = st.dictionaries(
    st.text("abcdefghij_", min_size=3, max_size=8).map(lambda k: f"x_{k}"),
    st.integers() | st.text(max_size=5) | st.booleans(),
    max_size=3,
)


@st.composite
def _entries(draw: st.DrawFn) -> dict:
    kind = draw(st.sampled_from(["sinusoid", "speckle-sinusoid", "gray", "flat"]))
    entry: dict = {"kind": kind}
    if kind in ("sinusoid", "speckle-sinusoid"):
        steps = draw(st.integers(1, 12))
        entry.update(
            frequency=draw(st.integers(1, 64) | st.floats(0.5, 64)), steps=steps, step=draw(st.integers(0, steps - 1))
        )
        for key in ("axis", "offset", "amplitude", "phase_rad", "shift_rad"):
            if draw(st.booleans()):
                entry[key] = draw(st.sampled_from(["x", "y"])) if key == "axis" else draw(_numbers)
        if kind == "speckle-sinusoid":
            for key, values in (
                ("seed", st.integers(0, 2**31)),
                ("dot_px", st.integers(1, 8)),
                ("speckle_gain", st.floats(0, 1)),
            ):
                if draw(st.booleans()):
                    entry[key] = draw(values)
    elif kind == "gray":
        bits = draw(st.integers(1, 10))
        entry.update(bits=bits, bit=draw(st.integers(0, bits - 1)))
        for key, values in (("axis", st.sampled_from(["x", "y"])), ("inverted", st.booleans())):
            if draw(st.booleans()):
                entry[key] = draw(values)
    else:
        entry["level"] = draw(_numbers)
    entry.update(draw(_extra))
    keys = draw(st.permutations(list(entry)))
    return {key: entry[key] for key in keys}


@settings(max_examples=200, deadline=None)
@given(_entries())
def test_any_valid_entry_round_trips_exactly(entry: dict) -> None:
    pattern = parse_pattern(entry)
    out = pattern.to_dict()
    assert json.dumps(out) == json.dumps(entry)  # same keys, same order, same values (5 stays 5)
    assert parse_pattern(out) == pattern
    assert pattern == entry and dict(pattern) == entry


def test_patterns_built_in_code_write_the_main_keys_and_changed_options() -> None:
    assert Sinusoid(frequency=8, steps=4, step=1).to_dict() == {
        "kind": "sinusoid",
        "axis": "x",
        "frequency": 8,
        "steps": 4,
        "step": 1,
    }
    assert list(Sinusoid(frequency=8, steps=4, step=1, phase_rad=math.pi).to_dict())[-1] == "phase_rad"
    assert Gray(bit=0, bits=3).to_dict() == {"kind": "gray", "axis": "x", "bit": 0, "bits": 3, "inverted": False}
    assert Flat(level=1).to_dict() == {"kind": "flat", "level": 1}
    parsed = parse_pattern({"step": 0, "kind": "sinusoid", "frequency": 4, "steps": 4, "note": "kept"})
    moved = parsed.replace(shift_rad=-1.0).to_dict()
    assert list(moved) == ["step", "kind", "frequency", "steps", "note", "shift_rad"]


@pytest.mark.parametrize(
    ("entry", "key", "message"),
    [
        ({"kind": "flat"}, "level", "level: missing"),
        ({"kind": "cross"}, "kind", "kind: expected one of sinusoid, speckle-sinusoid, gray, binary, flat"),
        (
            {"kind": "sinusoid", "frequency": 0, "steps": 4, "step": 0},
            "frequency",
            "expected a positive number, found 0",
        ),
        ({"kind": "sinusoid", "frequency": 4, "steps": 4, "step": 4}, "step", "expected 0 .. 3 (steps = 4), found 4"),
        (
            {"kind": "sinusoid", "frequency": 4, "steps": 4, "step": 0, "axis": "z"},
            "axis",
            "expected 'x' or 'y', found 'z'",
        ),
        ({"kind": "gray", "bit": 0, "bits": 2, "inverted": "yes"}, "inverted", "expected true or false, found 'yes'"),
        (
            {"kind": "speckle-sinusoid", "frequency": 4, "steps": 1, "step": 0, "seed": -1},
            "seed",
            "expected an integer >= 0, found -1",
        ),
        (
            {"kind": "speckle-sinusoid", "frequency": 4, "steps": 1, "step": 0, "dot_px": 0},
            "dot_px",
            "expected an integer >= 1, found 0",
        ),
        (
            {"kind": "speckle-sinusoid", "frequency": 4, "steps": 1, "step": 0, "speckle_gain": 1.5},
            "speckle_gain",
            "expected a value in [0, 1], found 1.5",
        ),
    ],
)
def test_one_validation_every_layer_names_the_key(entry: dict, key: str, message: str) -> None:
    with pytest.raises(PatternError) as info:
        parse_pattern(entry)
    assert info.value.key == key and message in str(info.value)
    with pytest.raises(CaptureError, match=rf"capture.json: patterns\[3\]\.{key}: "):
        validate_pattern("capture.json", 3, entry)
    with pytest.raises(ValueError, match=f"pattern .*{key}"):
        projector_validate(entry)
    with pytest.raises(ValueError, match=key):
        pattern_image(entry, (16, 8))


def test_same_projection_ignores_extra_keys_and_defaults_written_out() -> None:
    a = {"kind": "sinusoid", "axis": "x", "frequency": 8, "steps": 4, "step": 0, "source": "rig A"}
    b = {"kind": "sinusoid", "frequency": 8.0, "steps": 4, "step": 0, "offset": 0.5}
    assert same_projection(a, b)
    assert not same_projection(a, {**b, "step": 1})
    assert not same_projection(SpeckleSinusoid(frequency=8, steps=4, step=0), Sinusoid(frequency=8, steps=4, step=0))


def test_grouping_uses_the_typed_patterns() -> None:
    patterns = ScanConfig(frequencies=(1.0, 8.0), steps=3, gray_bits=2).pattern_models()
    groups = group_patterns(patterns)
    assert [(g.frequency, g.steps) for g in groups.along("x")] == [(1.0, 3), (8.0, 3)]
    assert groups.along("x")[0].shifts == pytest.approx([0.0, 2 * math.pi / 3, 4 * math.pi / 3])
    assert sorted(groups.gray["x"].planes) == [0, 1] and sorted(groups.gray["x"].inverted) == [0, 1]


def test_speckle_module_does_not_import_the_pattern_module() -> None:
    """processing.projection.speckle is the field; processing.projection.patterns uses it, not the other way round (no cycle)."""
    tree = ast.parse((ROOT / "processing" / "projection" / "speckle.py").read_text())
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import) for alias in node.names}
    assert "processing.projection.patterns" not in imported
