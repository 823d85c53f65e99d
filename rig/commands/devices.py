"""`rig devices`: what is connected (cameras, serial ports, DLP projectors on USB) and the simulated rig.

The probes live in :mod:`rig.hardware.probes`; this command only prints them.
"""

from __future__ import annotations

import argparse

from rig.commands._common import add_command
from rig.hardware.probes import PROBES, format_probe, probe_opencv, simulated


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "devices",
        run,
        help="list connected cameras, serial ports, DLP projectors and the simulated rig",
        description="List what is connected: OpenCV and Basler cameras, serial ports (trigger box), "
        "TI DLP projectors on USB, whether off-screen rendering works, and the simulated devices. "
        "The first column is the backend name for the rig config file, the second the key that selects the device.",
    )
    parser.add_argument("--no-opencv", action="store_true", help="skip opening OpenCV cameras (slow on some systems)")


def run(args: argparse.Namespace) -> int:
    probes = [p for p in PROBES if not (args.no_opencv and p is probe_opencv)]
    for probe in probes:
        print(format_probe(probe()), flush=True)
    print(format_probe(simulated()))
    return 0
