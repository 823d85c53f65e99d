"""Benchmark: how well auto's unresolved mask covers its wrong orders on drawn cases, and what the vote costs.

Per case of :func:`rig.study.family.draw_case` (develop set unless ``--held-out``): the object
capture corrected by ``auto`` as ``rig process`` calls it (with the lower frequencies), then the share
of the valid pixels on wrong orders, the unresolved fraction auto reports, the share of the wrong
pixels inside the unresolved mask (recall) and the share of the mask on right orders; and the seconds
of :func:`~processing.correction.order_margin.undecided_orders` against auto's (median of
``--repeats`` runs each, one BLAS thread, the spread as min - max).

    python benchmarks/bench_auto_unresolved.py --cases 6,23,27,37,48,49 --repeats 3
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_auto_family import parse_cases  # noqa: E402
from benchmarks.measure import load_line  # noqa: E402
from processing.correction.order_margin import undecided_orders  # noqa: E402
from processing.correction.registry import correct_auto  # noqa: E402
from rig.study.family import capture, draw_case, scene_heights  # noqa: E402


def _seconds(run: Callable[[], object], repeats: int) -> list[float]:
    """Seconds of ``repeats`` calls of ``run``."""
    out = []
    for _ in range(repeats):
        tick = time.perf_counter()
        run()
        out.append(time.perf_counter() - tick)
    return out


def _spread(values: Sequence[float]) -> str:
    """Median (min - max) in milliseconds."""
    return f"{1e3 * float(np.median(values)):.0f} ms ({1e3 * min(values):.0f} - {1e3 * max(values):.0f})"


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", default="6,23,27,37,48,49", help="case indices, e.g. 0-7,12")
    parser.add_argument("--held-out", action="store_true", help="the held-out set instead of the develop set")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs of auto and of the vote per case")
    args = parser.parse_args(argv)
    from threadpoolctl import threadpool_limits

    before = os.getloadavg()
    print("case | wrong | unresolved | wrong inside | mask right | auto | vote | vote / auto")
    for index in parse_cases(args.cases):
        case = draw_case(index, args.held_out)
        obj = capture(case, scene_heights(case), np.random.default_rng(case.seed))
        inputs: dict[str, Any] = {"mask": obj.lit, "frequency": obj.frequency, "lower_wrapped": list(obj.lower)}
        with threadpool_limits(1):
            out, info = correct_auto(obj.phase, obj.wrapped, **inputs)
            auto_s = _seconds(functools.partial(correct_auto, obj.phase, obj.wrapped, **inputs), args.repeats)
            vote = functools.partial(undecided_orders, out, obj.phase, obj.wrapped, obj.lit)
            vote_s = _seconds(vote, args.repeats)
        with np.errstate(invalid="ignore"):
            wrong = obj.lit & (np.abs(out - obj.truth) > np.pi)
        mask = info["unresolved_mask"]
        valid = max(int(obj.lit.sum()), 1)
        inside = (wrong & mask).sum() / max(int(wrong.sum()), 1)
        right = 1.0 - (wrong & mask).sum() / max(int(mask.sum()), 1)
        ratio = float(np.median(vote_s)) / float(np.median(auto_s))
        print(
            f"{case.describe()} | {wrong.sum() / valid:.4f} | {info['unresolved']['fraction']:.4f} | {inside:.3f} | "
            f"{right:.3f} | {_spread(auto_s)} | {_spread(vote_s)} | {100 * ratio:.1f} %",
            flush=True,
        )
    print(load_line(before, os.getloadavg()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
