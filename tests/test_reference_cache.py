"""The processed reference plane is reused while nothing it depends on changes, and only then."""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pytest

from rig.api import process_to
from rig.pipeline import reference_cache
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process


@pytest.fixture(autouse=True)
def _empty_memory(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setenv(reference_cache.CACHE_ENV, str(tmp_path / "user-cache"))
    reference_cache.forget()
    yield
    reference_cache.forget()


def process_capture(capture: Path, calibration: Path, out: Path, options: ProcessOptions) -> dict:
    """What `rig process` runs: processing (caching the reference on disk) then the outputs."""
    return process_to(capture, out, calibration, options)


def _cache() -> Path:
    root = reference_cache.cache_root()
    assert root is not None
    return root / reference_cache.DIRECTORY


def _entries(_calibration: Path | None = None) -> list[Path]:
    return sorted(_cache().glob(f"{reference_cache.PREFIX}*.npz"))


def _listing(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob("*"))


def _reference_cached(out: Path) -> bool:
    return "cached" in json.loads((out / "report.json").read_text())["timings_s"]["reference"]


def test_second_run_reads_the_reference_from_the_user_cache(small_capture, tmp_path: Path) -> None:
    options = ProcessOptions(correction="none")
    calibration_files = _listing(small_capture.calibration)
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", options)
    assert _listing(small_capture.calibration) == calibration_files  # nothing written beside the user's data
    assert len(_entries(small_capture.calibration)) == 1
    assert not _reference_cached(tmp_path / "a")
    reference_cache.forget()  # a new process: nothing in memory, the file is what is reused
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "b", options)
    assert _reference_cached(tmp_path / "b")
    first, second = (np.load(tmp_path / name / "height.npy") for name in ("a", "b"))
    np.testing.assert_array_equal(first, second)
    assert not list(_cache().glob(".tmp-*"))


def test_in_memory_processing_writes_nothing_but_reuses_in_memory(small_capture) -> None:
    options = ProcessOptions(correction="none")
    first = process(small_capture.capture, small_capture.calibration, options)
    assert not _cache().exists()
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
    else:  # another reference capture or calibration: a new entry (the stale one ages out)
        assert len(after) == 2 and set(before) < set(after)


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


def test_disabled_cache_writes_nothing(small_capture, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv(reference_cache.CACHE_ENV, "off")
    assert reference_cache.cache_root() is None
    process_capture(small_capture.capture, small_capture.calibration, tmp_path / "a", ProcessOptions(correction="none"))
    assert (tmp_path / "a" / "height.npy").exists() and not (tmp_path / "user-cache").exists()


def test_unwritable_cache_path_goes_without(small_capture, tmp_path: Path) -> None:
    """A file where the cache directory would be (or any OSError writing it) only costs the cache."""
    _cache().parent.mkdir(parents=True)
    _cache().write_text("in the way")
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


def test_calibration_and_reference_manifests_are_read_again_when_their_files_change(small_capture) -> None:
    options = ProcessOptions(correction="none")
    first = process(small_capture.capture, small_capture.calibration, options)
    again = process(small_capture.capture, small_capture.calibration, options)
    assert again.calibration is first.calibration  # unchanged files: read and checked once
    assert again.reference is not None and first.reference is not None
    assert again.reference.capture is first.reference.capture
    path = small_capture.calibration / "calibration.json"
    data = json.loads(path.read_text())
    data["l0_mm"] *= 1.1
    path.write_text(json.dumps(data))
    recalibrated = process(small_capture.capture, small_capture.calibration, options)
    assert recalibrated.calibration is not first.calibration
    assert recalibrated.calibration.l0_mm == pytest.approx(data["l0_mm"])
    assert recalibrated.height is not None and first.height is not None
    assert not np.allclose(recalibrated.height[first.mask], first.height[first.mask])
    manifest = small_capture.calibration / "reference" / "capture.json"
    manifest.write_text(manifest.read_text())  # rewritten: another file version, read again
    rewritten = process(small_capture.capture, small_capture.calibration, options)
    assert rewritten.reference is not None and rewritten.reference.capture is not recalibrated.reference.capture
