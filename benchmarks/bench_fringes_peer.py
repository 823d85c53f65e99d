"""Benchmark against the ``fringes`` package: phase error and speed on the same 12 frames.

The frames: the thesis' sphere cap on the default 1024 x 768 simulated rig, two frequencies
(15, 16) x 6 steps, 8 bit, seeded noise (``benchmarks/bench_pipeline.py``'s scene). Both decode
the same uint8 stack:

- ours: :func:`rig.pipeline.run.process` given the frames in memory (``frames=``) with the
  simulated calibration, ``--correction none``: the fused pass (phase shifting, modulation mask,
  Ding's two-frequency unwrapping and the noise-weighted fusion of both frequencies), the height,
  the validity and the uncertainty map; the same with the highest frequency alone and the former
  modulation-ratio rule (``--param frequency_fusion=false --min-modulation 0.2``: what the fusion
  and the noise rule cost); and the fused kernel alone
  (:func:`processing.unwrap.fused_pass.fringe_pass` with ``fuse_noise``, on the pipeline's threads);
- the peer: ``fringes.Fringes.decode`` (its numba decoder, all threads) set to the frames'
  convention (one axis, ``v = (15, 16)``, ``N = 6``, ``p0 = 0``, ``reverse``: the frames shift by
  +2 pi n / N), in its ``precise`` and ``fast`` modes. Its coordinate ``x`` is turned back into
  the absolute phase 2 pi v x / L.

Phase error: RMS and median |error| of the absolute phase at the highest frequency against the
simulated truth, over the lit pixels both decode, per seed. Speed: interleaved runs (run i times
every row once), median and spread, CPU time, and ``peer/this`` per run against the peer's
``precise`` decode. Each timed call starts 50 ms after the previous one ended: numba's OpenMP
threads (GNU libgomp) keep both cores busy spin-waiting for 3-5 ms after each of the peer's
decodes, which the row timed next would otherwise pay for (measured: 4 ms of CPU in the 2 ms
after a decode, none after 5 ms; ``OMP_WAIT_POLICY=passive`` removes it). The peer needs
``fringes`` (``pip install fringes``: it pulls OpenCV with GUI libraries, so a separate
environment, with this repository on the path); without it the peer rows are skipped and said so.

    python benchmarks/bench_fringes_peer.py [--runs 7] [--seeds 0 1 2] [--snr-db 30]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.bench_pipeline import GROUPS, STEPS, pipeline_pass, simulate  # noqa: E402
from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from mock_devices import synth  # noqa: E402
from processing.geometry.uncertainty import noise_sigma  # noqa: E402
from processing.unwrap.fused_pass import fringe_pass  # noqa: E402
from rig.hardware.synthesis import write_simulated_scan  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402

FREQUENCIES = (15, 16)
PEER = "fringes decode (precise)"
SETTLE_S = 0.05  # pause before each timed call: the peer's OpenMP threads stop spinning (docstring)


def peer_decoder(mode: str) -> Any | None:
    """A ``fringes.Fringes`` set to the frames' layout and phase convention, or None without the package."""
    try:
        import fringes
    except ImportError:
        return None
    decoder = fringes.Fringes()
    decoder.X, decoder.Y = 1024, 768
    decoder.D, decoder.axes = 1, 0
    decoder.K, decoder.N, decoder.v = len(FREQUENCIES), STEPS, list(FREQUENCIES)
    decoder.p0, decoder.reverse, decoder.mode = 0.0, True, mode
    return decoder


def peer_phase(decoder: Any, frames: np.ndarray) -> np.ndarray:
    """The peer's absolute phase at the highest frequency: 2 pi v x / L of its decoded coordinate."""
    decoded = decoder.decode(frames[..., None])
    coordinate = np.asarray(decoded.x, dtype=np.float64).reshape(frames.shape[1:])
    return 2.0 * np.pi * FREQUENCIES[-1] * coordinate / float(decoder.L[0])


def errors(phase: np.ndarray, truth: np.ndarray, keep: np.ndarray) -> tuple[float, float]:
    """RMS and median |error| of ``phase`` against ``truth`` over ``keep``."""
    error = phase[keep].astype(np.float64) - truth[keep]
    return float(np.sqrt(np.mean(error**2))), float(np.median(np.abs(error)))


def accuracy(seeds: list[int], snr_db: float, decoders: dict[str, Any]) -> list[str]:
    """One line per seed and decoder: phase RMS and median |error| against the truth."""
    lines = []
    for seed in seeds:
        scan = simulate(FREQUENCIES, snr_db, seed=seed)
        frames = scan.object_frames
        truth = synth.true_absolute_phase(scan.object_map, scan.geometry, FREQUENCIES[-1])
        sigma_i = noise_sigma(frames, GROUPS)
        phases = {
            "ours, fused frequencies": fringe_pass(frames, GROUPS, FREQUENCIES, "two-frequency", fuse_noise=sigma_i),
            "ours, highest frequency alone": fringe_pass(frames, GROUPS, FREQUENCIES, "two-frequency"),
        }
        maps = {name: np.where(scan_.valid, scan_.phase, np.nan) for name, scan_ in phases.items()}
        maps.update({name: peer_phase(decoder, frames) for name, decoder in decoders.items()})
        keep = scan.object_map.lit & np.logical_and.reduce([np.isfinite(m) for m in maps.values()])
        reference = errors(maps[PEER], truth, keep)[0] if PEER in maps else None
        for name, phase in maps.items():
            rms, median = errors(phase, truth, keep)
            versus = "" if reference is None else f", {rms / reference:.7f}x the peer's RMS"
            lines.append(f"seed {seed}: {name:<32} RMS {rms:.5f} rad, median |error| {median:.5f} rad{versus}")
    return lines


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="interleaved timed runs (median reported; >= 5)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2], help="simulations for the phase error")
    parser.add_argument("--snr-db", type=float, default=30.0)
    args = parser.parse_args(argv)
    if args.runs < 5:
        parser.error("--runs: expected at least 5")
    decoders = {name: peer_decoder(mode) for name, mode in ((PEER, "precise"), ("fringes decode (fast)", "fast"))}
    available = {name: d for name, d in decoders.items() if d is not None}
    if not available:
        print("fringes: not importable (pip install fringes in a separate environment); peer rows skipped")
    print(f"phase error against the truth, {FREQUENCIES} x {STEPS} steps, {args.snr_db} dB, 1024x768, 8 bit:")
    for line in accuracy(args.seeds, args.snr_db, available):
        print(line)

    scan = simulate(FREQUENCIES, args.snr_db, seed=args.seeds[0])
    frames = scan.object_frames
    workdir = tempfile.TemporaryDirectory(prefix="bench-fringes-")
    paths = write_simulated_scan(scan, Path(workdir.name) / "scan")
    options = ProcessOptions(correction="none")

    former = ProcessOptions(correction="none", min_modulation_ratio=0.2, params={"frequency_fusion": False})

    def pipeline() -> None:
        result = process(paths.capture, paths.calibration, options, frames=frames)
        assert result.uncertainty is not None and "frequency_fusion" in result.object.info

    def highest_alone() -> None:
        process(paths.capture, paths.calibration, former, frames=frames)

    sigma_i = noise_sigma(frames, GROUPS)
    rows: dict[str, Callable[[], object]] = {
        "rig pipeline in memory (fusion, validity, uncertainty, height)": pipeline,
        "rig pipeline, highest frequency alone, ratio rule": highest_alone,
        "fused kernel with fusion (fringe_pass)": lambda: pipeline_pass(frames, FREQUENCIES, fuse_noise=sigma_i),
    }
    rows.update({name: (lambda d=d: peer_phase(d, frames)) for name, d in available.items()})
    load_before = os.getloadavg()
    print(f"timing {args.runs} interleaved runs of {len(rows)} rows ...", file=sys.stderr)
    times = interleaved(rows, args.runs, settle=SETTLE_S)
    load_after = os.getloadavg()
    print("12 uint8 frames 1024x768 (2 frequencies x 6 steps), in memory, single process")
    for line in cpu_description():
        print(line)
    print(load_line(load_before, load_after))
    if PEER in times:
        print_table(times, PEER)
    else:
        for name, samples in times.items():
            walls = [t[0] * 1e3 for t in samples]
            print(f"{name}: median {statistics.median(walls):.1f} ms ({min(walls):.1f}-{max(walls):.1f})")
    workdir.cleanup()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
