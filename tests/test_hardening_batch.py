"""Issue 22 reproducers for the batch runner and the store: one test per class.

The batch's clean-up touches only what it wrote (4), staging names are never read as finished
inputs (5) nor accepted as output names (11), the batch reads manifests through the safe file
layer (13), a full disk names the file and is not an "internal error", symbolic links to capture
folders get their own index row.
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from cli_steps import assert_one_line, run

from rig.batch.discovery import LINK_REASON, STAGING_REASON, discover
from rig.batch.index import read_table
from rig.batch.tasks import CaptureTask, run_task
from rig.cli import main
from rig.errors import CaptureError, OutputError
from rig.hardware.synthesis import write_simulated_archive
from rig.pipeline.plan import ProcessOptions
from rig.store import files, result_files
from rig.store.capture import CaptureWriter, read_capture

REPO = Path(__file__).resolve().parents[1]
SUBPROCESS_TIMEOUT_S = 120
PATTERNS = [{"kind": "sinusoid", "axis": "x", "frequency": 1, "steps": 3, "step": j} for j in range(3)]
CAMERA = {"width": 16, "height": 12, "bit_depth": 8}
PROJECTOR = {"width": 32, "height": 24}


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    """Two simulated 64x48 scans and their calibration: ``ROOT/archive``, ``ROOT/calibration``."""
    return write_simulated_archive(tmp_path_factory.mktemp("archive"), 2, 64, 48, seed=5)


def _tree(root: Path) -> dict[str, bytes | None]:
    """Every path under ``root`` with its bytes (None for a folder)."""
    return {str(p.relative_to(root)): None if p.is_dir() else p.read_bytes() for p in sorted(root.rglob("*"))}


# 4. the batch's clean-up touches only what a batch writes, by exact name ---------------------------------


def test_batch_into_a_parent_of_the_archive_keeps_salvage_captures_and_user_folders(archive, tmp_path) -> None:
    source, calibration = archive
    data = tmp_path / "data"  # OUT: the archive, a kept interrupted capture and a user's folders below it
    shutil.copytree(source, data / "archive")
    interrupted = data / "archive" / "scan-001" / "object.incomplete-k3pt9q2z"
    shutil.copytree(data / "archive" / "scan-001" / "object", interrupted)
    manifest = json.loads((interrupted / "capture.json").read_text())
    (interrupted / "capture.json").write_text(json.dumps({**manifest, "complete": False}))
    mine = data / "thesis.replaced-20240101"
    mine.mkdir()
    (mine / "draft.tex").write_text("years of work")
    (data / "archive" / ".notes.tmp").write_text("a user's file")
    (data / "scan-000").mkdir()
    (data / "scan-000" / "object.incomplete-user1234").mkdir()  # a user's folder of the same shape, not ours
    (data / "scan-000" / "object.incomplete-user1234" / "capture.json").write_text("{}")
    kept = {p: _tree(p) for p in (interrupted, mine, data / "scan-000" / "object.incomplete-user1234")}
    stale = data / "scan-000" / "object.incomplete-ab12cd34"  # what a killed batch leaves: removed
    stale.mkdir()
    (stale / "height.npy").write_bytes(b"partial")
    (data / ".index.csv.q1w2e3r4.tmp").write_text("capture,sta")

    argv = ["batch", str(data / "archive"), "--calibration", str(calibration), "-o", str(data), "--workers", "1"]
    assert main([*argv, "-q"]) == 0
    assert {p: _tree(p) for p in kept} == kept
    assert (data / "archive" / ".notes.tmp").read_text() == "a user's file"
    assert not stale.exists() and not (data / ".index.csv.q1w2e3r4.tmp").exists()
    rows = {r["capture"]: r for r in read_table(data / "index.csv")}
    assert rows["scan-001/object.incomplete-k3pt9q2z"]["status"] == "skipped"
    assert rows["scan-000/object"]["status"] == rows["scan-001/object"]["status"] == "ok"


# 5. staging names are never read as finished inputs ------------------------------------------------------


def test_a_staging_calibration_or_capture_is_refused_as_input(capsys, tmp_path, small_capture) -> None:
    staged_cal = tmp_path / "cal.incomplete-abc"
    shutil.copytree(small_capture.calibration, staged_cal)
    code, err = run(capsys, "process", small_capture.capture, "--calibration", staged_cal, "-o", tmp_path / "o1")
    assert_one_line(code, err, "cal.incomplete-abc", "never committed")
    (tmp_path / "cal").symlink_to(staged_cal)  # an ordinary name leading to one
    code, err = run(capsys, "process", small_capture.capture, "--calibration", tmp_path / "cal", "-o", tmp_path / "o2")
    assert_one_line(code, err, "never committed")
    set_aside = tmp_path / "scan.replaced-x1y2z3w4"
    shutil.copytree(small_capture.capture, set_aside)
    code, err = run(capsys, "process", set_aside, "-o", tmp_path / "o3")
    assert_one_line(code, err, "scan.replaced-x1y2z3w4", "rename it")
    assert read_capture(set_aside, salvage=True).complete  # still readable when asked for explicitly
    assert not (tmp_path / "o1").exists() and not (tmp_path / "o2").exists() and not (tmp_path / "o3").exists()


def test_the_batch_lists_a_staging_capture_as_skipped(tmp_path) -> None:
    folder = tmp_path / "a" / "part.incomplete-1"
    folder.mkdir(parents=True)
    (folder / "capture.json").write_text(json.dumps({"format": "fpp-capture", "complete": True}))
    (found,) = discover([tmp_path / "a"])
    assert found.name == "part.incomplete-1" and found.skip_reason == STAGING_REASON


# 11. reserved suffixes are refused as names, at every door ------------------------------------------------


@pytest.mark.parametrize("name", ["part.incomplete-1", "part.replaced-x"])
def test_reserved_names_are_refused_as_outputs(capsys, tmp_path, small_capture, simulated_rig_toml, name) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(simulated_rig_toml((96, 64), (48, 32), 40))
    for argv in (
        ("scan", "--config", config, "-o", tmp_path / name),
        ("process", small_capture.capture, "-o", tmp_path / name, "-q"),
        ("simulate", "-o", tmp_path / name, "--size", "32x24"),
    ):
        code, err = run(capsys, *argv)
        assert_one_line(code, err, name, "reserved")
    with pytest.raises(CaptureError, match="reserved"), CaptureWriter(tmp_path / name, CAMERA, PROJECTOR, PATTERNS):
        pass
    with pytest.raises(OutputError, match="reserved"):  # the check the console's scan service makes
        files.check_writable(tmp_path / name, ("capture",), False, OutputError)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["rig.toml", "scan"]


# 13. manifests are read through the safe file layer -------------------------------------------------------

_PLAN_SCRIPT = textwrap.dedent(
    """
    import resource, sys
    from pathlib import Path
    resource.setrlimit(resource.RLIMIT_AS, (int(sys.argv[2]), int(sys.argv[2])))
    from rig.batch.runner import BatchPlan, plan_tasks
    from rig.batch.discovery import discover
    archive = Path(sys.argv[1])
    found = discover([archive])
    tasks, known = plan_tasks(BatchPlan(archives=[archive], output=archive.parent / "out"), found)
    print(sorted(t.name for t in tasks), [o.row.capture for o in known])
    """
)


def test_a_fifo_or_huge_manifest_neither_hangs_nor_fills_the_batch_client(tmp_path) -> None:
    archive = tmp_path / "archive"
    (archive / "fifo").mkdir(parents=True)
    os.mkfifo(archive / "fifo" / "capture.json")  # nobody ever writes to it
    (archive / "sparse").mkdir()
    with open(archive / "sparse" / "capture.json", "wb") as handle:
        handle.truncate(1 << 30)  # 1 GiB of holes: no disk used, a gigabyte for whoever reads it
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    address_space = 2 << 30  # far below what reading the sparse manifest whole needs (>= 2 GiB of bytes and text)
    done = subprocess.run(
        [sys.executable, "-c", _PLAN_SCRIPT, str(archive), str(address_space)],
        env=env,
        capture_output=True,
        text=True,
        timeout=SUBPROCESS_TIMEOUT_S,  # the FIFO used to block the client here forever
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip() == "['fifo', 'sparse'] []"  # processed, so that each gets rig process's error line


def test_the_batch_reports_what_is_wrong_with_fifo_and_huge_manifests(archive, tmp_path) -> None:
    root = tmp_path / "archive"
    shutil.copytree(archive[0] / "scan-000", root / "good")
    (root / "fifo").mkdir()
    os.mkfifo(root / "fifo" / "capture.json")
    (root / "sparse").mkdir()
    with open(root / "sparse" / "capture.json", "wb") as handle:
        handle.truncate(1 << 30)
    env = {**os.environ, "PYTHONPATH": str(REPO) + os.pathsep + os.environ.get("PYTHONPATH", "")}
    done = subprocess.run(
        [sys.executable, "-m", "rig.cli", "batch", str(root), "-o", str(tmp_path / "out"), "--workers", "1", "-q"],
        env=env,
        capture_output=True,
        text=True,
        timeout=SUBPROCESS_TIMEOUT_S,
        check=False,
    )
    assert done.returncode == 1 and "Traceback" not in done.stderr, done.stderr
    rows = {r["capture"]: r for r in read_table(tmp_path / "out" / "index.csv")}
    assert rows["good/object"]["status"] == "ok"
    assert rows["fifo"]["status"] == "error" and "expected a regular file, found a FIFO" in rows["fifo"]["message"]
    assert rows["sparse"]["status"] == "error" and f"found {1 << 30}" in rows["sparse"]["message"]


# minor: a full disk names the file; the batch says so instead of "internal error" ---------------------------

NO_SPACE = OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))  # what write() and fsync() raise: no file name


def test_a_full_disk_names_the_file_being_written(capsys, tmp_path, simulated_rig_toml, monkeypatch) -> None:
    config = tmp_path / "rig.toml"
    config.write_text(simulated_rig_toml((96, 64), (48, 32), 40))

    def full(_fd: int) -> None:
        raise NO_SPACE

    monkeypatch.setattr(os, "fsync", full)
    code, err = run(capsys, "scan", "--config", config, "-o", tmp_path / "part")
    assert_one_line(code, err, "No space left on device", "part.incomplete-", "frames/000.png")


def test_a_full_disk_in_a_batch_task_is_a_disk_full_row(archive, tmp_path, monkeypatch) -> None:
    root, calibration = archive

    def full(*_args: object, **_kwargs: object) -> None:
        raise NO_SPACE

    monkeypatch.setattr(result_files, "write_preview", full)
    task = CaptureTask(
        name="part",
        capture=str(root / "scan-000" / "object"),
        output=str(tmp_path / "out" / "part"),
        calibration=str(calibration),
        options=ProcessOptions(correction="none"),
        fingerprint="f",
    )
    row = run_task(task).row
    assert row.status == "error" and "internal error" not in row.message
    assert row.message == f"{tmp_path / 'out' / 'part'}: No space left on device"
    assert not (tmp_path / "out").exists() or not list((tmp_path / "out").iterdir())


# minor: a symbolic link to a capture folder gets a row saying why it was not processed ----------------------


def test_a_linked_capture_folder_is_listed_as_skipped(tmp_path) -> None:
    outside = tmp_path / "elsewhere" / "part"
    outside.mkdir(parents=True)
    (outside / "capture.json").write_text(json.dumps({"format": "fpp-capture", "complete": True}))
    (tmp_path / "a" / "real").mkdir(parents=True)
    (tmp_path / "a" / "real" / "capture.json").write_text(json.dumps({"format": "fpp-capture", "complete": True}))
    (tmp_path / "a" / "linked").symlink_to(outside)
    found = {c.name: c.skip_reason for c in discover([tmp_path / "a"])}
    assert found["real"] is None
    assert found["linked"] is not None and found["linked"].startswith(LINK_REASON) and str(outside) in found["linked"]


def test_stale_leftovers_are_found_only_beside_named_outputs(tmp_path) -> None:
    from rig.batch.resume import remove_stale

    out = tmp_path / "out"
    ours = [out / "a" / "object.incomplete-x1y2z3w4", out / "b" / "object.replaced-q1w2e3r4"]
    theirs = [
        out / "c" / "object.incomplete-x1y2z3w4",  # beside no output of this batch
        out / "a" / "object.incomplete-short",  # not the staging name's exact shape
        out / "a" / "deeper" / "object.incomplete-x1y2z3w4",
    ]
    for path in ours + theirs:
        path.mkdir(parents=True)
        np.save(path / "height.npy", np.zeros(2))
    capture = out / "b" / "object.incomplete-k9k9k9k9"  # a capture kept for salvage beside an output
    (capture / "frames").mkdir(parents=True)
    (capture / "capture.json").write_text("{}")
    (out / ".index.csv.abcdefgh.tmp").write_text("x")
    (out / ".mine.csv.abcdefgh.tmp").write_text("x")
    assert remove_stale(out, ["a/object", "b/object"], ("index.csv", "compare.csv")) == 3
    assert not any(p.exists() for p in ours) and all(p.exists() for p in theirs)
    assert capture.is_dir() and (out / ".mine.csv.abcdefgh.tmp").exists()
