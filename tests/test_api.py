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


# ------------------------------------------------------------------ one processing entry


def test_process_options_defaults_are_rig_process_defaults() -> None:
    import argparse

    from rig.commands.process import add_processing_options, processing_options

    parser = argparse.ArgumentParser()
    add_processing_options(parser)
    assert processing_options(parser.parse_args([])) == api.ProcessOptions()
    assert api.ProcessOptions().correction == api.DEFAULT_CORRECTION


def test_a_loaded_capture_is_not_read_again(small_capture, monkeypatch) -> None:
    from rig.store import capture as capture_store

    capture = api.load_capture(small_capture.capture)

    def no_second_read(*_args, **_kwargs):
        raise AssertionError("the capture was read from disk again")

    monkeypatch.setattr(capture_store, "read_capture", no_second_read)
    monkeypatch.setattr("rig.pipeline.run.read_capture", no_second_read)
    result = api.process(capture, options=api.ProcessOptions(correction="none"))
    assert result.object.capture is capture


def test_frames_in_memory_give_the_same_result_as_their_capture(small_capture) -> None:
    capture = api.load_capture(small_capture.capture)
    stack = api.FrameStack(capture.load_frames(), capture.patterns, capture.projector_size, name="stack")
    options = api.ProcessOptions(correction="none")
    from_memory = api.process(stack, small_capture.calibration, options)
    from_disk = api.process(capture, small_capture.calibration, options)
    assert np.array_equal(from_memory.mask, from_disk.mask)
    assert np.array_equal(from_memory.height, from_disk.height, equal_nan=True)
    assert from_memory.report["capture"] == "stack"


def test_a_frame_stack_that_does_not_fit_its_patterns_is_one_line(small_capture) -> None:
    capture = api.load_capture(small_capture.capture)
    frames = capture.load_frames()
    with pytest.raises(api.CaptureError, match=r"expected \(N, H, W\) with N = \d+ patterns"):
        api.process(api.FrameStack(frames[:-1], capture.patterns, capture.projector_size))


def test_quick_pass_comes_first_without_the_correction(small_capture) -> None:
    quick: list = []
    result = api.process(
        small_capture.capture, small_capture.calibration, api.ProcessOptions(correction="vote"), quick=quick.append
    )
    assert [r.options.correction for r in quick] == ["none"] and result.options.correction == "vote"
    api.process(
        small_capture.capture, small_capture.calibration, api.ProcessOptions(correction="none"), quick=quick.append
    )
    assert len(quick) == 1  # nothing to be quick about without a correction


def _imports() -> dict[str, set[str]]:
    """Module -> the modules of this project it imports (anywhere in it, type-only imports included)."""
    import ast

    root = Path(api.__file__).resolve().parents[1]
    paths = {p: ".".join(p.relative_to(root).with_suffix("").parts) for p in root.glob("rig/**/*.py")}
    modules = {name.removesuffix(".__init__") for name in paths.values()}
    graph: dict[str, set[str]] = {}
    for path, name in paths.items():
        found: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ImportFrom) and node.module:
                found |= {node.module, *(f"{node.module}.{alias.name}" for alias in node.names)}
            elif isinstance(node, ast.Import):
                found |= {alias.name for alias in node.names}
        graph[name.removesuffix(".__init__")] = found & modules
    return graph


def test_only_rig_api_imports_the_pipeline_run() -> None:
    importers = {name for name, imported in _imports().items() if "rig.pipeline.run" in imported}
    assert importers == {"rig.api"}


def test_the_run_its_result_and_the_result_store_import_no_circle() -> None:
    graph = _imports()
    for start in ("rig.pipeline.run", "rig.pipeline.result", "rig.store.result_files", "rig.store.results", "rig.api"):
        seen, todo = set(), list(graph[start])
        while todo:
            module = todo.pop()
            assert module != start, f"{start} imports itself through {sorted(seen)}"
            if module not in seen:
                seen.add(module)
                todo.extend(graph.get(module, ()))


def test_scan_then_process_checks_everything_before_the_scan(small_capture, tmp_path) -> None:
    taken = tmp_path / "part-processed"
    taken.mkdir()
    (taken / "report.json").write_text('{"program": "fpp-rig 1"}')
    with pytest.raises(api.ResultExistsError, match="--overwrite"):
        api.scan_then_process(tmp_path / "part", small_capture.calibration)
    with pytest.raises(api.CalibrationError):
        api.scan_then_process(tmp_path / "part", tmp_path / "no-calibration", tmp_path / "elsewhere")
    assert not (tmp_path / "part").exists() and not (tmp_path / "elsewhere").exists()  # nothing scanned
