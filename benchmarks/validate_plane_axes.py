"""The reference-plane model's default axis against the other, and both: height error on a tilted-baseline rig.

The simulated reference-plane rig with its baseline turned ``--angle`` degrees from x towards y
(80 by default: mostly vertical, so the row fringes see d0 sin 80 and the column fringes d0 cos
80 of it), a hemisphere under four-step fringes at (1, 8, 64) across the 912 projector columns and
(1, 10, 80) across the 1140 rows (14.25 projector pixels per period on either), 35 dB, and the
rig's exact calibration fitted on both axes. Processed with ``--correction none`` by default (the
axis with the larger sensitivity 2 pi f0 |d0| / l0), along x, along y and both; height RMS error
over the lit pixels per seed, with the ratios x / y (tan(angle) expected) and both / y.

    PYTHONPATH=. python benchmarks/validate_plane_axes.py [--seeds 21 22 23 24 25] [--angle 80]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from rig.hardware.synthesis import demo_geometry, simulate_scan, sinusoid_patterns, write_simulated_scan  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402
from rig.pipeline.run import process  # noqa: E402

PATTERNS = sinusoid_patterns((1, 8, 64), 4, "x") + sinusoid_patterns((1, 10, 80), 4, "y")


def run_seed(seed: int, angle: float, root: Path) -> dict[str, float | str]:
    """Height RMS of the default, x, y and both for one seeded scan, and the axis the default took."""
    geometry = replace(demo_geometry(160, 120), baseline_angle_deg=angle)
    scan = simulate_scan("hemisphere", geometry=geometry, patterns=PATTERNS, seed=seed)
    scan.calibrated_axes = ("x", "y")
    paths = write_simulated_scan(scan, root / f"scan-{seed}")
    out: dict[str, float | str] = {}
    for axis in (None, "x", "y", "both"):
        result = process(paths.capture, paths.calibration, ProcessOptions(correction="none", axis=axis))
        error = np.where(result.mask & scan.lit, result.height - scan.height_mm, np.nan)
        out[axis or "default"] = float(np.sqrt(np.nanmean(error**2)))
        if axis is None:
            out["chosen"] = result.object.info["axis_choice"]["axis"]
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[21, 22, 23, 24, 25])
    parser.add_argument("--angle", type=float, default=80.0, help="baseline angle from x towards y (degrees)")
    args = parser.parse_args()
    print(f"baseline {args.angle:g} deg; tan = {np.tan(np.deg2rad(args.angle)):.3f}")
    print("seed  chosen  default_mm  x_mm    y_mm    both_mm  x/y    both/y")
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            r = run_seed(seed, args.angle, Path(tmp))
            x, y, both = float(r["x"]), float(r["y"]), float(r["both"])
            print(
                f"{seed:<5} {r['chosen']:<7} {float(r['default']):<11.4f} {x:<7.4f} {y:<7.4f} {both:<8.4f} "
                f"{x / y:<6.2f} {both / y:.3f}"
            )


if __name__ == "__main__":
    main()
