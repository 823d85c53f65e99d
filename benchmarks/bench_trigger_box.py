"""Benchmark: host-side cost of one trigger through the serial stack.

The real ``SerialTriggerBox`` drives the ``FakeTriggerBox`` on a pseudo-terminal (so this measures
pyserial, the pty and the line protocol, not a USB CDC link or the firmware's pulse). Rows: median
round trip of ``FIRE`` (the per-pattern cost in a scan), of ``PING`` (the smallest exchange) and,
as the peer in the same run, a bare write/readline of the same bytes over the same pty with no
protocol (ids, checksums, retries) on top. Prints medians and the ratio to the peer.

    python benchmarks/bench_trigger_box.py [--runs 7] [--count 200]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import threading
import time
import tty
from pathlib import Path

import serial

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivers.trigger_box import SerialTriggerBox  # noqa: E402
from mock_devices.trigger_box import FakeTriggerBox  # noqa: E402


def time_calls(call, count: int) -> float:
    start = time.perf_counter()
    for _ in range(count):
        call()
    return (time.perf_counter() - start) / count


def bare_echo_round_trip(count: int) -> float:
    """write + readline of a FIRE-sized line over a pty whose peer echoes a reply-sized line."""
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def echo() -> None:
        while not stop.is_set():
            try:
                data = os.read(master, 64)
            except OSError:
                return
            if data:
                os.write(master, b"! PULSE 0*4E\n5 OK 0*01\n")

    thread = threading.Thread(target=echo, daemon=True)
    thread.start()
    port = serial.serial_for_url(os.ttyname(slave), baudrate=115200, timeout=1.0)

    def once() -> None:
        port.write(b"5 FIRE*0D\n")
        port.readline()
        port.readline()

    try:
        return time_calls(once, count)
    finally:
        stop.set()
        port.close()
        os.close(master)
        thread.join(timeout=1.0)
        os.close(slave)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=7)
    parser.add_argument("--count", type=int, default=200)
    args = parser.parse_args()

    fire, ping, bare = [], [], []
    for _ in range(args.runs):
        with FakeTriggerBox() as fake, SerialTriggerBox(fake.port) as box:
            box.arm(args.count)
            fire.append(time_calls(box.fire, args.count))
            ping.append(time_calls(box.ping, args.count))
        bare.append(bare_echo_round_trip(args.count))
    peer = statistics.median(bare)
    print(f"{'exchange':<28}{'median us':>12}{'x bare':>10}")
    for name, values in (
        ("FIRE (SerialTriggerBox)", fire),
        ("PING (SerialTriggerBox)", ping),
        ("bare pty write+readline", bare),
    ):
        median = statistics.median(values)
        print(f"{name:<28}{median * 1e6:>12.0f}{median / peer:>10.2f}")
    print(f"({args.runs} runs x {args.count} exchanges)", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
