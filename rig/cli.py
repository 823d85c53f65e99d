"""The `rig` command line: dispatches to one module per subcommand and turns user errors into one line."""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

from rig import __version__
from rig.errors import USER_ERRORS, os_error_line

# Subcommand modules under rig/commands, in the order `rig --help` lists them.
COMMAND_MODULES: tuple[str, ...] = (
    "scan",
    "calibrate",
    "verify",
    "devices",
    "simulate",
    "process",
    "batch",
    "info",
    "import_",
    "demo",
    "study",
    "console",
)

EXIT_USER_ERROR = 1
EXIT_INTERRUPTED = 130


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="rig",
        description="Run a fringe projection profilometry scanner: scan, calibrate, process captures.",
    )
    parser.add_argument("--version", action="version", version=f"fpp-rig {__version__}")
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv for debug)")
    subparsers = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        importlib.import_module(f"rig.commands.{name}").register(subparsers)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=(logging.WARNING, logging.INFO, logging.DEBUG)[min(args.verbose, 2)],
        format="%(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "func", None):
        parser.print_help(sys.stderr)
        return EXIT_USER_ERROR
    try:
        return int(args.func(args) or 0)
    except USER_ERRORS as exc:
        print(f"rig {args.command}: error: {one_line(str(exc))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except OSError as exc:  # the environment refused (disk full, permissions, a vanished file): still one line
        print(f"rig {args.command}: error: {one_line(os_error_line(exc))}", file=sys.stderr)
        return EXIT_USER_ERROR
    except MemoryError:
        print(f"rig {args.command}: error: out of memory (see the size limits in docs/safety.md)", file=sys.stderr)
        return EXIT_USER_ERROR
    except KeyboardInterrupt:
        print(f"rig {args.command}: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED


def one_line(text: str) -> str:
    """An error message as one line: inner line breaks and control characters become visible escapes."""
    return "".join(ch if ch.isprintable() else repr(ch)[1:-1] for ch in text)


if __name__ == "__main__":
    sys.exit(main())
