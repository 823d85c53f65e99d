"""Benchmark: the default correction ``auto`` per capture, against the ``none`` path in the same run.

One 1024 x 768 object capture (two frequencies x 6 steps, uint8) per case. Rows, timed in
interleaved runs (run i times every row once, in turn, so a change of load hits all rows alike):

- ``rig process, correction none``: :func:`rig.pipeline.run.process` given the object's frames in
  memory (``frames=``) with the simulated calibration, ``--correction none``: what ``rig process
  --correction none`` computes between decoding the PNGs and writing the outputs (the fused pass with
  the frequency fusion, the noise-based validity rule, rejected pixels rescued, heights, the
  uncertainty map and small islands dropped; the reference plane from the reference cache, as every
  scan after the first finds it). The peer every ratio is taken against;
- ``rig process, default (auto)``: the same with the default correction, what ``rig process``
  computes; its ratio to the row above is the cost of ``auto`` as a user meets it;
- ``none path (fringe_pass + eq. 1.15)``: the kernel alone,
  :func:`processing.unwrap.fused_pass.fringe_pass` + eq. 1.15 in float32 against a precomputed
  reference phase, run as the pipeline runs it: its blocks on
  :data:`processing.concurrency.THREADS` threads, BLAS on one (``rig.blas.kernel_blas``). It leaves out
  the fusion, the validity rule, the rescue, the uncertainty and the islands of the row above;
- ``auto (correction only)``: :func:`processing.correction.registry.correct_auto` on the object's
  absolute and wrapped phase, weighed against the lower frequency's wrapped phase (the reference is
  corrected once and cached, not per capture);
- ``rpca-phase (correction only)``: plain ch. 4 RPCA, for scale;
- ``none path + auto``: the kernel and ``auto`` together.

The corrections run with single-threaded BLAS, as ``rig process`` runs its correction stage
(``rig.blas.rpca_blas``): multi-threaded OpenBLAS spends most of a small block solve's time
synchronising its threads when the cores are busy.

Per row: median wall time, its spread over the runs (min - max), the median CPU time, and
``row / none``: the median over runs of the row's time divided by the ``rig process, correction
none`` time in the same run (min - max); a last line gives the kernel-level ratio (``none path +
auto`` over ``none path``) the same way. The header gives the CPU, its SIMD level and the load
average before and after. Cases: the thesis' sphere cap at f = (5, 8), 15 dB (few wrong orders), and
isolated objects at f = (18, 25), 18 dB (a quarter of the orders wrong); the object's wrong orders
before and after ``auto`` end each case.

    python benchmarks/bench_auto.py [--runs 7] [--case cap isolated]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_pipeline import GROUPS, STEPS, fused_pipeline, pipeline_pass  # noqa: E402
from benchmarks.measure import Sample, cpu_description, interleaved, load_line  # noqa: E402
from mock_devices import scenes, synth  # noqa: E402
from processing.correction.registry import correct_auto, correct_rpca_phase  # noqa: E402
from processing.geometry.height import phase_to_height  # noqa: E402
from processing.unwrap.fused_pass import fringe_pass  # noqa: E402
from rig.blas import rpca_blas  # noqa: E402
from rig.hardware.synthesis import SimulatedPaths, SimulatedScan, simulate_scan, write_simulated_scan  # noqa: E402
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402

TWO_PI = 2.0 * np.pi
CASES = {
    "cap": ("sphere cap, f = (5, 8), 15 dB", (5, 8), 15.0),
    "isolated": ("isolated objects, f = (18, 25), 18 dB", (18, 25), 18.0),
}


def simulated_scan(case: str, seed: int = 0) -> SimulatedScan:
    """The object and reference captures of one case on a 1024 x 768 rig (d0 = 1250 mm: no height pole)."""
    _, frequencies, snr_db = CASES[case]
    geometry = synth.RigGeometry(d0_mm=1250.0)
    appearance = synth.Appearance(snr_db=snr_db, bit_depth=8)
    patterns = synth.sinusoid_patterns(frequencies, STEPS)
    rows, cols, pixel = geometry.camera_height, geometry.camera_width, geometry.pixel_mm
    heights = scenes.sphere_cap(rows, cols, pixel) if case == "cap" else scenes.isolated_objects(rows, cols, pixel)
    return simulate_scan(heights, geometry=geometry, patterns=patterns, appearance=appearance, seed=seed)


def auto_pipeline(stack, frequencies, reference_phase, geometry) -> np.ndarray:
    """fringe_pass (keeping the lower frequency's wrapped phase), ``auto`` on the object's phase, eq. 1.15 (float32)."""
    scan = pipeline_pass(stack, frequencies, keep_all=True)
    with rpca_blas():  # as rig process runs the correction stage
        phase, _ = correct_auto(
            scan.phase.astype(np.float64),
            scan.wrapped[-1].astype(np.float64),
            mask=scan.valid,
            frequency=frequencies[1],
            lower_wrapped=[(frequencies[0], scan.wrapped[0])],
        )
    delta = (phase - reference_phase).astype(np.float32)
    return phase_to_height(delta, geometry.l0_mm, geometry.d0_mm, geometry.per_mm(frequencies[1]), dtype=np.float32)


def as_correction_stage(correction: Callable[[], object]) -> Callable[[], object]:
    """``correction`` run as ``rig process`` runs its correction stage: with single-threaded BLAS."""

    def run() -> object:
        with rpca_blas():
            return correction()

    return run


def _stats(values: list[float]) -> str:
    return f"{statistics.median(values):9.4f} ({min(values):.4f} - {max(values):.4f})"


PIPELINE_NONE = "rig process, correction none"
PIPELINE_AUTO = "rig process, default (auto)"
KERNEL_NONE = "none path (fringe_pass + eq. 1.15)"
KERNEL_AUTO = "none path + auto"


def _pipeline(paths: SimulatedPaths, frames: np.ndarray, correction: str) -> Callable[[], object]:
    """``rig process`` in memory on the written capture, given its frames (``frames=``)."""
    options = ProcessOptions(correction=correction)
    return lambda: process(paths.capture, paths.calibration, options, frames=frames)


def _ratios(times: dict[str, list[Sample]], row: str, peer: str) -> list[float]:
    """``row``'s wall time over ``peer``'s, run by run."""
    return [wall / base for (wall, _), (base, _) in zip(times[row], times[peer], strict=True)]


def run_case(case: str, runs: int) -> None:
    label, freqs, _ = CASES[case]
    simulated = simulated_scan(case)
    geometry, obj_map, obj, ref = (
        simulated.geometry,
        simulated.object_map,
        simulated.object_frames,
        simulated.reference_frames,
    )
    workdir = tempfile.TemporaryDirectory(prefix="bench-auto-")
    paths = write_simulated_scan(simulated, Path(workdir.name) / "scan")
    reference_phase = fringe_pass(ref, GROUPS, freqs, "two-frequency").phase  # stored with the calibration
    scan = fringe_pass(obj, GROUPS, freqs, "two-frequency", keep_all=True)
    phase, wrapped, valid = scan.phase.astype(np.float64), scan.wrapped[-1].astype(np.float64), scan.valid
    evidence = {"frequency": freqs[1], "lower_wrapped": [(freqs[0], scan.wrapped[0])]}
    rows: dict[str, Callable[[], object]] = {
        PIPELINE_NONE: _pipeline(paths, obj, "none"),
        PIPELINE_AUTO: _pipeline(paths, obj, DEFAULT_CORRECTION),
        KERNEL_NONE: lambda: fused_pipeline(obj, freqs, reference_phase, geometry, as_rig_runs_it=True),
        "auto (correction only)": as_correction_stage(lambda: correct_auto(phase, wrapped, mask=valid, **evidence)),
        "rpca-phase (correction only)": as_correction_stage(lambda: correct_rpca_phase(phase, wrapped, mask=valid)),
        KERNEL_AUTO: lambda: auto_pipeline(obj, freqs, reference_phase, geometry),
    }
    times = interleaved(rows, runs)
    workdir.cleanup()
    print(f"\n{label}, 1024 x 768, {runs} interleaved runs")
    print(f"{'row':38s} {'wall s: median (min - max)':>30s} {'CPU s':>8s} {'row / none: median (min - max)':>34s}")
    for name, samples in times.items():
        walls = [wall for wall, _ in samples]
        ratios = _ratios(times, name, PIPELINE_NONE)
        cpu = statistics.median(c for _, c in samples)
        spread = f"{statistics.median(ratios):8.1f} ({min(ratios):.1f} - {max(ratios):.1f})"
        print(f"{name:38s} {_stats(walls):>30s} {cpu:8.4f} {spread:>34s}")
    kernel = _ratios(times, KERNEL_AUTO, KERNEL_NONE)
    print(
        f"kernel level ({KERNEL_AUTO} / {KERNEL_NONE}): {statistics.median(kernel):.1f} "
        f"({min(kernel):.1f} - {max(kernel):.1f})"
    )
    truth = synth.true_absolute_phase(obj_map, geometry, freqs[1])
    lit = obj_map.lit & valid
    with rpca_blas():
        corrected, info = correct_auto(phase, wrapped, mask=valid, **evidence)
    before = int(np.sum(np.abs(phase - truth)[lit] > np.pi))
    after = int(np.sum(np.abs(corrected - truth)[lit] > np.pi))
    print(
        f"wrong orders of the object: {before} before, {after} after auto ({lit.sum()} lit pixels); "
        f"auto kept the {info['guard']!r} candidate, {info['iterations']} RPCA iterations, rank {info['rank']}"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="interleaved timed runs (median reported; >= 3)")
    parser.add_argument("--case", nargs="+", choices=sorted(CASES), default=["cap", "isolated"])
    args = parser.parse_args(argv)
    if args.runs < 3:
        parser.error("--runs: expected at least 3")
    for line in cpu_description():
        print(line)
    load_before = os.getloadavg()
    for case in args.case:
        run_case(case, args.runs)
    print()
    print(load_line(load_before, os.getloadavg()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
