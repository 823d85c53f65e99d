"""`rig batch ARCHIVE... --calibration CAL -o OUT`: reprocess every capture of archives on Dask.

Parsing and printing only: the work is :func:`rig.batch.run_batch`. Progress (done/total,
captures per minute, ETA) is drawn from its events; the summary goes to stderr, the comparison
table (``--compare``) to stdout.
"""

from __future__ import annotations

import argparse
import logging
import statistics
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from rig.commands._common import add_command, add_report_options, print_json
from rig.commands.process import add_format_option, add_processing_options, processing_options
from rig.errors import ConfigError
from rig.events import Event, Reporter
from rig.progress import Progress

if TYPE_CHECKING:
    from rig.batch import BatchResult

EXIT_FAILED = 1
SHOW_FAILURES = 5  # failed captures named on stderr; index.csv has them all


def register(subparsers: argparse._SubParsersAction) -> None:
    parser = add_command(
        subparsers,
        "batch",
        run,
        help="reprocess every capture of archives (on Dask, locally or on a cluster)",
        description="Find every capture (directory with capture.json) under each ARCHIVE and process it "
        "with the pipeline and options of `rig process`, as Dask tasks: on a local cluster of one process "
        "per CPU by default, or on an existing cluster (--scheduler). Writes OUT/<capture path>/ with the "
        "files of `rig process` and OUT/index.csv (one row per capture). A rerun skips captures whose "
        "outputs are complete and whose inputs and options are unchanged. Exit status 1 if any capture failed.",
    )
    parser.add_argument(
        "archives", type=Path, nargs="+", metavar="ARCHIVE", help="directory searched for captures, recursively"
    )
    parser.add_argument("--calibration", type=Path, metavar="CAL", help="calibration directory (calibration.json)")
    parser.add_argument(
        "-o", "--output", type=Path, required=True, metavar="OUT", help="output directory (created; reused on a rerun)"
    )
    add_processing_options(parser)
    add_format_option(parser)
    where = parser.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        metavar="N",
        help="local cluster of N single-threaded worker processes (default: one per CPU)",
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="an existing Dask cluster's scheduler, e.g. tcp://host:8786 (workers must see the same paths)",
    )
    parser.add_argument(
        "--compare",
        metavar="METHODS",
        help="also process each capture with these corrections (comma-separated, e.g. none,vote,auto) and write "
        "OUT/compare.csv: valid fraction, order breaks, heights, NMSE_h where the capture has ground truth",
    )
    add_report_options(parser, json_help="print the counts (and the comparison) as JSON on stdout")


def parse_methods(text: str | None) -> tuple[str, ...]:
    """``"none,vote,auto"`` -> ``("none", "vote", "auto")``; ConfigError for an empty or repeated name."""
    if text is None:
        return ()
    methods = tuple(m.strip() for m in text.split(","))
    if not all(methods) or len(set(methods)) != len(methods):
        raise ConfigError(f"--compare: expected distinct comma-separated correction names, found {text!r}")
    return methods


class ProgressView:
    """Renders the batch's events: the bar with captures per minute and ETA, messages as lines."""

    def __init__(self, bar: Progress) -> None:
        self.bar = bar
        self.started = time.time()

    def __call__(self, event: Event) -> None:
        if event.kind == "message":
            self.bar.say(f"batch: {event.note}")
        elif event.kind == "begin":
            self.bar.begin(event.total)
            self.started = event.time
        elif event.kind == "step":
            self.bar.step(f"{rate_and_eta(event.done, event.total, event.time - self.started)} {event.note}")


def rate_and_eta(done: int, total: int, elapsed_s: float) -> str:
    """``"12.0 captures/min, ETA 0:05"`` from progress so far."""
    if done <= 0 or elapsed_s <= 0:
        return ""
    per_min = done / elapsed_s * 60.0
    left = round((total - done) / per_min * 60.0)
    return f"{per_min:.1f} captures/min, ETA {left // 60}:{left % 60:02d}"


def compare_summary(result: BatchResult, methods: tuple[str, ...]) -> list[dict]:
    """Per method: captures ok/failed, medians of valid fraction, order breaks and NMSE_h (over captures with truth)."""
    table = []
    for method in methods:
        rows = [r for r in result.compare if r.method == method]
        ok = [r for r in rows if r.status == "ok"]

        def median(values: list) -> float | None:
            values = [v for v in values if v is not None]
            return float(statistics.median(values)) if values else None

        table.append(
            {
                "method": method,
                "ok": len(ok),
                "failed": len(rows) - len(ok),
                "valid_fraction": median([r.valid_fraction for r in ok]),
                "order_breaks": median([r.order_breaks for r in ok]),
                "nmse_h": median([r.nmse_h for r in ok]),
                "with_truth": sum(1 for r in ok if r.nmse_h is not None),
            }
        )
    return table


def _fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def print_compare_table(table: list[dict]) -> None:
    print(f"{'method':<12} {'ok':>5} {'failed':>6} {'valid':>7} {'breaks':>8} {'NMSE_h':>10} {'truth':>6}")
    for row in table:
        print(
            f"{row['method']:<12} {row['ok']:>5} {row['failed']:>6} {_fmt(row['valid_fraction'], '.1%'):>7} "
            f"{_fmt(row['order_breaks'], '.0f'):>8} {_fmt(row['nmse_h'], '.3g'):>10} {row['with_truth']:>6}"
        )
    print("(medians over the captures each method processed; NMSE_h over those with ground truth)")


def quiet_dask_logs() -> None:
    """Dask logs every scheduler, worker and connection start at INFO: keep its warnings only (-v shows all)."""
    import distributed  # noqa: F401  (importing it sets its loggers' levels, which are lowered here)

    for name in list(logging.root.manager.loggerDict):
        if name == "distributed" or name.startswith("distributed."):
            logging.getLogger(name).setLevel(logging.WARNING)


def run(args: argparse.Namespace) -> int:
    from rig.batch import BatchPlan, run_batch
    from rig.store.results import parse_formats

    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: expected at least 1, found {args.workers}")
    if not args.verbose:
        quiet_dask_logs()
    plan = BatchPlan(
        archives=list(args.archives),
        output=args.output,
        calibration=args.calibration,
        options=processing_options(args),
        compare=parse_methods(args.compare),
        formats=parse_formats(args.formats),
        workers=args.workers,
        scheduler=args.scheduler,
    )
    with Progress("batch", total=1, quiet=args.quiet) as bar:
        result = run_batch(plan, progress=Reporter("batch", sink=ProgressView(bar)))
    ok, failed, skipped = (result.count(s) for s in ("ok", "error", "skipped"))
    table = compare_summary(result, plan.compare) if plan.compare else []
    if args.json:
        print_json(
            {
                "captures": len(result.rows),
                "ok": ok,
                "error": failed,
                "skipped": skipped,
                "kept": result.kept,
                "seconds": result.seconds,
                "index": str(result.index_path),
                **({"compare": table, "compare_csv": str(result.compare_path)} if table else {}),
            }
        )
    elif table:
        print_compare_table(table)
    processed = ok - result.kept + failed
    rate = f", {processed / result.seconds * 60:.1f} captures/min" if processed and result.seconds > 0 else ""
    print(
        f"rig batch: {ok} ok ({result.kept} unchanged since an earlier run), {failed} failed, {skipped} skipped "
        f"of {len(result.rows)} captures in {result.seconds:.1f} s{rate}; {result.index_path}",
        file=sys.stderr,
    )
    for row in [r for r in result.rows if r.status != "ok"][:SHOW_FAILURES]:
        print(f"  {row.status}: {row.capture}: {row.message}", file=sys.stderr)
    if failed:
        print(
            f"rig batch: error: {failed} of {len(result.rows)} captures failed (see {result.index_path})",
            file=sys.stderr,
        )
        return EXIT_FAILED
    return 0
