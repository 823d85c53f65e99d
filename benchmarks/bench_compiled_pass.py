"""What a compiled per-pixel kernel would give the fused pass, and what it would cost: a measurement
for a decision fpp-rig has not taken.

The in-memory pipeline (``rig process`` given its frames) spends two thirds of its time in the fused
pass (:mod:`processing.unwrap.fused_pass`): about a hundred numpy and OpenCV calls per 64k-pixel
block, each reading and writing whole float32 vectors. A compiled loop visits each pixel once. This
script swaps the pass's block, where it can, for three numba kernels written the way the pass is:

- per frequency, the weighted sums A, B cos phi, B sin phi of the uint8 frames, the modulation B and
  the modulation mask in one loop (the angle stays numpy's ``arctan2``, the pass's own
  :func:`processing.unwrap.fused_pass._angle_into`: numba's scalar ``atan2`` is slower);
- Ding's two-frequency look-up (the pass's 256-entry tables);
- the noise-weighted fusion of the two frequencies (:mod:`processing.phase.frequency_fusion`'s
  weights, agreement test and sigma).

The swap covers the plans ``rig process`` runs on two-frequency captures (integer frames, Ding's
method, the fusion on); other plans run numpy's block, and the report counts both. It prints, in
the same interleaved runs (run i times every row once):

1. agreement of the compiled pass with numpy's on the peer benchmark's frames (phase, mask, sigma,
   pixels whose fringe order differs);
2. ``rig process --correction none`` in memory and the fused pass alone, numpy against compiled, on
   those frames ((15, 16) x 6 steps, 30 dB, 1024 x 768), with the ``fringes`` package's decode as the
   peer when it is importable (benchmarks/bench_fringes_peer.py's setup);
3. the cost ratio of ``auto`` to ``none`` (benchmarks/bench_auto.py's cases and rows), numpy against
   compiled: the compiled pass speeds both, so the ratio rises;
4. what a fresh process pays before its first compiled call: ``import numba`` and loading the
   cached kernels, against ``python -c "import numpy, cv2"``.

numba is not a dependency of fpp-rig. ``fringes`` brings it, so the environment of
bench_fringes_peer.py runs this script (with this repository on the path):

    PYTHONPATH=. <environment with numba>/bin/python benchmarks/bench_compiled_pass.py [--runs 7]
"""

from __future__ import annotations

import argparse
import contextlib
import importlib
import math
import os
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_auto import CASES, simulated_scan  # noqa: E402
from benchmarks.bench_fringes_peer import FREQUENCIES, PEER, SETTLE_S, peer_decoder, peer_phase  # noqa: E402
from benchmarks.bench_pipeline import GROUPS, pipeline_pass, simulate  # noqa: E402
from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from processing.geometry.uncertainty import noise_sigma  # noqa: E402
from processing.phase.frequency_fusion import weight_unit  # noqa: E402
from processing.unwrap import fused_pass  # noqa: E402
from rig.hardware.synthesis import write_simulated_scan  # noqa: E402
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402

TWO_PI = 2.0 * math.pi


def demodulate(flat, rows, weights, begin, end, ratio, threshold, nonnegative, a, c, s, b, valid, first):
    """A, B cos phi, B sin phi (the weights' rows) of one frequency over pixels [begin, end), B and the mask
    (B >= max(threshold, ratio A), A > 0 unless ``nonnegative``), ANDed into ``valid`` unless ``first``."""
    n = end - begin
    a[:n] = 0
    c[:n] = 0
    s[:n] = 0
    for j in range(rows.size):
        frame = flat[rows[j], begin:end]
        w0, w1, w2 = weights[0, j], weights[1, j], weights[2, j]
        for q in range(n):
            value = np.float32(frame[q])
            a[q] += w0 * value
            c[q] += w1 * value
            s[q] += w2 * value
    for q in range(n):
        amplitude = np.sqrt(c[q] * c[q] + s[q] * s[q])
        b[q] = amplitude
        ok = (amplitude >= max(a[q] * ratio, threshold)) & (nonnegative | (a[q] > 0))
        valid[q] = ok if first else (valid[q] & ok)


def ding_lookup(low, high, f1, f2, orders, reach, valid, modulated, base):
    """Ding's index round(f2 t1 - f1 t2 + f1) through the pass's tables: the highest frequency's absolute phase
    into ``base``, the mask before the look-up into ``modulated``, unreachable indices out of ``valid``."""
    inverse, two_pi = np.float32(1.0 / TWO_PI), np.float32(TWO_PI)
    last = orders.size - 1
    for q in range(low.size):
        index = np.float32(f2) * (low[q] * inverse) - np.float32(f1) * (high[q] * inverse) + np.float32(f1)
        i = min(max(np.int32(math.floor(index + np.float32(0.5))), 0), last)
        base[q] = np.float32(orders[i]) * two_pi + high[q]
        inside = valid[q]
        modulated[q] = inside
        valid[q] = inside & (reach[i] != 0)


def fuse_pair(low, base, b_low, b_high, modulated, phase, sigma, low_scale, high_scale, ratio, bound, noise):
    """frequency_fusion.fuse_frequencies for one lower frequency, weights in its unit; returns the disagreeing
    pixels. NaN phase outside ``modulated``."""
    inverse = np.float32(1.0 / TWO_PI)
    to_low = np.float32(1.0 / (TWO_PI * ratio))
    to_high = np.float32(TWO_PI * ratio)
    nan = np.float32(np.nan)
    disagreeing = 0
    for q in range(low.size):
        top = high_scale * b_high[q] * b_high[q]
        offset = low[q] * inverse - base[q] * to_low
        offset = (offset - math.floor(offset + np.float32(0.5))) * to_high
        weight = low_scale * b_low[q] * b_low[q]
        square = offset * offset
        agrees = (square < np.float32(math.pi**2)) & (square * weight * top <= (weight + top) * bound)
        weight = weight if agrees else np.float32(0.0)
        inside = modulated[q]
        disagreeing += np.int32(inside & (not agrees))
        total = top + weight
        value = base[q] + offset * weight / total
        phase[q] = value if inside else nan
        sigma[q] = np.sqrt(noise / total)
    return disagreeing


def compile_kernels(cache: bool = False) -> dict[str, Callable[..., Any]]:
    """The three kernels through numba (nogil: the pass's two threads run them at once; fast-math without its
    no-NaN and no-infinity assumptions, which the mask and the NaN phase need)."""
    numba = importlib.import_module("numba")
    flags = {"contract", "arcp", "reassoc", "nsz", "afn"}
    jit = numba.njit(nogil=True, fastmath=flags, boundscheck=False, error_model="numpy", cache=cache)
    return {f.__name__: jit(f) for f in (demodulate, ding_lookup, fuse_pair)}


class CompiledBlock:
    """A replacement for ``fused_pass._Plan._block`` that runs the kernels where the plan allows it."""

    def __init__(self, kernels: dict[str, Callable[..., Any]], numpy_block: Callable[..., None]) -> None:
        self.kernels, self.numpy_block = kernels, numpy_block
        self.blocks = {"compiled": 0, "numpy": 0}

    @staticmethod
    def covers(plan: Any, out: Any) -> bool:
        """Integer frames, two frequencies, Ding's tables and the fusion on, no order map: rig process's plan."""
        return bool(
            plan.finite_frames
            and len(plan.specs) == 2
            and plan.tables is not None
            and plan.fusion is not None
            and out.orders is None
        )

    def __call__(self, plan: Any, out: Any, begin: int, end: int, scratch: Any) -> None:
        if not self.covers(plan, out):
            self.blocks["numpy"] += 1
            self.numpy_block(plan, out, begin, end, scratch)
            return
        self.blocks["compiled"] += 1
        window, n = slice(begin, end), end - begin
        valid = out.valid[window]
        (a, c, s), spare = (row[:n] for row in scratch.coeffs), scratch.level[:n]
        angles, amplitudes = [], []
        for g, spec in enumerate(plan.specs):
            rows = (
                np.arange(spec.rows.start, spec.rows.stop, spec.rows.step)
                if isinstance(spec.rows, slice)
                else spec.rows
            )
            slot = plan.kept.index(g) if g in plan.kept else -1
            amplitude = out.modulation[slot][window] if slot >= 0 and out.modulation else scratch.modulation[g][:n]
            self.kernels["demodulate"](
                plan.flat, rows, spec.weights, begin, end, np.float32(plan.ratio), np.float32(plan.thresholds[g]),
                plan.background_nonnegative, a, c, s, amplitude, valid, g == 0,
            )  # fmt: skip
            angle = out.wrapped[slot][window] if slot >= 0 else scratch.angle[g][:n]
            fused_pass._angle_into(c, s, angle, plan.cv2, finite=True, opposite=plan.opposite)
            if slot >= 0 and out.brightness:
                np.add(a, amplitude, out=out.brightness[slot][window])
            elif slot >= 0:
                np.copyto(out.background[slot][window], a)
            angles.append(angle)
            amplitudes.append(amplitude)
        modulated = out.modulated[window]
        tables = plan.tables
        self.kernels["ding_lookup"](
            angles[0], angles[1], tables.f1, tables.f2, tables.orders, tables.reach, valid, modulated, spare
        )
        fusion = plan.fusion
        unit, bound, noise = weight_unit(fusion.noise)
        ratio = fusion.frequencies[1] / fusion.frequencies[0]
        low_scale, high_scale = np.float32(fusion.steps[0] * unit / ratio**2), np.float32(fusion.steps[1] * unit)
        disagreeing = self.kernels["fuse_pair"](
            angles[0], spare, amplitudes[0], amplitudes[1], modulated, out.phase[window], out.sigma[window],
            low_scale, high_scale, np.float32(ratio), np.float32(bound), np.float32(noise),
        )  # fmt: skip
        fusion.disagreeing.append(int(disagreeing))


@contextlib.contextmanager
def compiled_pass(block: CompiledBlock) -> Iterator[None]:
    """The fused pass with ``block`` in place of its numpy block, for the duration."""

    def method(plan: Any, out: Any, begin: int, end: int, scratch: Any) -> None:  # binds like the method replaced
        block(plan, out, begin, end, scratch)

    original = fused_pass._Plan._block
    fused_pass._Plan._block = method  # type: ignore[method-assign]
    try:
        yield
    finally:
        fused_pass._Plan._block = original  # type: ignore[method-assign]


def agreement(block: CompiledBlock, frames: np.ndarray) -> list[str]:
    """The compiled pass against numpy's on the same frames, as rig process runs it."""
    options = {"fuse_noise": noise_sigma(frames, GROUPS), "brightness": True, "orders": False}
    reference = pipeline_pass(frames, FREQUENCIES, **options)
    with compiled_pass(block):
        compiled = pipeline_pass(frames, FREQUENCIES, **options)
    both = reference.valid & compiled.valid
    difference = np.abs(reference.phase - compiled.phase)[both]
    sigma = np.abs(compiled.sigma / reference.sigma - 1.0)[both]
    return [
        f"mask: {int(np.sum(reference.valid != compiled.valid))} pixels differ "
        f"(of {reference.valid.size}); modulated: {int(np.sum(reference.modulated != compiled.modulated))}",
        f"phase: max |difference| {difference.max():.2e} rad; fringe order differs at {int(np.sum(difference > np.pi))}",
        f"sigma: max relative difference {sigma.max():.1e}; disagreeing pixels {reference.disagreeing} numpy, "
        f"{compiled.disagreeing} compiled",
    ]


def switched(block: CompiledBlock, func: Callable[[], object]) -> Callable[[], object]:
    """``func`` run with the compiled pass."""

    def run() -> object:
        with compiled_pass(block):
            return func()

    return run


def peer_rows(block: CompiledBlock, runs: int) -> None:
    """Part 2: rig process in memory and the fused pass, numpy and compiled, and fringes' decode."""
    scan = simulate(FREQUENCIES, 30.0, seed=0)
    frames = scan.object_frames
    workdir = tempfile.TemporaryDirectory(prefix="bench-compiled-")
    paths = write_simulated_scan(scan, Path(workdir.name) / "scan")
    options = ProcessOptions(correction="none")
    sigma_i = noise_sigma(frames, GROUPS)

    def pipeline() -> object:
        return process(paths.capture, paths.calibration, options, frames=frames)

    def kernel() -> object:
        return pipeline_pass(frames, FREQUENCIES, fuse_noise=sigma_i, brightness=True, orders=False)

    rows: dict[str, Callable[[], object]] = {
        "rig process in memory, numpy pass": pipeline,
        "rig process in memory, compiled pass": switched(block, pipeline),
        "fused pass, numpy": kernel,
        "fused pass, compiled": switched(block, kernel),
    }
    decoder = peer_decoder("precise")
    if decoder is not None:
        rows[PEER] = lambda: peer_phase(decoder, frames)
    else:
        print("fringes: not importable; the ratios below are to the numpy pipeline")
    times = interleaved(rows, runs, settle=SETTLE_S)
    workdir.cleanup()
    print(f"\n(15, 16) x 6 steps, 30 dB, 1024 x 768, {runs} interleaved runs")
    print_table(times, PEER if decoder is not None else "rig process in memory, numpy pass")


def ratio_rows(block: CompiledBlock, case: str, runs: int) -> None:
    """Part 3: auto over none in the same run, numpy and compiled (bench_auto's rows)."""
    simulated = simulated_scan(case)
    workdir = tempfile.TemporaryDirectory(prefix="bench-compiled-")
    paths = write_simulated_scan(simulated, Path(workdir.name) / "scan")
    frames = simulated.object_frames

    def pipeline(correction: str) -> Callable[[], object]:
        options = ProcessOptions(correction=correction)
        return lambda: process(paths.capture, paths.calibration, options, frames=frames)

    rows = {
        "none, numpy": pipeline("none"),
        "auto, numpy": pipeline(DEFAULT_CORRECTION),
        "none, compiled": switched(block, pipeline("none")),
        "auto, compiled": switched(block, pipeline(DEFAULT_CORRECTION)),
    }
    times = interleaved(rows, runs)
    workdir.cleanup()
    print(f"\n{CASES[case][0]}, rig process in memory, {runs} interleaved runs")
    for kind in ("numpy", "compiled"):
        none, auto = ([t[0] for t in times[f"{c}, {kind}"]] for c in ("none", DEFAULT_CORRECTION))
        ratios = [x / y for x, y in zip(auto, none, strict=True)]
        print(
            f"{kind:9s} none {statistics.median(none) * 1e3:6.1f} ms, auto {statistics.median(auto) * 1e3:6.1f} ms, "
            f"auto / none {statistics.median(ratios):.1f} ({min(ratios):.1f} - {max(ratios):.1f})"
        )


_FIRST_CALL = """
import time
import numpy as np
from benchmarks.bench_compiled_pass import compile_kernels
begin = time.perf_counter()
k = compile_kernels(cache=True)
n, f = 64, np.float32
v = np.zeros(n, f)
m = np.ones(n, bool)
k["demodulate"](np.zeros((6, n), np.uint8), np.arange(6), np.ones((3, 6), f), 0, n, f(.2), f(1), True, v, v, v, v, m, True)
k["ding_lookup"](v, v, 15, 16, np.zeros(256, np.int32), np.zeros(256, np.uint8), m, m, v)
k["fuse_pair"](v, v, v, v, m, v, v, f(1), f(1), f(1.1), f(1), f(1))
print(time.perf_counter() - begin)
"""


def start_cost(runs: int) -> None:
    """Part 4: what a process that has numpy, OpenCV and rig loaded pays up to its first compiled call (numba
    imported, the kernels loaded from numba's cache), in a fresh process per run."""
    root = str(Path(__file__).resolve().parents[1])
    with tempfile.TemporaryDirectory(prefix="bench-numba-cache-") as cache:
        env = {**os.environ, "NUMBA_CACHE_DIR": cache, "PYTHONPATH": root}
        command = [sys.executable, "-c", _FIRST_CALL]
        subprocess.run(command, env=env, check=True, capture_output=True)  # compiles and fills the cache
        seconds = [
            float(subprocess.run(command, env=env, check=True, capture_output=True, text=True).stdout)
            for _ in range(runs)
        ]
    print(
        f"\na fresh process, import numba and the first call of the cached kernels: {statistics.median(seconds):.3f} s "
        f"({min(seconds):.3f} - {max(seconds):.3f}), {runs} runs"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="interleaved timed runs (median reported; >= 3)")
    args = parser.parse_args(argv)
    if args.runs < 3:
        parser.error("--runs: expected at least 3")
    try:
        kernels = compile_kernels()
    except ImportError:
        print("numba: not importable (it comes with fringes; see the docstring); nothing measured")
        return 0
    block = CompiledBlock(kernels, fused_pass._Plan._block)
    for line in cpu_description():
        print(line)
    print(f"numba {importlib.import_module('numba').__version__}")
    load_before = os.getloadavg()
    print("\ncompiled pass against numpy's, (15, 16) x 6 steps, 30 dB:")
    for line in agreement(block, simulate(FREQUENCIES, 30.0, seed=0).object_frames):
        print(line)
    peer_rows(block, args.runs)
    for case in CASES:
        ratio_rows(block, case, args.runs)
    start_cost(args.runs)
    print(f"\nblocks run: {block.blocks['compiled']} compiled, {block.blocks['numpy']} numpy")
    print(load_line(load_before, os.getloadavg()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
