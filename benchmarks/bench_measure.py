"""Benchmark: the measuring tools of the console (`rig.measure`) on a full-resolution result.

A 2048 x 1536 height map with points (a gauge block on a tilted plane, 5 % invalid pixels), each
tool over the whole map (a profile across it, a distance, a plane fit with the height-above-plane
map, a 64-bin histogram, region statistics), against a peer measured in the same runs: one
``np.nanmedian`` of the map (a single whole-map reduction). Prints the figures, the CPU and the load.

    python benchmarks/bench_measure.py [--runs 7] [--size 2048x1536]

Target: every tool well under the 1.5 s the console allows a result to appear in.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402
from rig import measure  # noqa: E402


def surface(width: int, height: int, seed: int = 1) -> measure.Surface:
    rng = np.random.default_rng(seed)
    rows, cols = np.mgrid[0:height, 0:width]
    x, y = (cols - width / 2) * 0.25, (rows - height / 2) * 0.25
    values = 0.02 * x - 0.01 * y + rng.normal(0.0, 0.05, (height, width))
    values[height // 3 : 2 * height // 3, width // 3 : 2 * width // 3] += 25.0
    values[rng.random((height, width)) < 0.05] = np.nan
    points = np.stack([x, y, values], axis=-1).astype(np.float32)
    return measure.Surface(values.astype(np.float32), "mm", points)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--size", default="2048x1536")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    s = surface(width, height)
    region = (10, 10, width - 10, height // 4)
    rows = {
        "peer: np.nanmedian(map)": lambda: np.nanmedian(s.values),
        "profile across the map": lambda: measure.line_profile(s, (0, height // 2), (width - 1, height // 2)),
        "distance": lambda: measure.point_distance(s, (10, 10), (width - 10, height - 10)),
        "plane fit (whole map)": lambda: measure.fit_plane(s),
        "plane fit + height above": lambda: measure.height_above_plane(s, measure.fit_plane(s, region)),
        "histogram (64 bins)": lambda: measure.histogram(s),
        "region statistics": lambda: measure.region_stats(s),
    }
    before = os.getloadavg()
    times = interleaved(rows, args.runs)
    after = os.getloadavg()
    print(f"measuring on a {width}x{height} height map with points, {args.runs} runs")
    print_table(times, "peer: np.nanmedian(map)")
    for line in cpu_description():
        print(line)
    print(load_line(before, after))


if __name__ == "__main__":
    main()
