"""The console session: what the page asks for, as jobs on the rig the console holds.

- The devices are held by :class:`rig.console.devices.RigHolder` (one worker thread makes every
  device call), the live view is :class:`rig.console.live_view.LiveView` (frames between tasks
  while a page watches) or, when switched on, :class:`rig.console.live_3d.Live3D` (short scans
  processed as they come), processing and the results on screen are
  :class:`rig.console.processing.Processing` (its own thread, so the rig is free again at once).
- One acquisition at a time: a scan, calibration or verification while another runs is refused
  with :class:`Busy`. A scan goes through :func:`rig.acquisition.scan.scan_with` with the held
  devices; its frames go to processing from memory as they arrive.
- Scans, processing runs, calibrations and verifications are jobs of :class:`rig.jobs.Jobs` (thread-safe; every
  job ends done, failed or cancelled, whatever it raises). Their progress comes from the services'
  :class:`rig.events.Reporter` events, published through ``publish`` with the kind of what they
  count (scan: frames, process: stages, calibrate: steps, verify: frames then positions); each job has a
  :class:`rig.events.CancelToken` (Stop button, shutdown). A page that closes stops nothing: jobs
  belong to the console, and a page that opens is shown the running ones and the newest result.
"""

from __future__ import annotations

import logging
import math
import threading
from collections.abc import Callable
from concurrent.futures import Future
from pathlib import Path
from typing import Any

import numpy as np

from drivers.errors import DeviceError
from rig.config import PATTERN_SETS, RigConfig
from rig.console import scan_setup
from rig.console.datadir import DataDir
from rig.console.devices import ProjectorSetting, Publish, RigHolder
from rig.console.live_3d import Live3D
from rig.console.live_view import LIVE_FPS, LiveView
from rig.console.processing import FrameCollector, Processing
from rig.console.results import ResultView
from rig.errors import RigError
from rig.events import Cancelled, Reporter
from rig.jobs import Job, Jobs
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions
from rig.store.exposures import with_exposures
from rig.store.files import INCOMPLETE_MARK

log = logging.getLogger(__name__)

GAMMA_LEVELS_MAX = 256  # projector gamma ramp levels (an 8-bit projector has no more)
BOARD_VIEWS_MAX = 100
HEIGHTS_MAX = 50


class Busy(RigError):
    """The rig is already acquiring; the request would start a second acquisition."""


class Conflict(RigError):
    """The name a request gives is taken: nothing is replaced without being asked."""


class ConsoleSession:
    """Owns the rig of ``config`` for one console; see the module docstring.

    Parameters
    ----------
    config : RigConfig
    data : DataDir
    publish : callable(message, image_bytes_or_None)
        Called from any thread with every status change, progress event, result and live frame.
    fault_injection : bool
        Allow :meth:`inject_fault` (simulated rig only): tests and fault drills.
    live_fps : float
        Highest live frame rate (the rest of the time is left to the machine's other work).
    """

    def __init__(
        self,
        config: RigConfig,
        data: DataDir,
        publish: Publish,
        fault_injection: bool = False,
        live_fps: float = LIVE_FPS,
    ) -> None:
        self.config = config
        self.data = data
        self.publish = publish
        self.fault_injection = fault_injection
        self.calibration: str | None = None
        calibrations = data.names("calibrations")
        if calibrations:
            self.calibration = calibrations[0]
        self.jobs = Jobs(lambda message: publish(message, None))
        self.rig = RigHolder(config, publish, self._publish_status)
        self.processing = Processing(data, self.jobs, publish, self._calibration_dir, self._publish_status)
        self.live = LiveView(self.rig, publish, live_fps, paused=lambda: self.processing.scan_in_flight)
        self.live_3d = Live3D(
            self.rig, publish, lambda: self.live.watching, self._calibration_dir, paused=self.live.paused
        )
        self.rig.feeds = [self.live_3d, self.live]
        self.current: Job | None = None  # the acquisition running
        self._acquiring = threading.Lock()
        self._answer: threading.Event | None = None
        self.prompt: dict[str, str] | None = None  # the calibration prompt waiting for the operator
        self.setup, self.setup_note = scan_setup.load(data.root)  # remembered per data folder

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Start the rig's worker thread and open the rig on it (an opening error is shown, not raised);
        prepare the calibration's reference plane meanwhile."""
        self.processing.warm(ProcessOptions(correction=DEFAULT_CORRECTION))
        self.rig.start()

    def close(self) -> None:
        """Stop every job, close the devices, stop the threads (Ctrl-C, app shutdown)."""
        self.jobs.stop(reason="the console is shutting down")
        self.live_3d.on = False
        self.rig.close()
        self.processing.close()
        self.live_3d.close()

    # ------------------------------------------------------------------ what the rig holds
    @property
    def exposure_us(self) -> float:
        return self.rig.exposure_us

    @property
    def gain(self) -> float | None:
        return self.rig.gain

    @property
    def projector(self) -> ProjectorSetting:
        return self.rig.projector

    @property
    def device_error(self) -> str | None:
        return self.rig.device_error

    def devices(self) -> list[dict[str, Any]]:
        """Each device's backend, name, state and details."""
        return self.rig.describe()

    def watch(self, delta: int) -> None:
        """A page starts (+1) or stops (-1) watching the live view."""
        self.live.watch(delta)

    # ------------------------------------------------------------------ settings
    def _refuse_while_acquiring(self, what: str) -> None:
        if self.current is not None:
            raise Busy(f"busy: {what} cannot change while {self.current.kind} {self.current.name} runs")

    def set_exposure(self, exposure_us: float | None = None, gain: float | None = None) -> dict[str, Any]:
        """Camera exposure (us) and gain for the live view and the next scans."""
        self._refuse_while_acquiring("the exposure")
        reply = self.rig.set_exposure(exposure_us, gain)
        self._publish_status()
        return reply

    def set_projector(self, setting: ProjectorSetting) -> dict[str, Any]:
        """Show a pattern between scans (alignment, exposure checks, the live modulation map)."""
        self._refuse_while_acquiring("the projector pattern")
        reply = self.rig.set_projector(setting)
        self._publish_status()
        return reply

    def set_scan_setup(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change the scan setup (checked, remembered in the data folder); every page sees it."""
        setup = scan_setup.checked(self.setup, changes)
        scan_setup.save(self.data.root, setup)
        self.setup, self.setup_note = setup, None
        self._publish_status()
        return self.describe_setup()

    def describe_setup(self) -> dict[str, Any]:
        """The scan setup as the page shows it, with the rig config's values for empty fields."""
        scan = self.setup.config(self.config).scan
        return {
            **self.setup.to_dict(),
            "pattern_sets": list(PATTERN_SETS),
            "used": {
                "frequencies": list(scan.frequencies),
                "steps": scan.steps,
                "frames": len(scan.patterns()) * max(len(scan.exposures_us), 1),
            },
            "exposure_limits_us": self.rig.exposure_limits_us(),
            "note": self.setup_note,
        }

    def suggest_exposures(self) -> dict[str, Any]:
        """The exposure assistant's plan for what is in front of the rig now (a short pre-capture).

        An acquisition: :class:`Busy` while another runs. The plan is shown, not applied: the page
        puts its exposures in the setup when the operator takes them.
        """
        from rig.acquisition.exposure_plan import plan_exposures

        self._acquisition_slot()
        try:

            def run() -> dict[str, Any]:
                devices = self.rig.open()
                devices.camera.stop()  # the live view's acquisition
                try:
                    return plan_exposures(devices, default_us=self.rig.exposure_us).to_dict()
                finally:
                    self.rig.restore_projector()

            return self.rig.call(run)
        finally:
            self._acquiring.release()

    def set_live(self, overlay: bool | None = None, view: str | None = None) -> dict[str, Any]:
        return self.live.set(overlay, view)

    def set_live_3d(self, on: bool) -> dict[str, Any]:
        """Continuous scanning with the short pattern set, processed and shown as it comes (or not)."""
        reply = self.live_3d.set(on)
        self._publish_status()
        return reply

    def set_calibration(self, name: str | None) -> str | None:
        """The calibration scans are processed with (a name in DATA/calibrations, or None: phase only)."""
        if name is not None:
            self.data.existing("calibrations", name)
        self.calibration = name
        self.processing.warm(ProcessOptions(correction=DEFAULT_CORRECTION))
        self._publish_status()
        return name

    def _calibration_dir(self) -> Path | None:
        return self.data.existing("calibrations", self.calibration) if self.calibration else None

    def inject_fault(self, fault: str) -> None:
        """Reopen the simulated rig with a named device fault (only with ``fault_injection``)."""
        if not self.fault_injection:
            raise RigError("fault injection is not enabled for this console")
        self._refuse_while_acquiring("the rig")
        self.rig.inject_fault(fault)

    # ------------------------------------------------------------------ jobs
    def _acquisition_slot(self) -> None:
        """Take the one acquisition slot, or raise :class:`Busy` naming what holds it."""
        if not self._acquiring.acquire(blocking=False):
            running = self.current
            what = f"{running.kind} {running.name}" if running else "an acquisition"
            raise Busy(f"busy: {what} is running; one acquisition at a time")

    def _new_entry(self, kind: str, name: str | None, prefix: str) -> tuple[str, Path]:
        """A free name and path in DATA/kind (``prefix-<time>`` by default); a taken name is refused."""
        name = name or self.data.new_name(kind, prefix)
        path = self.data.path(kind, name)
        if path.exists() or self.data.staged(kind, name):
            raise Conflict(f"{kind}/{name}: already exists; choose another name")
        return name, path

    def _start_acquisition(
        self,
        kind: str,
        folder: str,
        name: str | None,
        prefix: str,
        client: str | None,
        work: Callable[[Job, Path], None],
    ) -> Job:
        """Take the acquisition slot and queue ``work(job, DATA/folder/NAME)`` on the rig's worker thread
        (a scan, a calibration, a verification); ``work`` ends with :meth:`_end_acquisition`."""
        self._acquisition_slot()
        try:
            name, path = self._new_entry(folder, name, prefix)
            job = self.jobs.start(kind, name, client)
            self.current = job
            self.rig.submit(lambda: work(job, path))
        except BaseException:
            self._acquiring.release()
            raise
        self._publish_status()
        return job

    def _end_acquisition(self) -> None:
        """Free the acquisition slot and say so (the last step of every acquisition, whatever happened),
        before the job's end is published: a page that hears "stopped" may scan again at once."""
        self.current = None
        self._acquiring.release()
        self._publish_status()

    def scan(
        self,
        name: str | None = None,
        process: bool = True,
        options: ProcessOptions | None = None,
        client: str | None = None,
    ) -> Job:
        """Start a scan of what is in front of the rig into DATA/captures/NAME (then process it).

        :class:`Busy` if an acquisition runs; the job runs to its end whatever the pages do.
        """
        setup = self.setup
        return self._start_acquisition(
            "scan",
            "captures",
            name,
            setup.capture_prefix(),
            client,
            lambda job, path: self._scan(job, path, process, options, setup),
        )

    def _scan(
        self, job: Job, path: Path, process: bool, options: ProcessOptions | None, setup: scan_setup.ScanSetup
    ) -> None:
        """Worker thread: the acquisition itself; with ``process``, its frames go to processing from
        memory as soon as the last one arrives, while the capture is still being written."""
        from rig.acquisition.scan import scan_with

        stored: Future[None] = Future()

        def acquire() -> None:
            devices = self.rig.open()
            devices.camera.stop()  # the live view's software-trigger acquisition
            scan = setup.config(self.config).scan
            base = scan.patterns()
            patterns = with_exposures(base, scan.exposures_us)  # each exposure's full sequence in turn
            reporter = Reporter(f"scan {job.name}", sink=self.jobs.sink(job, "scan"), cancel=job.token)
            reporter.begin(len(patterns), f"scan {job.name}")
            projector = (devices.projector.width, devices.projector.height)
            held = FrameCollector(patterns, projector, devices.camera.pixel_format.bit_depth, str(path))

            def on_frame(index: int, image: np.ndarray) -> None:
                if held.add(index, image) and process:
                    self.jobs.update(job, stage="processing", result=job.name)
                    self.processing.queue(job, held.stack(), job.name, options, True, stored=stored)

            scan_with(
                devices, path, base, progress=reporter, exposure_us=self.rig.exposure_us, gain=self.rig.gain,
                on_frame=on_frame, exposures=scan.exposures_us or None, extra=setup.capture_extra(),
            )  # fmt: skip

        error = self.jobs.run(job, acquire, then_finish=not process, before_end=self._end_acquisition)
        if error is not None:
            stored.set_exception(error)
            if not isinstance(error, Cancelled) and self.rig.devices is not None and _is_device_fault(error):
                self.rig.device_failed(error, f"scan {job.name}")
        else:
            stored.set_result(None)
            self.rig.restore_projector()
            if not process:
                self.jobs.update(job, result=job.name)
        self._publish_status()

    def calibrate(
        self,
        name: str | None = None,
        heights_mm: tuple[float, ...] = (25.0, 50.0, 100.0, 150.0),
        board_views: int = 6,
        client: str | None = None,
        model: str = "reference-plane",
        gamma_levels: int = 0,
    ) -> Job:
        """Run the calibration session into DATA/calibrations/NAME (an acquisition: :class:`Busy` if one runs).

        The same steps, prompts and options as ``rig calibrate``: ``model`` (reference-plane,
        polynomial; stereo on a real rig only) and ``gamma_levels`` (a projector gamma ramp of that
        many flat levels first, 0: none; at most :data:`GAMMA_LEVELS_MAX`, checked before anything
        is allocated). Prompts reach the page as ``prompt`` messages and wait for :meth:`answer`;
        the simulated rig sets up each step by itself.
        """
        plan = self._calibration_plan(heights_mm, board_views, model, gamma_levels)
        return self._start_acquisition(
            "calibrate", "calibrations", name, "cal", client, lambda job, path: self._calibrate(job, path, plan)
        )

    def _run_session(self, job: Job, run: Callable[[], None]) -> None:
        """Worker thread: a session that opens the rig itself, so the console's rig is closed meanwhile."""
        self.rig.close_rig()
        self.jobs.run(job, run, before_end=self._end_acquisition)
        self._publish_status()

    def _calibration_plan(self, heights_mm: tuple[float, ...], board_views: int, model: str, gamma_levels: int) -> Any:
        """The checked plan of a console calibration (bounds first: nothing sized by a request before)."""
        from rig.calibrate.session import MODELS, STEREO, CalibrationPlan
        from rig.hardware.simulated import STEREO_REFUSAL

        if model not in MODELS:
            raise RigError(f"model: expected one of {', '.join(MODELS)}, found {model!r}")
        if model == STEREO and self.config.simulated:
            raise RigError(STEREO_REFUSAL)
        if gamma_levels != 0 and not 5 <= gamma_levels <= GAMMA_LEVELS_MAX:
            raise RigError(
                f"gamma_levels: expected 0 (no gamma ramp) or 5 .. {GAMMA_LEVELS_MAX} levels, found {gamma_levels}"
            )
        if not 0 <= board_views <= BOARD_VIEWS_MAX:
            raise RigError(f"board_views: expected 0 .. {BOARD_VIEWS_MAX} tilted views, found {board_views}")
        if not 1 <= len(heights_mm) <= HEIGHTS_MAX or not all(math.isfinite(h) for h in heights_mm):
            raise RigError(f"heights_mm: expected 1 .. {HEIGHTS_MAX} finite plane heights, found {list(heights_mm)}")
        plan = CalibrationPlan(
            heights_mm=tuple(float(h) for h in heights_mm),
            board_views=int(board_views),
            model=model,
            gamma_levels=int(gamma_levels),
        )
        plan.check()
        return plan

    def _calibrate(self, job: Job, path: Path, plan: Any) -> None:
        """Worker thread: the session opens the rig itself, so the console's rig is closed meanwhile."""
        from rig.calibrate.session import calibrate

        def run() -> None:
            reporter = Reporter(f"calibrate {job.name}", sink=self.jobs.sink(job, "calibrate"), cancel=job.token)
            operator = None if self.config.simulated else self.operator(job)
            report = calibrate(self.config, plan, path, operator, progress=reporter)  # committed only when computed
            cal = report.calibration
            self.publish(
                {
                    "type": "calibration",
                    "name": job.name,
                    "job": job.id,
                    "lines": list(report.lines),
                    "l0_mm": cal.l0_mm,
                    "d0_mm": cal.d0_mm,
                    "f0_per_mm": cal.f0_per_mm,
                    "model": cal.model,
                },
                None,
            )
            self.calibration = job.name
            self.jobs.update(job, result=job.name)

        self._run_session(job, run)

    def verify(
        self,
        name: str | None = None,
        calibration: str | None = None,
        counts: tuple[int, int, int] = (10, 7, 6),
        mpe_mm: dict[str, float] | None = None,
        client: str | None = None,
    ) -> Job:
        """Verify ``calibration`` (default: the chosen one) into DATA/verifications/NAME, as ``rig verify``.

        ``counts``: sphere, ball-bar and plane positions (fewer than the guideline's: a reduced
        procedure, said so in the report). An acquisition (:class:`Busy` if one runs); on a real rig
        each placement is a ``prompt`` message answered with :meth:`answer`.
        """
        from rig.console.verification import VERIFICATIONS, verification_plan

        chosen = calibration or self.calibration
        if not chosen:
            raise RigError("calibration: none chosen; choose a calibration (or make one) to verify")
        calibration_dir = self.data.existing("calibrations", chosen)
        plan = verification_plan(self.config, *counts, mpe_mm=mpe_mm)
        return self._start_acquisition(
            "verify", VERIFICATIONS, name, f"verify-{chosen}", client,
            lambda job, path: self._verify(job, path, calibration_dir, chosen, plan),
        )  # fmt: skip

    def _verify(self, job: Job, path: Path, calibration_dir: Path, calibration: str, plan: Any) -> None:
        from rig.console.verification import run_verification

        def run() -> None:
            reporter = Reporter(f"verify {job.name}", sink=self.jobs.sink(job, "verify"), cancel=job.token)
            ask = lambda text: self.ask_operator(job, text)  # noqa: E731 - a real rig's prompt, in the page
            report = run_verification(self.config, self.data, plan, calibration_dir, path, reporter, ask)
            message = {"type": "verification", "name": job.name, "job": job.id, "calibration": calibration}
            self.publish({**message, "pass": report["pass"], "summary": report["summary"]}, None)
            self.jobs.update(job, result=job.name)

        self._run_session(job, run)

    def operator(self, job: Job) -> Any:
        """The calibration operator of a real rig: each prompt goes to the page and waits for Done."""
        from rig.calibrate.operator import ConsoleOperator

        return ConsoleOperator(ask=lambda text: self.ask_operator(job, text))

    def ask_operator(self, job: Job, text: str) -> str:
        """Show an operator prompt (calibration, verification) in the page and wait for :meth:`answer`; Stop cancels.

        The terminal's "press Enter" becomes the page's Done button. The prompt waiting is part of
        the status, so a page opened meanwhile shows it too.
        """
        answered = threading.Event()
        text = text.strip().removesuffix(", press Enter").strip()
        self._answer, self.prompt = answered, {"job": job.id, "text": text}
        self.publish({"type": "prompt", **self.prompt}, None)
        self._publish_status()
        try:
            while not answered.wait(0.2):
                job.token.check(job.kind)
        finally:
            self.prompt = None
            self._publish_status()
        return ""

    def answer(self) -> None:
        """The operator has done what the current prompt (calibration, verification) asked."""
        answer = self._answer
        if answer is None or answer.is_set() or self.prompt is None:
            raise RigError("no operator prompt is waiting for an answer")
        answer.set()

    def process(
        self,
        capture: str,
        options: ProcessOptions | None = None,
        name: str | None = None,
        client: str | None = None,
        salvage: bool = False,
    ) -> Job:
        """Reprocess DATA/captures/CAPTURE with ``options`` into DATA/results/NAME (queued).

        A NAME already in DATA/results is refused with :class:`Conflict`: a result is never replaced.
        ``salvage``: CAPTURE is an interrupted scan's folder (``NAME.incomplete-XXXX``); what it
        holds is processed, which fails with one line if frames the processing needs are missing.
        """
        if salvage:
            path = self.data.interrupted("captures", capture)
            base = f"{capture.partition(INCOMPLETE_MARK)[0]}-salvaged"
        else:
            path = self.data.existing("captures", capture)
            base = capture
        options = options or ProcessOptions(correction=DEFAULT_CORRECTION)
        name, _ = self._new_entry("results", name, f"{base}-{options.correction}")
        job = self.jobs.start("process", name, client)
        self.processing.queue(job, path, name, options, False, salvage)
        self._publish_status()
        return job

    def discard(self, capture: str) -> str:
        """Move an interrupted scan's folder into DATA/trash (nothing is deleted); its new place."""
        moved = self.data.to_trash("captures", capture)
        self._publish_status()
        return moved

    def result(self, name: str) -> ResultView:
        """A result by name: in memory, or read back from DATA/results/NAME."""
        return self.processing.result(name)

    @property
    def latest(self) -> dict[str, Any] | None:
        """The newest result shown: name, job, final."""
        return self.processing.latest

    def stop(self, job_id: str | None = None) -> list[str]:
        """Cancel ``job_id`` (default: every running job); returns the ids asked to stop."""
        return self.jobs.stop(job_id)

    # ------------------------------------------------------------------ state
    def status(self) -> dict[str, Any]:
        """What the rig does, its settings, the running jobs and the newest result (any thread)."""
        current = self.current
        running = self.jobs.running()
        acquisition = self.jobs.get(current.id) if current is not None else None
        if current is not None:
            state = "calibrating" if current.kind == "calibrate" else "scanning"
        elif running:
            state = "processing"
        elif self.rig.device_error and self.rig.devices is None:
            state = "fault"
        elif self.live_3d.watching and self.rig.devices is not None:
            state = "live 3-D"
        elif self.live.watching and self.rig.devices is not None:
            state = "live"
        else:
            state = "idle"
        return {
            "state": state,
            "busy": current is not None,
            "acquisition": acquisition,
            "jobs": running,
            "latest_result": self.latest,
            "device_error": self.rig.device_error,
            "devices": self.devices(),
            "exposure_us": self.rig.exposure_us,
            "gain": self.rig.gain,
            "projector": dict(self.rig.projector.__dict__),
            "live": self.live.describe(),
            "live_3d": self.live_3d.describe(),
            "calibration": self.calibration,
            "prompt": self.prompt,
            "calibrations": self.data.names("calibrations"),
            "scan_setup": self.describe_setup(),
            "simulated": self.config.simulated,
            "fault_injection": self.fault_injection,
            "config": str(self.config.source) if self.config.source else "built-in simulated rig",
            "data": self.data.describe(),
        }

    def _publish_status(self) -> None:
        self.publish({"type": "status", "status": self.status()}, None)


def _is_device_fault(exc: BaseException) -> bool:
    """Whether an acquisition error came from a device (close and reopen the rig) rather than from the data."""
    from rig.acquisition.loop import AcquisitionError

    seen: BaseException | None = exc
    while seen is not None:
        if isinstance(seen, (DeviceError, AcquisitionError)):
            return True
        seen = seen.__cause__
    return False
