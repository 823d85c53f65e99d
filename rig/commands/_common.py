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


class LazyChoices:
    """``choices=`` of an option whose names live in a module the parser should not import.

    argparse only iterates or tests membership when that command's options are parsed or its
    help is printed, so ``rig --help`` and other commands never load the module (numpy, OpenCV...).
    """

    def __init__(self, load: Callable[[], Any]) -> None:
        self._load = load
        self._names: list[str] | None = None

    def _get(self) -> list[str]:
        if self._names is None:
            self._names = sorted(self._load())
        return self._names

    def __contains__(self, item: object) -> bool:
        return item in self._get()

    def __iter__(self) -> Any:
        return iter(self._get())

    def __len__(self) -> int:
        return len(self._get())


class LazyHelp:
    """``help=`` text computed when help is printed (it names entries of a registry the parser does not load)."""

    def __init__(self, text: Callable[[], str]) -> None:
        self._text = text

    def __str__(self) -> str:
        return self._text()

    def __bool__(self) -> bool:
        return True

    def strip(self) -> str:
        return str(self).strip()

    def __mod__(self, params: Any) -> str:
        return str(self) % params


def print_json(obj: Any) -> None:
    """A command's machine-readable result on stdout."""
    print(json.dumps(obj, indent=2))


def split_size(text: str) -> tuple[int, int]:
    """``"640x480"`` -> ``(640, 480)``; ValueError unless two integers joined by an ``x``."""
    width, height = (int(v) for v in text.lower().split("x"))
    return width, height
