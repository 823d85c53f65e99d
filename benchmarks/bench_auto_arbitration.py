"""Benchmark: what auto's steps 6a - 6b cost, on the maps of bench_auto.py.

``auto`` judges the blobs where its low-rank surface's orders differ from the kept ones (step 6a,
:func:`processing.correction.surface_orders.arbitrate_low_rank_orders`) and moves the pixels a fringe or
more off three or four neighbours (step 6b, :func:`processing.correction.broken_pixels.mend_broken_pixels`).
Per case of ``benchmarks/bench_auto.py`` (1024 x 768, with the lower frequency's wrapped phase),
interleaved runs time, in CPU seconds of this process: ``correct_auto`` as it is, ``correct_auto`` with
both steps replaced by pass-throughs, and the two steps alone inside the first; the ratio is the steps
over ``auto`` without them (median of the runs). Single-threaded BLAS, as ``rig process`` runs the
correction.

    python benchmarks/bench_auto_arbitration.py [--runs 9]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_auto import CASES, GROUPS, simulated_scan  # noqa: E402
from benchmarks.measure import load_line  # noqa: E402
from processing.correction import registry  # noqa: E402
from processing.unwrap.fused_pass import fringe_pass  # noqa: E402
from rig.blas import rpca_blas  # noqa: E402


def _cpu(run: Callable[[], Any]) -> float:
    start = time.process_time()
    run()
    return time.process_time() - start


def run_case(case: str, runs: int) -> None:
    label, freqs, _ = CASES[case]
    obj = simulated_scan(case).object_frames
    scan = fringe_pass(obj, GROUPS, freqs, "two-frequency", keep_all=True)
    phase, wrapped, valid = scan.phase.astype(np.float64), scan.wrapped[-1].astype(np.float64), scan.valid
    evidence = {"frequency": freqs[1], "lower_wrapped": [(freqs[0], scan.wrapped[0])]}
    arbitrate, mend = registry._arbitrate_with_low_rank, registry._mend_broken_pixels
    step_seconds = [0.0]  # of the run under way: step 6b runs twice (again next to what 6c and 6d moved)

    def timed(step: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any, **kwargs: Any) -> Any:
            start = time.process_time()
            out = step(*args, **kwargs)
            step_seconds[-1] += time.process_time() - start
            return out

        return run

    def auto() -> Any:
        return registry.correct_auto(phase, wrapped, mask=valid, **evidence)

    with_steps, without = [], []
    try:
        with rpca_blas():
            for _ in range(runs):
                registry._arbitrate_with_low_rank, registry._mend_broken_pixels = timed(arbitrate), timed(mend)
                with_steps.append(_cpu(auto))
                step_seconds.append(0.0)
                registry._arbitrate_with_low_rank = lambda _maps, reordered, unresolved, *_, **__: (
                    reordered,
                    unresolved,
                )
                registry._mend_broken_pixels = lambda _maps, reordered, *_, **__: reordered
                without.append(_cpu(auto))
    finally:
        registry._arbitrate_with_low_rank, registry._mend_broken_pixels = arbitrate, mend
    steps = step_seconds[:-1]
    ratios = [s / w for s, w in zip(steps, without, strict=True)]
    print(
        f"{label}: auto {statistics.median(with_steps):.4f} s CPU, without steps 6a - 6b "
        f"{statistics.median(without):.4f} s; the steps {statistics.median(steps):.4f} s = "
        f"{statistics.median(ratios):.1%} of auto without them ({min(ratios):.1%} - {max(ratios):.1%})"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--runs", type=int, default=9)
    args = parser.parse_args(argv)
    before = os.getloadavg()
    for case in CASES:
        run_case(case, args.runs)
    print(load_line(before, os.getloadavg()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
