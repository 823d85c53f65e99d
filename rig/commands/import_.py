"""`rig import FOLDER --patterns SPEC -o CAPTURE`: make a capture from another rig's images."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rig.commands._common import add_command

SPEC_HELP = (
    "what the images show, in file order: groups separated by ';', e.g. "
    "'sin:f=32,steps=12,phase=pi; gray:bits=6' or 'sin:f=64/58/53,steps=4,phase=pi' or "
    "'sin:f=36,shifts=0/90/180/270deg'; kinds sin (f, steps, phase, shifts, axis), gray and binary (bits, "
    "order=msb|lsb, inverted=none|after|interleaved, period=CELL_PX, axis), flat:LEVEL, white, black, skip:N; "
    "or @FILE.json with "
    '{"patterns": [capture-format entries], "files": [names]}'
)


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "import",
        run,
        help="turn a folder of fringe images from another rig into a capture",
        description="Match the folder's images (natural order: 2.png before 10.png) with the patterns "
        "of SPEC, convert them to single-channel, and write a verified capture that records where "
        "they came from.",
    )
    parser.add_argument("folder", type=Path, metavar="FOLDER", help="folder holding the images")
    parser.add_argument("--patterns", required=True, metavar="SPEC", help=SPEC_HELP)
    parser.add_argument(
        "-o", "--output", type=Path, required=True, metavar="CAPTURE", help="capture directory to create"
    )
    parser.add_argument(
        "--projector-width", type=int, metavar="PX", help="projector width in pixels (default: the image width)"
    )
    parser.add_argument(
        "--projector-height", type=int, metavar="PX", help="projector height in pixels (default: the image height)"
    )
    parser.add_argument(
        "--shift-sign",
        type=int,
        choices=(1, -1),
        default=1,
        help="-1 if the rig's frames are I = A + B cos(phi - delta) (default +1: cos(phi + delta))",
    )
    parser.add_argument("--glob", metavar="PATTERN", help="only files matching PATTERN, e.g. 'lens_crop_*.jpg'")
    parser.add_argument(
        "--order", choices=("natural", "name", "mtime"), default="natural", help="file order (default natural)"
    )
    parser.add_argument("--crop", metavar="X,Y,W,H", help="keep only this rectangle of every image")
    parser.add_argument("--downsample", type=int, default=1, metavar="N", help="average N x N pixel blocks (default 1)")
    parser.add_argument("--scene", default="object", help="scene label of the capture (default object)")
    parser.add_argument(
        "--exposures",
        metavar="US,US,...",
        help="the folder holds SPEC's files once per exposure, each exposure's full sequence in turn "
        "(e.g. 2000,8000,32000 microseconds): a capture at several exposures, fused when processed",
    )
    parser.add_argument("--overwrite", action="store_true", help="replace an existing capture")


def run(args: argparse.Namespace) -> int:
    from rig.config import parse_exposures
    from rig.store.exposures import describe_exposures
    from rig.store.importer import ImportOptions, import_folder, parse_crop

    options = ImportOptions(
        projector_width=args.projector_width,
        projector_height=args.projector_height,
        shift_sign=args.shift_sign,
        glob=args.glob,
        order=args.order,
        crop=parse_crop(args.crop) if args.crop else None,
        downsample=args.downsample,
        scene=args.scene,
        overwrite=args.overwrite,
        exposures_us=parse_exposures(args.exposures) if args.exposures else (),
    )
    capture = import_folder(args.folder, args.patterns, args.output, options)
    provenance = capture.manifest["import"]
    print(
        f"{capture.path}: {len(capture.frames)} frames from {args.folder} ({capture.width}x{capture.height}, "
        f"{capture.bit_depth}-bit, projector {capture.projector_size[0]}x{capture.projector_size[1]})"
        + (f"; skipped {len(provenance['skipped'])}" if provenance["skipped"] else "")
        + (f"; {', '.join(provenance['conversions'])}" if provenance["conversions"] else ""),
        file=sys.stderr,
    )
    exposures = describe_exposures(capture.pattern_models, str(capture.manifest_path))
    if exposures:
        print(f"{capture.path}: {exposures}", file=sys.stderr)
    return 0
