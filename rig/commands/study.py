"""`rig study`: regenerate the thesis' simulations and write the comparison report (rig/study.py)."""

from __future__ import annotations

import argparse
from pathlib import Path


def _positive(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, found {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, found {text!r}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "study",
        help="reproduce the thesis' simulations; write a Markdown report, CSV and figures",
        description="Simulate the thesis' experiments (Table 4.1, ch. 2.4 denoising, the t sweep of ch. 3, "
        "NMSE vs SNR, isolated objects, single-shot speckle unwrapping) on a fixed simulated rig and write "
        "README.md, study.csv and PNG figures with the thesis' numbers beside ours. The full study takes "
        "several minutes on two cores; --quick runs every experiment on small images in seconds.",
    )
    parser.add_argument(
        "-o",
        "--output",
        type=Path,
        default=Path("docs/study"),
        metavar="DIR",
        help="output directory (default docs/study)",
    )
    parser.add_argument("--quick", action="store_true", help="small images and short sweeps (a smoke test)")
    parser.add_argument(
        "--seeds",
        type=_positive,
        default=None,
        metavar="N",
        help="noise seeds for the repeated experiments (default 3, quick 2)",
    )
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from rig.study.experiments import StudyConfig, run_study, stderr_progress

    if args.quick:
        config = StudyConfig.quick_config(seeds=args.seeds or 2)
    else:
        config = StudyConfig(seeds=args.seeds or 3)
    path = run_study(config, args.output, progress=stderr_progress)
    print(path)
    return 0
