"""Fuzzing the inputs a user controls (issue 10): mutated captures, calibrations, configs, arguments.

Seeded (``derandomize=True``) and bounded so the suite stays fast. Every run must end in success
or in exit status 1 with exactly one error line, no traceback, nothing created outside the output
it named, and no output left claiming success.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from rig.cli import main
from rig.store.capture import CaptureWriter

FUZZ = settings(
    max_examples=25,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

PATTERNS = [{"kind": "sinusoid", "axis": "x", "frequency": f, "steps": 3, "step": j} for f in (1, 4) for j in range(3)]

json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(-(2**70), 2**70),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=12),
    st.sampled_from(["../../etc/passwd", "/etc/passwd", "frames/000.png", "", "\u0000x", "a" * 300]),
)
json_values = st.recursive(
    json_scalars,
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=6), inner, max_size=3),
    max_leaves=8,
)


@pytest.fixture(scope="module")
def pristine(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fuzz")
    rng = np.random.default_rng(0)
    with CaptureWriter(
        root / "cap", {"width": 24, "height": 16, "bit_depth": 8}, {"width": 64, "height": 48}, PATTERNS
    ) as writer:
        for i in range(len(PATTERNS)):
            writer.add_frame(i, rng.integers(0, 255, (16, 24), dtype=np.uint8))
    return root / "cap"


def _paths(obj: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path inside a JSON document."""
    out = [prefix]
    if isinstance(obj, dict):
        for key, value in obj.items():
            out += _paths(value, prefix + (key,))
    elif isinstance(obj, list):
        for i, value in enumerate(obj):
            out += _paths(value, prefix + (i,))
    return out


def _set(obj: Any, path: tuple, value: Any) -> Any:
    if not path:
        return value
    parent = obj
    for key in path[:-1]:
        parent = parent[key]
    parent[path[-1]] = value
    return obj


def _listing(root: Path) -> set[str]:
    return {str(p.relative_to(root)) for p in root.rglob("*")}


def assert_clean_outcome(code: int, err: str, root: Path, before: set[str], output: Path | None) -> None:
    assert "Traceback" not in err, err
    if code != 0:
        lines = [line for line in err.splitlines() if line.strip() and " error: " in line]
        assert code == 1 and len(lines) == 1, err
        assert (
            len(
                [
                    line
                    for line in err.splitlines()
                    if line.strip()
                    and ": error:" not in line
                    and not line.startswith(("process ", "scan ", "simulate "))
                ]
            )
            == 0
        ), err
        if output is not None:
            assert not output.exists() or output.name in before, f"failed run left {output}"
    created = _listing(root) - before
    allowed = str(output.relative_to(root)) if output is not None else None
    stray = {c for c in created if allowed is None or not (c == allowed or c.startswith(allowed + "/"))}
    assert not stray, f"written outside the named output: {sorted(stray)[:5]}"


@FUZZ
@given(data=st.data())
def test_mutated_capture_manifest(capsys, tmp_path_factory, pristine, data) -> None:
    root = tmp_path_factory.mktemp("m")
    cap = root / "cap"
    shutil.copytree(pristine, cap)
    manifest = json.loads((cap / "capture.json").read_text())
    for _ in range(data.draw(st.integers(1, 3))):
        path = data.draw(st.sampled_from(_paths(manifest)[1:]))
        manifest = _set(manifest, path, data.draw(json_values))
    text = json.dumps(manifest, allow_nan=True)
    (cap / "capture.json").write_text(text)
    before = _listing(root)
    out = root / "out"
    command = data.draw(st.sampled_from(["info", "process"]))
    argv = ["info", str(cap)] if command == "info" else ["process", str(cap), "-o", str(out), "-q"]
    code = main(argv)
    assert_clean_outcome(code, capsys.readouterr().err, root, before, out if command == "process" else None)


@FUZZ
@given(data=st.data())
def test_mutated_frame_files(capsys, tmp_path_factory, pristine, data) -> None:
    root = tmp_path_factory.mktemp("f")
    cap = root / "cap"
    shutil.copytree(pristine, cap)
    frame = cap / "frames" / f"{data.draw(st.integers(0, len(PATTERNS) - 1)):03d}.png"
    original = frame.read_bytes()
    kind = data.draw(st.sampled_from(["truncate", "flip", "link-out", "dir", "empty"]))
    if kind == "truncate":
        frame.write_bytes(original[: data.draw(st.integers(0, len(original) - 1))])
    elif kind == "flip":
        at = data.draw(st.integers(0, len(original) - 1))
        frame.write_bytes(original[:at] + bytes([original[at] ^ 0xFF]) + original[at + 1 :])
    elif kind == "link-out":
        frame.unlink()
        frame.symlink_to("/etc/passwd")
    elif kind == "dir":
        frame.unlink()
        frame.mkdir()
    else:
        frame.write_bytes(b"")
    before = _listing(root)
    code = main(["info", str(cap)])
    assert_clean_outcome(code, capsys.readouterr().err, root, before, None)
    assert code == 1


@FUZZ
@given(
    key=st.sampled_from(["l0_mm", "d0_mm", "f0_per_mm", "f0_frequency", "pixel_mm", "reference", "model", "format"]),
    value=json_values,
)
def test_mutated_calibration(capsys, tmp_path_factory, small_scan, key, value) -> None:
    from rig.hardware.synthesis import write_simulated_scan

    root = tmp_path_factory.mktemp("c")
    paths = write_simulated_scan(small_scan, root / "scan")
    path = paths.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data[key] = value
    path.write_text(json.dumps(data, allow_nan=True))
    before = _listing(root)
    out = root / "out"
    code = main(["process", str(paths.capture), "--calibration", str(paths.calibration), "-o", str(out), "-q"])
    assert_clean_outcome(code, capsys.readouterr().err, root, before, out)
    if code == 0:
        report = json.loads((out / "report.json").read_text())
        assert (
            "Infinity" not in json.dumps(report)
            and np.isfinite(np.load(out / "height.npy")[np.load(out / "mask.npy")]).all()
        )


toml_values = st.one_of(
    st.integers(-(2**63), 2**63 - 1).map(str),
    st.floats(allow_nan=False).map(lambda v: repr(v).replace("inf", "1e999")),
    st.text(alphabet="abc[]{}=\"'\\\n 0123456789.,-", max_size=20),
    st.sampled_from(['"none"', "[1, 1e308]", "[100000, 100000]", "true"]),
)
CONFIG_KEYS = [
    ("camera", "size"),
    ("camera", "exposure_us"),
    ("scan", "frequencies"),
    ("scan", "steps"),
    ("scan", "retries"),
    ("trigger", "baudrate"),
    ("trigger", "timeout_s"),
    ("simulation", "snr_db"),
    ("projector", "size"),
    ("scan", "speckle_frequency"),
    ("simulation", "scene"),
]


@FUZZ
@given(section_key=st.sampled_from(CONFIG_KEYS), value=toml_values)
def test_mutated_config(capsys, tmp_path_factory, section_key, value) -> None:
    from rig.config import load_config
    from rig.errors import ConfigError

    root = tmp_path_factory.mktemp("t")
    config = root / "rig.toml"
    config.write_text(f"[{section_key[0]}]\n{section_key[1]} = {value}\n")
    try:  # parsing alone: every wrong value is a ConfigError, nothing else
        load_config(config)
    except ConfigError as exc:
        assert "\n" not in str(exc)


@FUZZ
@given(
    argv=st.lists(
        st.one_of(
            st.sampled_from(
                ["--size", "--steps", "--frequencies", "--snr-db", "--seed", "--scene", "--overwrite", "--pattern-set"]
            ),
            st.text(alphabet="0123456789x.-e+abc/", max_size=10),
        ),
        max_size=6,
    )
)
def test_fuzzed_simulate_arguments(capsys, tmp_path_factory, monkeypatch, argv) -> None:
    monkeypatch.setenv("RIG_MAX_IMAGE_SIDE", "64")  # any size the fuzzer finds stays small
    root = tmp_path_factory.mktemp("a")
    out = root / "sim"
    before = _listing(root)
    try:
        code = main(["simulate", "-o", str(out), "--size", "24x16", "--frequencies", "1", "--steps", "3", *argv])
    except SystemExit as exit_:  # argparse's usage error: its own exit status 2, never a traceback
        assert exit_.code == 2
        return
    assert_clean_outcome(code, capsys.readouterr().err, root, before, out)
