"""`rig verify`: the rig's accuracy in the terms of VDI/VDE 2634 Part 2 (PF, PS, SD, F) against its MPE.

Without ``--config`` the built-in simulated rig places its artefacts itself and runs unattended;
on a real rig the operator is prompted for each position ("ball bar, position 3 of 7: ..., press
Enter"). ``--from DIR`` recomputes the figures from a stored verification's captures (with this
calibration and MPE). Prints one line: PASS/FAIL and the four worst values.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from rig.commands._common import add_command, add_report_options, print_json


def _mpe(text: str) -> dict[str, float]:
    from rig.verify.results import parse_mpe

    try:
        return parse_mpe(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _count(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive number of positions, found {text!r}")
    return value


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "verify",
        run,
        help="verify the rig's accuracy (VDI/VDE 2634-2: PF, PS, SD, F) with spheres, a ball bar and a plane",
        description="Scan calibrated artefacts at the guideline's positions (the simulated rig places them "
        "itself), fit them, and compare probing error form PF and size PS, sphere-spacing error SD and "
        "flatness error F with the declared MPE; writes REPORT/report.json, report.md and figures, and "
        "appends to CAL/verification-history.jsonl.",
    )
    parser.add_argument(
        "--config", type=Path, metavar="RIG.toml", help="rig config file (default: the built-in simulated rig)"
    )
    parser.add_argument(
        "--calibration", type=Path, required=True, metavar="CAL", help="calibration directory to verify"
    )
    parser.add_argument(
        "--artefacts",
        type=Path,
        metavar="ARTEFACTS.toml",
        help="calibrated artefact values (default: the simulated rig's)",
    )
    parser.add_argument(
        "--mpe-mm",
        type=_mpe,
        metavar="PF,PS,SD,F",
        help="maximum permissible errors in mm (default on the simulated rig 0.5,0.15,0.1,0.4; with --from: "
        "the stored report's; required otherwise)",
    )
    parser.add_argument(
        "--from", dest="from_dir", type=Path, metavar="DIR", help="recompute from a stored verification"
    )
    parser.add_argument(
        "-o", "--output", type=Path, metavar="REPORT", help="report directory (default: verification; with --from: DIR)"
    )
    parser.add_argument("--spheres", type=_count, default=None, metavar="N", help="sphere positions (default 10)")
    parser.add_argument("--overwrite", action="store_true", help="replace an existing verification directory")
    add_report_options(parser, json_help="print report.json on stdout")


def _stored_mpe(from_dir: Path) -> dict[str, float] | None:
    """The MPE a stored verification's report declared, if it has one."""
    from rig.errors import OutputError
    from rig.verify.guideline import QUANTITIES
    from rig.verify.report import read_report

    try:
        report = read_report(from_dir)
        return {q: float(report[q]["mpe_mm"]) for q in QUANTITIES}
    except (OutputError, KeyError, TypeError, ValueError):
        return None


def _plan(args: argparse.Namespace, simulated: bool):
    from rig.errors import ConfigError
    from rig.verify.plan import VerificationPlan

    plan = VerificationPlan()
    stored = _stored_mpe(args.from_dir) if args.from_dir is not None and args.mpe_mm is None else None
    if args.mpe_mm is not None:
        plan.mpe_mm = args.mpe_mm
    elif stored is not None:
        plan.mpe_mm = stored
    elif not simulated:
        raise ConfigError("--mpe-mm: missing: declare the rig's maximum permissible errors PF,PS,SD,F in mm")
    if args.spheres is not None:
        plan.sphere_positions = args.spheres
    return plan


def run(args: argparse.Namespace) -> int:
    from rig.progress import Progress
    from rig.verify.results import failures
    from rig.verify.session import recompute, verify

    if args.from_dir is not None:
        from rig.verify.artefacts import load_artefacts

        plan = _plan(args, simulated=False)  # the MPE: --mpe-mm, or what the stored report declared
        artefacts = load_artefacts(args.artefacts) if args.artefacts is not None else None
        with Progress(f"verify --from {args.from_dir}", total=1, quiet=args.quiet) as bar:
            result = recompute(
                args.from_dir, args.calibration, plan, args.output, bar.reporter(), args.overwrite, artefacts
            )
    else:
        from rig.config import load_config
        from rig.hardware.assembly import rig_sets_up_scenes
        from rig.verify.artefacts import load_artefacts
        from rig.verify.operator import PromptOperator

        config = load_config(args.config)
        unattended = rig_sets_up_scenes(config)
        plan = _plan(args, simulated=unattended)
        artefacts = load_artefacts(args.artefacts)
        operator = None if unattended else PromptOperator()
        output = args.output or Path("verification")
        with Progress(f"verify {output}", total=1, quiet=args.quiet) as bar:
            result = verify(config, plan, artefacts, args.calibration, output, operator, bar.reporter(), args.overwrite)
    report = result.report
    for line in failures(report) + report["drift"]["warnings"] + report["notes"]:
        print(f"  {line}", file=sys.stderr)
    print(f"{result.directory}/report.json, report.md written", file=sys.stderr)
    if args.json:
        print_json(report)
    print(report["summary"])
    return 0 if report["pass"] else 2
