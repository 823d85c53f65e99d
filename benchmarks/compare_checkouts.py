"""Benchmark: the in-memory pipeline of two checkouts of this repository, call by call in turn.

On a shared machine the speed of everything drifts by tens of per cent within minutes, so two
benchmark runs made one after the other can disagree more than the change they compare. Here one
worker process per checkout (each importing only its own code) prepares the same simulated capture
as ``benchmarks/bench_pipeline.py`` (12 uint8 frames 1024 x 768, two frequencies x 6 steps,
30 dB), then the two are asked in turn to run :func:`rig.pipeline.run.process` once
(``frames=``, correction none), alternating which goes first; each pair of calls saw nearly the
same machine. Printed: per checkout the median and fastest wall time and the median CPU time of the
worker, and the median over pairs of ``new / old`` wall and CPU time (with the quartiles), the
CPU model and the load average before and after.

    python benchmarks/compare_checkouts.py OLD_CHECKOUT NEW_CHECKOUT [--pairs 40] [--threads 2]

``--threads`` sets :data:`processing.concurrency.THREADS` in both workers (1: everything in the
calling thread, whose CPU time is the steadiest figure on a busy machine).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, load_line  # noqa: E402

_WORKER = """
import sys, tempfile, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from benchmarks.bench_pipeline import simulate
from processing import concurrency
from rig.hardware.synthesis import write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process
concurrency.THREADS = int(sys.argv[2])
scan = simulate((15, 16), 30.0)
paths = write_simulated_scan(scan, Path(tempfile.mkdtemp(prefix="compare-")) / "scan")
def once():
    process(paths.capture, paths.calibration, ProcessOptions(correction="none"), frames=scan.object_frames)
for _ in range(5):
    once()
print("ready", flush=True)
for _ in sys.stdin:
    wall, cpu = time.perf_counter(), time.process_time()
    once()
    print(time.perf_counter() - wall, time.process_time() - cpu, flush=True)
"""


def _start(checkout: Path, threads: int) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(checkout)}
    worker = subprocess.Popen(
        [sys.executable, "-c", _WORKER, str(checkout), str(threads)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
        cwd=checkout,
    )
    assert worker.stdout is not None
    if worker.stdout.readline().strip() != "ready":
        raise SystemExit(f"{checkout}: its worker did not start (is it a checkout of this repository?)")
    return worker


def _call(worker: subprocess.Popen[str]) -> tuple[float, float]:
    assert worker.stdin is not None and worker.stdout is not None
    worker.stdin.write("run\n")
    worker.stdin.flush()
    wall, cpu = worker.stdout.readline().split()
    return float(wall), float(cpu)


def _quartiles(values: list[float]) -> str:
    q1, median, q3 = statistics.quantiles(values, n=4)
    return f"{median:.3f} ({q1:.3f} - {q3:.3f})"


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old", type=Path, help="checkout of the code before")
    parser.add_argument("new", type=Path, help="checkout of the code after")
    parser.add_argument("--pairs", type=int, default=40, help="calls of each checkout, in turn (>= 8)")
    parser.add_argument("--threads", type=int, default=2, help="processing.concurrency.THREADS in both (>= 1)")
    args = parser.parse_args(argv)
    if args.pairs < 8:
        parser.error("--pairs: expected at least 8")
    if args.threads < 1:
        parser.error("--threads: expected at least 1")
    for checkout in (args.old, args.new):
        if not (checkout / "rig" / "pipeline" / "run.py").is_file():
            parser.error(f"{checkout}: not a checkout of this repository (no rig/pipeline/run.py)")
    load_before = os.getloadavg()
    workers = {"old": _start(args.old, args.threads), "new": _start(args.new, args.threads)}
    times: dict[str, list[tuple[float, float]]] = {"old": [], "new": []}
    try:
        for i in range(args.pairs):
            for name in ("old", "new") if i % 2 == 0 else ("new", "old"):
                time.sleep(0.02)
                times[name].append(_call(workers[name]))
    finally:
        for worker in workers.values():
            assert worker.stdin is not None
            worker.stdin.close()
            worker.wait()
    print(
        f"rig.pipeline.run.process(frames=...), correction none, 1024x768, threads {args.threads}, {args.pairs} pairs"
    )
    for line in cpu_description():
        print(line)
    print(load_line(load_before, os.getloadavg()))
    for name, checkout in (("old", args.old), ("new", args.new)):
        walls = [1e3 * wall for wall, _ in times[name]]
        cpus = [1e3 * cpu for _, cpu in times[name]]
        print(
            f"{name} ({checkout}): wall median {statistics.median(walls):.1f} ms (fastest {min(walls):.1f}), "
            f"CPU median {statistics.median(cpus):.1f} ms"
        )
    pairs = list(zip(times["old"], times["new"], strict=True))
    print(f"new / old per pair, wall: {_quartiles([n[0] / o[0] for o, n in pairs])}")
    print(f"new / old per pair, CPU:  {_quartiles([n[1] / o[1] for o, n in pairs])}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
