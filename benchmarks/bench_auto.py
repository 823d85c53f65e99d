"""Benchmark: the default correction ``auto`` per capture, against the ``none`` path in the same run.

One 1024 x 768 object capture (two frequencies x 6 steps, uint8) per case; the reference plane's
phase is precomputed, as the calibration stores it. Rows, timed in interleaved runs (run i times
every row once, in turn, so a change of load hits all rows alike):

- ``none path``: :func:`processing.unwrap.fused_pass.fringe_pass` + eq. 1.15 in float32, what
  ``rig process --correction none`` computes (the peer every ratio is taken against), run as the
  pipeline runs it: its blocks on :data:`processing.concurrency.THREADS` threads, BLAS on one
  (``rig.blas.kernel_blas``; a second OpenBLAS thread beside two block threads made the pass
  a third slower on the 2-core development machine);
- ``auto (correction only)``: :func:`processing.correction.registry.correct_auto` on the object's
  absolute and wrapped phase, weighed against the lower frequency's wrapped phase (the reference is
  corrected once and cached, not per capture);
- ``rpca-phase (correction only)``: plain ch. 4 RPCA, for scale;
- ``none path + auto``: the two together, what ``rig process`` computes by default (its fused pass
  run as the none path's).

The corrections run with single-threaded BLAS, as ``rig process`` runs its correction stage
(``rig.blas.rpca_blas``): multi-threaded OpenBLAS spends most of a small block solve's time
synchronising its threads when the cores are busy.

Per row: median wall time, its spread over the runs (min - max), the median CPU time, and
``row / none``: the median over runs of the row's time divided by the none path's time in the
same run (min - max). The header gives the CPU, its SIMD level and the load average before and
after. Cases: the thesis' sphere cap at f = (5, 8), 15 dB (few wrong orders), and isolated objects
at f = (18, 25), 18 dB (a quarter of the orders wrong); the object's wrong orders before and after
``auto`` end each case.

    python benchmarks/bench_auto.py [--runs 7] [--case cap isolated]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_pipeline import GROUPS, STEPS, fused_pipeline, pipeline_pass  # noqa: E402
from benchmarks.measure import cpu_description, interleaved, load_line  # noqa: E402
from mock_devices import scenes, synth  # noqa: E402
from processing.correction.registry import correct_auto, correct_rpca_phase  # noqa: E402
from processing.geometry.height import phase_to_height  # noqa: E402
from processing.unwrap.fused_pass import fringe_pass  # noqa: E402
from rig.blas import rpca_blas  # noqa: E402
from rig.hardware.synthesis import simulate_scan  # noqa: E402

TWO_PI = 2.0 * np.pi
CASES = {
    "cap": ("sphere cap, f = (5, 8), 15 dB", (5, 8), 15.0),
    "isolated": ("isolated objects, f = (18, 25), 18 dB", (18, 25), 18.0),
}


def simulate(case: str, seed: int = 0):
    """Object and reference frames of one case on a 1024 x 768 rig (d0 = 1250 mm: no height pole)."""
    _, frequencies, snr_db = CASES[case]
    geometry = synth.RigGeometry(d0_mm=1250.0)
    appearance = synth.Appearance(snr_db=snr_db, bit_depth=8)
    patterns = synth.sinusoid_patterns(frequencies, STEPS)
    rows, cols, pixel = geometry.camera_height, geometry.camera_width, geometry.pixel_mm
    heights = scenes.sphere_cap(rows, cols, pixel) if case == "cap" else scenes.isolated_objects(rows, cols, pixel)
    scan = simulate_scan(heights, geometry=geometry, patterns=patterns, appearance=appearance, seed=seed)
    return geometry, frequencies, scan.object_map, scan.object_frames, scan.reference_frames


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


def run_case(case: str, runs: int) -> None:
    label, frequencies, _ = CASES[case]
    geometry, freqs, obj_map, obj, ref = simulate(case)
    reference_phase = fringe_pass(ref, GROUPS, freqs, "two-frequency").phase  # stored with the calibration
    scan = fringe_pass(obj, GROUPS, freqs, "two-frequency", keep_all=True)
    phase, wrapped, valid = scan.phase.astype(np.float64), scan.wrapped[-1].astype(np.float64), scan.valid
    evidence = {"frequency": freqs[1], "lower_wrapped": [(freqs[0], scan.wrapped[0])]}
    rows: dict[str, Callable[[], object]] = {
        "none path (fringe_pass + eq. 1.15)": lambda: fused_pipeline(
            obj, freqs, reference_phase, geometry, as_rig_runs_it=True
        ),
        "auto (correction only)": as_correction_stage(lambda: correct_auto(phase, wrapped, mask=valid, **evidence)),
        "rpca-phase (correction only)": as_correction_stage(lambda: correct_rpca_phase(phase, wrapped, mask=valid)),
        "none path + auto": lambda: auto_pipeline(obj, freqs, reference_phase, geometry),
    }
    times = interleaved(rows, runs)
    peer = [wall for wall, _ in times["none path (fringe_pass + eq. 1.15)"]]
    print(f"\n{label}, 1024 x 768, {runs} interleaved runs")
    print(f"{'row':38s} {'wall s: median (min - max)':>30s} {'CPU s':>8s} {'row / none: median (min - max)':>34s}")
    for name, samples in times.items():
        walls = [wall for wall, _ in samples]
        ratios = [wall / base for wall, base in zip(walls, peer, strict=True)]
        cpu = statistics.median(c for _, c in samples)
        spread = f"{statistics.median(ratios):8.1f} ({min(ratios):.1f} - {max(ratios):.1f})"
        print(f"{name:38s} {_stats(walls):>30s} {cpu:8.4f} {spread:>34s}")
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
