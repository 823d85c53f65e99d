"""The processed reference plane is reused while nothing it depends on changes, and only then."""

from __future__ import annotations

import json
import os
import stat
from pathlib import Path

import numpy as np
import pytest

from rig.pipeline import reference_cache
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process, process_capture


@pytest.fixture(autouse=True)
def _empty_memory():
    reference_cache.forget()
    yield
    reference_cache.forget()


def _entries(calibration: Path) -> list[Path]:
    return sorted((calibration / reference_cache.DIRECTORY).glob(f"{reference_cache.PREFIX}*.npz"))


def _reference_cached(out: Path) -> bool:
    return "cached" in json.loads((out / "report.json").read_text())["timings_s"]["reference"]


def test_second_run_reads_the_reference_from_the_calibration_directory(small_capture, tmp_path: Path) -> None:
    options = ProcessOptions(correction="none")
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", options)
    assert len(_entries(small_capture.calibration)) == 1
    assert not _reference_cached(tmp_path / "a")
    reference_cache.forget()  # a new process: nothing in memory, the file is what is reused
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "b", options)
    assert _reference_cached(tmp_path / "b")
    first, second = (np.load(tmp_path / name / "height.npy") for name in ("a", "b"))
    np.testing.assert_array_equal(first, second)
    assert not list((small_capture.calibration / reference_cache.DIRECTORY).glob(".tmp-*"))


def test_in_memory_processing_writes_nothing_but_reuses_in_memory(small_capture) -> None:
    options = ProcessOptions(correction="none")
    first = process(small_capture.capture, small_capture.calibration, options)
    assert not (small_capture.calibration / reference_cache.DIRECTORY).exists()
    second = process(small_capture.capture, small_capture.calibration, options)
    assert second.reference is not None and "cached" in second.reference.timings
    np.testing.assert_array_equal(first.height, second.height)
    with pytest.raises(ValueError):
        second.reference.unwrapped.phase[0, 0] = 0.0  # shared between runs: read-only


@pytest.mark.parametrize("change", ["options", "reference frame", "calibration file"])
def test_any_change_misses_and_replaces_the_stale_entry(small_capture, tmp_path: Path, change: str) -> None:
    options = ProcessOptions(correction="none")
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", options)
    before = _entries(small_capture.calibration)
    reference_cache.forget()
    if change == "options":
        options = ProcessOptions(correction="none", min_modulation_ratio=0.3)
    elif change == "reference frame":
        frame = sorted((small_capture.calibration / "reference" / "frames").iterdir())[0]
        os.utime(frame, ns=(frame.stat().st_atime_ns, frame.stat().st_mtime_ns + 1_000_000_000))
    else:
        path = small_capture.calibration / "calibration.json"
        data = json.loads(path.read_text())
        data["note"] = "recalibrated"
        path.write_text(json.dumps(data))
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "b", options)
    assert not _reference_cached(tmp_path / "b")
    after = _entries(small_capture.calibration)
    if change == "options":  # both option sets stay usable side by side
        assert len(after) == 2 and set(before) < set(after)
        reference_cache.forget()
        process_capture(
            small_capture.capture, small_capture.calibration, tmp_path / "c", ProcessOptions(correction="none")
        )
        assert _reference_cached(tmp_path / "c")
    else:  # another reference capture or calibration: the old entry is stale and removed
        assert len(after) == 1 and after != before


def test_corrupt_entry_is_processed_again_and_rewritten(small_capture, tmp_path: Path) -> None:
    options = ProcessOptions(correction="none")
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", options)
    (entry,) = _entries(small_capture.calibration)
    entry.write_bytes(b"not an npz file")
    reference_cache.forget()
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "b", options)
    assert not _reference_cached(tmp_path / "b")
    with np.load(_entries(small_capture.calibration)[0]) as data:
        assert data["phase"].shape == np.load(tmp_path / "b" / "height.npy").shape


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into read-only directories")
def test_read_only_calibration_directory_goes_without(small_capture, tmp_path: Path) -> None:
    calibration = small_capture.calibration
    mode = calibration.stat().st_mode
    calibration.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    try:
        process_capture(small_capture.capture, calibration, tmp_path / "a", ProcessOptions(correction="none"))
    finally:
        calibration.chmod(mode)
    assert (tmp_path / "a" / "height.npy").exists() and not _entries(calibration)


def test_unwritable_cache_path_goes_without(small_capture, tmp_path: Path) -> None:
    """A file where the cache directory would be (or any OSError writing it) only costs the cache."""
    (small_capture.calibration / reference_cache.DIRECTORY).write_text("in the way")
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", ProcessOptions(correction="none"))
    assert (tmp_path / "a" / "height.npy").exists()


def test_frames_in_memory_give_the_same_result_and_are_checked(small_capture) -> None:
    from rig.errors import ProcessingError
    from rig.store.capture import read_capture

    options = ProcessOptions(correction="none")
    frames = read_capture(small_capture.capture).load_frames()
    from_disk = process(small_capture.capture, small_capture.calibration, options)
    in_memory = process(small_capture.capture, small_capture.calibration, options, frames=frames)
    np.testing.assert_array_equal(from_disk.height, in_memory.height)
    with pytest.raises(ProcessingError, match="frames: expected shape"):
        process(small_capture.capture, small_capture.calibration, options, frames=frames[1:])
    with pytest.raises(ProcessingError, match="frames: expected dtype"):
        process(small_capture.capture, small_capture.calibration, options, frames=frames.astype(np.float64))
