"""`rig info CAPTURE`: what a capture holds; verifies every frame (checksum, size, bit depth)."""

from __future__ import annotations

import argparse
from collections import Counter
from typing import TYPE_CHECKING, Any

from rig.commands._common import add_capture_argument, add_command, print_json

if TYPE_CHECKING:
    from rig.store.capture import Capture


def describe_patterns(patterns: list[dict[str, Any]]) -> list[str]:
    """One line per group of patterns, e.g. ``sinusoid x: f=8, 4 steps``."""
    lines: list[str] = []
    sinusoids: dict[tuple[str, str, float], int] = Counter()
    gray: dict[tuple[str, int, bool], int] = Counter()  # (code, axis and cells), bits, inverted
    flats: list[float] = []
    for p in patterns:
        if p["kind"] in ("sinusoid", "speckle-sinusoid"):
            sinusoids[(p["kind"], p.get("axis", "x"), float(p["frequency"]))] += 1
        elif p["kind"] in ("gray", "binary"):
            cells = f"{p['kind']} {p.get('axis', 'x')}" + (
                f" ({p['period_px']:g}-px cells)" if "period_px" in p else ""
            )
            gray[(cells, int(p["bits"]), bool(p.get("inverted", False)))] += 1
        elif p["kind"] == "flat":
            flats.append(float(p["level"]))
    for (kind, axis, freq), count in sinusoids.items():
        lines.append(f"{kind} {axis}: frequency {freq:g}, {count} step{'s' if count != 1 else ''}")
    for (code, bits, inverted), count in gray.items():
        lines.append(f"{code}: {count} of {bits} bit planes{' (inverted)' if inverted else ''}")
    if flats:
        lines.append("flat: levels " + ", ".join(f"{level:g}" for level in flats))
    return lines


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "info",
        run,
        help="show what a capture holds and verify its frames",
        description="Print a capture's scene, image sizes, patterns and frames, and verify every frame "
        "(sha256, image size, bit depth). Exits non-zero on any problem.",
    )
    add_capture_argument(parser)
    parser.add_argument("--salvage", action="store_true", help="inspect an incomplete capture too")
    parser.add_argument("--json", action="store_true", help="print the facts as JSON")


def facts(capture: Capture) -> dict[str, Any]:
    """What `rig info` reports, as a dict."""
    from rig.store.exposures import describe_exposures, exposure_sets

    base = [p.to_dict() for p in exposure_sets(capture.pattern_models, str(capture.manifest_path)).base]

    m = capture.manifest
    return {
        "path": str(capture.path),
        "scene": capture.scene,
        "complete": capture.complete,
        "created_utc": m.get("created_utc"),
        "camera": m["camera"],
        "projector": m["projector"],
        "patterns": len(capture.patterns),
        "pattern_groups": describe_patterns(base),  # of one exposure's sequence
        "exposures": describe_exposures(capture.pattern_models, str(capture.manifest_path)),
        "frames": len(capture.frames),
        "verified": True,
        "extra_keys": sorted(
            k
            for k in m
            if k
            not in {
                "format",
                "version",
                "scene",
                "created_utc",
                "complete",
                "camera",
                "projector",
                "patterns",
                "frames",
            }
        ),
    }


def run(args: argparse.Namespace) -> int:
    from rig.store.capture import read_capture

    capture = read_capture(args.capture, salvage=args.salvage, verify=False)
    for frame in capture.frames:  # sha256, then decoding: size, channels, bit depth
        capture.load_frame(int(frame["pattern"]))
    info = facts(capture)
    if args.json:
        print_json(info)
        return 0
    cam, proj = info["camera"], info["projector"]
    print(
        f"{info['path']}: {info['scene']} capture, {'complete' if info['complete'] else 'INCOMPLETE'}, created {info['created_utc']}"
    )
    print(f"camera {cam['width']}x{cam['height']} {cam['bit_depth']}-bit, projector {proj['width']}x{proj['height']}")
    print(f"{info['patterns']} patterns, {info['frames']} frames, all verified (sha256, size, bit depth)")
    if info["exposures"]:
        print(info["exposures"])
    for line in info["pattern_groups"]:
        print(f"  {line}")
    if info["extra_keys"]:
        print("extra keys: " + ", ".join(info["extra_keys"]))
    return 0
