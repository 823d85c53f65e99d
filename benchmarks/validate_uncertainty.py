"""Predicted height sigma against the observed error on the simulated rig, per SNR.

For each SNR, a seeded hemisphere scan (6-step sinusoids at 1, 8, 64 periods, 320 x 240) is
processed with its calibration; the observed error is the RMS of (height - truth) / predicted sigma
over the valid lit pixels, which is 1 when the prediction is right. Usage::

    python benchmarks/validate_uncertainty.py [--seed 11] [--correction auto] [--snr 10 20 30 40]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np

from mock_devices import synth
from rig.hardware.synthesis import demo_appearance, demo_geometry, simulate_scan, write_simulated_scan
from rig.pipeline.plan import ProcessOptions
from rig.pipeline.run import process


def error_ratio(
    snr_db: float, seed: int, correction: str = "auto", steps: int = 6, size: tuple[int, int] = (320, 240)
) -> dict[str, float]:
    """RMS of the normalised error, and the median predicted and observed sigma (mm), at one SNR."""
    scan = simulate_scan(
        "hemisphere",
        geometry=demo_geometry(*size),
        patterns=synth.sinusoid_patterns((1, 8, 64), steps),
        appearance=demo_appearance(snr_db),
        seed=seed,
    )
    with tempfile.TemporaryDirectory() as tmp:
        paths = write_simulated_scan(scan, Path(tmp) / "scan")
        result = process(paths.capture, paths.calibration, ProcessOptions(correction=correction))
    assert result.height is not None and result.uncertainty is not None
    keep = result.mask & scan.lit & np.isfinite(result.uncertainty)
    error = result.height[keep] - scan.height_mm[keep]
    sigma = result.uncertainty[keep].astype(np.float64)
    inliers = np.abs(error) < 6 * sigma  # unwrapping slips are not noise: counted apart
    return {
        "ratio": float(np.sqrt(np.mean((error[inliers] / sigma[inliers]) ** 2))),
        "predicted_mm": float(np.median(sigma)),
        "observed_rms_mm": float(np.sqrt(np.mean(error[inliers] ** 2))),
        "outliers": float(1.0 - inliers.mean()),
        "gain": float(result.object.info.get("correction_noise_gain", 1.0)),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--correction", default="auto", help="the phase correction (default auto, as rig process)")
    parser.add_argument("--snr", type=float, nargs="+", default=[10.0, 20.0, 30.0, 40.0])
    args = parser.parse_args()
    print("snr_db  observed/predicted  predicted_median_mm  observed_rms_mm  outliers  correction_gain")
    for snr in args.snr:
        r = error_ratio(snr, args.seed, args.correction)
        print(
            f"{snr:6.1f}  {r['ratio']:18.3f}  {r['predicted_mm']:19.4f}  {r['observed_rms_mm']:15.4f}  {r['outliers']:8.4f}  {r['gain']:.3f}"
        )


if __name__ == "__main__":
    main()
