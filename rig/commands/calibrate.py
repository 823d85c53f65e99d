"""`rig calibrate`: capture the calibration planes (and board, gamma ramp) and write calibration.json.

Without ``--config`` the built-in simulated rig is calibrated unattended. With a real rig the
operator is prompted for each step, or ``--stage-command`` moves a motorised stage. ``--from DIR``
recomputes from the captures a previous session stored (optionally with another ``--model``);
``--import-opencv FILE`` turns an OpenCV FileStorage projector-camera calibration into a
``stereo`` calibration.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING

from calibration.errors import CalibrationError
from rig.commands._common import add_command, add_report_options, print_json, split_size
from rig.errors import ConfigError

if TYPE_CHECKING:
    from calibration.camera import BoardSpec


def _heights(text: str) -> tuple[float, ...]:
    try:
        return tuple(float(part) for part in text.split(",") if part.strip())
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated heights in mm, found {text!r}") from None


def _size(text: str) -> tuple[int, int]:
    try:
        return split_size(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT, found {text!r}") from None


NO_BOARD = "none"


def _board(text: str) -> BoardSpec | str:
    """``chessboard:9x7:20`` or ``charuco:9x7:20:14`` (kind, squares, square mm, marker mm); ``none``."""
    if text == NO_BOARD:
        return NO_BOARD
    parts = text.split(":")
    try:
        kind, squares, square = parts[0], _size(parts[1]), float(parts[2])
        marker = float(parts[3]) if len(parts) > 3 else None
    except (IndexError, ValueError, argparse.ArgumentTypeError):
        raise argparse.ArgumentTypeError(f"expected KIND:COLSxROWS:SQUARE_MM[:MARKER_MM], found {text!r}") from None
    from calibration.camera import (
        BoardSpec,  # imported here: it loads OpenCV, which `rig --help` does not need
    )

    try:
        return BoardSpec(kind, squares, square, marker)
    except CalibrationError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "calibrate",
        run,
        help="calibrate the rig: reference plane, planes at known heights, board, gamma -> calibration.json",
        description="Walk through a calibration session (the simulated rig runs it unattended) and fit "
        "l0, d0, f0 (reference-plane model) or a per-pixel polynomial; or recompute from a stored "
        "session (--from), or import an OpenCV projector-camera calibration (--import-opencv).",
    )
    _source_options(parser)
    _session_options(parser)
    _device_and_import_options(parser)
    parser.add_argument("--overwrite", action="store_true", help="replace an existing calibration directory")
    add_report_options(parser, json_help="print calibration.json on stdout")


def _source_options(parser: argparse.ArgumentParser) -> None:
    """Where the calibration goes and where its captures come from."""
    parser.add_argument(
        "-o", "--output", type=Path, metavar="CAL", help="calibration directory to create (default: calibration)"
    )
    parser.add_argument(
        "--config", type=Path, metavar="RIG.toml", help="rig config file (default: the built-in simulated rig)"
    )
    parser.add_argument(
        "--from", dest="from_dir", type=Path, metavar="DIR", help="recompute from the captures of a stored session"
    )


def _session_options(parser: argparse.ArgumentParser) -> None:
    """What the session captures and which model it fits."""
    parser.add_argument(
        "--heights",
        type=_heights,
        default=None,
        metavar="MM,MM,...",
        help="plane heights above the reference plane (default 25,50,100,150)",
    )
    parser.add_argument(
        "--model",
        choices=("reference-plane", "polynomial", "stereo"),
        default=None,
        help="height model to fit (default reference-plane, eq. 1.15; stereo: projector-camera "
        "calibration from board poses with fringes along x and y)",
    )
    parser.add_argument("--degree", type=int, default=None, help="polynomial degree (default 3)")
    parser.add_argument(
        "--board",
        type=_board,
        default=None,
        metavar="KIND:COLSxROWS:SQUARE_MM[:MARKER_MM]",
        help="calibration target (default chessboard:9x7:20; 'none' with --pixel-mm)",
    )
    parser.add_argument(
        "--board-views",
        type=int,
        default=None,
        metavar="N",
        help="tilted board views for camera intrinsics (default 6; 0: pixel size only)",
    )
    parser.add_argument("--pixel-mm", type=float, default=None, help="pixel size on the plane, instead of measuring it")
    parser.add_argument(
        "--gamma",
        type=int,
        nargs="?",
        const=17,
        default=0,
        metavar="LEVELS",
        help="measure the projector gamma with a ramp of LEVELS flat levels (default 17) and write gamma-lut.npy",
    )
    parser.add_argument(
        "--flatness-tolerance",
        type=float,
        default=None,
        metavar="MM",
        help="largest RMS height spread of a calibration plane (default 1 mm)",
    )


def _device_and_import_options(parser: argparse.ArgumentParser) -> None:
    """A motorised stage, and the import of an OpenCV projector-camera calibration."""
    parser.add_argument(
        "--stage-command",
        metavar="CMD",
        help="move a motorised stage instead of prompting, e.g. 'stage-move --mm {height_mm}'",
    )
    parser.add_argument(
        "--import-opencv",
        type=Path,
        metavar="FILE.yml",
        help="write a 'stereo' calibration from an OpenCV FileStorage file (SLMaster's M1 D1 M4 D4 Rlp Tlp S, "
        "or stereoCalibrate's results as K1 D1 K2 D2 R T, M1 D1 M2 D2 R T or cameraMatrix1 distCoeffs1 "
        "cameraMatrix2 distCoeffs2 R T; camera first, projector second)",
    )
    parser.add_argument("--projector-size", type=_size, metavar="WxH", help="projector resolution for --import-opencv")
    parser.add_argument(
        "--camera-size",
        type=_size,
        metavar="WxH",
        help="camera resolution for --import-opencv, when the file holds no S or imageSize",
    )
    parser.add_argument(
        "--pixel-centre",
        type=float,
        default=0.5,
        metavar="P",
        help="for --import-opencv: where projector pixel k sits in the phase convention "
        "(0.5: this product's patterns; 0: phase 2 pi f k / W at column k, as SLMaster)",
    )


def _import_opencv(args: argparse.Namespace) -> int:
    from rig.calibrate.imports import import_opencv

    if args.projector_size is None:
        raise ConfigError("--import-opencv needs --projector-size WxH (the FileStorage file does not record it)")
    target = import_opencv(
        args.import_opencv,
        args.output or Path("calibration"),
        args.projector_size,
        camera_size=args.camera_size,
        pixel_centre=args.pixel_centre,
        overwrite=args.overwrite,
    )
    print(f"{target}: stereo calibration imported from {args.import_opencv}", file=sys.stderr)
    return 0


def _plan(args: argparse.Namespace, base=None):
    from rig.calibrate.session import CalibrationPlan

    plan = base or CalibrationPlan()
    updates = {
        "heights_mm": args.heights,
        "model": args.model,
        "degree": args.degree,
        "board_views": args.board_views,
        "pixel_mm": args.pixel_mm,
        "flatness_tolerance_mm": args.flatness_tolerance,
    }
    for key, value in updates.items():
        if value is not None:
            setattr(plan, key, value)
    if args.board is not None:
        plan.board = None if args.board == NO_BOARD else args.board
    if args.gamma:
        plan.gamma_levels = args.gamma
    return plan


def run(args: argparse.Namespace) -> int:
    from rig.calibrate.operator import ConsoleOperator, StageCommand
    from rig.calibrate.session import CALIBRATION_KINDS, CalibrationPlan, calibrate, compute, compute_calibration
    from rig.progress import Progress

    if args.import_opencv is not None:
        return _import_opencv(args)
    from rig.errors import OutputError
    from rig.store import files

    in_place = args.from_dir is not None and (args.output is None or files.same_path(args.output, args.from_dir))
    # unwritable or foreign: say so before the session or the computation
    if in_place:
        files.check_writable_directory(args.from_dir, OutputError)
    elif args.output is not None:
        files.check_writable(args.output, CALIBRATION_KINDS, args.overwrite, OutputError)
    if args.from_dir is not None:
        session = args.from_dir / "session.json"
        base = None
        if session.is_file():
            base = CalibrationPlan.load(session)
        elif not (args.from_dir / "planes").is_dir():
            raise CalibrationError(f"{args.from_dir}: not a calibration session (no session.json, no planes/)")
        plan = _plan(args, base)
        plan.check()
        with Progress(f"calibrate --from {args.from_dir}", total=1, quiet=args.quiet) as bar:
            if in_place:
                report = compute(args.from_dir, plan, progress=bar.reporter())
            else:  # a new calibration directory (with a copy of the reference), committed as a whole
                computed = compute_calibration(args.from_dir, plan, progress=bar.reporter())
                # staged only now: a kill while computing leaves no staging folder behind
                with files.staged_directory(args.output, CALIBRATION_KINDS, args.overwrite, OutputError) as staging:
                    report = computed.write(staging)
                report.calibration.path = args.output
    else:
        from rig.config import load_config

        config = load_config(args.config)
        plan = _plan(args)
        output = args.output or Path("calibration")
        from rig.hardware.assembly import rig_sets_up_scenes

        operator = None
        if not rig_sets_up_scenes(config):  # the simulated rig runs unattended
            stage = StageCommand(args.stage_command) if args.stage_command else None
            operator = ConsoleOperator(stage=stage)
        with Progress(f"calibrate {output}", total=1, quiet=args.quiet) as bar:
            # captured and computed beside OUTPUT, then committed: a kill keeps the old calibration
            report = calibrate(config, plan, output, operator, progress=bar.reporter(), overwrite=args.overwrite)
    cal = report.calibration
    for line in report.lines:
        print(f"  {line}", file=sys.stderr)
    print(f"{cal.where}: {cal.model} calibration written", file=sys.stderr)
    if args.json:
        print_json(cal.to_dict())
    return 0
