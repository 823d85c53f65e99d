"""`rig scan`: project the pattern sequence, capture one frame per pattern, write a capture.

Without ``--config`` the built-in simulated rig scans its virtual scene. With ``--calibration CAL
--process`` the new capture is processed into a height map right away (like ``rig process``).
The config's ``[scan] pattern_set`` picks phase-shifting sinusoids (default) or the one-frame
speckle single shot (``"speckle"``), which ``rig process`` unwraps against the calibration's
reference capture of the same pattern.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from rig.errors import ConfigError
from rig.progress import Progress

log = logging.getLogger(__name__)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "scan",
        help="capture a fringe sequence with the rig (the simulated rig without --config)",
        description="Project each pattern, trigger the camera, fetch its frame and write a capture "
        "directory atomically (complete only if every pattern has its frame).",
    )
    parser.add_argument(
        "--config", type=Path, metavar="RIG.toml", help="rig config file (default: the built-in simulated rig)"
    )
    parser.add_argument(
        "-o", "--output", type=Path, metavar="CAPTURE", help="capture directory to create (default: capture-<UTC time>)"
    )
    parser.add_argument(
        "--scene",
        default="object",
        help="what is in front of the rig: 'object' (default), 'reference' (the flat reference plane) "
        "or another label such as 'plane-at-25mm'; the simulated rig shows that scene",
    )
    parser.add_argument("--calibration", type=Path, metavar="CAL", help="calibration directory, for --process")
    parser.add_argument("--process", action="store_true", help="process the capture into a height map after the scan")
    parser.add_argument(
        "--process-output", type=Path, metavar="OUT", help="where --process writes (default: CAPTURE-processed)"
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing capture directory")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.process and args.calibration is None:
        raise ConfigError("--process needs --calibration CAL (the calibration to turn phase into height)")
    if args.calibration is not None and not args.process:
        raise ConfigError("--calibration is used only with --process")
    from rig.config import load_config  # the pattern model (numpy): not for `rig --help`

    config = load_config(args.config)
    if args.process:  # a wrong calibration should stop us before the scan, not after it
        from calibration.store import read_calibration

        read_calibration(args.calibration)
    from rig.acquisition.scan import (  # pulls in the drivers: not for `rig --help`
        default_capture_path,
        scan,
    )

    output = args.output or default_capture_path()
    destination = args.process_output or output.with_name(output.name + "-processed")
    if args.process:  # both outputs must be writable before the scan starts
        from rig.pipeline.outputs import check_output_directory

        check_output_directory(destination)
    with Progress(f"scan {output}", total=len(config.scan.patterns())) as progress:
        result = scan(config, output, scene=args.scene, overwrite=args.overwrite, progress=progress)
    print(
        f"{result.path}: {len(result.frames)} frames in {result.wall_s:.2f} s"
        + (
            f" ({result.attempts - len(result.frames)} retried, {result.discarded} discarded)"
            if result.attempts > len(result.frames) or result.discarded
            else ""
        ),
        file=sys.stderr,
    )
    print(result.path)  # stdout: the capture directory, for scripts (the default name has the time in it)
    if args.process:
        from rig.commands.process import print_summary
        from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions
        from rig.pipeline.run import process_capture, total_steps

        with Progress(f"process {output}", total=total_steps(with_reference=True)) as progress:
            report = process_capture(
                output, args.calibration, destination, ProcessOptions(correction=DEFAULT_CORRECTION), progress=progress
            )
        print_summary(report, destination)
        print(destination)
    return 0
