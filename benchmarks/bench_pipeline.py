"""Benchmark: 12 uint8 frames (two frequencies x 6 steps, 1024 x 768) -> height map, in memory.

Rows, timed in the same interleaved runs (run i times every row once, in turn, so a change of
load hits all rows alike):

- ``rig pipeline, correction none``: :func:`rig.pipeline.run.process` given the 12 frames in
  memory (``frames=``) with its calibration: manifest and calibration read, the reference plane
  from the reference cache (processed once, as every scan after the first finds it), the stages
  (the fused pass, correction none), eq. 1.15 and the mask: what ``rig process --correction none``
  computes between decoding the PNGs and writing the outputs; its fused pass and its
  independent steps on :data:`processing.concurrency.THREADS` threads (two on a machine with two
  cores or more);
- ``rig pipeline, correction none, 1 thread``: the same with ``processing.concurrency.THREADS``
  set to 1 (as in rig's batch workers): everything in the calling thread;
- ``rig pipeline, default``: the same with the default correction (``auto``);
- ``fused kernel``: :func:`processing.unwrap.fused_pass.fringe_pass` (phase shifting of both
  frequencies, modulation mask and Ding's two-frequency unwrapping in one float32 pass, OpenCV's
  angle and look-up kernels) then eq. 1.15 in float32 against the reference phase;
- ``fused kernel, numpy only``: the same with ``opencv=False`` (numpy's arctan2);
- ``float64 stage functions``: the public float64 functions one after the other (``phase_shift``
  per frequency, ``shadow_mask``, ``unwrap_two_frequency``, ``phase_to_height``), the path
  ``rig process`` ran before the fused pass;
- the peer, OpenCV contrib's ``cv2.structured_light.SinusoidalPattern`` (PSP): three-step phase
  maps of both frequencies from frames 0, 2, 4 of each six-step set (shifts of 2 pi / 3) with
  ``computePhaseMap``, then ``unwrapPhaseMap`` of the high frequency (its histogram-based spatial
  unwrapper; it has no temporal unwrapping and no height).

Per row: median wall time, its spread over the runs (min - max), the median CPU time of the
process, and ``peer/this``: the median over runs of the peer's time divided by the row's time in
the same run (with its min - max). The header gives the CPU model, its SIMD level as numpy and
OpenCV see it, and the load average before and after. A check against the simulated truth ends
the report.

    python benchmarks/bench_pipeline.py [--runs 11] [--frequencies 15 16] [--snr-db 30] [--no-auto]

To see a CPU without AVX-512 on one that has it (numpy's arctan2 and others get 5-10x slower):
``NPY_DISABLE_CPU_FEATURES="X86_V4 AVX512F AVX512CD AVX512_SKX AVX512_CLX AVX512_CNL
AVX512_ICL AVX512_SPR" python benchmarks/bench_pipeline.py`` (numpy 2.4 names; the header line
"numpy dispatches to" shows what is left).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from mock_devices import scenes, synth  # noqa: E402
from processing import concurrency  # noqa: E402
from processing.geometry.height import phase_to_height  # noqa: E402
from processing.phase.shifting import phase_shift, shadow_mask  # noqa: E402
from processing.unwrap.fused_pass import fringe_pass  # noqa: E402
from processing.unwrap.temporal import unwrap_two_frequency  # noqa: E402
from rig.blas import kernel_blas  # noqa: E402
from rig.hardware.synthesis import simulate_scan, write_simulated_scan  # noqa: E402
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402

STEPS = 6
PEER = "OpenCV PSP 2x computePhaseMap + unwrapPhaseMap"


def simulate(frequencies: tuple[int, int], snr_db: float, seed: int = 0):
    """Object and reference captures of the thesis' sphere cap on the default 1024 x 768 rig."""
    geometry = synth.RigGeometry()
    appearance = synth.Appearance(ambient=0.05, snr_db=snr_db, bit_depth=8)
    patterns = synth.sinusoid_patterns(frequencies, STEPS)
    heights = scenes.sphere_cap(geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    return simulate_scan(heights, geometry=geometry, patterns=patterns, appearance=appearance, seed=seed)


GROUPS = [list(range(STEPS)), list(range(STEPS, 2 * STEPS))]


def pipeline_pass(stack, frequencies, **options):
    """fringe_pass (two-frequency, :data:`GROUPS`) as ``rig process`` runs it: its blocks on
    :data:`processing.concurrency.THREADS` threads, BLAS on one (``rig.blas.kernel_blas``); ``options`` go to it."""
    with kernel_blas():
        return fringe_pass(stack, GROUPS, frequencies, "two-frequency", threads=concurrency.THREADS, **options)


def fused_pipeline(
    stack, frequencies, reference_phase, geometry, opencv: bool = True, as_rig_runs_it: bool = False
) -> np.ndarray:
    """fringe_pass + eq. 1.15 in float32; NaN where the mask or the unwrapping failed. ``as_rig_runs_it``: the pass
    as :func:`pipeline_pass` runs it, else on one thread with BLAS as it is."""
    if as_rig_runs_it:
        scan = pipeline_pass(stack, frequencies, opencv=opencv)
    else:
        scan = fringe_pass(stack, GROUPS, frequencies, "two-frequency", opencv=opencv)
    delta = scan.phase  # NaN where not valid, which eq. 1.15 carries through
    delta -= reference_phase
    return phase_to_height(delta, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(frequencies[1]), dtype=np.float32)


def stage_pipeline(stack, frequencies, reference_phase, geometry) -> np.ndarray:
    """The float64 public functions one after the other (rig process's former path)."""
    f1, f2 = frequencies
    low, high = phase_shift(stack[:STEPS]), phase_shift(stack[STEPS:])
    unwrapped = unwrap_two_frequency(low.phase, high.phase, f1, f2)
    valid = shadow_mask(low.modulation, low.background)
    valid &= shadow_mask(high.modulation, high.background)
    valid &= unwrapped.valid
    delta = unwrapped.phase
    delta -= reference_phase
    height = phase_to_height(delta, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(f2))
    height[~valid] = np.nan
    return height.astype(np.float32)


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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=11, help="interleaved timed runs (median reported; >= 5)")
    parser.add_argument("--frequencies", type=int, nargs=2, default=(15, 16), metavar=("F1", "F2"))
    parser.add_argument("--snr-db", type=float, default=30.0)
    parser.add_argument("--no-auto", action="store_true", help="leave out the default-correction (auto) row")
    args = parser.parse_args(argv)
    if args.runs < 5:
        parser.error("--runs: expected at least 5")
    freqs = tuple(args.frequencies)
    print(f"simulating 1024x768, frequencies {freqs}, {STEPS} steps, SNR {args.snr_db} dB ...", file=sys.stderr)
    scan = simulate(freqs, args.snr_db)
    geometry, heights, obj_map = scan.geometry, scan.height_mm, scan.object_map
    obj, ref = scan.object_frames, scan.reference_frames
    reference_phase = fringe_pass(ref, GROUPS, freqs, "two-frequency").phase  # the calibration's job, done once
    reference_phase64 = reference_phase.astype(np.float64)
    workdir = tempfile.TemporaryDirectory(prefix="bench-pipeline-")
    paths = write_simulated_scan(scan, Path(workdir.name) / "scan")

    def pipeline(correction: str, threads: int | None = None) -> np.ndarray:
        saved = concurrency.THREADS
        concurrency.THREADS = saved if threads is None else threads
        try:
            result = process(paths.capture, paths.calibration, ProcessOptions(correction=correction), frames=obj)
        finally:
            concurrency.THREADS = saved
        assert result.height is not None
        return result.height

    rows: dict[str, Callable[[], object]] = {
        "rig pipeline in memory, correction none": lambda: pipeline("none"),
        "rig pipeline in memory, correction none, 1 thread": lambda: pipeline("none", threads=1),
    }
    if not args.no_auto:
        rows[f"rig pipeline in memory, default ({DEFAULT_CORRECTION})"] = lambda: pipeline(DEFAULT_CORRECTION)
    rows.update(
        {
            "fused kernel (fringe_pass + eq. 1.15)": lambda: fused_pipeline(obj, freqs, reference_phase, geometry),
            "fused kernel, numpy only": lambda: fused_pipeline(obj, freqs, reference_phase, geometry, opencv=False),
            "float64 stage functions": lambda: stage_pipeline(obj, freqs, reference_phase64, geometry),
            PEER: lambda: opencv_pipeline(obj, freqs, geometry),
        }
    )

    # Check against the simulated truth: right fringe orders (phase within pi) and height error.
    height = fused_pipeline(obj, freqs, reference_phase, geometry)
    fused = fringe_pass(obj, GROUPS, freqs, "two-frequency")
    truth_phase = synth.true_absolute_phase(obj_map, geometry, freqs[1])
    valid = np.isfinite(height)
    lit = obj_map.lit & valid
    order_errors = int(np.sum(np.abs(fused.phase[lit] - truth_phase[lit]) >= np.pi))
    rms = float(np.sqrt(np.mean((height[lit] - heights[lit]) ** 2)))
    stage_gap = float(np.nanmax(np.abs(stage_pipeline(obj, freqs, reference_phase64, geometry) - height)))
    product = pipeline("none")
    product_rms = float(np.sqrt(np.nanmean((product[lit] - heights[lit]) ** 2)))

    load_before = os.getloadavg()
    print(
        f"timing {args.runs} interleaved runs of {len(rows)} rows (the OpenCV peer takes ~0.3-1 s each) ...",
        file=sys.stderr,
    )
    times = interleaved(rows, args.runs)
    load_after = os.getloadavg()

    print("12 uint8 frames 1024x768 (2 frequencies x 6 steps) -> height map, in memory, single process")
    for line in cpu_description():
        print(line)
    print(load_line(load_before, load_after))
    print_table(times, PEER)
    print(
        f"runs: {args.runs} interleaved; check: {order_errors} wrong fringe orders among {lit.sum()} valid lit pixels, "
        f"height RMS error {rms:.3f} mm (rig pipeline {product_rms:.3f} mm), valid {100 * valid.mean():.1f}%, "
        f"fused vs float64 stages {stage_gap:.1e} mm"
    )
    workdir.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
