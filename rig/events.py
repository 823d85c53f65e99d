"""Progress events and cancellation: how a service talks to whichever front-end called it.

A service (scan, process, calibrate, batch) never prints. It takes a :class:`Reporter` and calls
``reporter.begin(total)`` once it knows how much work there is, ``reporter.step(note)`` after each
unit of work and ``reporter.message(text)`` for what the operator should read. Each call becomes an
:class:`Event` handed to the reporter's sink — the CLI draws a progress bar from them
(:class:`rig.progress.Progress`), the console pushes them over a websocket, a batch task logs them.

Cancellation rides on the same object: a front-end keeps the :class:`CancelToken` it gave the
reporter and calls ``token.cancel()`` (a Stop button, a closed page). The next ``step`` (or an
explicit ``reporter.check()``) raises :class:`Cancelled` inside the service, which unwinds through
the same clean-up paths as any error: devices closed, nothing left that claims to be complete.

>>> seen = []
>>> reporter = Reporter("scan", sink=seen.append)
>>> reporter.begin(2); reporter.step("frame 1"); reporter.step("frame 2")
>>> [e.kind for e in seen], seen[-1].done
(['begin', 'step', 'step'], 2)
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Literal, Protocol

from rig.errors import RigError

EventKind = Literal["begin", "step", "message"]


class Cancelled(RigError):
    """The task was stopped on request (Stop button, Ctrl-C, a closed page)."""


@dataclass(frozen=True)
class Event:
    """One thing a service reports: progress ``done``/``total`` of ``task``, or a message."""

    task: str
    kind: EventKind
    done: int
    total: int
    note: str = ""
    time: float = field(default_factory=time.time)
    data: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (the console sends these over its websocket)."""
        return {
            "task": self.task,
            "kind": self.kind,
            "done": self.done,
            "total": self.total,
            "note": self.note,
            "time": self.time,
            "data": self.data,
        }


EventSink = Callable[[Event], None]


class CancelToken:
    """A thread-safe flag a front-end sets to stop a running service."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.reason = ""

    def cancel(self, reason: str = "stopped on request") -> None:
        """Ask the task to stop at its next step."""
        self.reason = reason
        self._event.set()

    @property
    def cancelled(self) -> bool:
        return self._event.is_set()

    def check(self, task: str = "task") -> None:
        """Raise :class:`Cancelled` if :meth:`cancel` was called."""
        if self._event.is_set():
            raise Cancelled(f"{task}: {self.reason}")


class ProgressSink(Protocol):
    """The part of a reporter a service calls (the CLI's bar and :class:`Reporter` both fit)."""

    def begin(self, total: int, note: str = "") -> None: ...

    def step(self, note: str = "", count: int = 1) -> None: ...


class Reporter:
    """Turns a service's progress calls into :class:`Event` objects and checks for cancellation.

    Parameters
    ----------
    task : str
        What the events are about ("scan part-001", "process part-001").
    sink : callable, optional
        Receives every event; None drops them (a notebook that wants no output).
    cancel : CancelToken, optional
        Checked on every step; None means the task cannot be stopped except by an exception.
    total : int
        Steps expected, if known up front; services call :meth:`begin` when they know it.
    """

    def __init__(
        self, task: str, sink: EventSink | None = None, cancel: CancelToken | None = None, total: int = 0
    ) -> None:
        self.task = task
        self.sink = sink
        self.cancel = cancel if cancel is not None else CancelToken()
        self.total = int(total)
        self.done = 0

    def _emit(self, kind: EventKind, note: str, data: dict[str, Any] | None = None) -> None:
        if self.sink is not None:
            self.sink(Event(self.task, kind, self.done, self.total, note, data=data or {}))

    def begin(self, total: int, note: str = "") -> None:
        """Announce ``total`` steps of work (may be called again when a sub-task adds steps)."""
        self.check()
        self.total = max(int(total), 0)
        self._emit("begin", note)

    def step(self, note: str = "", count: int = 1) -> None:
        """Mark ``count`` steps done (``note`` says which); raises :class:`Cancelled` if stopped."""
        self.done = self.done + count if not self.total else min(self.done + count, self.total)
        self._emit("step", note)
        self.check()

    def message(self, text: str, **data: Any) -> None:
        """Something for the operator to read (a prompt, a warning, a result figure)."""
        self._emit("message", text, data)

    def check(self) -> None:
        """Raise :class:`Cancelled` if the task was asked to stop."""
        self.cancel.check(self.task)
