"""Benchmark: 12 uint8 frames (two frequencies x 6 steps, 1024 x 768) -> height map.

Our path: phase shifting of both frequencies, Ding two-frequency unwrapping, shadow mask and
eq. 1.15 against a reference phase precomputed as calibration would. Peer, in the same run:
OpenCV contrib's ``cv2.structured_light.SinusoidalPattern`` (PSP: three-step phase maps of both
frequencies from frames 0, 2, 4 of each six-step set, i.e. shifts of 2 pi / 3, then
``unwrapPhaseMap`` of the high frequency, its histogram-based spatial unwrapper; it has no
temporal unwrapping and no height). Prints medians, the ratio, peak memory and a check of the
result against the simulated truth.

    python benchmarks/bench_pipeline.py [--runs 9] [--frequencies 15 16] [--snr-db 30]
"""

from __future__ import annotations

import argparse
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
from processing.phase_shift import phase_shift, shadow_mask  # noqa: E402
from processing.temporal import unwrap_two_frequency  # noqa: E402

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
    """The timed core: phase shifting both frequencies, then Ding's two-frequency method."""
    f1, f2 = frequencies
    low = phase_shift(stack[:STEPS])
    high = phase_shift(stack[STEPS:])
    unwrapped = unwrap_two_frequency(low.phase, high.phase, f1, f2)
    return unwrapped, high


def our_pipeline(stack, frequencies, reference_phase, geometry) -> np.ndarray:
    unwrapped, high = absolute_phase(stack, frequencies)
    valid = shadow_mask(high.modulation, high.background)
    valid &= unwrapped.valid
    height = phase_to_height(unwrapped.phase - reference_phase, geometry.l0_mm, geometry.d0_mm,
                             geometry.per_mm(frequencies[1]))
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


def timed(func, runs: int) -> list[float]:
    func()  # warm-up: caches, look-up tables, page faults of the first allocation
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        func()
        times.append(time.perf_counter() - start)
    return times


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9, help="timed runs per path (median reported; >= 7)")
    parser.add_argument("--frequencies", type=int, nargs=2, default=(15, 16), metavar=("F1", "F2"))
    parser.add_argument("--snr-db", type=float, default=30.0)
    parser.add_argument("--opencv-runs", type=int, default=None, help="runs of the (slow) OpenCV path; default --runs")
    args = parser.parse_args(argv)
    freqs = tuple(args.frequencies)
    print(f"simulating 1024x768, frequencies {freqs}, {STEPS} steps, SNR {args.snr_db} dB ...", file=sys.stderr)
    geometry, heights, obj_map, obj, ref = simulate(freqs, args.snr_db)
    reference, _ = absolute_phase(ref, freqs)  # calibration's job, done once
    reference_phase = reference.phase

    height = our_pipeline(obj, freqs, reference_phase, geometry)
    truth_orders = np.floor(synth.true_absolute_phase(obj_map, geometry, freqs[1]) / (2 * np.pi))
    unwrapped, _ = absolute_phase(obj, freqs)
    lit = obj_map.lit & np.isfinite(height)
    order_ok = float(np.mean(unwrapped.orders[lit] == truth_orders[lit]))
    rms = float(np.sqrt(np.mean((height[lit] - heights[lit]) ** 2)))

    rss_before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    ours = timed(lambda: our_pipeline(obj, freqs, reference_phase, geometry), args.runs)
    rss_after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    tracemalloc.start()
    our_pipeline(obj, freqs, reference_phase, geometry)
    _, traced_peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    print("running the OpenCV path ...", file=sys.stderr)
    peer = timed(lambda: opencv_pipeline(obj, freqs, geometry), args.opencv_runs or args.runs)

    ours_ms, peer_ms = statistics.median(ours) * 1e3, statistics.median(peer) * 1e3
    print(f"{'path':<52} {'median ms':>10} {'min ms':>8} {'runs':>5}")
    print(f"{'fpp-rig: 2x phase_shift + Ding unwrap + mask + height':<52} {ours_ms:>10.1f} {min(ours) * 1e3:>8.1f} {len(ours):>5}")
    print(f"{'OpenCV PSP: 2x computePhaseMap + unwrapPhaseMap':<52} {peer_ms:>10.1f} {min(peer) * 1e3:>8.1f} {len(peer):>5}")
    print(f"speed-up (median): {peer_ms / ours_ms:.1f}x")
    print(f"peak numpy allocations (tracemalloc, one run): {traced_peak / 2**20:.1f} MiB; "
          f"maxrss growth over the timed runs: {(rss_after - rss_before) / 1024:.1f} MiB")
    print(f"check: fringe orders right on {100 * order_ok:.3f}% of valid lit pixels, "
          f"height RMS error {rms:.3f} mm, valid {100 * np.mean(np.isfinite(height)):.1f}%")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
