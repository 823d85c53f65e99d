"""Benchmark: rendering a pattern at projector resolution, moderngl shader vs numpy.

Ours: ``GLProjector.show`` (fragment shader with the gamma LUT, into an 8-bit framebuffer, read
back as float32: what the simulated camera sees). Peer in the same run: ``processing.projection.patterns
.pattern_image`` followed by ``apply_gamma_lut`` (the numpy definition the shader is tested
against). Prints the median time per frame of each kind, the ratio and the largest difference.

    python benchmarks/bench_projector.py [--runs 15] [--width 912] [--height 1140]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.projector import apply_gamma_lut  # noqa: E402
from drivers.projector_gl import GLProjector  # noqa: E402
from processing.projection.patterns import pattern_image  # noqa: E402

PATTERNS = {
    "sinusoid": {"kind": "sinusoid", "axis": "x", "frequency": 64, "steps": 4, "step": 1},
    "gray": {"kind": "gray", "axis": "x", "bit": 5, "bits": 10},
    "speckle-sinusoid": {"kind": "speckle-sinusoid", "axis": "x", "frequency": 8, "steps": 3, "step": 0, "seed": 1},
}


def median_time(action, runs: int) -> float:
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=15)
    parser.add_argument("--width", type=int, default=912)
    parser.add_argument("--height", type=int, default=1140)
    args = parser.parse_args()
    size = (args.width, args.height)
    lut = (np.linspace(0.0, 1.0, 256) ** (1 / 2.2)).astype(np.float32)
    print(f"projector {size[0]}x{size[1]}, gamma LUT 256 entries, median of {args.runs} runs")
    with GLProjector(size) as projector:
        projector.set_gamma_lut(lut)
        for name, pattern in PATTERNS.items():
            projector.show(pattern)  # warm-up: shader compile, speckle texture upload
            numpy_frame = apply_gamma_lut(pattern_image(pattern, size), lut)
            gl_s = median_time(lambda pattern=pattern: (projector.show(pattern), projector.wait_shown()), args.runs)
            np_s = median_time(lambda pattern=pattern: apply_gamma_lut(pattern_image(pattern, size), lut), args.runs)
            diff = float(np.max(np.abs(projector.last_frame() - numpy_frame))) * 255
            print(
                f"{name:17s} moderngl {gl_s * 1e3:7.2f} ms   numpy {np_s * 1e3:7.2f} ms   "
                f"numpy/moderngl {np_s / gl_s:5.1f}x   max diff {diff:.2f}/255"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
