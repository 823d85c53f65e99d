"""Benchmark: the console's live view frame rate and its scan-to-result time on the simulated rig.

- live view: frames per second the console session publishes (software trigger, figures,
  modulation map under a fringe, JPEG) with one page watching, at ``--live-size``;
- scan to result: seconds from the scan's last stored frame to the result being published to
  the page (capture committed, processed without fringe-order correction, map ready), at
  ``--scan-size``, beside the peer: :func:`rig.api.process` of the same capture from disk with the
  same options, timed in the same run (``console / peer``: the console's overhead).

The browser adds drawing (image, 3-D surface) on top; the console's browser tests print that.
Each figure: median and min - max over ``--runs`` runs; the header gives CPU model and load average.

    python benchmarks/bench_console.py [--runs 5] [--live-size 640x480] [--scan-size 1024x768]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, load_line  # noqa: E402
from rig import api  # noqa: E402
from rig.config import parse_config  # noqa: E402
from rig.console.datadir import DataDir  # noqa: E402
from rig.console.devices import ProjectorSetting  # noqa: E402
from rig.console.session import ConsoleSession  # noqa: E402
from rig.pipeline.plan import ProcessOptions  # noqa: E402


def size(text: str) -> tuple[int, int]:
    w, h = text.lower().split("x")
    return int(w), int(h)


class Recorder:
    """Collects what the session publishes."""

    def __init__(self) -> None:
        self.frames: list[float] = []
        self.results: list[dict[str, Any]] = []
        self.event = threading.Condition()

    def __call__(self, message: dict[str, Any], image: bytes | None) -> None:
        with self.event:
            if message["type"] == "frame":
                self.frames.append(time.monotonic())
            elif message["type"] == "result":
                self.results.append(message)
            self.event.notify_all()


def calibrate(session: ConsoleSession, config: Any) -> None:
    """The simulated rig's exact geometry as calibration "cal", with a reference scan."""
    from calibration.store import write_calibration
    from rig.acquisition.scan import scan
    from rig.hardware.simulated import geometry_from_config
    from rig.hardware.synthesis import exact_calibration

    cal = session.data.root / "calibrations" / "cal"
    scan(config, cal / "reference", scene="reference")
    write_calibration(cal, exact_calibration(geometry_from_config(config)))
    session.set_calibration("cal")


def live_fps(width: int, height: int, seconds: float) -> float:
    config = parse_config({"camera": {"size": [width, height]}})
    recorder = Recorder()
    with tempfile.TemporaryDirectory() as tmp:
        session = ConsoleSession(config, DataDir(tmp), recorder, live_fps=1000.0)
        session.start()
        try:
            session.set_projector(ProjectorSetting("fringe", 16.0))
            session.watch(1)
            time.sleep(1.0)  # warm up
            start, count0 = time.monotonic(), len(recorder.frames)
            time.sleep(seconds)
            fps = (len(recorder.frames) - count0) / (time.monotonic() - start)
            session.watch(-1)
        finally:
            session.close()
    return fps


def scan_to_result(width: int, height: int, runs: int) -> tuple[list[float], list[float]]:
    config = parse_config({"camera": {"size": [width, height]}})
    recorder = Recorder()
    console_s, peer_s = [], []
    with tempfile.TemporaryDirectory() as tmp:
        session = ConsoleSession(config, DataDir(tmp), recorder)
        session.start()
        try:
            calibrate(session, config)
            for run in range(runs):
                job = session.scan(name=f"run-{run}", options=ProcessOptions(correction="none"))
                with recorder.event:
                    recorder.event.wait_for(
                        lambda job=job: any(r["job"] == job.id for r in recorder.results), timeout=120
                    )
                result = next(r for r in recorder.results if r["job"] == job.id)
                console_s.append(float(result["since_last_frame_s"]))
                while job.state == "running":
                    time.sleep(0.05)
                capture = session.data.path("captures", job.name)
                started = time.perf_counter()
                api.process(capture, session.data.path("calibrations", "cal"), ProcessOptions(correction="none"))
                peer_s.append(time.perf_counter() - started)
        finally:
            session.close()
    return console_s, peer_s


def spread(values: list[float]) -> str:
    return f"{statistics.median(values):.3f} s ({min(values):.3f} - {max(values):.3f})"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--live-size", type=size, default=(640, 480))
    parser.add_argument("--scan-size", type=size, default=(1024, 768))
    parser.add_argument("--live-seconds", type=float, default=5.0)
    args = parser.parse_args()
    for line in cpu_description():
        print(line)
    load_before = os.getloadavg()
    fps = live_fps(*args.live_size, args.live_seconds)
    print(
        f"live view {args.live_size[0]}x{args.live_size[1]}, fringe shown (modulation map computed): {fps:.1f} fps "
        f"(uncapped; the console caps it at 20)"
    )
    console_s, peer_s = scan_to_result(*args.scan_size, args.runs)
    ratios = [c / p for c, p in zip(console_s, peer_s)]
    print(f"scan to result published, {args.scan_size[0]}x{args.scan_size[1]}, correction none, {args.runs} runs:")
    print(f"  console (last frame -> result): {spread(console_s)}")
    print(f"  peer rig.api.process from disk: {spread(peer_s)}")
    print(f"  console / peer: {statistics.median(ratios):.2f} ({min(ratios):.2f} - {max(ratios):.2f})")
    print(load_line(load_before, os.getloadavg()))


if __name__ == "__main__":
    main()
