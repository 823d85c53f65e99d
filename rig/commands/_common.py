"""Argument helpers shared by the `rig` subcommands, so that the same option reads the same everywhere."""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any


def add_command(
    subparsers: argparse._SubParsersAction,
    name: str,
    run: Callable[[argparse.Namespace], int],
    *,
    help: str,
    description: str,
) -> argparse.ArgumentParser:
    """Add subcommand ``name`` whose parsed arguments go to ``run``; returns its parser for the options."""
    parser = subparsers.add_parser(name, help=help, description=description)
    parser.set_defaults(func=run)
    return parser


def add_capture_argument(parser: argparse.ArgumentParser) -> None:
    """The positional CAPTURE directory."""
    parser.add_argument("capture", type=Path, metavar="CAPTURE", help="capture directory")


def add_report_options(parser: argparse.ArgumentParser, json_help: str = "print a summary as JSON on stdout") -> None:
    """``--json`` (machine-readable result on stdout) and ``-q/--quiet`` (no progress on stderr)."""
    parser.add_argument("--json", action="store_true", help=json_help)
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress on stderr")


def print_json(obj: Any) -> None:
    """A command's machine-readable result on stdout."""
    print(json.dumps(obj, indent=2))


def split_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)``; ValueError unless two integers joined by an ``x``."""
    width, height = (int(v) for v in text.lower().split("x"))
    return width, height
