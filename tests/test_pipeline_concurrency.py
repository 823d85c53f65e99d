"""The in-memory pipeline's parallel steps change no output: blocks shared by two threads, and the
islands found beside the uncertainty map, against the same run on one thread and the islands' definition."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from mock_devices import synth
from processing import concurrency
from processing.correction.islands import island_mask
from processing.unwrap import fused_pass
from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.result import ProcessResult
from rig.pipeline.run import process

FRACTION = ProcessOptions().min_island_fraction


@pytest.fixture(autouse=True)
def small_blocks(monkeypatch: pytest.MonkeyPatch) -> None:
    """Blocks of 16k pixels, so the small capture below spans five and the threads share them."""
    monkeypatch.setattr(fused_pass, "BLOCK", 16384)


@pytest.fixture(scope="module")
def scan(tmp_path_factory: pytest.TempPathFactory) -> tuple[np.ndarray, Path, Path]:
    """A 320 x 240 two-frequency six-step capture (five blocks of the fused pass), noisy enough for islands."""
    simulated = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(320, 240),
        patterns=synth.sinusoid_patterns((15, 16), 6),
        appearance=synth.Appearance(ambient=0.0, snr_db=12.0, bit_depth=8),
        seed=4,
    )
    paths = write_simulated_scan(simulated, tmp_path_factory.mktemp("concurrency") / "scan")
    return simulated.object_frames, paths.capture, paths.calibration


def _run(scan: tuple[np.ndarray, Path, Path], **options: Any) -> ProcessResult:
    frames, capture, calibration = scan
    return process(capture, calibration, ProcessOptions(correction="none", **options), frames=frames)


def _same(a: ProcessResult, b: ProcessResult) -> None:
    """Equal masks and islands; heights and sigmas equal up to BLAS's last-bit rounding (buffer alignment)."""
    assert a.height is not None and b.height is not None
    assert a.uncertainty is not None and b.uncertainty is not None
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_allclose(a.height, b.height, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(a.uncertainty, b.uncertainty, rtol=1e-6, atol=1e-9)
    assert a.object.info["islands_dropped"] == b.object.info["islands_dropped"]


def test_two_threads_give_the_one_thread_result(scan, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(concurrency, "THREADS", 1)
    alone = _run(scan)
    monkeypatch.setattr(concurrency, "THREADS", 2)
    shared = _run(scan)
    assert alone.object.info["islands_dropped"] > 0  # the island step has something to do
    _same(alone, shared)


def test_islands_beside_the_uncertainty_match_their_definition_and_the_sequential_path(scan) -> None:
    beside = _run(scan)  # no --max-sigma: the islands are found beside the uncertainty map
    sequential = _run(scan, max_sigma=1e9)  # a bound that drops nothing: the islands after it, in turn
    kept_all = _run(scan, min_island_fraction=0.0)
    _same(beside, sequential)
    expected = kept_all.mask & ~island_mask(kept_all.mask, FRACTION)
    np.testing.assert_array_equal(beside.mask, expected)
    assert np.count_nonzero(kept_all.mask & ~beside.mask) == beside.object.info["islands_dropped"] > 0
