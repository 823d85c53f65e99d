"""Benchmark: where the in-memory pipeline's time goes, step by step (12 frames 1024 x 768, correction none).

Times :func:`rig.pipeline.run.process` given the frames in memory (``frames=``), as
``benchmarks/bench_pipeline.py``'s first row does, with each of its steps wrapped in a timer: the
manifest read, the scenes (pattern groups, calibration, axis choice and fit checks), the reference
cache's key and load, the noise estimate beside the fused pass's modulation thresholds (from the
subsample), the pass's blocks (inside them the mask, Ding's look-up and the frequency fusion), the
validity bound, the heights (the reference-plane model's heights, sigma and mask in one blocked pass;
other models: eq. 1.15 and the finite mask beside the uncertainty's combined phase sigma and model a
step ahead, then the uncertainty map beside the islands), the islands, and the result. Per step:
the median over the runs of its wall time and of the CPU time of the thread that called it (the
blocks' other thread and the helper thread's steps are not in that column when they run beside
another; the process's CPU time in the header holds everything). A step run beside another shows
its own wall time; the steps do not add up to the total.

    python benchmarks/bench_pipeline_steps.py [--runs 20] [--threads 1]

``--threads`` sets :data:`processing.concurrency.THREADS` (default: as the machine gives it).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import tempfile
import time
from collections import defaultdict
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import processing.unwrap.fused_pass as fused_pass  # noqa: E402
import rig.pipeline.run as run  # noqa: E402
import rig.pipeline.stages as stages  # noqa: E402
from benchmarks.bench_pipeline import simulate  # noqa: E402
from benchmarks.measure import cpu_description, load_line  # noqa: E402
from processing import concurrency  # noqa: E402
from rig.hardware.synthesis import write_simulated_scan  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402

# (module or class, attribute, label): the steps in the order process() runs them
STEPS: list[tuple[Any, str, str]] = [
    (run, "read_capture", "manifest read"),
    (run, "_scenes", "scenes: groups, calibration, axis, fit checks"),
    (run.reference_cache, "cache_key", "reference cache key"),
    (run.reference_cache, "load", "reference cache load"),
    (stages, "_noise_sigma", "noise estimate (fit residual)"),
    (fused_pass, "_group_specs", "pass: thresholds (subsample)"),
    (fused_pass, "_run_blocks", "pass: blocks"),
    (fused_pass._Plan, "_mask", "  blocks: modulation mask"),
    (fused_pass._Plan, "_ding_opencv", "  blocks: Ding look-up"),
    (fused_pass, "fuse_frequencies", "  blocks: frequency fusion"),
    (stages, "_keep_fused", "pass outputs kept (rescue check)"),
    (stages, "_bound_phase_sigma", "validity: phase sigma bound"),
    (run, "_plane_heights", "heights, sigma and mask (reference plane, blocked)"),
    (run, "_height", "height: eq. 1.15, finite mask"),
    (run, "_uncertainty_start", "uncertainty: phase sigma, model a step ahead"),
    (run, "_uncertainty", "uncertainty map"),
    (run, "_islands", "islands"),
    (run, "_drop_islands", "islands dropped"),
    (run, "ProcessResult", "result"),
]


def instrument(spent: dict[str, list[float]]) -> None:
    """Wrap every step so that each call adds its wall and calling-thread CPU seconds to ``spent``."""
    for owner, name, label in STEPS:
        original: Callable[..., Any] = getattr(owner, name)

        def timed(*args: Any, _original: Callable[..., Any] = original, _label: str = label, **kwargs: Any) -> Any:
            wall, cpu = time.perf_counter(), time.thread_time()
            try:
                return _original(*args, **kwargs)
            finally:
                totals = spent[_label]
                totals[0] += time.perf_counter() - wall
                totals[1] += time.thread_time() - cpu

        setattr(owner, name, functools.wraps(original)(timed) if callable(original) else timed)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=20, help="timed runs after 5 warm-up runs (>= 5)")
    parser.add_argument("--threads", type=int, default=None, help="processing.concurrency.THREADS (>= 1)")
    args = parser.parse_args(argv)
    if args.runs < 5:
        parser.error("--runs: expected at least 5")
    if args.threads is not None:
        if args.threads < 1:
            parser.error("--threads: expected at least 1")
        concurrency.THREADS = args.threads
    scan = simulate((15, 16), 30.0)
    workdir = tempfile.TemporaryDirectory(prefix="bench-steps-")
    paths = write_simulated_scan(scan, Path(workdir.name) / "scan")
    options = ProcessOptions(correction="none")
    spent: dict[str, list[float]] = defaultdict(lambda: [0.0, 0.0])
    instrument(spent)
    per_step: dict[str, list[list[float]]] = defaultdict(lambda: [[], []])
    totals: list[list[float]] = [[], []]
    load_before = os.getloadavg()
    for run_index in range(5 + args.runs):
        spent.clear()
        wall, cpu = time.perf_counter(), time.process_time()
        run.process(paths.capture, paths.calibration, options, frames=scan.object_frames)
        if run_index < 5:
            continue
        totals[0].append(time.perf_counter() - wall)
        totals[1].append(time.process_time() - cpu)
        for label, (step_wall, step_cpu) in spent.items():
            per_step[label][0].append(step_wall)
            per_step[label][1].append(step_cpu)
    load_after = os.getloadavg()
    workdir.cleanup()

    print(f"rig.pipeline.run.process(frames=...), correction none, 1024x768, threads {concurrency.THREADS}")
    for line in cpu_description():
        print(line)
    print(load_line(load_before, load_after))
    print(
        f"total: median {1e3 * np.median(totals[0]):.1f} ms (min {1e3 * min(totals[0]):.1f}), "
        f"process CPU {1e3 * np.median(totals[1]):.1f} ms; {args.runs} runs"
    )
    print(f"{'step':48s} {'wall ms':>8s} {'CPU ms':>8s}")
    for _, _, label in STEPS:
        if label in per_step:
            walls, cpus = per_step[label]
            print(f"{label:48s} {1e3 * np.median(walls):8.2f} {1e3 * np.median(cpus):8.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
