"""Benchmark: decoding a Gray code and unwrapping two fringe sets with it, kamino410's layout at its size.

1936 x 1216 uint8 frames of a 1920 x 1080 display seen through a smooth warp: 5 Gray planes of
100-px cells and their inverses, wrapped phases of the 100-px and 200/3-px fringes (19.2 and 28.8
fringes). Rows, timed in the same interleaved runs:

- ``decode_stripes``: :func:`processing.unwrap.temporal.decode_stripes`, plane against inverse, one
  plane at a time into the stripe map;
- ``unwrap_coded``: :func:`processing.unwrap.temporal.unwrap_coded` of both sets (the code resolves
  their 200-px beat, both follow hierarchically);
- ``border_side``: :func:`processing.unwrap.temporal.border_side`, which side of a cell border each
  pixel is on by its bits (what a plain code of one cell per period adds);
- the peer, ``stacked decode``: the same decoding by whole-stack numpy operations (bits of all
  planes, cumulative XOR, a weighted sum in int64), how decode_gray worked before.

    python benchmarks/bench_codes.py [--runs 9]
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from processing.projection.patterns import Gray, gray_intensity  # noqa: E402
from processing.unwrap import temporal  # noqa: E402

CAMERA = (1216, 1936)
DISPLAY_WIDTH = 1920.0
CELL_PX, BITS = 100.0, 5
FREQUENCIES = (19.2, 28.8)


def _scene(seed: int = 0) -> tuple[np.ndarray, np.ndarray, list[np.ndarray], np.ndarray]:
    """Planes, inverse planes (uint8), wrapped phases and the true display column of every camera pixel."""
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0 : CAMERA[0], 0 : CAMERA[1]].astype(np.float64)
    u = cols * DISPLAY_WIDTH / CAMERA[1] + 12.0 * np.sin(rows / 90.0)  # a smooth warp
    u = np.clip(u, 0.0, DISPLAY_WIDTH - 1e-6)
    albedo = 0.3 + 0.7 * rng.random(CAMERA) ** 0.2

    def capture(level: np.ndarray) -> np.ndarray:
        return np.clip(10 + 200 * albedo * level + rng.normal(0, 2, CAMERA), 0, 255).astype(np.uint8)

    planes = [Gray(bit=b, bits=BITS, period_px=CELL_PX) for b in range(BITS)]
    normal = np.stack([capture(gray_intensity(p, u, DISPLAY_WIDTH)) for p in planes])
    inverse = np.stack([capture(1.0 - gray_intensity(p, u, DISPLAY_WIDTH)) for p in planes])
    phis = [np.angle(np.exp(2j * np.pi * f * u / DISPLAY_WIDTH) + rng.normal(0, 0.02, CAMERA)) for f in FREQUENCIES]
    return normal, inverse, phis, u


def _stacked_decode(planes: np.ndarray, inverse: np.ndarray) -> np.ndarray:
    words = np.bitwise_xor.accumulate((planes > inverse).astype(np.uint8), axis=0)
    weights = 1 << np.arange(planes.shape[0] - 1, -1, -1, dtype=np.int64)
    return np.tensordot(weights, words.astype(np.int64), axes=(0, 0))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=9)
    args = parser.parse_args()
    normal, inverse, phis, u = _scene()
    stripes = temporal.decode_stripes(normal, inverse)
    before = os.getloadavg()
    times = interleaved(
        {
            "decode_stripes": lambda: temporal.decode_stripes(normal, inverse),
            "unwrap_coded": lambda: temporal.unwrap_coded(phis, FREQUENCIES, stripes, CELL_PX / DISPLAY_WIDTH),
            "border_side": lambda: temporal.border_side(normal, stripes, inverse),
            "stacked decode (peer)": lambda: _stacked_decode(normal, inverse),
        },
        args.runs,
    )
    after = os.getloadavg()
    for line in cpu_description():
        print(line)
    print(load_line(before, after))
    print(f"{CAMERA[1]}x{CAMERA[0]} camera, {BITS} Gray planes + inverses, frequencies {FREQUENCIES}, {args.runs} runs")
    print_table(times, "stacked decode (peer)")
    result = temporal.unwrap_coded(phis, FREQUENCIES, stripes, CELL_PX / DISPLAY_WIDTH)
    error = np.abs(result.phase - 2 * np.pi * FREQUENCIES[-1] * u / DISPLAY_WIDTH)
    same = np.array_equal(stripes, _stacked_decode(normal, inverse))
    print(f"check: decodes identical {same}; orders right on {np.mean(error < np.pi):.4%} of the pixels")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
