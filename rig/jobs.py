"""The jobs service: scans, processing runs and calibrations that run on the server, whoever watches.

A front-end (the console) starts work through :meth:`Jobs.start`, hands the job's
:class:`rig.events.Reporter` sink (:meth:`Jobs.sink`) to the service it calls, and ends the job
with :meth:`Jobs.run`, which guarantees a final state (done, failed or cancelled) whatever the
work raises — a MemoryError as much as a :class:`rig.errors.RigError`. Jobs belong to the server,
not to the page that started them: a closed or reloaded page stops nothing.

Every change is made under one lock, and every reader gets copies taken under it, so an event-loop
thread can start and list jobs while worker threads update them. Each change is published as a
message (``{"type": "job" | "progress", ...}``) through the ``publish`` callable given, from the
thread that made it; progress messages carry the ``kind`` of what they measure: ``scan`` (frames
stored), ``process`` (processing stages), ``calibrate`` (calibration steps) or ``verify``
(verification frames, then one step per artefact position).
"""

from __future__ import annotations

import itertools
import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field, fields
from typing import Any

from rig.errors import RigError
from rig.events import Cancelled, CancelToken, Event, EventSink

log = logging.getLogger(__name__)

JOBS_KEPT = 50  # finished jobs remembered for /api/jobs/ID (running ones are never dropped)
PROGRESS_KINDS = ("scan", "process", "calibrate", "verify")
FINAL_STATES = ("done", "failed", "cancelled")


@dataclass
class Job:
    """A scan, processing run or calibration; mutated only by :class:`Jobs` under its lock."""

    id: str
    kind: str
    name: str
    client: str | None = None
    state: str = "running"  # running | done | failed | cancelled
    stage: str = ""
    progress_kind: str = ""  # what done/total count: scan, process, calibrate, verify (:data:`PROGRESS_KINDS`)
    done: int = 0
    total: int = 0
    error: str | None = None
    result: str | None = None
    started: float = field(default_factory=time.time)
    finished: float | None = None
    last_frame: float | None = None  # when a scan's last frame was stored (time.time)
    token: CancelToken = field(default_factory=CancelToken, repr=False, compare=False)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready copy (without the cancel token)."""
        return {f.name: getattr(self, f.name) for f in fields(self) if f.name != "token"}


class Jobs:
    """Thread-safe registry of jobs; see the module docstring.

    Parameters
    ----------
    publish : callable(message)
        Receives every job change and progress event (any thread).
    keep : int
        Finished jobs remembered; the oldest finished ones are forgotten beyond it.
    """

    def __init__(self, publish: Callable[[dict[str, Any]], None], keep: int = JOBS_KEPT) -> None:
        self._publish = publish
        self._keep = keep
        self._lock = threading.Lock()
        self._jobs: OrderedDict[str, Job] = OrderedDict()
        self._ids = itertools.count(1)

    # ------------------------------------------------------------------ reading (copies)
    def get(self, job_id: str) -> dict[str, Any] | None:
        """Job ``job_id`` as a dict, or None if unknown."""
        with self._lock:
            job = self._jobs.get(job_id)
            return job.as_dict() if job is not None else None

    def running(self) -> list[dict[str, Any]]:
        """Every running job, oldest first."""
        with self._lock:
            return [job.as_dict() for job in self._jobs.values() if job.state == "running"]

    def all(self) -> list[dict[str, Any]]:
        """Every remembered job, oldest first."""
        with self._lock:
            return [job.as_dict() for job in self._jobs.values()]

    # ------------------------------------------------------------------ changing
    def start(self, kind: str, name: str, client: str | None = None) -> Job:
        """Register a running job and publish it."""
        with self._lock:
            job = Job(id=f"{kind}-{next(self._ids)}", kind=kind, name=name, client=client)
            self._jobs[job.id] = job
            self._forget_finished()
            message = {"type": "job", "job": job.as_dict()}
        self._publish(message)
        return job

    def _forget_finished(self) -> None:
        excess = len(self._jobs) - self._keep
        for job_id in [i for i, j in self._jobs.items() if j.state != "running"][: max(0, excess)]:
            del self._jobs[job_id]

    def update(self, job: Job, **fields: Any) -> None:
        """Set ``fields`` of ``job`` (stage, result, ...) and publish the job."""
        with self._lock:
            for key, value in fields.items():
                setattr(job, key, value)
            message = {"type": "job", "job": job.as_dict()}
        self._publish(message)

    def sink(self, job: Job, kind: str) -> EventSink:
        """A Reporter sink recording ``kind`` progress (scan, process, calibrate, verify) on ``job``."""
        if kind not in PROGRESS_KINDS:
            raise ValueError(f"progress kind: expected one of {', '.join(PROGRESS_KINDS)}, found {kind!r}")

        def sink(event: Event) -> None:
            with self._lock:
                job.stage, job.progress_kind, job.done, job.total = event.task, kind, event.done, event.total
                if kind == "scan" and event.kind == "step" and event.total and event.done >= event.total:
                    job.last_frame = job.last_frame or time.time()
            self._publish({"type": "progress", "job": job.id, "kind": kind, "event": event.as_dict()})

        return sink

    def finish(self, job: Job, error: BaseException | None = None) -> None:
        """End ``job``: done (no error), cancelled (:class:`Cancelled`) or failed (anything else)."""
        with self._lock:
            if job.state in FINAL_STATES:
                return
            job.finished = time.time()
            if error is None:
                job.state = "done"
            elif isinstance(error, Cancelled):
                job.state, job.error = "cancelled", str(error)
            else:
                job.state, job.error = "failed", _describe(error)
            message = {"type": "job", "job": job.as_dict()}
        if job.state == "failed":
            text = f"{job.kind} {job.name}: {job.error}"
            self._publish({"type": "error", "source": job.kind, "job": job.id, "message": text})
        self._publish(message)

    def run(
        self,
        job: Job,
        work: Callable[[], Any],
        then_finish: bool = True,
        before_end: Callable[[], None] | None = None,
    ) -> BaseException | None:
        """Run ``work()``; any exception ends the job (failed or cancelled) and is returned, never raised.

        With ``then_finish`` the job is marked done when ``work`` returns; without it (a scan whose
        processing follows) it stays running unless ``work`` raised. ``before_end`` runs after ``work``
        whatever happened and before the job's end is published, so that what it frees (the
        acquisition slot) is free by the time anyone hears the job ended.
        """
        try:
            try:
                work()
            finally:
                if before_end is not None:
                    before_end()
        except BaseException as exc:  # noqa: BLE001 - every job must end, whatever stopped it
            if not isinstance(exc, (RigError, OSError, ValueError)):
                log.exception("job %s (%s %s) failed", job.id, job.kind, job.name)
            self.finish(job, exc)
            if isinstance(exc, (KeyboardInterrupt, SystemExit)):
                raise
            return exc
        if then_finish:
            self.finish(job)
        return None

    def stop(self, job_id: str | None = None, reason: str = "stopped from the console") -> list[str]:
        """Cancel ``job_id`` (default: every running job); the ids asked to stop."""
        with self._lock:
            chosen = [j for j in self._jobs.values() if j.state == "running" and job_id in (None, j.id)]
        if job_id is not None and not chosen:
            raise RigError(f"job {job_id!r}: not running")
        for job in chosen:
            job.token.cancel(reason)
        return [job.id for job in chosen]


def _describe(error: BaseException) -> str:
    """One line for a failed job: the message, or the exception's kind when it has none."""
    if isinstance(error, MemoryError):
        return "out of memory" + (f": {error}" if str(error) else "")
    return str(error) or type(error).__name__
