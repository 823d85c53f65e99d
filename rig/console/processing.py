"""The console's processing: captures to results on a processing thread, and the results held to show.

Processing (:func:`rig.api.process`) runs on its own thread so the rig is free again at once. A
scan's frames are collected in memory as they arrive (:class:`FrameCollector`) and processed from
there the moment the last one is in, while the capture is still being written: its result first
without fringe-order correction, then with the requested options; the outputs are written
(:func:`rig.api.write_outputs`, which never replaces a result) once the capture is stored, and not
at all if storing it failed. A reprocessed capture is read from disk. The newest results are held
in memory for the page (older ones are read back from DATA/results).
"""

from __future__ import annotations

import logging
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from rig.console.datadir import DataDir
from rig.console.devices import Publish
from rig.console.results import ResultView
from rig.errors import RigError
from rig.events import Reporter
from rig.jobs import Job, Jobs
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions

log = logging.getLogger(__name__)

RESULTS_KEPT = 8  # results held in memory (older ones are read back from disk)
STORED_WAIT_S = 120.0  # how long finished processing waits for its capture to be stored


class FrameCollector:
    """A scan's frames held in memory as they arrive, in pattern order (a :class:`rig.api.FrameStack` at the end).

    ``patterns``: the scan's capture-format pattern entries; ``projector_size``: (width, height);
    ``bit_depth``: the camera's; ``name``: the capture's path (what report.json records).
    """

    def __init__(
        self, patterns: list[dict[str, Any]], projector_size: tuple[int, int], bit_depth: int, name: str
    ) -> None:
        self.patterns = patterns
        self.projector_size = projector_size
        self.bit_depth = bit_depth
        self.name = name
        self._frames: np.ndarray | None = None
        self._count = 0

    def add(self, index: int, image: np.ndarray) -> bool:
        """Hold frame ``index`` (a copy); True when it completes the stack."""
        if self._frames is None:
            self._frames = np.empty((len(self.patterns), *image.shape), dtype=image.dtype)
        self._frames[index] = image
        self._count += 1
        return self._count == len(self.patterns)

    def stack(self) -> Any:
        """The complete stack as a :class:`rig.api.FrameStack`."""
        from rig.api import FrameStack

        if self._frames is None or self._count != len(self.patterns):
            raise RigError(f"{self.name}: {self._count} of {len(self.patterns)} frames held; expected all")
        return FrameStack(self._frames, self.patterns, self.projector_size, self.bit_depth, name=self.name)


class Processing:
    """The processing thread of one console and the results it made; see the module docstring.

    ``calibration`` gives the directory of the calibration chosen now (None: phase only), read
    when a run starts; ``on_change`` is called when a run ends (the console publishes its status).
    """

    def __init__(
        self,
        data: DataDir,
        jobs: Jobs,
        publish: Publish,
        calibration: Callable[[], Path | None],
        on_change: Callable[[], None],
    ) -> None:
        self.data = data
        self.jobs = jobs
        self.publish = publish
        self.calibration = calibration
        self.on_change = on_change
        self.results: OrderedDict[str, ResultView] = OrderedDict()
        self.latest: dict[str, Any] | None = None  # the newest result shown: name, job, final
        self._lock = threading.Lock()
        self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="console-process")
        self._scans_in_flight = 0  # scans' runs queued or running (the live view pauses for them)

    @property
    def scan_in_flight(self) -> bool:
        """Whether a scan's frames are being processed (or wait to be): the operator waits for that result."""
        return self._scans_in_flight > 0

    def close(self) -> None:
        """Finish the run in progress and drop the queued ones."""
        self._thread.shutdown(wait=True, cancel_futures=True)

    def queue(
        self,
        job: Job,
        capture: Any,
        name: str,
        options: ProcessOptions | None,
        quick_first: bool,
        salvage: bool = False,
        stored: Future[None] | None = None,
    ) -> None:
        """Hand ``job`` to the processing thread; if it is gone (shutting down), the job fails there and then.

        ``capture``: a capture directory, or a scan's frames in memory (:meth:`FrameCollector.stack`)
        with ``stored``, the future of that capture being written (outputs wait for it).
        """
        scan = stored is not None
        try:
            with self._lock:
                self._scans_in_flight += scan
            self._thread.submit(self._process, job, capture, name, options, quick_first, salvage, stored)
        except RuntimeError as exc:
            self._done(scan)
            self.jobs.finish(job, RigError(f"not processed: {exc}"))

    def _done(self, scan: bool) -> None:
        with self._lock:
            self._scans_in_flight -= scan

    def _process(
        self,
        job: Job,
        capture: Any,
        name: str,
        options: ProcessOptions | None,
        quick_first: bool,
        salvage: bool,
        stored: Future[None] | None,
    ) -> None:
        """Processing thread: the capture to a result on screen (a quick one first), then its files.

        Through :func:`rig.api.process`, the processing entry of every front-end; the result store
        refuses to replace an existing result (:class:`rig.errors.ResultExistsError`, HTTP 409).
        """
        from rig import api

        options = options or ProcessOptions(correction=DEFAULT_CORRECTION)
        reporter = Reporter(f"process {name}", sink=self.jobs.sink(job, "process"), cancel=job.token)

        def show_quick(first: Any) -> None:
            self._show(ResultView.from_result(name, first), job, final=False)

        def run() -> None:
            quick = show_quick if quick_first else None
            result = api.process(capture, self.calibration(), options, reporter, salvage=salvage, quick=quick)
            view = ResultView.from_result(name, result)
            self._show(view, job, final=True)
            if stored is not None:
                stored.result(timeout=STORED_WAIT_S)  # a capture that failed to be stored gets no result files
            api.write_outputs(result, self.data.path("results", name))
            view.saved = True
            self.jobs.update(job, result=name)
            self.publish({"type": "saved", "name": name, "job": job.id}, None)

        try:
            self.jobs.run(job, run)
        finally:
            self._done(stored is not None)
        self.on_change()

    def warm(self, options: ProcessOptions) -> None:
        """Process the chosen calibration's reference plane now, on the processing thread, with both
        passes of a scan (into the reference cache): the first scan after choosing a calibration is
        then as quick as the next ones."""
        try:
            self._thread.submit(self._warm, options)
        except RuntimeError:  # shutting down
            pass

    def _warm(self, options: ProcessOptions) -> None:
        from rig import api

        try:
            calibration = self.calibration()
            if calibration is None:
                return
            reference = api.load_calibration(calibration).reference
            if reference is None:
                return  # a model without a reference plane: nothing to prepare
            api.process(calibration / reference, calibration, options, quick=lambda _: None)
        except (RigError, OSError, ValueError) as exc:  # said again, as a failed job, when a scan uses it
            log.info("console: reference plane not prepared: %s", exc)

    def _keep(self, view: ResultView) -> None:
        """Hold ``view`` in memory as the newest result, dropping the oldest beyond RESULTS_KEPT."""
        with self._lock:
            self.results[view.name] = view
            self.results.move_to_end(view.name)
            while len(self.results) > RESULTS_KEPT:
                self.results.popitem(last=False)

    def _show(self, view: ResultView, job: Job, final: bool) -> None:
        self._keep(view)
        self.latest = {"name": view.name, "job": job.id, "final": final}
        last_frame = (self.jobs.get(job.id) or {}).get("last_frame")
        since = time.time() - last_frame if last_frame else None
        self.publish(
            {
                "type": "result",
                "name": view.name,
                "job": job.id,
                "client": job.client,
                "final": final,
                "since_last_frame_s": since,
                "summary": view.summary(),
            },
            None,
        )

    def result(self, name: str) -> ResultView:
        """A result by name: in memory, or read back from DATA/results/NAME."""
        with self._lock:
            view = self.results.get(name)
        if view is not None:
            return view
        path = self.data.existing("results", name)
        view = ResultView.from_directory(name, path)
        self._keep(view)
        return view
