"""`rig simulate`: synthesise a scan offline (no devices): object capture, calibration, truth.

Writes what a calibrated rig would leave on disk after ``rig calibrate`` and ``rig scan``::

    OUT/object/                         the capture of the scene
    OUT/calibration/calibration.json    the exact reference-plane model of the simulated rig
    OUT/calibration/reference/          the reference-plane capture, same patterns
    OUT/truth-height.npy                the scene's heights in mm

so that ``rig process OUT/object --calibration OUT/calibration -o RESULT`` can be checked
against ``truth-height.npy``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any

from rig.commands._common import LazyChoices, split_size
from rig.errors import ConfigError

if TYPE_CHECKING:
    from rig.config import RigConfig


def _pattern_sets() -> tuple[str, ...]:
    from rig.config import PATTERN_SETS  # the pattern model (numpy): not for `rig --help`

    return PATTERN_SETS


def _size(text: str) -> tuple[int, int]:
    try:
        width, height = split_size(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT such as 640x480, found {text!r}") from None
    if width < 8 or height < 8:
        raise argparse.ArgumentTypeError(f"expected at least 8x8 pixels, found {text!r}")
    return width, height


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "simulate",
        help="synthesise a capture, its reference and calibration offline (no devices)",
        description="Render a virtual scene and the reference plane under the scan's patterns with the "
        "simulated rig geometry, and write the object capture, the calibration (with its reference "
        "capture) and the true height map. Defaults come from the built-in simulated rig or --config.",
    )
    parser.add_argument("-o", "--output", type=Path, required=True, metavar="OUT", help="directory to create")
    parser.add_argument(
        "--config", type=Path, metavar="RIG.toml", help="take patterns, sizes and geometry from a rig config"
    )
    parser.add_argument("--scene", help="scene name (flat, sphere-cap, hemisphere, two-hemispheres, steps, isolated)")
    parser.add_argument("--snr-db", help="camera noise as signal-to-noise ratio in dB, or 'none'")
    parser.add_argument(
        "--frequencies", type=float, nargs="+", metavar="F", help="sinusoid frequencies (fringes across the projector)"
    )
    parser.add_argument("--steps", type=int, metavar="J", help="phase shifts per frequency")
    parser.add_argument(
        "--pattern-set",
        choices=LazyChoices(_pattern_sets),
        metavar="SET",
        help="'phase-shifting' (sinusoids, the default) or 'speckle': one speckle-embedded fringe frame "
        "(single shot, [scan] speckle_* settings)",
    )
    parser.add_argument(
        "--patterns",
        type=Path,
        metavar="PATTERNS.json",
        help="a JSON list of capture-format pattern entries (overrides --frequencies/--steps)",
    )
    parser.add_argument(
        "--size",
        type=_size,
        metavar="WxH",
        help="camera size in pixels, field of view kept (default from the config: 1024x768)",
    )
    parser.add_argument("--seed", type=int, help="noise seed")
    parser.add_argument("--overwrite", action="store_true", help="replace existing captures in OUT")
    parser.set_defaults(func=run)


def config_with_overrides(config: RigConfig, args: argparse.Namespace) -> RigConfig:
    """The rig config with the command line's values in place, checked by the config file's rules."""
    overrides: dict[str, dict[str, Any]] = {"camera": {}, "scan": {}, "simulation": {}}
    if args.scene is not None:
        overrides["simulation"]["scene"] = args.scene
    if args.snr_db is not None:
        try:
            overrides["simulation"]["snr_db"] = "none" if args.snr_db == "none" else float(args.snr_db)
        except ValueError:
            raise ConfigError(f"--snr-db: expected a number in dB or 'none', found {args.snr_db!r}") from None
    if args.seed is not None:
        overrides["simulation"]["seed"] = args.seed
    if args.frequencies is not None:
        overrides["scan"]["frequencies"] = list(args.frequencies)
    if args.steps is not None:
        overrides["scan"]["steps"] = args.steps
    if getattr(args, "pattern_set", None) is not None:
        overrides["scan"]["pattern_set"] = args.pattern_set
    if args.size is not None:
        overrides["camera"]["size"] = list(args.size)
    from rig.config import parse_config

    checked = parse_config(overrides, where="command line")
    replaced = {}
    for section, values in overrides.items():
        names = [name for key in values for name in (("width", "height") if key == "size" else (key,))]
        fields = {name: getattr(getattr(checked, section), name) for name in names}
        replaced[section] = dataclasses.replace(getattr(config, section), **fields)
    return dataclasses.replace(config, **replaced)


def load_patterns(path: Path) -> list[dict[str, Any]]:
    """Pattern entries from a JSON file: a list, or an object with a ``patterns`` list (a capture.json)."""
    from rig.store.capture import validate_pattern

    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ConfigError(f"{path}: patterns file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the patterns: {exc}") from None
    patterns = data.get("patterns") if isinstance(data, dict) else data
    if not isinstance(patterns, list) or not patterns:
        raise ConfigError(f"{path}: expected a non-empty JSON list of pattern entries (or an object with 'patterns')")
    for i, pattern in enumerate(patterns):
        try:
            validate_pattern(str(path), i, pattern)
        except Exception as exc:  # CaptureError from the capture validator: re-labelled as a config error
            raise ConfigError(str(exc)) from None
    return patterns


SIMULATION_KINDS = ("simulation",)


def run(args: argparse.Namespace) -> int:
    from rig.config import load_config
    from rig.hardware.simulated import (
        appearance_from_config,
        geometry_from_config,
        scene_height,
    )
    from rig.hardware.synthesis import (
        simulate_scan,
        simulated_paths,
        write_simulated_scan,
    )
    from rig.progress import Progress

    config = config_with_overrides(load_config(args.config), args)
    patterns = load_patterns(args.patterns) if args.patterns is not None else config.scan.patterns()
    geometry = geometry_from_config(config)
    from rig.errors import OutputError
    from rig.store import files

    # OUT is written whole into a temporary sibling and renamed into place; --overwrite replaces
    # an earlier simulation only, never another directory
    files.check_writable(args.output, SIMULATION_KINDS, args.overwrite, OutputError)
    with Progress(f"simulate {args.output}", total=2) as progress:
        scan = simulate_scan(
            scene=scene_height(config, "object", geometry),
            geometry=geometry,
            patterns=patterns,
            appearance=appearance_from_config(config),
            seed=config.simulation.seed,
        )
        scan.description["scene"] = config.simulation.scene
        progress.step("write")
        with files.staged_directory(args.output, SIMULATION_KINDS, args.overwrite, OutputError) as staging:
            write_simulated_scan(scan, staging)
        paths = simulated_paths(args.output)
        progress.step()
    print(f"{paths.capture}: {len(patterns)} frames of scene {config.simulation.scene!r}", file=sys.stderr)
    print(f"{paths.calibration}: calibration with reference {paths.reference}", file=sys.stderr)
    print(f"{paths.truth}: true heights (mm)", file=sys.stderr)
    return 0
