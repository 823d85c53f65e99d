"""`rig batch` (issue 14): the same results as `rig process` capture by capture, on an embedded
local cluster and on a real external `dask scheduler` + `dask worker`; corrupt and incomplete
captures isolated; a batch killed at a random (seeded) moment and rerun finishes with nothing
missing, duplicated or half-written.

The archive: 7 simulated 64x48 scans sharing one calibration, one with a frame that no longer
matches its checksum, one with an unreadable capture.json and one interrupted (complete false).
"""

from __future__ import annotations

import contextlib
import json
import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from benchmarks.dask_cluster import external_cluster, free_port, repo_env
from rig.batch.discovery import INCOMPLETE_REASON, discover
from rig.batch.index import INDEX_COLUMNS, IndexRow, read_table, write_index
from rig.batch.resume import calibration_digest, fingerprint, options_key, remove_stale
from rig.batch.tasks import CaptureTask, run_task
from rig.cli import main
from rig.errors import ConfigError
from rig.hardware.synthesis import write_simulated_archive
from rig.pipeline.plan import ProcessOptions
from rig.store.files import INCOMPLETE_MARK, REPLACED_MARK

GOOD = ["scan-000/object", "scan-001/object", "scan-002/object", "scan-004/object"]
CORRUPT_FRAME, CORRUPT_MANIFEST, INCOMPLETE = "scan-003/object", "scan-005/object", "scan-006/object"
ARRAYS = ("height.npy", "phase.npy", "mask.npy")
SUBPROCESS_TIMEOUT_S = 120


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    archive, calibration = write_simulated_archive(tmp_path_factory.mktemp("batch"), 7, 64, 48, seed=3)
    frame = sorted((archive / CORRUPT_FRAME / "frames").iterdir())[2]
    frame.write_bytes(frame.read_bytes()[:-40] + b"\0" * 40)  # bit rot: checksum no longer matches
    (archive / CORRUPT_MANIFEST / "capture.json").write_text(
        '{"format": "fpp-capture", "version": 1,', encoding="utf-8"
    )
    manifest_path = archive / INCOMPLETE / "capture.json"
    manifest = json.loads(manifest_path.read_text(encoding="utf-8"))
    manifest["complete"] = False
    manifest_path.write_text(json.dumps(manifest), encoding="utf-8")
    return archive, calibration


@pytest.fixture(scope="module")
def expected(
    archive: tuple[Path, Path], tmp_path_factory: pytest.TempPathFactory
) -> dict[str, tuple[Path | None, str]]:
    """`rig process` on every capture: its output directory, or None and its error line."""
    root, calibration = archive
    out_root = tmp_path_factory.mktemp("process")
    results: dict[str, tuple[Path | None, str]] = {}
    for name in GOOD + [CORRUPT_FRAME, CORRUPT_MANIFEST]:
        out = out_root / name
        proc = subprocess.run(
            [
                sys.executable,
                "-m",
                "rig.cli",
                "process",
                str(root / name),
                "--calibration",
                str(calibration),
                "-o",
                str(out),
                "-q",
            ],
            capture_output=True,
            text=True,
            env=repo_env(),
            check=False,
            timeout=SUBPROCESS_TIMEOUT_S,
        )
        prefix = "rig process: error: "
        error = [line for line in proc.stderr.splitlines() if line.startswith(prefix)]
        results[name] = (out, "") if proc.returncode == 0 else (None, error[0][len(prefix) :])
    return results


def _rows(out: Path) -> dict[str, dict[str, str]]:
    rows = read_table(out / "index.csv")
    names = [r["capture"] for r in rows]
    assert len(names) == len(set(names)), names  # one row per capture
    return {r["capture"]: r for r in rows}


def _without_timings(report: object) -> object:
    """A report less what varies from run to run (timings)."""
    if isinstance(report, dict):
        return {k: _without_timings(v) for k, v in report.items() if k not in ("timings_s", "seconds")}
    return report


def _assert_same_outputs(batch_dir: Path, process_dir: Path) -> None:
    assert sorted(p.name for p in batch_dir.iterdir()) == sorted(p.name for p in process_dir.iterdir())
    for name in ARRAYS:
        a, b = np.load(batch_dir / name), np.load(process_dir / name)
        assert a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True), name
    for name in ("points.ply", "preview.png"):
        assert (batch_dir / name).read_bytes() == (process_dir / name).read_bytes(), name
    ours, theirs = (json.loads((d / "report.json").read_text()) for d in (batch_dir, process_dir))
    assert "fingerprint" in ours.pop("batch")
    assert _without_timings(ours) == _without_timings(theirs)


def _assert_batch_results(out: Path, archive: Path, expected: dict[str, tuple[Path | None, str]]) -> None:
    rows = _rows(out)
    assert set(rows) == set(GOOD) | {CORRUPT_FRAME, CORRUPT_MANIFEST, INCOMPLETE}
    for name in GOOD:
        assert rows[name]["status"] == "ok", rows[name]
        _assert_same_outputs(out / name, expected[name][0])
        report = json.loads((out / name / "report.json").read_text())
        assert float(rows[name]["valid_fraction"]) == pytest.approx(report["valid_fraction"], rel=1e-5)
        assert float(rows[name]["height_max_mm"]) == pytest.approx(report["height_mm"]["max"], rel=1e-5)
        assert rows[name]["correction"] == "auto" and rows[name]["worker"].startswith("tcp://")
    for name in (CORRUPT_FRAME, CORRUPT_MANIFEST):
        assert rows[name]["status"] == "error"
        assert rows[name]["message"] == expected[name][1]  # the line `rig process` prints
        assert not (out / name).exists()
    assert rows[INCOMPLETE]["status"] == "skipped" and rows[INCOMPLETE]["message"] == INCOMPLETE_REASON
    leftovers = [
        p for p in out.rglob("*") if INCOMPLETE_MARK in p.name or REPLACED_MARK in p.name or p.name.endswith(".tmp")
    ]
    assert leftovers == []


# ------------------------------------------------------------------ the local cluster


def test_batch_equals_process_isolates_failures_compares_and_resumes(archive, expected, tmp_path, capsys) -> None:
    root, calibration = archive
    out = tmp_path / "out"
    args = ["batch", str(root), "--calibration", str(calibration), "-o", str(out), "--workers", "2", "-q"]
    code = main(args + ["--compare", "none,auto"])
    _, err = capsys.readouterr()
    assert code == 1  # two captures failed
    assert "2 failed" in err and "1 skipped" in err and "Traceback" not in err
    _assert_batch_results(out, root, expected)
    assert list(read_table(out / "index.csv")[0]) == list(INDEX_COLUMNS)

    compare = read_table(out / "compare.csv")
    assert [(r["capture"], r["method"]) for r in compare] == [
        (n, m) for n in sorted(GOOD + [CORRUPT_FRAME, CORRUPT_MANIFEST]) for m in ("none", "auto")
    ]
    for row in compare:
        if row["capture"] in GOOD:
            assert row["status"] == "ok" and int(row["order_breaks"]) >= 0
            assert 0 <= float(row["nmse_h"]) < 1  # truth-height.npy beside every simulated capture
        else:
            assert row["status"] == "error" and row["message"] == expected[row["capture"]][1]
    auto = {r["capture"]: r for r in compare if r["method"] == "auto"}
    rows = _rows(out)
    for name in GOOD:  # the main outputs are the --correction (auto) result, the same run as compare's auto row
        assert auto[name]["valid_fraction"] == rows[name]["valid_fraction"]
        assert auto[name]["height_median_mm"] == rows[name]["height_median_mm"]

    # rerun: finished outputs are kept untouched, only the failed captures are tried again
    stamps = {name: (out / name / "height.npy").stat().st_mtime_ns for name in GOOD}
    index_before, compare_before = _rows(out), read_table(out / "compare.csv")
    assert main(args + ["--compare", "none,auto"]) == 1
    _, err = capsys.readouterr()
    assert "4 unchanged since an earlier run" in err
    assert {name: (out / name / "height.npy").stat().st_mtime_ns for name in GOOD} == stamps
    assert all(_rows(out)[name] == index_before[name] for name in GOOD)  # the same rows, worker and seconds included
    assert [r for r in read_table(out / "compare.csv") if r["capture"] in GOOD] == [
        r for r in compare_before if r["capture"] in GOOD
    ]


def test_changed_options_or_calibration_change_the_fingerprint(archive, tmp_path) -> None:
    root, calibration = archive
    capture = root / GOOD[0]
    cal = calibration_digest(calibration)
    base = fingerprint(capture, cal, options_key(ProcessOptions(correction="auto"), ()))
    assert base == fingerprint(capture, cal, options_key(ProcessOptions(correction="auto"), ()))
    assert base != fingerprint(capture, cal, options_key(ProcessOptions(correction="none"), ()))
    assert base != fingerprint(capture, cal, options_key(ProcessOptions(correction="auto"), ("none",)))
    assert base != fingerprint(root / GOOD[1], cal, options_key(ProcessOptions(correction="auto"), ()))
    moved = tmp_path / "cal"
    import shutil

    shutil.copytree(calibration, moved)
    assert calibration_digest(moved) == cal  # content, not location
    text = (moved / "calibration.json").read_text().replace('"l0_mm": ', '"l0_mm": 1')
    (moved / "calibration.json").write_text(text)
    assert calibration_digest(moved) != cal
    assert fingerprint(root / CORRUPT_MANIFEST, cal, "") is None  # unreadable manifest: never reused


# ------------------------------------------------------------------ a real external scheduler


def test_external_scheduler_gives_the_same_results(archive, expected, tmp_path, capsys) -> None:
    root, calibration = archive
    out = tmp_path / "out"
    with external_cluster(1, log=tmp_path / "dask.log") as address:
        code = main(
            ["batch", str(root), "--calibration", str(calibration), "-o", str(out), "--scheduler", address, "-q"]
        )
    _, err = capsys.readouterr()
    assert code == 1, err
    _assert_batch_results(out, root, expected)


def test_unreachable_scheduler_is_one_line(archive, tmp_path, capsys, monkeypatch) -> None:
    from rig.batch import runner

    monkeypatch.setattr(runner, "CONNECT_TIMEOUT_S", 2.0)
    root, calibration = archive
    code = main(
        [
            "batch",
            str(root),
            "--calibration",
            str(calibration),
            "-o",
            str(tmp_path / "out"),
            "--scheduler",
            f"tcp://127.0.0.1:{free_port()}",
            "-q",
        ]
    )
    _, err = capsys.readouterr()
    lines = [line for line in err.splitlines() if line.strip()]
    assert code == 1 and len(lines) == 1 and "--scheduler: cannot connect" in lines[0], err


# ------------------------------------------------------------------ killed and rerun


def test_killed_at_a_random_moment_then_rerun_completes(archive, expected, tmp_path, capsys) -> None:
    root, calibration = archive
    out = tmp_path / "out"
    args = ["batch", str(root), "--calibration", str(calibration), "-o", str(out), "--workers", "2", "-q"]
    rng = random.Random(14)
    proc = subprocess.Popen(
        [sys.executable, "-m", "rig.cli", *args],
        env=repo_env(),
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + SUBPROCESS_TIMEOUT_S
        while not any((out / n).exists() for n in GOOD) and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)  # the cluster is up and the first result is in
        time.sleep(rng.uniform(0.0, 0.3))
        killed = proc.poll() is None
        os.killpg(proc.pid, signal.SIGKILL)  # the client, its scheduler and its workers, mid-flight
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)
    done = [n for n in GOOD if (out / n).exists()]
    for name in done:  # whatever is in place is whole
        assert sorted(p.name for p in (out / name).iterdir()) == sorted(
            json.loads((out / name / "report.json").read_text())["files"].values()
        )
    assert main(args) == 1
    _, err = capsys.readouterr()
    _assert_batch_results(out, root, expected)
    if killed:
        assert f"{len(done)} unchanged since an earlier run" in err


# ------------------------------------------------------------------ discovery and commits (no Dask)


def _capture(path: Path, complete: bool = True) -> Path:
    path.mkdir(parents=True)
    (path / "capture.json").write_text(json.dumps({"format": "fpp-capture", "complete": complete}))
    return path


def test_discovery_recurses_names_relative_and_skips_incomplete(tmp_path) -> None:
    a = tmp_path / "projA"
    _capture(a / "day1" / "part-1")
    _capture(a / "day1" / "part-2", complete=False)
    _capture(a / "day2" / "deep" / "part-3")
    _capture(a / "cal" / "reference")
    _capture(a / "out" / "x")
    (a / "day1" / "part-1" / "frames").mkdir()
    found = discover([a], exclude=[a / "cal", a / "out"])
    assert [(c.name, c.skip_reason is not None) for c in found] == [
        ("day1/part-1", False),
        ("day1/part-2", True),
        ("day2/deep/part-3", False),
    ]
    b = tmp_path / "projB"
    _capture(b)
    names = [c.name for c in discover([a, b], exclude=[a / "cal", a / "out"])]
    assert names == ["projA/day1/part-1", "projA/day1/part-2", "projA/day2/deep/part-3", "projB"]
    with pytest.raises(ConfigError, match="no capture found"):
        discover([tmp_path / "projA" / "cal"], exclude=[a / "cal"])
    with pytest.raises(ConfigError, match="archive directory not found"):
        discover([tmp_path / "missing"])


def test_a_task_never_replaces_what_rig_did_not_write(archive, tmp_path) -> None:
    root, calibration = archive
    target = tmp_path / "out" / "part"
    target.mkdir(parents=True)
    (target / "notes.txt").write_text("mine")
    task = CaptureTask(
        name="part",
        capture=str(root / GOOD[0]),
        output=str(target),
        calibration=str(calibration),
        options=ProcessOptions(correction="none"),
        fingerprint="f",
    )
    outcome = run_task(task)  # the function a worker runs, called here without Dask
    assert outcome.row.status == "error" and "not written by this program" in outcome.row.message
    assert [p.name for p in target.iterdir()] == ["notes.txt"]
    (target / "notes.txt").unlink()
    outcome = run_task(task)
    assert outcome.row.status == "ok" and outcome.row.worker == "local"
    report = json.loads((target / "report.json").read_text())
    assert report["batch"]["fingerprint"] == "f" and sorted(report["files"].values()) == sorted(
        p.name for p in target.iterdir()
    )


def test_stale_leftovers_of_a_killed_run_are_removed(tmp_path) -> None:
    out = tmp_path / "out"
    for name in (f"a/object{INCOMPLETE_MARK}x1y2z3w4", f"b/object{REPLACED_MARK}x2y3z4w5", "c/object"):
        (out / name).mkdir(parents=True)
    (out / ".index.csv.abcdefgh.tmp").write_text("capture,sta")
    (out / "c" / "object" / "report.json").write_text("{}")
    # killed between writing the last file (report.json) and the rename: whole, but never committed
    written = out / f"d/object{INCOMPLETE_MARK}x3y4z5w6"
    written.mkdir(parents=True)
    (written / "height.npy").write_bytes(b"")
    (written / "report.json").write_text(json.dumps({"program": "fpp-rig 1.0"}))
    verification = out / f"e/object{INCOMPLETE_MARK}x4y5z6w7"  # the same marker name, another kind: kept
    verification.mkdir(parents=True)
    (verification / "report.json").write_text(json.dumps({"format": "fpp-verification"}))
    outputs = ["a/object", "b/object", "c/object", "d/object", "e/object"]
    assert remove_stale(out, outputs, ("index.csv",)) == 4
    assert sorted(str(p.relative_to(out)) for p in out.rglob("*")) == [
        "a",
        "b",
        "c",
        "c/object",
        "c/object/report.json",
        "d",
        "e",
        f"e/object{INCOMPLETE_MARK}x4y5z6w7",
        f"e/object{INCOMPLETE_MARK}x4y5z6w7/report.json",
    ]


def test_a_table_is_replaced_whole(tmp_path) -> None:
    rows = [
        IndexRow(capture="b", status="ok", valid_fraction=0.5),
        IndexRow(capture="a", status="error", message="x, y"),
    ]
    write_index(tmp_path / "index.csv", rows)
    assert [(r["capture"], r["message"]) for r in read_table(tmp_path / "index.csv")] == [("a", "x, y"), ("b", "")]
    (tmp_path / "index.csv").write_text("capture,status\nz,ok\n")
    write_index(tmp_path / "index.csv", rows[:1])
    assert [r["capture"] for r in read_table(tmp_path / "index.csv")] == ["b"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["index.csv"]  # no temporary left
