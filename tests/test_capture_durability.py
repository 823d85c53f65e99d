"""Capture writer durability: what is fsynced, and in which order relative to the renames.

A capture may claim ``complete: true`` only once its frames and manifest are on disk: every
frame file and the final manifest must be fsynced before the directory is renamed to its final
path, and the parent directory after. The ``complete: false`` manifest of a scan in progress is
fsynced at most every ``manifest_sync_s``. Calls to ``os.fsync`` / ``os.replace`` are recorded
with the path each file descriptor names (Linux ``/proc/self/fd``).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from rig.store import capture as capture_module
from rig.store import files
from rig.store.capture import CaptureWriter, read_capture

pytestmark = pytest.mark.skipif(not Path("/proc/self/fd").is_dir(), reason="needs /proc/self/fd to name fsynced files")

PROJECTOR = {"width": 64, "height": 32}
CAMERA = {"width": 32, "height": 24, "bit_depth": 8}
PATTERNS = [{"kind": "sinusoid", "axis": "x", "frequency": 2, "steps": 4, "step": j} for j in range(4)]


@pytest.fixture
def disk_log(monkeypatch: pytest.MonkeyPatch) -> list[tuple[str, ...]]:
    """Every fsync ('fsync', path) and replace ('replace', src, dst) made while writing, in order."""
    events: list[tuple[str, ...]] = []
    real_fsync, real_replace = os.fsync, os.replace

    def fsync(fd: int) -> None:
        events.append(("fsync", os.readlink(f"/proc/self/fd/{fd}")))
        real_fsync(fd)

    def replace(src, dst) -> None:
        events.append(("replace", str(src), str(dst)))
        real_replace(src, dst)

    real_commit_rename = files.rename_noreplace

    def commit_rename(src, dst) -> None:
        events.append(("replace", str(src), str(dst)))
        real_commit_rename(src, dst)

    monkeypatch.setattr(capture_module.os, "fsync", fsync)
    monkeypatch.setattr(capture_module.os, "replace", replace)
    monkeypatch.setattr(files, "rename_noreplace", commit_rename)
    return events


def _write(path: Path, sync_s: float | None = None) -> None:
    images = np.random.default_rng(0).integers(0, 255, size=(len(PATTERNS), 24, 32), dtype=np.uint8)
    writer = CaptureWriter(path, CAMERA, PROJECTOR, PATTERNS)
    if sync_s is not None:
        writer.manifest_sync_s = sync_s
    with writer:
        for i, image in enumerate(images):
            writer.add_frame(i, image)


def _manifest_fsyncs(events: list[tuple[str, ...]]) -> list[int]:
    """Positions of fsyncs of manifest temporaries (``.capture.json.*.tmp``)."""
    return [i for i, e in enumerate(events) if e[0] == "fsync" and Path(e[1]).name.startswith(".capture.json.")]


def test_commit_syncs_frames_and_manifest_before_the_capture_appears(tmp_path: Path, disk_log) -> None:
    final = tmp_path / "scan"
    _write(final)
    assert read_capture(final).complete
    (commit,) = [i for i, e in enumerate(disk_log) if e[0] == "replace" and e[2] == str(final)]
    temp = Path(disk_log[commit][1])
    synced_before = {e[1] for e in disk_log[:commit] if e[0] == "fsync"}
    frames = {str(temp / "frames" / f"{i:03d}.png") for i in range(len(PATTERNS))}
    assert frames <= synced_before, sorted(frames - synced_before)
    assert {str(temp / "frames"), str(temp)} <= synced_before  # the directory entries too
    # The manifest renamed last into the temporary directory (complete: true) was fsynced first.
    manifests = [i for i, e in enumerate(disk_log[:commit]) if e[0] == "replace" and e[2] == str(temp / "capture.json")]
    last_manifest = disk_log[manifests[-1]][1]
    assert ("fsync", last_manifest) in disk_log[: manifests[-1]]
    assert ("fsync", str(tmp_path)) in disk_log[commit:]  # the rename itself made durable


def test_manifest_in_progress_is_not_synced_after_every_frame(tmp_path: Path, disk_log) -> None:
    _write(tmp_path / "scan")  # a few small frames: well within one manifest_sync_s
    rewrites = [e for e in disk_log if e[0] == "replace" and e[2].endswith("capture.json")]
    assert len(rewrites) == 1 + len(PATTERNS) + 1  # on entry, after every frame, at commit
    assert len(_manifest_fsyncs(disk_log)) == 1  # only the commit's


def test_manifest_sync_interval_zero_syncs_every_rewrite(tmp_path: Path, disk_log) -> None:
    _write(tmp_path / "scan", sync_s=0.0)
    assert len(_manifest_fsyncs(disk_log)) == 1 + len(PATTERNS) + 1


def test_interrupted_capture_syncs_its_manifest(tmp_path: Path, disk_log) -> None:
    writer = CaptureWriter(tmp_path / "scan", CAMERA, PROJECTOR, PATTERNS)
    with pytest.raises(RuntimeError), writer:
        writer.add_frame(0, np.zeros((24, 32), np.uint8))
        raise RuntimeError("operator pulled the cable")
    (partial,) = tmp_path.glob("scan.incomplete-*")
    salvaged = read_capture(partial, salvage=True)
    assert not salvaged.complete and len(salvaged.frames) == 1 and "RuntimeError" in salvaged.manifest["interrupted"]
    last = _manifest_fsyncs(disk_log)[-1]
    rename = [e for e in disk_log[last:] if e[0] == "replace"][0]
    assert rename[2] == str(partial / "capture.json")  # the interrupted note is what got synced
