"""`rig demo`: simulate a scan of a built-in object, process it, and compare with the truth."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from rig.commands._common import LazyChoices, add_command, add_report_options, print_json, split_size
from rig.errors import ConfigError, OutputError
from rig.hardware.scenes import scene_names
from rig.progress import Progress


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "demo",
        run,
        help="simulate a scan of a built-in object, process it and report the height error",
        description="Synthesise an object capture, a reference-plane capture and their calibration "
        "(4-step fringes at 1, 8 and 64 periods), process them like `rig process` and write the height "
        "map, point cloud and preview, with the error against the true heights.",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("demo-output"),
        metavar="DIR",
        help="output directory (default ./demo-output; replaced if it holds an earlier demo)",
    )
    parser.add_argument(
        "--scene",
        default="hemisphere",
        choices=LazyChoices(scene_names),
        metavar="NAME",
        help="object to scan: %(choices)s (default hemisphere)",
    )
    parser.add_argument("--size", default="640x480", metavar="WxH", help="camera size (default 640x480)")
    parser.add_argument("--snr", type=float, default=35.0, metavar="DB", help="camera noise, SNR in dB (default 35)")
    parser.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    add_report_options(parser)


def parse_size(text: str) -> tuple[int, int]:
    """``--size WxH``: 16 to 8192 pixels per side."""
    try:
        width, height = split_size(text)
    except ValueError:
        raise ConfigError(f"--size: expected WIDTHxHEIGHT such as 640x480, found {text!r}") from None
    if not (16 <= width <= 8192 and 16 <= height <= 8192):
        raise ConfigError(f"--size: expected 16..8192 pixels per side, found {text!r}")
    return width, height


DEMO_KINDS = ("demo",)


def _summary(
    args: argparse.Namespace,
    out: Path,
    width: int,
    height: int,
    scan: Any,
    result: Any,
    report: dict[str, Any],
    paths: Any,
) -> dict[str, Any]:
    """demo.json: what was simulated and how far the processed heights are from the truth."""
    import numpy as np

    assert result.height is not None
    valid = result.mask & scan.lit
    error = result.height[valid].astype(np.float64) - scan.height_mm[valid]
    rms = float(np.sqrt(np.mean(error**2)))
    return {
        "output": str(out),
        "scene": args.scene,
        "size": [width, height],
        "unwrap": report["methods"]["unwrap"],
        "valid_fraction": report["valid_fraction"],
        "height_error_mm": {
            "rms": rms,
            "max_abs": float(np.max(np.abs(error))),
            "median_abs": float(np.median(np.abs(error))),
        },
        "true_max_height_mm": float(scan.height_mm.max()),
        "files": {k: str(out / "processed" / v) for k, v in report["files"].items()},
        "capture": str(paths.capture),
        "calibration": str(paths.calibration),
        "truth": str(paths.truth),
        "processing_s": report["timings_s"]["total"],
    }


def run(args: argparse.Namespace) -> int:
    # numpy, the synthesiser and the pipeline: imported when the demo runs, not for `rig --help`
    from rig.api import process, process_steps
    from rig.hardware.synthesis import (
        demo_appearance,
        demo_geometry,
        simulate_scan,
        simulated_paths,
        write_simulated_scan,
    )
    from rig.store import files
    from rig.store.results import write_result

    width, height = parse_size(args.size)
    out: Path = args.output
    # the whole demo directory is built beside OUT and renamed into place; an earlier demo is replaced
    files.check_writable(out, DEMO_KINDS, True, OutputError)
    with (
        Progress("demo", total=2 + process_steps(True) + 1, quiet=args.quiet) as progress,
        files.staged_directory(out, DEMO_KINDS, True, OutputError) as staging,
    ):
        scan = simulate_scan(
            args.scene,
            geometry=demo_geometry(width, height),
            seed=args.seed,
            appearance=demo_appearance(args.snr),
        )
        progress.step("synthesised")
        staged = write_simulated_scan(scan, staging / "scan")
        progress.step("captures written")
        result = process(staged.capture, staged.calibration, progress=progress)
        report = write_result(result, staging / "processed", staged_inputs=(staging, out))  # names the final paths
        progress.step("outputs")
        paths = simulated_paths(out / "scan")
        summary = _summary(args, out, width, height, scan, result, report, paths)
        (staging / "demo.json").write_text(json.dumps(summary, indent=2) + "\n")
    if args.json:
        print_json(summary)
        return 0
    e = summary["height_error_mm"]
    print(
        f"demo: {args.scene} {width}x{height}, unwrapped with {summary['unwrap']}, {summary['valid_fraction']:.1%} pixels valid"
    )
    print(
        f"height error vs truth: rms {e['rms']:.3f} mm, max {e['max_abs']:.3f} mm (object {summary['true_max_height_mm']:.1f} mm high)"
    )
    for name in ("height", "points", "preview", "report"):
        print(f"  {name:8s} {summary['files'][name]}")
    print(f"  capture  {paths.capture}  (calibration {paths.calibration})")
    return 0
