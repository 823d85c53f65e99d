"""The unwrapping registry: one entry per method, one return type, every front-end's list from it;
the phase stage's report says which path did the work (issue 19)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from processing.unwrap.temporal import UnwrapResult
from rig.commands.process import _unwrap_methods
from rig.pipeline import plan
from rig.pipeline.corrections import REGISTRY as CORRECTIONS
from rig.pipeline.registry import available_options, options_markdown
from rig.pipeline.run import process
from rig.pipeline.stages import DENOISERS, SCENE_STAGES
from rig.pipeline.unwrapping import REGISTRY, UNWRAP_METHODS, UnwrapInputs, UnwrapMethod, help_text

DOCS = Path(__file__).resolve().parents[1] / "docs" / "processing-options.md"

# Frequencies each entry is exercised with (whole counts as the methods need), lowest first.
CASES = {
    "two-frequency": [5, 8],
    "three-frequency": [6, 10, 15],
    "hierarchical": [1, 8, 64],
    "heterodyne": [64, 58, 53][::-1],
    "spatial": [4],
    "ftp": [4],
}


def _ignore_convention(*args: object, **kwargs: object) -> None:
    return None


def _inputs(frequencies: list[int]) -> tuple[UnwrapInputs, np.ndarray]:
    """Noise-free wrapped phases of a projector ramp u / W in [0, 1) across 64 x 200 pixels, and the truth."""
    u = np.broadcast_to(np.linspace(0.0, 0.999, 200), (64, 200))
    truths = [2 * np.pi * f * u for f in frequencies]
    phases = [np.angle(np.exp(1j * t)) for t in truths]
    valid = np.ones(u.shape, dtype=bool)
    return UnwrapInputs(phases, list(frequencies), valid, {}, _ignore_convention), truths[-1]


def test_every_front_end_lists_the_registry() -> None:
    assert all(isinstance(m, UnwrapMethod) and m.description and name == m.name for name, m in REGISTRY.items())
    assert UNWRAP_METHODS == ("auto", *REGISTRY)
    assert sorted(_unwrap_methods()) == sorted(UNWRAP_METHODS)
    assert all(f"{name}: " in help_text() for name in UNWRAP_METHODS)
    options = available_options()
    assert [c["name"] for c in options["unwrap"]["choices"]] == list(UNWRAP_METHODS)
    assert [c["name"] for c in options["correction"]["choices"]] == list(CORRECTIONS)
    assert [c["name"] for c in options["denoise"]["choices"]] == list(DENOISERS)
    assert json.loads(json.dumps(options)) == options  # served as JSON as it is
    assert DOCS.read_text(encoding="utf-8") == options_markdown(), "regenerate docs/processing-options.md"


@pytest.mark.parametrize("name", sorted(CASES))
def test_every_entry_returns_one_type_against_the_truth(name: str) -> None:
    method = REGISTRY[name]
    inputs, truth = _inputs(CASES[name])
    result = method(inputs)
    assert isinstance(result, UnwrapResult) and result.absolute is (name not in ("spatial", "ftp"))
    assert result.valid.all()
    if result.absolute:
        assert result.orders is not None
        np.testing.assert_allclose(result.phase, truth, atol=1e-6)
    else:  # spatial: the truth up to one multiple of 2 pi (one connected region), no fringe orders
        assert result.orders is None
        offset = result.phase - truth
        np.testing.assert_allclose(offset, offset.flat[0], atol=1e-6)
        assert abs(offset.flat[0] / (2 * np.pi) - round(offset.flat[0] / (2 * np.pi))) < 1e-9


def test_declared_needs_match_the_methods() -> None:
    assert [m.name for m in REGISTRY.values() if m.fused] == [
        "two-frequency",
        "three-frequency",
        "hierarchical",
        "heterodyne",
    ]
    assert REGISTRY["gray"].needs == ("gray",) and REGISTRY["three-frequency"].frequencies == 3
    assert not any(REGISTRY[name].rescue for name in ("gray", "spatial", "ftp"))


@pytest.mark.parametrize(("unwrap", "path"), [("auto", "fused_pass"), ("spatial", "phase_steps_s")])
def test_phase_stage_reports_the_path_that_did_the_work(small_capture, unwrap: str, path: str) -> None:
    result = process(small_capture.capture, small_capture.calibration, plan.ProcessOptions(unwrap=unwrap))
    names = [name for name, _ in SCENE_STAGES]
    assert names == ["load", "undistort", "denoise", "phase", "correction"]
    assert set(result.timings["object"]) == set(names)
    info = result.object.info
    assert path in info and ("fused_pass" in info) is (path == "fused_pass")
    if path == "phase_steps_s":
        assert set(info[path]) == {"wrapped", "unwrap"} and min(info[path].values()) >= 0
