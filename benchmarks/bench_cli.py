"""Benchmark: the `rig` command line as a user runs it, start-up included: wall time, CPU and peak memory.

A simulated two-frequency six-step capture (sphere cap, 30 dB, 8-bit PNG frames, frequencies 15
and 16) and its reference-plane calibration are written to a temporary directory; one ``rig
process`` then fills the calibration's reference cache, as the first scan after a calibration
does. Rows, each a fresh ``python -m rig.cli`` process of this checkout, timed in interleaved runs:

- ``rig --help``;
- ``rig process CAPTURE --calibration CAL -o OUT --overwrite --correction none``;
- ``rig process CAPTURE --calibration CAL -o OUT --overwrite`` (the default correction, ``auto``);
- the peer, ``python -c "import numpy, cv2"``: the start-up floor of any Python tool built on
  them, measured in the same runs.

Children run with compiled modules cached (``PYTHONPYCACHEPREFIX`` in the temporary directory,
``PYTHONDONTWRITEBYTECODE`` dropped), as an installed copy runs.

Wall time, CPU time (user + system) and peak resident memory of each child come from
``/usr/bin/time`` (its wall clock has 10 ms resolution: the benchmark's own clock is used). Printed: median wall
time, its spread (min - max), median CPU, ``peer/this`` per run (median, min - max), median peak
memory; the CPU and load average around the runs.

    python benchmarks/bench_cli.py [--runs 7] [--size 1024x768] [--no-auto]

``--size 2048x1536`` gives the scaling row of the issue's table (the same patterns and field of
view, four times the pixels).
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.measure import cpu_description, interleaved, load_line, print_table  # noqa: E402

PEER = 'peer: python -c "import numpy, cv2"'


TIME = Path("/usr/bin/time")
# Compiled modules are cached as in any installed copy (outside the tree; the warm-up writes them),
# even where the environment sets PYTHONDONTWRITEBYTECODE: compiling every module on each start
# would cost more than processing the capture.
PYCACHE = str(Path(tempfile.gettempdir()) / "fpp-rig-bench-pycache")


def run_child(command: list[str]) -> tuple[float, float, int]:
    """(wall s, CPU s, peak RSS KiB) of one child process; raises if it fails.

    CPU and peak memory come from /usr/bin/time, a small process of its own (a child forked from
    this large benchmark process would count the parent's pages in its peak); the wall clock is
    this process's (/usr/bin/time's has 10 ms resolution). Without /usr/bin/time: CPU from the
    children's resource usage, peak memory 0 (unknown).
    """
    env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
    env.update(PYTHONPATH=str(ROOT), PYTHONPYCACHEPREFIX=PYCACHE)
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    with tempfile.NamedTemporaryFile("r", suffix=".time") as report:
        wrapped = [str(TIME), "-f", "%U %S %M", "-o", report.name, *command] if TIME.exists() else command
        start = time.perf_counter()
        child = subprocess.run(wrapped, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, check=False)
        wall = time.perf_counter() - start
        if child.returncode != 0:
            message = child.stderr.decode(errors="replace").strip()[-500:]
            raise RuntimeError(f"{' '.join(command)} failed ({child.returncode}): {message}")
        if TIME.exists():
            user, system, rss = report.read().split()[-3:]
            return wall, float(user) + float(system), int(rss)
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime), 0


def timed_row(command: list[str], peak_rss: list[int]) -> Callable[[], tuple[float, float]]:
    """A row for :func:`interleaved`: one run of ``command``, its (wall s, CPU s); its peak RSS goes to ``peak_rss``."""

    def once() -> tuple[float, float]:
        wall, cpu, rss = run_child(command)
        peak_rss.append(rss)
        return wall, cpu

    return once


def prepare(directory: Path, size: tuple[int, int]) -> tuple[Path, Path]:
    """A simulated capture and calibration of ``size`` (width, height) in ``directory``."""
    from mock_devices import scenes, synth
    from rig.hardware.synthesis import demo_geometry, simulate_scan, write_simulated_scan

    geometry = demo_geometry(*size)  # the same field of view at the requested size
    heights = scenes.sphere_cap(geometry.camera_height, geometry.camera_width, geometry.pixel_mm)
    scan = simulate_scan(
        heights,
        geometry=geometry,
        patterns=synth.sinusoid_patterns((15, 16), 6),
        appearance=synth.Appearance(ambient=0.05, snr_db=30.0, bit_depth=8),
        seed=0,
    )
    paths = write_simulated_scan(scan, directory / "scan")
    return paths.capture, paths.calibration


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7, help="interleaved runs per row (median reported; >= 3)")
    parser.add_argument("--size", default="1024x768", metavar="WxH", help="camera size (default 1024x768)")
    parser.add_argument("--no-auto", action="store_true", help="leave out the default-correction (auto) row")
    args = parser.parse_args(argv)
    if args.runs < 3:
        parser.error("--runs: expected at least 3")
    width, height = (int(v) for v in args.size.lower().split("x"))
    with tempfile.TemporaryDirectory(prefix="bench-cli-") as tmp:
        work = Path(tmp)
        print(f"simulating a {width}x{height} capture (2 frequencies x 6 steps) ...", file=sys.stderr)
        capture, calibration = prepare(work, (width, height))
        rig = [sys.executable, "-m", "rig.cli"]
        process = [
            *rig,
            "process",
            str(capture),
            "--calibration",
            str(calibration),
            "-o",
            str(work / "out"),
            "-q",
            "--overwrite",
        ]
        rows = {"rig --help": [*rig, "--help"], "rig process --correction none": [*process, "--correction", "none"]}
        if not args.no_auto:
            rows["rig process (default correction)"] = process
        rows[PEER] = [sys.executable, "-c", "import numpy, cv2"]
        for command in rows.values():  # warm-up: page cache, .pyc files, the calibration's reference cache
            run_child(command)
        load_before = os.getloadavg()
        print(f"timing {args.runs} interleaved runs of {len(rows)} rows ...", file=sys.stderr)
        memory: dict[str, list[int]] = {name: [] for name in rows}
        timed = {name: timed_row(command, memory[name]) for name, command in rows.items()}
        samples = interleaved(timed, args.runs, warm_up=False)  # warmed up above, before the load is read
        load_after = os.getloadavg()
    print(f"`rig` command line, {width}x{height} capture (2 frequencies x 6 steps, 8-bit PNG), fresh process per run")
    for line in cpu_description():
        print(line)
    print(load_line(load_before, load_after))
    notes = {name: f"peak RSS {statistics.median(values) / 1024:.0f} MiB" for name, values in memory.items()}
    print_table(samples, PEER, unit="s", scale=1.0, digits=3, extra=notes)
    print(f"runs: {args.runs} interleaved; CPU and peak RSS of each child from /usr/bin/time")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
