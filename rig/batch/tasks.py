"""The work of one capture, as a Dask worker runs it: paths in, a small row out.

The task receives paths and options only (the scheduler never holds image data) and runs the same
:func:`rig.api.process` and :func:`rig.store.results.write_result` as ``rig process`` (which
commits the output directory in one rename, through :mod:`rig.store.files`), with the
input fingerprint added to report.json in that same commit. Every error a capture can cause becomes an
``error`` row carrying the line ``rig process`` would print; the batch goes on.
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from rig.batch.index import CompareRow, IndexRow, height_stats
from rig.batch.resume import BATCH_KEY
from rig.errors import USER_ERRORS, os_error_line
from rig.pipeline.plan import ProcessOptions
from rig.store.results import DEFAULT_FORMATS

TRUTH_FILE = "truth-height.npy"  # what rig.hardware.synthesis writes beside a simulated capture
BLAS_THREADS = 1  # per task: the worker's thread count, not BLAS, sets the parallelism


@dataclass(frozen=True)
class CaptureTask:
    """Everything a worker needs for one capture: absolute paths, options, the inputs' fingerprint."""

    name: str
    capture: str
    output: str
    calibration: str | None
    options: ProcessOptions
    fingerprint: str | None
    compare: tuple[str, ...] = ()
    formats: tuple[str, ...] = DEFAULT_FORMATS  # output formats (rig.store.results.FORMATS)


@dataclass
class TaskOutcome:
    """What comes back to the client: the index row and, with ``--compare``, one row per method."""

    row: IndexRow
    compare: list[CompareRow] = field(default_factory=list)


def worker_name() -> str:
    """The Dask worker running this task (its address), or "local" outside a worker."""
    try:
        from distributed import get_worker

        return str(get_worker().address)
    except (ImportError, ValueError):
        return "local"


def error_message(exc: BaseException) -> str:
    """The one line ``rig process`` prints for a user error or an operating-system refusal (after
    ``rig process: error:``); a bug is named as such."""
    if isinstance(exc, USER_ERRORS):
        return str(exc)
    if isinstance(exc, OSError):  # the environment refused (a full disk, permissions): as `rig process` says it
        return os_error_line(exc)
    return f"internal error: {type(exc).__name__}: {exc}"


def truth_height(capture_dir: Path, shape: tuple[int, int]) -> np.ndarray | None:
    """The true heights of a simulated capture (``truth-height.npy`` beside it), if it has them."""
    path = capture_dir.parent / TRUTH_FILE
    if not path.is_file():
        return None
    truth = np.load(path)
    return truth if truth.shape == shape else None


def compare_row(name: str, method: str, result: Any, seconds: float, truth: np.ndarray | None) -> CompareRow:
    """Figures of one correction's result: valid fraction, order breaks left, heights, NMSE_h against truth."""
    from processing.height import nmse
    from processing.phase_correction import order_breaks

    report = result.report
    heights = height_stats(report)
    error = None
    if truth is not None and result.height is not None and np.any(truth[result.mask] != 0):
        error = nmse(result.height, truth, result.mask)
    return CompareRow(
        capture=name,
        method=method,
        status="ok",
        valid_fraction=float(report["valid_fraction"]),
        order_breaks=order_breaks(result.phase, result.mask),
        nmse_h=error,
        seconds=seconds,
        height_min_mm=heights["height_min_mm"],
        height_median_mm=heights["height_median_mm"],
        height_max_mm=heights["height_max_mm"],
    )


def warm_up() -> None:
    """Import the pipeline in a worker before its first capture (a second or so), so that progress rates mean work."""
    import rig.api  # noqa: F401
    import rig.store.results  # noqa: F401  # the pipeline's stages and the result encoders


def _process(task: CaptureTask, options: ProcessOptions) -> Any:
    from rig.api import process

    return process(task.capture, task.calibration, options)


def _compare(task: CaptureTask, main: Any, main_seconds: float) -> list[CompareRow]:
    rows: list[CompareRow] = []
    truth = None
    for method in task.compare:
        t0 = time.perf_counter()
        try:
            if method == task.options.correction and main is not None:
                result, seconds = main, main_seconds
            else:
                result = _process(task, dataclasses.replace(task.options, correction=method))
                seconds = time.perf_counter() - t0
            if truth is None:
                truth = truth_height(Path(task.capture), result.mask.shape)
            rows.append(compare_row(task.name, method, result, seconds, truth))
        except Exception as exc:  # noqa: BLE001 - one method failing must not stop the others
            rows.append(
                CompareRow(
                    capture=task.name,
                    method=method,
                    status="error",
                    message=error_message(exc),
                    seconds=time.perf_counter() - t0,
                )
            )
    return rows


def _single_threaded_worker() -> None:
    """One thread per worker: the cluster runs a worker per core, so OpenCV's thread pool, the
    frame-reading threads and the side-by-side steps of ``auto`` would only oversubscribe the
    cores (BLAS is limited around each task). Only inside a Dask worker process: a task run in
    the caller's process changes nothing."""
    try:
        from distributed import get_worker

        get_worker()
    except (ImportError, ValueError):
        return
    import cv2

    from processing import concurrency
    from rig.store import capture

    cv2.setNumThreads(1)
    capture.LOAD_THREADS = 1
    concurrency.THREADS = 1


def run_task(task: CaptureTask) -> TaskOutcome:
    """Process one capture, commit its outputs and return its rows; never raises for a bad capture."""
    from rig.blas import blas_threads
    from rig.store.results import check_target, write_result

    _single_threaded_worker()
    started = time.perf_counter()
    worker = worker_name()
    row = IndexRow(capture=task.name, status="error", correction=task.options.correction, worker=worker)
    main = None
    main_seconds = 0.0
    with blas_threads(BLAS_THREADS):
        try:
            check_target(task.output, overwrite=True)  # before the work: never replace what rig did not write
            main = _process(task, task.options)
            main_seconds = time.perf_counter() - started
        except Exception as exc:  # noqa: BLE001 - isolate every failure to its capture
            row.message = error_message(exc)
        compare = _compare(task, main, main_seconds) if task.compare else []
        if main is not None:
            try:
                batch = {
                    "fingerprint": task.fingerprint,
                    "worker": worker,
                    "seconds": time.perf_counter() - started,
                    "compare": [dataclasses.asdict(r) for r in compare],
                }
                report = write_result(main, task.output, task.formats, overwrite=True, extra={BATCH_KEY: batch})
                row.status, row.seconds = "ok", recorded_seconds(report)
                row.valid_fraction = float(report["valid_fraction"])
                row.message = "; ".join(report.get("notes", []))
                for key, value in height_stats(report).items():
                    setattr(row, key, value)
            except Exception as exc:  # noqa: BLE001
                row.message = error_message(exc)
    if row.seconds is None:
        row.seconds = time.perf_counter() - started
    return TaskOutcome(row=row, compare=compare)


def recorded_seconds(report: dict[str, Any]) -> float | None:
    """A capture's seconds as report.json records them: processing (compare included) plus writing the files."""
    try:
        return float(report[BATCH_KEY]["seconds"]) + float(report["timings_s"]["outputs"])
    except (KeyError, TypeError, ValueError):
        return None


def kept_outcome(name: str, report: dict[str, Any]) -> TaskOutcome:
    """The rows of an output an earlier run finished with the same inputs (read back from its report)."""
    batch = report[BATCH_KEY]
    row = IndexRow(
        capture=name,
        status="ok",
        message="; ".join(report.get("notes", [])),
        valid_fraction=report.get("valid_fraction"),
        correction=str(report.get("methods", {}).get("correction", "")),
        seconds=recorded_seconds(report),
        worker=str(batch.get("worker", "")),
        **height_stats(report),
    )
    compare = [CompareRow(**{**r, "capture": name}) for r in batch.get("compare", [])]
    return TaskOutcome(row=row, compare=compare)
