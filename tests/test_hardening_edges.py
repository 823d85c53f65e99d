"""Issue 10, the classes left after the file layer: degenerate maps in the preview, camera matrices
that cannot be inverted, `rig calibrate --overwrite`, the demo report's paths, a read-only output
filesystem and the OpenCV FileStorage reader's errors."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from rig.cli import main
from rig.errors import OutputError
from rig.pipeline import outputs
from rig.pipeline.outputs import write_outputs, write_preview
from rig.pipeline.run import process
from rig.store import files

REPO = Path(__file__).resolve().parents[1]


def run(capsys, *argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


def assert_one_line(code: int, err: str, *fragments: str) -> None:
    lines = [line for line in err.splitlines() if ": error:" in line]
    assert code == 1 and len(lines) == 1 and "Traceback" not in err, err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]


# 5. the preview of a degenerate map (the crash after phase.npy was written) ---------------------

DEGENERATE_MAPS = {
    "all-nan": lambda shape: np.full(shape, np.nan),
    "constant": lambda shape: np.full(shape, 7.0),
    "constant-huge": lambda shape: np.full(shape, 1e20),  # the ends coincide after +-0.5: was 0/0 in a tick
    "span-overflows": lambda shape: np.where(np.indices(shape)[1] % 2 == 0, -1e308, 1e308),  # was an endless tick loop
    "infinities": lambda shape: np.where(np.indices(shape)[1] % 2 == 0, np.inf, -np.inf),
    "one-finite": lambda shape: np.where(np.indices(shape).sum(axis=0) == 0, 3.0, np.nan),
    "float32-extremes": lambda shape: np.where(np.indices(shape)[0] % 2 == 0, 3.4e38, -3.4e38),
    "subnormal": lambda shape: np.arange(np.prod(shape)).reshape(shape) * 5e-324,
}


@pytest.mark.parametrize("name", sorted(DEGENERATE_MAPS))
def test_preview_of_a_degenerate_map_is_drawn(tmp_path, name) -> None:
    values = DEGENERATE_MAPS[name]((24, 40))
    with np.errstate(over="raise", divide="raise", invalid="raise"):  # no hidden overflow or 0/0 either
        low, high = write_preview(tmp_path / "p.png", values, "mm", name)
    assert np.isfinite([low, high, high - low]).all() and low < high
    import cv2

    assert cv2.imread(str(tmp_path / "p.png")).shape[:2] == (24, 40 + outputs.PREVIEW_BAR_PX)


def test_preview_of_an_empty_map_is_drawn(tmp_path) -> None:
    assert write_preview(tmp_path / "p.png", np.zeros((0, 0)), "rad") == (0.0, 1.0)  # was SIGFPE in OpenCV


@pytest.mark.parametrize("name", ["constant-huge", "span-overflows", "all-nan"])
def test_outputs_of_a_degenerate_height_map_are_complete(tmp_path, small_capture, name) -> None:
    result = process(small_capture.capture, small_capture.calibration)
    with np.errstate(over="ignore"):  # 1e308 becomes an infinity in float32, as a height would
        height = DEGENERATE_MAPS[name](result.mask.shape).astype(np.float32)
    out = tmp_path / "out"
    report = write_outputs(replace(result, height=height), out)
    on_disk = json.loads((out / "report.json").read_text(), parse_constant=lambda c: pytest.fail(c))
    assert on_disk["preview"] == report["preview"] and np.isfinite(report["preview"]["range"]).all()
    assert {p.name for p in out.iterdir()} == set(report["files"].values())


def test_a_failing_preview_keeps_the_old_output(tmp_path, small_capture, monkeypatch) -> None:
    result = process(small_capture.capture, small_capture.calibration)
    out = tmp_path / "out"
    write_outputs(result, out)
    before = {p.name: p.read_bytes() for p in out.iterdir()}

    def broken(*_args, **_kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(outputs, "write_preview", broken)
    with pytest.raises(OSError):
        write_outputs(result, out)
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before
    assert not list(tmp_path.glob("out.*"))  # no staging directory left behind
