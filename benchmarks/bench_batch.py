"""Benchmark: `rig batch` on an archive of simulated captures, 1 and 2 workers, against plain loops.

The archive: N simulated scans (default 100, 160x120, hemisphere / sphere cap / two hemispheres /
steps, 4-step sinusoids at 1/8/64, one shared calibration) of which 3 are corrupt (two frames that
no longer match their checksums, one unreadable capture.json) and 2 interrupted (complete false).

Rows, interleaved over ``--runs`` runs (median, min..max):

- ``batch 1 worker`` / ``batch 2 workers``: :func:`rig.batch.run_batch` on a fresh output directory
  with a local cluster of that many single-threaded worker processes; end to end (cluster start
  included) and steady state (first task submitted to last result back);
- ``in-process loop``: the functions `rig process` runs (process + write_result), one capture after
  the other in this process: the per-capture work without Dask, the peer for Dask's overhead;
- ``rig process loop``: the shell loop issue 14 replaces, one `rig process` subprocess per capture
  (on ``--loop-sample`` captures, timed once).

Then the checks of issue 14's "Done means": 95 ok + 3 error + 2 skipped rows with their reasons,
every ok output's arrays identical to the in-process loop's and to `rig process`'s (the sampled
captures); with ``--check``: killed at a seeded random moment and rerun, and through an external
`dask scheduler` with two `dask worker --nthreads 1`, the same results.

    python benchmarks/bench_batch.py [--captures 100] [--size 160x120] [--runs 3] [--loop-sample 20] [--check]

Wall-clock figures depend on what else runs on the machine: load average, CPU model and the CPU
time of this process and its children are printed beside them.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import resource
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.dask_cluster import external_cluster, repo_env  # noqa: E402
from benchmarks.measure import cpu_description, load_line  # noqa: E402
from rig.api import process  # noqa: E402
from rig.batch import BatchPlan, run_batch  # noqa: E402
from rig.batch.discovery import INCOMPLETE_REASON  # noqa: E402
from rig.batch.index import read_table  # noqa: E402
from rig.events import Event, Reporter  # noqa: E402
from rig.hardware.synthesis import write_simulated_archive  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402
from rig.store.files import INCOMPLETE_MARK, REPLACED_MARK  # noqa: E402
from rig.store.results import write_result  # noqa: E402

ARRAYS = ("height.npy", "phase.npy", "mask.npy")


def cpu_seconds() -> float:
    """CPU time of this process and of its finished children (worker processes included once reaped)."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def make_archive(root: Path, count: int, size: tuple[int, int]) -> tuple[Path, Path, dict[str, str]]:
    """The archive with 3 corrupt and 2 incomplete captures; returns (archive, calibration, {name: expected status})."""
    archive, calibration = write_simulated_archive(root, count, size[0], size[1], seed=0)
    names = sorted(str(p.parent.relative_to(archive)) for p in archive.rglob("capture.json"))
    status = dict.fromkeys(names, "ok")
    bad = random.Random(14).sample(names, 5)
    for name in bad[:2]:  # bit rot in a frame
        frame = sorted((archive / name / "frames").iterdir())[1]
        frame.write_bytes(frame.read_bytes()[:-64] + b"\0" * 64)
        status[name] = "error"
    (archive / bad[2] / "capture.json").write_text('{"format": "fpp-capture", "vers', encoding="utf-8")
    status[bad[2]] = "error"
    for name in bad[3:]:
        path = archive / name / "capture.json"
        manifest = json.loads(path.read_text(encoding="utf-8"))
        manifest["complete"] = False
        path.write_text(json.dumps(manifest), encoding="utf-8")
        status[name] = "skipped"
    return archive, calibration, status


def time_batch(archive: Path, calibration: Path, out: Path, workers: int | None, scheduler: str | None = None) -> dict:
    """One batch on a fresh output directory: wall (end to end), steady state, CPU seconds."""
    shutil.rmtree(out, ignore_errors=True)
    events: list[Event] = []
    cpu0, t0 = cpu_seconds(), time.perf_counter()
    result = run_batch(
        BatchPlan(
            archives=[archive],
            output=out,
            calibration=calibration,
            workers=workers,
            scheduler=scheduler,
            options=ProcessOptions(),
        ),
        progress=Reporter("batch", sink=events.append),
    )
    wall = time.perf_counter() - t0
    begin = next(e.time for e in events if e.kind == "begin")
    steps = [e.time for e in events if e.kind == "step"]
    processed = len(steps)
    return {
        "wall": wall,
        "steady": (steps[-1] - begin) if steps else 0.0,
        "processed": processed,
        "cpu": cpu_seconds() - cpu0,
        "result": result,
    }


def in_process_loop(archive: Path, calibration: Path, names: list[str], out: Path) -> float:
    """process + write_result per capture in this process (what `rig process` runs); wall seconds."""
    shutil.rmtree(out, ignore_errors=True)
    options = ProcessOptions()
    t0 = time.perf_counter()
    for name in names:
        with contextlib.suppress(Exception):
            write_result(process(archive / name, calibration, options), out / name)
    return time.perf_counter() - t0


def process_loop(archive: Path, calibration: Path, names: list[str], out: Path) -> float:
    """One `rig process` subprocess per capture, as a shell loop would; wall seconds."""
    env = repo_env()
    t0 = time.perf_counter()
    for name in names:
        subprocess.run(
            [
                sys.executable,
                "-m",
                "rig.cli",
                "process",
                str(archive / name),
                "--calibration",
                str(calibration),
                "-o",
                str(out / name),
                "-q",
            ],
            env=env,
            capture_output=True,
            check=False,
        )
    return time.perf_counter() - t0


def check_results(out: Path, status: dict[str, str], references: list[tuple[str, Path]]) -> list[str]:
    """Problems with a batch's output: wrong rows, missing or different arrays, leftovers (empty when right)."""
    problems = []
    rows = read_table(out / "index.csv")
    names = [r["capture"] for r in rows]
    if sorted(names) != sorted(status) or len(set(names)) != len(names):
        problems.append(f"index.csv: expected one row per capture ({len(status)}), found {len(names)} rows")
    by_name = {r["capture"]: r for r in rows}
    for name, expected in status.items():
        row = by_name.get(name)
        if row is None or row["status"] != expected:
            problems.append(f"{name}: expected {expected}, found {row and row['status']}")
        elif expected != "ok" and not row["message"]:
            problems.append(f"{name}: {expected} without a reason")
        elif expected == "skipped" and row["message"] != INCOMPLETE_REASON:
            problems.append(f"{name}: skipped for {row['message']!r}")
    for label, ref in references:
        for name in [n for n, s in status.items() if s == "ok" and (ref / n).exists()]:
            for array in ARRAYS:
                if not np.array_equal(np.load(out / name / array), np.load(ref / name / array), equal_nan=True):
                    problems.append(f"{name}/{array}: differs from the {label}")
    leftovers = [str(p) for p in out.rglob("*") if ".rig-batch-" in p.name]
    if leftovers:
        problems.append(f"leftover staging directories: {leftovers[:3]}")
    return problems


def committed(out: Path) -> tuple[int, int]:
    """(outputs in place, staging directories being written) under a batch's output directory."""
    reports = [p.parent.name for p in out.glob("*/*/report.json")]
    staging = sum(1 for name in reports if INCOMPLETE_MARK in name or REPLACED_MARK in name)
    return len(reports) - staging, staging


def kill_and_rerun(archive: Path, calibration: Path, out: Path, good: int, seed: int) -> tuple[int, int, int]:
    """`rig batch --workers 2` killed (SIGKILL to its whole process group) once a seeded random share of the
    captures is done, then rerun; returns (outputs in place at the kill, staging directories, outputs kept)."""
    shutil.rmtree(out, ignore_errors=True)
    target = round(random.Random(seed).uniform(0.05, 0.95) * good)
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "rig.cli",
            "batch",
            str(archive),
            "--calibration",
            str(calibration),
            "-o",
            str(out),
            "--workers",
            "2",
            "-q",
        ],
        env=repo_env(),
        start_new_session=True,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        while proc.poll() is None and committed(out)[0] < target:
            time.sleep(0.01)
    finally:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=60)
    in_place, staging = committed(out)
    events: list[Event] = []
    run_batch(
        BatchPlan(
            archives=[archive],
            output=out,
            calibration=calibration,
            workers=2,
            options=ProcessOptions(),
        ),
        progress=Reporter("batch", sink=events.append),
    )
    kept = next(e.data.get("kept", 0) for e in events if e.kind == "message")
    return in_place, staging, kept


def summary(values: list[float]) -> str:
    return f"{statistics.median(values):8.1f}  ({min(values):.1f} .. {max(values):.1f})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--captures", type=int, default=100, help="captures in the archive (>= 10; 5 of them bad)")
    parser.add_argument("--size", default="160x120", help="camera size WxH of the simulated captures")
    parser.add_argument("--runs", type=int, default=3, help="interleaved timed runs of each batch row")
    parser.add_argument(
        "--loop-sample", type=int, default=20, help="captures timed through `rig process` subprocesses (0: all)"
    )
    parser.add_argument("--check", action="store_true", help="also kill + rerun, and run on an external scheduler")
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    import logging

    logging.getLogger("distributed").setLevel(logging.ERROR)
    with tempfile.TemporaryDirectory(prefix="bench-batch-") as tmp:
        root = Path(tmp)
        t0 = time.perf_counter()
        archive, calibration, status = make_archive(root / "data", args.captures, size)  # type: ignore[arg-type]
        good = [n for n, s in status.items() if s == "ok"]
        print(
            f"archive: {len(status)} captures {args.size} ({len(good)} good, 3 corrupt, 2 incomplete), "
            f"written in {time.perf_counter() - t0:.1f} s"
        )
        for line in cpu_description():
            print(line)
        load_before = os.getloadavg()
        processable = [n for n, s in status.items() if s != "skipped"]
        sample = processable if args.loop_sample <= 0 else processable[: args.loop_sample]
        loop_wall = process_loop(archive, calibration, sample, root / "process")
        rows: dict[str, list[float]] = {
            k: [] for k in ("1w wall", "1w steady", "2w wall", "2w steady", "loop", "1w cpu", "2w cpu")
        }
        last_out = root / "out-2"
        for _ in range(args.runs):
            one = time_batch(archive, calibration, root / "out-1", workers=1)
            two = time_batch(archive, calibration, last_out, workers=2)
            loop = in_process_loop(archive, calibration, processable, root / "loop")
            n = one["processed"]
            rows["1w wall"].append(n / one["wall"] * 60)
            rows["1w steady"].append(n / one["steady"] * 60)
            rows["2w wall"].append(n / two["wall"] * 60)
            rows["2w steady"].append(n / two["steady"] * 60)
            rows["loop"].append(len(processable) / loop * 60)
            rows["1w cpu"].append(one["cpu"])
            rows["2w cpu"].append(two["cpu"])
        n = len(processable)
        print(f"\ncaptures per minute over {n} processed captures, median (min .. max) of {args.runs} runs:")
        print(f"  batch, 1 worker,  end to end   {summary(rows['1w wall'])}")
        print(f"  batch, 1 worker,  steady state {summary(rows['1w steady'])}")
        print(f"  batch, 2 workers, end to end   {summary(rows['2w wall'])}")
        print(f"  batch, 2 workers, steady state {summary(rows['2w steady'])}")
        print(f"  in-process loop (no Dask)      {summary(rows['loop'])}")
        print(f"  `rig process` subprocess loop  {len(sample) / loop_wall * 60:8.1f}  (once, {len(sample)} captures)")
        ratios_wall = [b / a for a, b in zip(rows["1w wall"], rows["2w wall"])]
        ratios_steady = [b / a for a, b in zip(rows["1w steady"], rows["2w steady"])]
        print(
            f"2 workers / 1 worker: end to end {statistics.median(ratios_wall):.2f}x "
            f"({min(ratios_wall):.2f} .. {max(ratios_wall):.2f}), steady state {statistics.median(ratios_steady):.2f}x "
            f"({min(ratios_steady):.2f} .. {max(ratios_steady):.2f})"
        )
        overhead = [60 / s - 60 / lp for s, lp in zip(rows["1w steady"], rows["loop"])]
        print(
            f"Dask overhead per capture (1 worker steady state minus in-process loop): "
            f"{statistics.median(overhead) * 1000:.0f} ms ({min(overhead) * 1000:.0f} .. {max(overhead) * 1000:.0f})"
        )
        print(
            f"CPU seconds (client + workers): 1 worker {statistics.median(rows['1w cpu']):.1f}, "
            f"2 workers {statistics.median(rows['2w cpu']):.1f}"
        )
        print(load_line(load_before, os.getloadavg()))

        refs = [("in-process loop", root / "loop"), ("`rig process` outputs", root / "process")]
        problems = check_results(last_out, status, refs)
        counts = {
            s: sum(1 for r in read_table(last_out / "index.csv") if r["status"] == s)
            for s in ("ok", "error", "skipped")
        }
        print(
            f"\ncheck: index.csv {counts}; arrays of every ok capture identical to the in-process loop, "
            f"{sum(1 for n in good if (root / 'process' / n).exists())} to `rig process`: "
            f"{'yes' if not problems else 'NO: ' + '; '.join(problems[:5])}"
        )
        if args.check:
            in_place, staging, kept = kill_and_rerun(archive, calibration, root / "killed", len(good), seed=14)
            problems_k = check_results(root / "killed", status, refs)
            print(
                f"check: killed (SIGKILL) with {in_place} of {len(good)} outputs in place and {staging} being written, "
                f"rerun kept {kept} "
                f"and completed: {'yes' if not problems_k else 'NO: ' + '; '.join(problems_k[:5])}"
            )
            with external_cluster(2) as address:
                external = time_batch(archive, calibration, root / "external", workers=None, scheduler=address)
            problems_e = check_results(root / "external", status, refs)
            print(
                f"check: external `dask scheduler` + 2 `dask worker --nthreads 1` ({address}), "
                f"{external['processed'] / external['wall'] * 60:.1f} captures/min: same results: "
                f"{'yes' if not problems_e else 'NO: ' + '; '.join(problems_e[:5])}"
            )
            problems += problems_k + problems_e
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
