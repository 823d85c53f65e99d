"""Benchmark: the whole simulated VDI/VDE 2634-2 verification (`rig verify` on the built-in rig).

Times the verification service over the guideline's 23 positions (10 sphere, 7 ball bar, 6 plane:
scan, process, fit, report) on the default simulated rig (1024 x 768 camera, 1/8/64 fringes x 4
steps), against a peer measured in the same runs: the calibration session of `rig calibrate`
(reference plane, four planes, board views). Prints the figures, the CPU and the load.

    python benchmarks/bench_verify.py [--runs 1]

Target: the verification within 5 minutes on two cores.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from rig.calibrate.session import CalibrationPlan, calibrate  # noqa: E402
from rig.config import RigConfig  # noqa: E402
from rig.verify.artefacts import Artefacts  # noqa: E402
from rig.verify.plan import VerificationPlan
from rig.verify.session import verify  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=1)
    args = parser.parse_args()
    config = RigConfig()
    root = Path(tempfile.mkdtemp(prefix="bench-verify-"))
    try:
        calibrate(config, CalibrationPlan(), root / "cal")  # the calibration every verification run checks
        counter = iter(range(10**6))
        outcome: dict[str, str] = {}

        def verification() -> None:
            result = verify(config, VerificationPlan(), Artefacts(), root / "cal", root / f"ver-{next(counter)}")
            outcome["verify (23 positions)"] = result.report["summary"]

        def calibration() -> None:
            calibrate(config, CalibrationPlan(), root / f"cal-{next(counter)}")

        before = os.getloadavg()
        times = interleaved({"verify (23 positions)": verification, "calibrate (peer)": calibration}, args.runs, False)
        after = os.getloadavg()
        print(*cpu_description(), sep="\n")
        print(load_line(before, after))
        print_table(times, peer="calibrate (peer)", unit="s", scale=1.0, digits=1, extra=outcome)
    finally:
        shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
