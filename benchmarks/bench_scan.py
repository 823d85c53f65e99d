"""Benchmark: a simulated 12-frame scan at 1024 x 768, end to end (render -> camera -> disk).

The built-in simulated rig (moderngl off-screen projector at 912 x 1140, simulated camera, fake
trigger box on a pty driven by the real serial driver) scans the default hemisphere with 1/8/64
fringes x 4 steps into a fresh capture directory, as ``rig scan`` does. Reported, medians over
``--runs`` scans:

- wall time of the scan (devices already open; capture committed and fsynced);
- device time: projector render + wait + read-back, and the simulated camera's exposure
  rendering (what real hardware would spend as projection and exposure);
- software overhead per frame = (wall - device time) / frames: the serial protocol, frame checks,
  queueing, the writer's non-overlapped tail and the atomic commit;
- the same with the frames written inline instead of on the writer thread (the peer).

    python benchmarks/bench_scan.py [--runs 5] [--trigger simulated-serial|software] [--size 1024x768]

Targets: overhead <= 10 ms per frame, whole scan <= 1.5 s.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.measure import cpu_description, load_line  # noqa: E402
from mock_devices.camera import SimulatedCamera  # noqa: E402
from rig.acquisition.loop import AcquisitionSettings, run_scan  # noqa: E402
from rig.config import CameraConfig, RigConfig, TriggerConfig  # noqa: E402
from rig.hardware.assembly import trigger_path  # noqa: E402
from rig.hardware.simulated import SimulatedRig  # noqa: E402
from rig.store.capture import read_capture  # noqa: E402


class CameraClock:
    """Accumulates the time the simulated camera spends rendering exposures (its 'device time')."""

    def __init__(self, camera: SimulatedCamera) -> None:
        self.seconds = 0.0
        render = camera._render

        def timed_render():
            started = time.perf_counter()
            try:
                return render()
            finally:
                self.seconds += time.perf_counter() - started

        camera._render = timed_render  # instance attribute: this benchmark's camera only


def one_scan(rig: SimulatedRig, config: RigConfig, out: Path, background: bool, clock: CameraClock) -> dict[str, float]:
    patterns = config.scan.patterns()
    settings = AcquisitionSettings(config.scan.show_timeout_s, config.scan.fetch_timeout_s, config.scan.retries)
    clock.seconds = 0.0
    started = time.perf_counter()
    result = run_scan(
        out,
        patterns,
        rig.projector,
        rig.camera,
        trigger_path(rig.camera, rig.trigger_box),
        settings,
        exposure_us=config.camera.exposure_us,
        background_writer=background,
    )
    wall = time.perf_counter() - started
    device = result.times.show_s + clock.seconds
    frames = len(patterns)
    return {
        "wall_s": wall,
        "device_s": device,
        "projector_s": result.times.show_s,
        "camera_s": clock.seconds,
        "overhead_ms_per_frame": 1e3 * (wall - device) / frames,
        "trigger_ms_per_frame": 1e3 * (result.times.trigger_s - clock.seconds) / frames,  # protocol, excl. exposure
        "fetch_ms_per_frame": 1e3 * result.times.fetch_s / frames,
        "store_ms_per_frame": 1e3 * result.times.store_s / frames,
        "writer_busy_s": result.writer_busy_s,
        "commit_s": result.times.finish_s,
        "frames": frames,
    }


def summarise(label: str, runs: list[dict[str, float]]) -> dict[str, float]:
    med = {key: statistics.median(run[key] for run in runs) for key in runs[0]}
    print(
        f"{label:<22} wall {med['wall_s']:.3f} s | device {med['device_s']:.3f} s "
        f"(projector {med['projector_s']:.3f}, camera {med['camera_s']:.3f}) | "
        f"overhead {med['overhead_ms_per_frame']:.1f} ms/frame | writer busy {med['writer_busy_s']:.3f} s, "
        f"commit tail {med['commit_s']:.3f} s\n"
        f"{'':<22} overhead per frame: trigger round trip {med['trigger_ms_per_frame']:.1f} ms, fetch "
        f"{med['fetch_ms_per_frame']:.2f} ms, hand-over to writer {med['store_ms_per_frame']:.2f} ms"
    )
    return med


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--trigger", default="simulated-serial", choices=("simulated-serial", "software"))
    parser.add_argument("--size", default="1024x768", help="camera WIDTHxHEIGHT")
    args = parser.parse_args()
    width, height = (int(v) for v in args.size.split("x"))
    config = dataclasses.replace(
        RigConfig(), camera=CameraConfig(width=width, height=height), trigger=TriggerConfig(backend=args.trigger)
    )
    load_before = os.getloadavg()
    work = Path(tempfile.mkdtemp(prefix="bench-scan-"))
    results: dict[str, list[dict[str, float]]] = {"writer thread": [], "inline writer (peer)": []}
    try:
        with SimulatedRig(config) as rig:
            clock = CameraClock(rig.camera)
            one_scan(rig, config, work / "warm-up", True, clock)
            for run in range(args.runs):
                for label, background in (("writer thread", True), ("inline writer (peer)", False)):
                    out = work / f"{run}-{background}"
                    results[label].append(one_scan(rig, config, out, background, clock))
                    shutil.rmtree(out)
            read_capture(work / "warm-up")  # the capture is complete and its checksums hold
        print(
            f"simulated scan: {len(config.scan.patterns())} frames, camera {width}x{height}, projector "
            f"{config.projector.width}x{config.projector.height}, trigger {args.trigger}, {args.runs} runs (medians)"
        )
        # Everything here is CPU time on this machine's cores: compare figures taken at a similar load.
        for line in cpu_description():
            print(line)
        print(load_line(load_before, os.getloadavg()))
        ours = summarise("writer thread", results["writer thread"])
        peer = summarise("inline writer (peer)", results["inline writer (peer)"])
        print(f"ratio wall inline / thread: {peer['wall_s'] / ours['wall_s']:.2f}")
        print(
            f"targets: overhead <= 10 ms/frame: {'met' if ours['overhead_ms_per_frame'] <= 10 else 'MISSED'}; "
            f"scan <= 1.5 s: {'met' if ours['wall_s'] <= 1.5 else 'MISSED'}"
        )
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
