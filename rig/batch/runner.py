"""Run a batch on Dask: an embedded ``LocalCluster`` by default, or an existing cluster's scheduler.

The client (this process) finds the captures, decides from the fingerprints what an earlier run
already finished, submits one task per remaining capture (paths only) with a bounded number in
flight, and rewrites ``index.csv`` as rows come back. It reports through a
:class:`rig.events.Reporter` (``begin``/``step`` per capture, ``message`` for the dashboard) and
never prints.
"""

from __future__ import annotations

import itertools
import logging
import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from processing.concurrency import available_cpus
from rig.batch.discovery import FoundCapture, discover
from rig.batch.index import CompareRow, IndexRow, write_compare, write_index
from rig.batch.resume import calibration_digest, fingerprint, options_key, remove_stale, reusable_report
from rig.batch.tasks import CaptureTask, TaskOutcome, kept_outcome, run_task, warm_up
from rig.errors import ConfigError
from rig.events import Reporter
from rig.pipeline.plan import ProcessOptions
from rig.store.results import DEFAULT_FORMATS

INDEX_FILE = "index.csv"
COMPARE_FILE = "compare.csv"
INDEX_EVERY_S = 2.0  # rewrite index.csv at most this often while the batch runs
CONNECT_TIMEOUT_S = 20.0


@dataclass
class BatchPlan:
    """What ``rig batch`` was asked: archives, calibration, output root, options, where to run."""

    archives: list[Path]
    output: Path
    calibration: Path | None = None
    options: ProcessOptions = field(default_factory=ProcessOptions)
    compare: tuple[str, ...] = ()
    formats: tuple[str, ...] = DEFAULT_FORMATS  # output formats (rig.store.results.FORMATS)
    workers: int | None = None  # local cluster size (default: the CPUs this process may use)
    scheduler: str | None = None  # tcp://host:port of an existing cluster instead of a local one


@dataclass
class BatchResult:
    """Rows of every capture found, the compare rows, and where the tables are."""

    rows: list[IndexRow]
    compare: list[CompareRow]
    index_path: Path
    compare_path: Path | None
    kept: int
    seconds: float

    def count(self, status: str) -> int:
        return sum(1 for r in self.rows if r.status == status)


def default_workers() -> int:
    """One single-threaded worker process per CPU this process may run on."""
    return available_cpus()


def _dashboard_available() -> bool:
    """Whether the dashboard's plots can be drawn here (Dask needs bokeh for them)."""
    import importlib.util

    return importlib.util.find_spec("bokeh") is not None


def worker_environ() -> dict[str, object]:
    """Dask's environment for new worker processes, less ``MALLOC_TRIM_THRESHOLD_``.

    Dask sets it (to hand memory back to the OS sooner); setting it also turns off glibc's
    adaptive mmap threshold, so every array above 128 KiB is mapped and unmapped afresh: 1.3x to
    2x the time per capture, depending on load (docs/benchmarks.md, "Archive batches on Dask").
    Its single-thread BLAS/OpenMP settings are kept.
    """
    import dask

    environ = dict(dask.config.get("distributed.nanny.pre-spawn-environ", default={}) or {})
    environ.pop("MALLOC_TRIM_THRESHOLD_", None)
    return environ


@contextmanager
def dask_client(plan: BatchPlan) -> Iterator[Any]:
    """A connected ``distributed.Client``: to ``plan.scheduler``, or to a new local cluster it closes after."""
    import dask
    from distributed import Client, LocalCluster

    if plan.scheduler is not None:
        try:
            client = Client(plan.scheduler, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError(f"--scheduler: cannot connect to {plan.scheduler}: {exc}") from None
        try:
            yield client
        finally:
            client.close()
        return
    workers = plan.workers or default_workers()
    if workers < 1:
        raise ConfigError(f"--workers: expected at least 1, found {workers}")
    try:
        with dask.config.set({"distributed.nanny.pre-spawn-environ": worker_environ()}):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                dashboard_address=":0",  # any free port: several batches may run at once
                silence_logs=logging.ERROR,
            )
    except (OSError, RuntimeError, TimeoutError) as exc:
        raise ConfigError(f"--workers {workers}: the local Dask cluster did not start: {exc}") from None
    try:
        client = Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def dashboard_link(client: Any) -> str | None:
    """The scheduler's dashboard address, when it serves one (its plots need bokeh where the scheduler runs)."""
    services = client.scheduler_info().get("services", {})
    if "dashboard" not in services:
        return None
    return client.dashboard_link + ("" if _dashboard_available() else " (install bokeh for its plots)")


def _output_dir(plan: BatchPlan, found: FoundCapture) -> Path:
    return plan.output.resolve() / found.name


def plan_tasks(plan: BatchPlan, found: list[FoundCapture]) -> tuple[list[CaptureTask], list[TaskOutcome]]:
    """Tasks for the captures to process, and the outcomes already known (skipped, kept from an earlier run)."""
    calibration = plan.calibration.resolve() if plan.calibration is not None else None
    cal_digest = calibration_digest(calibration)
    key = options_key(plan.options, plan.compare, plan.formats)
    tasks: list[CaptureTask] = []
    known: list[TaskOutcome] = []
    for capture in found:
        if capture.skip_reason is not None:
            known.append(
                TaskOutcome(
                    IndexRow(
                        capture=capture.name,
                        status="skipped",
                        message=capture.skip_reason,
                        correction=plan.options.correction,
                    )
                )
            )
            continue
        out = _output_dir(plan, capture)
        digest = fingerprint(capture.path, cal_digest, key)
        report = reusable_report(out, digest)
        if report is not None:
            known.append(kept_outcome(capture.name, report))
            continue
        tasks.append(
            CaptureTask(
                name=capture.name,
                capture=str(capture.path),
                output=str(out),
                calibration=None if calibration is None else str(calibration),
                options=plan.options,
                fingerprint=digest,
                compare=plan.compare,
                formats=plan.formats,
            )
        )
    return tasks, known


def _check_output(plan: BatchPlan) -> None:
    out = plan.output
    if (out / "capture.json").exists() or (out / "calibration.json").exists():
        raise ConfigError(f"{out}: is a capture or calibration directory; choose another output directory")
    if out.exists() and not out.is_dir():
        raise ConfigError(f"{out}: expected an output directory, found a file")
    if plan.calibration is not None and not (plan.calibration / "calibration.json").is_file():
        raise ConfigError(f"{plan.calibration}: no calibration.json (expected a calibration directory)")
    for method in plan.compare:
        from rig.pipeline.corrections import REGISTRY as CORRECTIONS

        if method not in CORRECTIONS:
            raise ConfigError(
                f"--compare: expected corrections from {', '.join(sorted(CORRECTIONS))}, found {method!r}"
            )


def run_batch(plan: BatchPlan, progress: Reporter | None = None) -> BatchResult:
    """Process every capture of the archives on Dask; write outputs, ``index.csv`` (and ``compare.csv``).

    Raises ConfigError for bad arguments (before any work); a bad capture is an ``error`` row.
    """
    started = time.perf_counter()
    _check_output(plan)
    exclude = [plan.output] + ([plan.calibration] if plan.calibration is not None else [])
    found = discover(plan.archives, exclude=exclude)
    plan.output.mkdir(parents=True, exist_ok=True)
    remove_stale(plan.output, [c.name for c in found], (INDEX_FILE, COMPARE_FILE))
    tasks, known = plan_tasks(plan, found)
    outcomes: list[TaskOutcome] = list(known)
    index_path = plan.output / INDEX_FILE
    compare_path = plan.output / COMPARE_FILE if plan.compare else None
    kept = sum(1 for o in known if o.row.status == "ok")
    if progress is not None:
        progress.message(
            f"{len(found)} captures: {len(tasks)} to process, {kept} unchanged since an earlier run, "
            f"{len(known) - kept} skipped",
            found=len(found),
            process=len(tasks),
            kept=kept,
        )
        if not tasks:
            progress.begin(0)
    try:
        if tasks:
            _run_on_dask(plan, tasks, outcomes, index_path, progress)
    finally:
        _write_tables(outcomes, index_path, compare_path, plan.compare)
    return BatchResult(
        rows=sorted((o.row for o in outcomes), key=lambda r: r.capture),
        compare=[r for o in outcomes for r in o.compare],
        index_path=index_path,
        compare_path=compare_path,
        kept=kept,
        seconds=time.perf_counter() - started,
    )


def _write_tables(
    outcomes: list[TaskOutcome], index_path: Path, compare_path: Path | None, methods: tuple[str, ...]
) -> None:
    write_index(index_path, [o.row for o in outcomes])
    if compare_path is not None:
        write_compare(compare_path, [r for o in outcomes for r in o.compare], methods)


def _lost_outcome(task: CaptureTask, exc: BaseException) -> TaskOutcome:
    """A task whose worker died (out of memory, killed) or that Dask gave up on: an error row."""
    message = f"worker lost while processing ({type(exc).__name__}: {exc})"
    row = IndexRow(capture=task.name, status="error", message=message, correction=task.options.correction)
    compare = [CompareRow(capture=task.name, method=m, status="error", message=message) for m in task.compare]
    return TaskOutcome(row=row, compare=compare)


def _run_on_dask(
    plan: BatchPlan, tasks: list[CaptureTask], outcomes: list[TaskOutcome], index_path: Path, progress: Reporter | None
) -> None:
    from distributed import as_completed

    with dask_client(plan) as client:
        if progress is not None:
            link = dashboard_link(client)
            nthreads = client.nthreads()  # one scheduler round trip for both counts
            threads, workers = sum(nthreads.values()), len(nthreads)
            where = plan.scheduler or "a local cluster"
            progress.message(
                f"dask: {workers} worker{'' if workers == 1 else 's'}, {threads} thread{'' if threads == 1 else 's'} on {where}"
                + (f"; dashboard {link}" if link else ""),
                dashboard=link,
                threads=threads,
            )
        client.run(warm_up)
        if progress is not None:
            progress.begin(len(tasks))  # from here on, the rate is that of the work (cluster up, pipeline imported)
        window = max(2 * sum(client.nthreads().values()), 4)  # tasks in flight: workers busy, client memory bounded
        pending = iter(tasks)
        by_key: dict[str, tuple[Any, CaptureTask]] = {}
        running = as_completed(loop=client.loop)

        def submit(task: CaptureTask) -> None:
            future = client.submit(run_task, task, pure=False, key=f"rig-batch-{task.name}-{os.urandom(4).hex()}")
            by_key[future.key] = (future, task)
            running.add(future)

        for task in itertools.islice(pending, window):
            submit(task)
        last_index = time.monotonic()
        try:
            for future in running:
                _, task = by_key.pop(future.key)
                try:
                    outcome = future.result()
                except Exception as exc:  # noqa: BLE001 - KilledWorker and the like: that capture failed
                    outcome = _lost_outcome(task, exc)
                outcomes.append(outcome)
                for nxt in itertools.islice(pending, 1):
                    submit(nxt)
                if time.monotonic() - last_index > INDEX_EVERY_S:
                    write_index(index_path, [o.row for o in outcomes])
                    last_index = time.monotonic()
                if progress is not None:
                    progress.step(f"{task.name} {outcome.row.status}")
        except BaseException:
            client.cancel([f for f, _ in by_key.values()])
            raise
