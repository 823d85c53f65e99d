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
from typing import TYPE_CHECKING

from rig.errors import ConfigError
from rig.progress import Progress

if TYPE_CHECKING:
    from rig.acquisition.loop import ScanResult

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
    parser.add_argument(
        "--exposures",
        metavar="US,US,...",
        help="capture each exposure's full sequence in turn, e.g. 2000,8000,32000 (microseconds); "
        "default [scan] exposures_us, else the camera's one exposure",
    )
    parser.add_argument(
        "--hdr",
        choices=("auto",),
        help="auto: a quick pre-capture chooses the fewest exposures (at most 3) that bring 98 %% of the lit "
        "object into the usable range, and says why",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing capture directory")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    if args.process and args.calibration is None:
        raise ConfigError("--process needs --calibration CAL (the calibration to turn phase into height)")
    if args.calibration is not None and not args.process:
        raise ConfigError("--calibration is used only with --process")
    from rig import api  # the pattern model, drivers and pipeline: not for `rig --help`
    from rig.acquisition.scan import default_capture_path
    from rig.store.results import default_output

    exposures = _exposures(args)
    config = api.load_config(args.config)
    output = args.output or default_capture_path()
    frames = len(config.scan.patterns())
    if not args.process:
        with Progress(f"scan {output}", total=frames) as progress:
            result = api.scan(
                output, config, scene=args.scene, overwrite=args.overwrite, progress=progress, exposures=exposures
            )
        _print_scan(result)
        return 0
    from rig.commands.process import print_summary

    destination = args.process_output or default_output(output)
    with Progress(f"scan and process {output}", total=frames + api.process_steps(with_reference=True)) as progress:
        result, report = api.scan_then_process(
            output,
            args.calibration,
            destination,
            config,
            scene=args.scene,
            overwrite=args.overwrite,
            scan_progress=progress,
            process_progress=progress,
            exposures=exposures,
        )
    _print_scan(result)
    print_summary(report, destination)
    print(destination)
    return 0


def _exposures(args: argparse.Namespace) -> tuple[float, ...] | str | None:
    """``--exposures`` parsed (one clear line if it is not a list of times), or ``"auto"`` for ``--hdr auto``."""
    from rig.config import parse_exposures

    if args.hdr and args.exposures:
        raise ConfigError("--hdr auto and --exposures: expected one of them (the assistant chooses the exposures)")
    if args.hdr:
        return "auto"
    return None if args.exposures is None else parse_exposures(args.exposures)


def _print_scan(result: ScanResult) -> None:
    """The scan's line on stderr and its capture directory on stdout (for scripts: the default name has the time)."""
    if result.exposure_plan is not None:
        for line in result.exposure_plan.lines():
            print(f"exposure assistant: {line}", file=sys.stderr)
    retried = result.attempts - len(result.frames)
    print(
        f"{result.path}: {len(result.frames)} frames in {result.wall_s:.2f} s"
        + (f" ({retried} retried, {result.discarded} discarded)" if retried or result.discarded else ""),
        file=sys.stderr,
    )
    print(result.path)
