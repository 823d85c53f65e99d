"""What every benchmark here prints around its figures: interleaved timing, a table with spread and
the ratio to a peer measured in the same runs, the CPU (model, SIMD level) and the load average."""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable, Mapping, Sequence

# (wall seconds, CPU seconds) of one run of a row
Sample = tuple[float, float]


def interleaved(
    funcs: Mapping[str, Callable[[], object]], runs: int, warm_up: bool = True, settle: float = 0.0
) -> dict[str, list[Sample]]:
    """(wall, CPU) seconds of each function, interleaved run by run so load changes hit all rows alike.

    ``settle``: seconds to sleep before each timed call, so that threads a row left spinning (an
    OpenMP pool waits actively for a few milliseconds after its work) do not run on the cores the
    next row is timed on.

    CPU time is the process's (all its threads): on a machine shared with other jobs it is less
    sensitive to their load than the wall clock. Rows that run a child process time it themselves
    and return ``(wall, cpu)``; that pair is used instead.
    """
    times: dict[str, list[Sample]] = {name: [] for name in funcs}
    if warm_up:
        for func in funcs.values():
            func()  # caches, look-up tables, first page faults, lazy imports
    for _ in range(runs):
        for name, func in funcs.items():
            if settle > 0:
                time.sleep(settle)
            wall, cpu = time.perf_counter(), time.process_time()
            out = func()
            measured = (time.perf_counter() - wall, time.process_time() - cpu)
            if isinstance(out, tuple) and len(out) == 2 and all(isinstance(v, float) for v in out):
                measured = out
            times[name].append(measured)
    return times


def cpu_description() -> list[str]:
    """CPU model and SIMD level, as the OS, numpy and OpenCV see them."""
    model, flags = "unknown", set()
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as info:
            for line in info:
                if line.startswith("model name") and model == "unknown":
                    model = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and not flags:
                    flags = set(line.split(":", 1)[1].split())
    except OSError:
        model = platform.processor() or "unknown"
    simd = [f for f in ("sse4_2", "avx", "avx2", "fma", "avx512f", "avx512bw", "avx512_fp16") if f in flags]
    lines = [f"CPU: {model}, {os.cpu_count()} logical CPUs; flags: {' '.join(simd) or 'none of interest'}"]
    try:
        import numpy as np
        from numpy._core._multiarray_umath import __cpu_features__ as features  # type: ignore[import-not-found]

        found = [f for f in ("AVX2", "FMA3", "AVX512F", "AVX512_SKX", "AVX512_SPR") if features.get(f)]
        lines.append(f"numpy {np.__version__} dispatches to: {' '.join(found) or 'baseline only'}")
    except ImportError:
        lines.append("numpy: not importable")
    try:
        import cv2

        lines.append(f"OpenCV {cv2.__version__}: {cv2.getCPUFeaturesLine()}")
    except ImportError:
        lines.append("OpenCV: not installed")
    return lines


def load_line(before: Sequence[float], after: Sequence[float]) -> str:
    return (
        f"load average (1/5/15 min): {' '.join(f'{x:.2f}' for x in before)} before, "
        f"{' '.join(f'{x:.2f}' for x in after)} after"
    )


def print_table(
    times: Mapping[str, list[Sample]],
    peer: str,
    unit: str = "ms",
    scale: float = 1e3,
    digits: int = 1,
    extra: Mapping[str, str] | None = None,
) -> None:
    """Median, min-max, CPU median and the per-run ratio peer/row (median and min-max) of each row."""
    peer_walls = [t[0] for t in times[peer]]
    width = max(len(name) for name in times) + 2
    print(
        f"{'row':<{width}} {'median ' + unit:>10} {'min-max ' + unit:>17} {'CPU ' + unit:>8} "
        f"{'peer/this (min-max)':>22}  {'' if extra is None else 'note'}"
    )
    for name, samples in times.items():
        walls = [t[0] for t in samples]
        ratios = [p / w for p, w in zip(peer_walls, walls)]
        spread = f"{min(walls) * scale:.{digits}f}-{max(walls) * scale:.{digits}f}"
        ratio = f"{statistics.median(ratios):.2f}x ({min(ratios):.2f}-{max(ratios):.2f})"
        cpu = statistics.median(t[1] for t in samples) * scale
        note = "" if extra is None else extra.get(name, "")
        print(
            f"{name:<{width}} {statistics.median(walls) * scale:>10.{digits}f} {spread:>17} {cpu:>8.{digits}f} "
            f"{ratio:>22}  {note}"
        )
