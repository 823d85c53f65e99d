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
from datetime import datetime, timezone
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.config import RigConfig, load_config
from rig.errors import CaptureError, ConfigError
from rig.progress import Progress

if TYPE_CHECKING:
    from rig.acquisition import ScanResult

log = logging.getLogger(__name__)


def default_capture_path(now: datetime | None = None) -> Path:
    """``capture-YYYYmmdd-HHMMSS`` in the current directory (UTC)."""
    now = now or datetime.now(timezone.utc)
    return Path(f"capture-{now.strftime('%Y%m%d-%H%M%S')}")


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "scan",
        help="capture a fringe sequence with the rig (the simulated rig without --config)",
        description="Project each pattern, trigger the camera, fetch its frame and write a capture "
        "directory atomically (complete only if every pattern has its frame).",
    )
    parser.add_argument("--config", type=Path, metavar="RIG.toml", help="rig config file (default: the built-in simulated rig)")
    parser.add_argument("-o", "--output", type=Path, metavar="CAPTURE", help="capture directory to create (default: capture-<UTC time>)")
    parser.add_argument(
        "--scene",
        default="object",
        help="what is in front of the rig: 'object' (default), 'reference' (the flat reference plane) "
        "or another label such as 'plane-at-25mm'; the simulated rig shows that scene",
    )
    parser.add_argument("--calibration", type=Path, metavar="CAL", help="calibration directory, for --process")
    parser.add_argument("--process", action="store_true", help="process the capture into a height map after the scan")
    parser.add_argument("--process-output", type=Path, metavar="OUT", help="where --process writes (default: CAPTURE-processed)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing capture directory")
    parser.set_defaults(func=run)


def scan(
    config: RigConfig,
    output: Path,
    scene: str = "object",
    overwrite: bool = False,
    show_progress: bool = True,
    patterns: Sequence[Mapping[str, Any]] | None = None,
    label: str = "scan",
) -> ScanResult:
    """Open the rig of ``config``, scan ``scene`` into ``output`` and close the rig.

    ``patterns``: the capture-format entries to project (default the config's ``[scan]`` set,
    :meth:`rig.config.ScanConfig.patterns`); ``label`` starts the progress line.
    """
    # imported here, not at module level: they pull in the drivers, which `rig --help` does not need
    from rig.acquisition import AcquisitionSettings, run_scan
    from rig.assembly import open_rig

    if output.exists() and not overwrite:  # fail before opening any device
        raise CaptureError(f"{output}: already exists; refusing to overwrite (choose another -o or pass --overwrite)")
    patterns = config.scan.patterns() if patterns is None else list(patterns)
    settings = AcquisitionSettings(
        show_timeout_s=config.scan.show_timeout_s,
        fetch_timeout_s=config.scan.fetch_timeout_s,
        retries=config.scan.retries,
    )
    log.info("scanning %d patterns into %s (%s)", len(patterns), output, settings)
    with open_rig(config, scene=scene) as devices, Progress(f"{label} {output}", total=len(patterns), quiet=not show_progress) as progress:
        extra = {"rig_config": str(config.source) if config.source else "built-in simulated rig"}
        if devices.simulation is not None:
            extra["simulation"] = devices.simulation.description()
        return run_scan(
            output,
            patterns,
            devices.projector,
            devices.camera,
            devices.trigger,
            settings,
            scene=scene,
            extra=extra,
            exposure_us=config.camera.exposure_us,
            gain=config.camera.gain,
            progress=progress,
            overwrite=overwrite,
        )


def run(args: argparse.Namespace) -> int:
    if args.process and args.calibration is None:
        raise ConfigError("--process needs --calibration CAL (the calibration to turn phase into height)")
    if args.calibration is not None and not args.process:
        raise ConfigError("--calibration is used only with --process")
    config = load_config(args.config)
    if args.process:  # a wrong calibration should stop us before the scan, not after it
        from calibration.store import read_calibration

        read_calibration(args.calibration)
    output = args.output or default_capture_path()
    result = scan(config, output, scene=args.scene, overwrite=args.overwrite)
    print(
        f"{result.path}: {len(result.frames)} frames in {result.wall_s:.2f} s"
        + (f" ({result.attempts - len(result.frames)} retried, {result.discarded} discarded)" if result.attempts > len(result.frames) or result.discarded else ""),
        file=sys.stderr,
    )
    print(result.path)  # stdout: the capture directory, for scripts (the default name has the time in it)
    if args.process:
        from rig.pipeline import DEFAULT_CORRECTION, ProcessOptions, process_capture, total_steps

        destination = args.process_output or output.with_name(output.name + "-processed")
        with Progress(f"process {output}", total=total_steps(with_reference=True)) as progress:
            process_capture(output, args.calibration, destination, ProcessOptions(correction=DEFAULT_CORRECTION), progress=progress)
        print(destination)
    return 0
