"""The public Python API (rig.api) and the services' events and cancellation."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rig import api
from rig.events import Cancelled, CancelToken, Event, Reporter


def test_process_in_memory_writes_nothing_then_outputs_match(small_capture, tmp_path: Path) -> None:
    before = sorted(p.name for p in tmp_path.rglob("*"))
    capture = api.load_capture(small_capture.capture)
    events: list[Event] = []
    result = api.process(capture, small_capture.calibration, progress=Reporter("process", sink=events.append))
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # in memory: no file written
    truth = np.load(small_capture.truth)
    valid = result.mask
    assert result.height is not None and result.points is not None
    assert valid.mean() > 0.5
    assert float(np.sqrt(np.nanmean((result.height[valid] - truth[valid]) ** 2))) < 0.5  # mm, 35 dB hemisphere
    assert result.report["methods"]["correction"] == api.DEFAULT_CORRECTION
    assert result.report["valid_fraction"] == pytest.approx(valid.mean())
    kinds = [e.kind for e in events]
    assert kinds[0] == "begin" and kinds.count("step") == events[0].total and events[-1].done == events[0].total
    report = api.write_outputs(result, tmp_path / "out")
    assert np.array_equal(np.load(tmp_path / "out" / "height.npy"), result.height, equal_nan=True)
    assert json.loads((tmp_path / "out" / "report.json").read_text())["valid_fraction"] == report["valid_fraction"]


def test_cancelled_processing_raises_and_writes_nothing(small_capture) -> None:
    token = CancelToken()
    steps: list[str] = []

    def stop_after_two(event: Event) -> None:
        if event.kind == "step":
            steps.append(event.note)
            if len(steps) == 2:
                token.cancel("stop pressed")

    with pytest.raises(Cancelled, match="stop pressed"):
        api.process(small_capture.capture, small_capture.calibration, progress=Reporter("p", stop_after_two, token))
    assert len(steps) == 2


def test_cancelled_scan_leaves_no_complete_capture(tmp_path: Path) -> None:
    token = CancelToken()

    def stop_at_third_frame(event: Event) -> None:
        if event.kind == "step" and event.done == 3:
            token.cancel()

    out = tmp_path / "part"
    with pytest.raises(Cancelled):
        api.scan(out, progress=Reporter("scan", stop_at_third_frame, token))
    assert not out.exists()
    leftovers = list(tmp_path.iterdir())
    for directory in leftovers:  # kept for salvage, visibly incomplete
        assert json.loads((directory / "capture.json").read_text())["complete"] is False


def test_scan_service_reports_every_frame(tmp_path: Path) -> None:
    events: list[Event] = []
    result = api.scan(tmp_path / "part", progress=Reporter("scan", events.append))
    steps = [e for e in events if e.kind == "step"]
    assert events[0].kind == "begin" and events[0].total == len(result.frames) == len(steps)
    assert api.load_capture(result.path).complete
