"""Benchmark: 12 uint8 frames (two frequencies x 6 steps, 1024 x 768) -> height map.

Our path: phase shifting of both frequencies, Ding two-frequency unwrapping, shadow mask and
eq. 1.15 against a reference phase precomputed as calibration would; step by step through the
public functions, and with the first two fused (``unwrap_two_frequency_stacks``). Peer, in the
same run: OpenCV contrib's ``cv2.structured_light.SinusoidalPattern`` (PSP: three-step phase
maps of both frequencies from frames 0, 2, 4 of each six-step set, i.e. shifts of 2 pi / 3,
then ``unwrapPhaseMap`` of the high frequency, its histogram-based spatial unwrapper; it has no
temporal unwrapping and no height). Prints medians, the ratio, peak memory and a check of the
result against the simulated truth.

    python benchmarks/bench_pipeline.py [--runs 9] [--frequencies 15 16] [--snr-db 30]

Rows: our two paths (interleaved, single-threaded), then OpenCV. Wall-clock medians depend on
what else runs on the machine: the load average is printed, and the CPU time of the process,
much less sensitive to it, beside them.
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from mock_devices import scenes, synth  # noqa: E402
from processing.height import phase_to_height  # noqa: E402
from processing.phase_shift import phase_shift, shadow_mask, wrapped_phase  # noqa: E402
from processing.temporal import unwrap_two_frequency, unwrap_two_frequency_stacks  # noqa: E402

STEPS = 6


def simulate(frequencies: tuple[int, int], snr_db: float, seed: int = 0):
    """Object and reference captures of the thesis' sphere cap on the default 1024 x 768 rig."""
    geometry = synth.RigGeometry()
    rng = np.random.default_rng(seed)
    appearance = synth.Appearance(ambient=0.05, snr_db=snr_db, bit_depth=8)
    patterns = synth.sinusoid_patterns(frequencies, STEPS)
    heights = scenes.sphere_cap(geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    obj_map = synth.projector_coordinates(heights, geometry)
    ref_map = synth.projector_coordinates(np.zeros_like(heights), geometry)
    obj = synth.render_stack(patterns, obj_map, geometry, appearance, rng)
    ref = synth.render_stack(patterns, ref_map, geometry, appearance, rng)
    return geometry, heights, obj_map, obj, ref


def absolute_phase(stack: np.ndarray, frequencies: tuple[int, int]):
    """The timed core: phase shifting both frequencies (background and modulation of the high
    one only, for the mask), then Ding's two-frequency method."""
    f1, f2 = frequencies
    low = wrapped_phase(stack[:STEPS])
    high = phase_shift(stack[STEPS:])
    unwrapped = unwrap_two_frequency(low, high.phase, f1, f2)
    return unwrapped, high


def our_pipeline(stack, frequencies, reference_phase, geometry) -> np.ndarray:
    unwrapped, high = absolute_phase(stack, frequencies)
    valid = shadow_mask(high.modulation, high.background)
    valid &= unwrapped.valid
    delta = unwrapped.phase
    delta -= reference_phase  # in place: the unwrapped phase is ours to reuse
    height = phase_to_height(delta, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(frequencies[1]))
    height[~valid] = np.nan
    return height


def fused_pipeline(stack, frequencies, reference_phase, geometry) -> np.ndarray:
    """The same steps with phase shifting and unwrapping fused (unwrap_two_frequency_stacks)."""
    scan = unwrap_two_frequency_stacks(stack[:STEPS], stack[STEPS:], *frequencies)
    valid = shadow_mask(scan.modulation, scan.background)
    valid &= scan.unwrapped.valid
    delta = scan.unwrapped.phase
    delta -= reference_phase
    height = phase_to_height(delta, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(frequencies[1]))
    height[~valid] = np.nan
    return height


def opencv_pipeline(stack, frequencies, geometry):
    import cv2

    sl = cv2.structured_light
    params = sl.SinusoidalPattern.Params()
    params.width, params.height = geometry.projector_width, geometry.projector_height
    params.nbrOfPeriods = int(frequencies[1])
    params.methodId = sl.PSP
    pattern = sl.SinusoidalPattern_create(params)
    size = (geometry.camera_width, geometry.camera_height)
    low_phase, _ = pattern.computePhaseMap([stack[j] for j in (0, 2, 4)])
    high_phase, high_mask = pattern.computePhaseMap([stack[STEPS + j] for j in (0, 2, 4)])
    return low_phase, pattern.unwrapPhaseMap(high_phase, size, shadowMask=high_mask)


def timed(funcs: dict, runs: int) -> dict[str, list[tuple[float, float]]]:
    """(wall, CPU) seconds of each function, interleaved run by run so load changes hit all alike.

    CPU time is the process's (all threads, OpenCV uses several): on a machine shared with
    other jobs it is far less sensitive to their load than the wall clock.
    """
    times: dict[str, list[tuple[float, float]]] = {name: [] for name in funcs}
    for func in funcs.values():
        func()  # warm-up: caches, look-up tables, first page faults
    for _ in range(runs):
        for name, func in funcs.items():
            wall, cpu = time.perf_counter(), time.process_time()
            func()
            times[name].append((time.perf_counter() - wall, time.process_time() - cpu))
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9, help="timed runs per path (median reported; >= 7)")
    parser.add_argument("--frequencies", type=int, nargs=2, default=(15, 16), metavar=("F1", "F2"))
    parser.add_argument("--snr-db", type=float, default=30.0)
    args = parser.parse_args(argv)
    if args.runs < 7:
        parser.error("--runs: expected at least 7")
    freqs = tuple(args.frequencies)
    print(f"simulating 1024x768, frequencies {freqs}, {STEPS} steps, SNR {args.snr_db} dB ...", file=sys.stderr)
    geometry, heights, obj_map, obj, ref = simulate(freqs, args.snr_db)
    reference, _ = absolute_phase(ref, freqs)  # calibration's job, done once
    reference_phase = reference.phase

    def ours():
        return our_pipeline(obj, freqs, reference_phase, geometry)

    def fused():
        return fused_pipeline(obj, freqs, reference_phase, geometry)

    # Check the result against the simulated truth (orders: phase within pi of the truth).
    height = ours()
    unwrapped, _ = absolute_phase(obj, freqs)
    truth_phase = synth.true_absolute_phase(obj_map, geometry, freqs[1])
    valid = np.isfinite(height)
    lit = obj_map.lit & valid
    order_errors = int(np.sum(np.abs(unwrapped.phase[lit] - truth_phase[lit]) >= np.pi))
    rms = float(np.sqrt(np.mean((height[lit] - heights[lit]) ** 2)))
    fused_gap = float(np.max(np.abs(fused()[lit] - height[lit])))

    peaks = []
    for func in (fused, ours):
        tracemalloc.start()
        func()
        peaks.append(tracemalloc.get_traced_memory()[1] / 2**20)
        tracemalloc.stop()
    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    load_before = os.getloadavg()[0]
    print(f"timing {args.runs} interleaved runs (the OpenCV path takes about a second each) ...", file=sys.stderr)
    rows = timed({"fpp-rig fused": fused, "fpp-rig step by step": ours}, args.runs)
    # Separately: a second of OpenCV between two of our runs would flush the caches each time.
    rows.update(timed({"OpenCV PSP 2x computePhaseMap + unwrapPhaseMap": lambda: opencv_pipeline(obj, freqs, geometry)},
                      args.runs))
    rss_after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss

    peer = statistics.median(t[0] for t in rows["OpenCV PSP 2x computePhaseMap + unwrapPhaseMap"]) * 1e3
    print("12 uint8 frames 1024x768 (2 frequencies x 6 steps) -> height map. fpp-rig step by step: wrapped_phase "
          "+ phase_shift + unwrap_two_frequency; fused: unwrap_two_frequency_stacks; both + shadow_mask + phase_to_height")
    print(f"load average {load_before:.1f} before, {os.getloadavg()[0]:.1f} after ({os.cpu_count()} CPUs)")
    print(f"{'path':<50} {'median ms':>10} {'min ms':>8} {'CPU ms':>7} {'runs':>5} {'OpenCV/this':>12}")
    for name, times in rows.items():
        median = statistics.median(t[0] for t in times) * 1e3
        cpu = statistics.median(t[1] for t in times) * 1e3
        fastest = min(t[0] for t in times) * 1e3
        print(f"{name:<50} {median:>10.1f} {fastest:>8.1f} {cpu:>7.1f} {len(times):>5} {peer / median:>11.1f}x")
    print(f"peak numpy allocations of one run (tracemalloc): fused {peaks[0]:.1f} MiB, step by step {peaks[1]:.1f} MiB; "
          f"process maxrss {rss_after / 1024:.0f} MiB (+{(rss_after - rss_before) / 1024:.0f} MiB while timing)")
    print(f"check: {order_errors} wrong fringe orders among {lit.sum()} valid lit pixels, "
          f"height RMS error {rms:.3f} mm, valid {100 * valid.mean():.1f}%, fused vs step by step {fused_gap:.1e} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
