"""Benchmark: every correction on a drawn family of cases, NMSE_h over the oracle's (rig.study.family).

Per method (none, vote, rpca-orders, rpca-phase, auto) the distribution of NMSE_h / oracle over
the cases (median, 90th percentile, worst), then per case ``auto``'s ratio to the oracle, to the
best single method and to none. Cases are drawn by :func:`rig.study.family.draw_case`: the develop
set (default) or the held-out set (``--held-out``, seeds nothing is tuned on).

Runs in parts: ``--cases 0-15`` picks cases, ``--jobs 2`` runs cases in parallel processes (one
BLAS thread each), ``--save part.jsonl`` appends each case's result to a file, and
``--report part1.jsonl part2.jsonl ... [--markdown OUT.md]`` prints (and writes) the table of
saved parts without computing anything. Each case takes about 1 - 40 s on one core (its pixel
count, and rpca-orders on dense errors, set it); ``--estimate`` times the first case given and
projects the rest from their pixel counts.

    python benchmarks/bench_auto_family.py --cases 0-63 --held-out --jobs 2 --save /tmp/held.jsonl
    python benchmarks/bench_auto_family.py --report /tmp/held.jsonl --markdown docs/study/family.md
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from collections.abc import Sequence
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import load_line  # noqa: E402
from rig.study.family import FAMILY_SIZE, METHODS, distribution, draw_case, evaluate, ratios  # noqa: E402

HEADER = [
    "# `auto` on a drawn family of cases",
    "",
    "Written by `python benchmarks/bench_auto_family.py --report PARTS --markdown docs/study/family.md` from the",
    "parts `--cases ... [--held-out] --save PART` computed (rig.study.family). Each case draws a scene kind",
    "(isolated objects, steps, caps, ramps, mixtures, objects leaving the view, tall objects with large shadows),",
    "an image of 400-1200 px per side, a frequency set (coprime pairs 5/8, 7/11, 13/17, 18/25, 29/32 unwrapped",
    "by Ding's method; hierarchical 1/6/36 and 1/8/64; heterodyne 64/58/53 and 32/29/27), 3-12 steps, SNR",
    "12-30 dB, 8/12/16-bit, l0 700-1500 mm, d0 of either sign 600-1500 mm and a 300-700 mm view, all from its",
    "own seed; the object and the reference plane are rendered by the product's simulated rig and corrected",
    "by each method as `rig process --correction M` does (auto skipped where the density guard says so, and",
    "given the wrapped phases of the lower frequencies).",
    "NMSE_h is over the pixels lit in both; the oracle keeps the measured wrapped phase with the true orders,",
    "so a method that also removes phase noise (ch. 4, auto) can go below 1. Best single = the lowest of",
    "none, vote, rpca-orders and rpca-phase on that case. A method whose heights are not finite on more than",
    "1 % of the pixels (an order error at eq. 1.15's pole) scores inf.",
]


def parse_cases(text: str) -> list[int]:
    """``"0-15"``, ``"3,7,9"`` or a mix -> case indices."""
    out: list[int] = []
    for part in text.split(","):
        first, _, last = part.partition("-")
        out.extend(range(int(first), int(last or first) + 1))
    return out


def _run_one(args: tuple[int, bool, tuple[str, ...]]) -> dict[str, Any]:
    from threadpoolctl import threadpool_limits

    index, held_out, methods = args
    with threadpool_limits(1):
        return evaluate(draw_case(index, held_out), methods)


def _methods(text: str) -> tuple[str, ...]:
    """``--methods`` -> the methods in :data:`METHODS` order, ``auto`` and ``none`` always included."""
    asked = {m.strip() for m in text.split(",") if m.strip()}
    unknown = asked - set(METHODS)
    if unknown:
        raise SystemExit(f"--methods: expected some of {', '.join(METHODS)}, found {', '.join(sorted(unknown))}")
    return tuple(m for m in METHODS if m in asked | {"auto", "none"})


def _fmt(value: float) -> str:
    if not math.isfinite(value):
        return "inf"
    return f"{value:.3g}"


def table(results: Sequence[dict[str, Any]]) -> list[str]:
    """Markdown lines: the per-method distribution, then auto per case."""
    per_case = [ratios(r) for r in results]
    lines = [
        f"{len(results)} cases. NMSE_h / oracle (true fringe orders):",
        "",
        "| method | median | 90th percentile | worst |",
        "| --- | --- | --- | --- |",
    ]
    for method in (m for m in METHODS if all(m in c for c in per_case)):
        med, p90, worst = distribution([c[method] for c in per_case])
        lines.append(f"| {method} | {_fmt(med)} | {_fmt(p90)} | {_fmt(worst)} |")
    auto = [c["auto"] for c in per_case]
    best = [c["auto/best"] for c in per_case]
    lines += [
        "",
        f"auto <= 2x oracle: {sum(a <= 2 for a in auto)} of {len(auto)}; <= 5x: {sum(a <= 5 for a in auto)}; "
        f"auto <= 1.1x the best single method: {sum(b <= 1.1 for b in best)}; "
        f"auto <= none: {sum(c['auto/none'] <= 1.0 for c in per_case)}.",
        "",
        "| case | wrong orders | auto / oracle | auto / best single | auto / none | best single | seconds |",
        "| --- | --- | --- | --- | --- | --- | --- |",
    ]
    for result, c in zip(results, per_case):
        scores = result["nmse"]
        single = min((m for m in ("vote", "rpca-orders", "rpca-phase", "none") if m in scores), key=scores.__getitem__)
        lines.append(
            f"| {result['description']} | {result['wrong_fraction']:.1%} | {_fmt(c['auto'])} | "
            f"{_fmt(c['auto/best'])} | {_fmt(c['auto/none'])} | {single} | {result['total_seconds']:.1f} |"
        )
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--cases", default=f"0-{FAMILY_SIZE - 1}", help="case indices, e.g. 0-15 or 1,4,9")
    parser.add_argument("--held-out", action="store_true", help="the held-out set (report on it, never tune)")
    parser.add_argument("--jobs", type=int, default=1, help="cases run at once, one process each")
    parser.add_argument("--save", type=Path, help="append each case's result to this JSON-lines file")
    parser.add_argument("--report", type=Path, nargs="+", help="print the table of saved parts, compute nothing")
    parser.add_argument("--markdown", type=Path, help="with --report: also write the table here")
    parser.add_argument(
        "--methods",
        default=",".join(METHODS),
        help="comma-separated methods to run (auto always; the table scores only those run)",
    )
    parser.add_argument("--estimate", action="store_true", help="time the first case, project the others")
    args = parser.parse_args(argv)
    if args.report:
        results = [json.loads(line) for path in args.report for line in path.read_text().splitlines() if line]
        lines = table(results)
        print("\n".join(lines))
        if args.markdown:
            args.markdown.write_text("\n".join([*HEADER, "", *lines]) + "\n")
        return 0
    indices = parse_cases(args.cases)
    methods = _methods(args.methods)
    cases = [draw_case(i, args.held_out) for i in indices]
    load_before = os.getloadavg()
    if args.estimate:
        first = _run_one((indices[0], args.held_out, methods))
        pixels = [c.width * c.height for c in cases]
        total = first["total_seconds"] * sum(pixels) / pixels[0]
        print(
            f"{cases[0].describe()}: {first['total_seconds']:.1f} s; all {len(cases)} cases about "
            f"{total / 60:.0f} min on one core ({total / 60 / max(args.jobs, 1):.0f} min with --jobs {args.jobs})"
        )
        return 0
    results = []
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=max(args.jobs, 1)) as pool:
        for result in pool.map(_run_one, [(i, args.held_out, methods) for i in indices]):
            results.append(result)
            c = ratios(result)
            print(
                f"{result['description']}: auto/oracle {_fmt(c['auto'])}, auto/best {_fmt(c['auto/best'])} "
                f"({result['total_seconds']:.0f} s)",
                flush=True,
            )
            if args.save:
                with args.save.open("a") as handle:
                    handle.write(json.dumps(result) + "\n")
    print(f"{len(results)} cases in {time.perf_counter() - start:.0f} s; {load_line(load_before, os.getloadavg())}")
    print("\n".join(table(results)))
    return 0


if __name__ == "__main__":
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    raise SystemExit(main())
