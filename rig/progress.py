"""A small progress bar on stderr for long commands.

On a terminal it redraws one line (``label [#####.....] 3/6 unwrap``); when stderr is not a
terminal (logs, CI, pipes) it prints only a start line and an end line with the elapsed time,
so captured output stays short. ``quiet=True`` silences it entirely. A command that fails before
its first step (bad input) prints nothing here: its one error line stands alone.

>>> with Progress("process", total=4) as progress:
...     progress.step("load")
"""

from __future__ import annotations

import sys
import time
from typing import Any, Literal, TextIO

BAR_WIDTH = 24


class Progress:
    """Progress of ``total`` steps of one command; use as a context manager."""

    def __init__(
        self, label: str, total: int, stream: TextIO | None = None, quiet: bool = False, tty: bool | None = None
    ) -> None:
        self.label = label
        self.total = max(int(total), 1)
        self.stream = sys.stderr if stream is None else stream
        self.quiet = quiet
        isatty = getattr(self.stream, "isatty", None)
        self.tty = bool(isatty and isatty()) if tty is None else tty
        self.done = 0
        self.started = 0.0
        self._width = 0
        self._announced = False

    def __enter__(self) -> Progress:
        self.started = time.perf_counter()
        self._draw("")
        return self

    def begin(self, total: int, note: str = "") -> None:
        """Services announce their steps; the bar keeps the larger count (a command may run several)."""
        self.total = max(self.total, int(total), 1)

    def step(self, note: str = "", count: int = 1) -> None:
        """Mark ``count`` steps done; ``note`` names what comes next (or what was done)."""
        if not self._announced and not self.quiet and not self.tty:
            self._print(f"{self.label}: started ({self.total} steps)\n")
        self._announced = True
        self.done = min(self.done + count, self.total)
        self._draw(note)

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> Literal[False]:
        elapsed = time.perf_counter() - self.started
        if self.quiet:
            return False
        if self.tty:
            self._print("\r" + " " * self._width + "\r")
        failed_before_work = exc_type is not None and exc_type is not KeyboardInterrupt and not self._announced
        if failed_before_work:
            return False
        outcome = "done" if exc_type is None else ("interrupted" if exc_type is KeyboardInterrupt else "failed")
        self._print(f"{self.label}: {outcome} in {elapsed:.1f} s\n")
        return False

    def say(self, text: str) -> None:
        """A line for the operator (a service's message) between redraws of the bar."""
        if self.quiet:
            return
        if self.tty:
            self._print("\r" + " " * self._width + "\r")
            self._width = 0
        self._print(text + "\n")

    def reporter(self, cancel: Any = None) -> Any:
        """A :class:`rig.events.Reporter` drawing its steps on this bar and printing its messages."""
        from rig.events import Event, Reporter

        def sink(event: Event) -> None:
            if event.kind == "begin":
                self.begin(event.total)
            elif event.kind == "step":
                self.step(event.note)
            else:
                self.say(event.note)

        return Reporter(self.label, sink, cancel)

    def _draw(self, note: str) -> None:
        if self.quiet or not self.tty:
            return
        filled = BAR_WIDTH * self.done // self.total
        line = f"{self.label} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] {self.done}/{self.total} {note}"
        pad = max(self._width - len(line), 0)
        self._width = len(line)
        self._print("\r" + line + " " * pad)

    def _print(self, text: str) -> None:
        self.stream.write(text)
        self.stream.flush()
