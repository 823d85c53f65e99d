"""`rig process CAPTURE --calibration CAL -o OUT`: phase, height map, point cloud, report, preview."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from rig.commands._common import (
    LazyChoices,
    LazyHelp,
    add_capture_argument,
    add_command,
    add_report_options,
    print_json,
)
from rig.errors import ConfigError
from rig.pipeline.plan import ProcessOptions
from rig.progress import Progress

# The pipeline (numpy, OpenCV) is imported when a command runs, not to build the parser: `rig --help`
# and commands that do not process stay quick. Choices and help naming its registries load lazily.


def _unwrap_methods() -> list[str]:
    from rig.pipeline.unwrapping import UNWRAP_METHODS

    return list(UNWRAP_METHODS)


def _unwrap_help() -> str:
    from rig.pipeline.unwrapping import help_text

    return f"phase unwrapping method (default auto); {help_text()}"


def _denoisers() -> list[str]:
    from rig.pipeline.stages import DENOISERS

    return list(DENOISERS)


def _corrections() -> list[str]:
    from rig.pipeline.corrections import REGISTRY

    return list(REGISTRY)


def _correction_help() -> str:
    from rig.pipeline.corrections import help_text

    return f"phase / fringe-order correction (default {ProcessOptions().correction}); {help_text()}"


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "process",
        run,
        help="turn a capture into absolute phase, a height map and a point cloud",
        description="Process a capture (and the reference-plane capture of its calibration) into "
        "height.npy, phase.npy, mask.npy, points.ply, report.json and preview.png (--format adds meshes "
        "and E57). Without --calibration only the phase is computed (phase.npy, wrapped.npy, mask.npy, "
        "a phase preview).",
    )
    add_capture_argument(parser)
    parser.add_argument("--calibration", type=Path, metavar="CAL", help="calibration directory (calibration.json)")
    parser.add_argument(
        "-o", "--output", type=Path, metavar="OUT", help="output directory (default: CAPTURE-processed)"
    )
    parser.add_argument(
        "--overwrite", action="store_true", help="replace an existing output directory (an earlier result only)"
    )
    add_processing_options(parser)
    add_format_option(parser)
    parser.add_argument("--salvage", action="store_true", help="accept an incomplete capture (interrupted scan)")
    add_report_options(parser)


def _add_validity_options(parser: argparse.ArgumentParser, defaults: ProcessOptions) -> None:
    """--min-modulation, --max-phase-sigma, --max-sigma: which pixels are valid (docs/uncertainty.md)."""
    parser.add_argument(
        "--min-modulation",
        type=float,
        default=defaults.min_modulation_ratio,
        metavar="RATIO",
        help="validity by the modulation ratio instead of the noise: valid pixels need fringe modulation B >= RATIO x "
        "background and x the image's 99th percentile of B (the former default, 0.2). Default: the noise rule "
        "(--max-phase-sigma) with a 0.02 floor, or 0.2 where no phase noise can be predicted (single frames)",
    )
    parser.add_argument(
        "--max-phase-sigma",
        type=float,
        default=defaults.max_phase_sigma,
        metavar="RAD",
        help=f"the noise rule: keep pixels whose predicted phase sigma is at most RAD (default {defaults.max_phase_sigma})",
    )
    parser.add_argument(
        "--max-sigma",
        type=float,
        default=defaults.max_sigma,
        metavar="MM",
        help="also keep only pixels whose predicted height sigma is at most MM (the noise rule applies, even with "
        "--min-modulation, whose ratio then drops to the 0.02 floor); default: no bound in mm",
    )


def add_processing_options(parser: argparse.ArgumentParser) -> None:
    """The pipeline's options (--unwrap, --denoise, --correction, ...), shared by `rig process` and `rig batch`.

    Their defaults are :class:`ProcessOptions`' own, so the command and the API cannot drift apart.
    """
    defaults = ProcessOptions()
    parser.add_argument(
        "--unwrap",
        default=defaults.unwrap,
        choices=LazyChoices(_unwrap_methods),
        metavar="METHOD",
        help=LazyHelp(_unwrap_help),  # type: ignore[arg-type]  # argparse calls str() on it
    )
    parser.add_argument(
        "--denoise",
        default=defaults.denoise,
        choices=LazyChoices(_denoisers),
        metavar="METHOD",
        help="fringe denoising before phase: %(choices)s (default none)",
    )
    parser.add_argument(
        "--correction",
        default=defaults.correction,
        choices=LazyChoices(_corrections),
        metavar="METHOD",
        help=LazyHelp(_correction_help),  # type: ignore[arg-type]  # argparse calls str() on it
    )
    _add_validity_options(parser, defaults)
    parser.add_argument(
        "--min-island",
        type=float,
        default=defaults.min_island_fraction,
        metavar="FRACTION",
        dest="min_island",
        help="drop isolated valid regions smaller than FRACTION of the largest (background specks; default 0.005)",
    )
    parser.add_argument(
        "--keep-islands", action="store_true", help="keep isolated valid regions (same as --min-island 0)"
    )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a parameter of the chosen denoising / correction method (repeatable; VALUE read as JSON if it parses)",
    )
    parser.add_argument(
        "--axis",
        choices=("x", "y", "both"),
        help="fringe axis to use when a capture has both; both: each pixel from both axes (camera-projector "
        "calibration, or reference-plane calibration fitted on both). Default: both with a camera-projector "
        "calibration; the axis with the larger sensitivity 2 pi f0 |d0| / l0 with a reference-plane calibration "
        "fitted on both; else the calibration's fringe_axis, else the first",
    )
    parser.add_argument(
        "--no-undistort",
        dest="undistort",
        action="store_false",
        default=None,
        help="keep lens distortion (default: removed when the calibration has camera_matrix and distortion; "
        "refused with a camera-projector calibration, whose triangulation models it)",
    )


def _format_help() -> str:
    from rig.store.results import DEFAULT_FORMATS, FORMATS

    listed = "; ".join(f"{f.name}: {f.file} ({f.what})" for f in FORMATS.values())
    return f"point and mesh files to write with a calibration, comma-separated (default {','.join(DEFAULT_FORMATS)}): {listed}"


def add_format_option(parser: argparse.ArgumentParser) -> None:
    """--format, shared by `rig process` and `rig batch` (the names of rig.store.results.FORMATS)."""
    parser.add_argument(
        "--format",
        dest="formats",
        metavar="NAMES",
        help=LazyHelp(_format_help),  # type: ignore[arg-type]  # argparse calls str() on it
    )


def processing_options(args: argparse.Namespace) -> ProcessOptions:
    """The :class:`ProcessOptions` of the options :func:`add_processing_options` added."""
    if args.undistort is False and getattr(args, "calibration", None) is not None:
        from calibration.store import read_calibration  # before any frame is read (rig batch: before any job)
        from rig.pipeline.fit import refuse_kept_distortion

        refuse_kept_distortion(read_calibration(args.calibration), ProcessOptions(undistort=False))
    return ProcessOptions(
        unwrap=args.unwrap,
        denoise=args.denoise,
        correction=args.correction,
        min_modulation_ratio=args.min_modulation,
        max_phase_sigma=args.max_phase_sigma,
        max_sigma=args.max_sigma,
        axis=args.axis,
        params=parse_params(args.param),
        undistort=args.undistort,
        min_island_fraction=0.0 if args.keep_islands else args.min_island,
    )


def summary(report: dict, out: Path) -> dict:
    """The short form of a report printed by --json."""
    keys = ("valid_fraction", "unresolved_fraction", "height_mm", "points", "notes")
    return {
        "output": str(out),
        "unwrap": report["methods"]["unwrap"],
        **{k: report[k] for k in keys if k in report},
        "files": report["files"],
        "timings_s": report["timings_s"],
    }


def parse_params(items: list[str]) -> dict[str, object]:
    """``KEY=VALUE`` strings to a dict; values are JSON when they parse (numbers, true/false), else strings."""
    params: dict[str, object] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError(f"--param: expected KEY=VALUE, found {item!r}")
        try:
            params[key.strip()] = json.loads(value)
        except json.JSONDecodeError:
            params[key.strip()] = value
    return params


def run(args: argparse.Namespace) -> int:
    from rig.api import process_steps, process_to
    from rig.store.results import default_output

    out = args.output or default_output(args.capture)
    options = processing_options(args)
    steps = process_steps(args.calibration is not None) + 1
    with Progress(f"process {args.capture}", total=steps, quiet=args.quiet) as progress:
        report = process_to(
            args.capture,
            out,
            args.calibration,
            options,
            progress,
            formats=None if args.formats is None else args.formats.split(","),
            overwrite=args.overwrite,
            salvage=args.salvage,
        )
        progress.step("outputs")
    if args.json:
        print_json(summary(report, out))
    else:
        print_summary(report, out)
    return 0


def print_summary(report: dict, out: Path) -> None:
    """The one-line summary of a processing run (and its notes) on stderr: `rig process`, `rig scan --process`."""
    from rig.pipeline.axes import ONLY_AXIS

    methods = report["methods"]
    line = f"{out}: valid {report['valid_fraction']:.1%}, unwrap {methods['unwrap']}"
    if (
        methods.get("axis_choice") and methods["axis_choice"] != ONLY_AXIS
    ):  # which axis, and why, when there was a choice
        line += f", axis {methods['fringe_axis']} ({methods['axis_choice']})"
    if report.get("height_mm"):  # None when no valid height is finite
        h = report["height_mm"]
        line += f", {report.get('quantity', 'height')} {h['min']:.2f} .. {h['max']:.2f} mm, {report['points']} points"
    if report.get("unresolved_fraction"):
        line += f", fringe orders unresolved on {report['unresolved_fraction']:.2%}"
    print(line, file=sys.stderr)
    for note in report["notes"]:
        print(f"note: {note}", file=sys.stderr)
