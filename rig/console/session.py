"""The console session: the one object that owns the opened rig and runs what the page asks for.

- Every device call happens on one worker thread, the thread that opened the rig (the off-screen
  projector's OpenGL context belongs to it). Requests are queued to it as tasks; between tasks,
  while a page watches, it takes live frames on the camera's software trigger
  (:mod:`rig.acquisition.live`). With no page watching the camera is stopped and the projector dark.
- One acquisition at a time: a scan while another runs is refused with :class:`Busy`.
- A scan goes through :func:`rig.acquisition.scan.scan_with` with the held devices; processing
  (:func:`rig.api.process`) runs on a processing thread so the rig is free again at once:
  first without fringe-order correction (on screen within a second), then with the requested
  options, whose outputs are written (:func:`rig.api.write_outputs`, which never replaces a result).
- Scans, processing runs, calibrations and verifications are jobs of :class:`rig.jobs.Jobs` (thread-safe; every
  job ends done, failed or cancelled, whatever it raises). Their progress comes from the services'
  :class:`rig.events.Reporter` events, published through ``publish`` with the kind of what they
  count (scan: frames, process: stages, calibrate: steps, verify: frames then positions); each job has a
  :class:`rig.events.CancelToken` (Stop button, shutdown). A page that closes stops nothing: jobs
  belong to the console, and a page that opens is shown the running ones and the newest result.
- A device error closes the rig and is published as a readable message; the next request (or live
  frame, after a short pause) opens the rig again.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from drivers.errors import DeviceError
from rig.acquisition.live import frame_figures, grab_frame
from rig.config import RigConfig
from rig.console.datadir import DataDir
from rig.console.results import ResultView
from rig.errors import RigError
from rig.events import Cancelled, Reporter
from rig.hardware.assembly import RigDevices, open_rig
from rig.jobs import Job, Jobs
from rig.pipeline.plan import DEFAULT_CORRECTION, ProcessOptions
from rig.store.files import INCOMPLETE_MARK
from rig.store.result_files import colour_map

log = logging.getLogger(__name__)

Publish = Callable[[dict[str, Any], bytes | None], None]
PROJECTOR_PATTERNS = ("black", "white", "fringe", "grid")
REOPEN_AFTER_S = 2.0  # pause before the live view opens a rig again after a device error
RESULTS_KEPT = 8  # results held in memory (older ones are read back from disk)
JPEG_QUALITY = 80
GAMMA_LEVELS_MAX = 256  # projector gamma ramp levels (an 8-bit projector has no more)
BOARD_VIEWS_MAX = 100
HEIGHTS_MAX = 50


class Busy(RigError):
    """The rig is already acquiring; the request would start a second acquisition."""


class Conflict(RigError):
    """The name a request gives is taken: nothing is replaced without being asked."""


@dataclass
class ProjectorSetting:
    """What the projector shows between scans: black, white, a fringe of chosen frequency and phase,
    or the alignment grid (lines every ``pitch_px`` projector pixels and a centre crosshair)."""

    pattern: str = "black"
    frequency: float = 8.0
    phase_deg: float = 0.0
    axis: str = "x"
    pitch_px: int = 64

    def check(self) -> None:
        if self.pattern not in PROJECTOR_PATTERNS:
            raise RigError(f"pattern: expected one of {', '.join(PROJECTOR_PATTERNS)}, found {self.pattern!r}")
        if self.axis not in ("x", "y"):
            raise RigError(f"axis: expected x or y, found {self.axis!r}")
        if not (math.isfinite(self.frequency) and 0 < self.frequency <= 512):
            raise RigError(f"frequency: expected fringes across the projector in (0, 512], found {self.frequency}")
        if not math.isfinite(self.phase_deg):
            raise RigError(f"phase_deg: expected a finite angle, found {self.phase_deg}")
        if isinstance(self.pitch_px, bool) or not isinstance(self.pitch_px, int) or not 4 <= self.pitch_px <= 4096:
            raise RigError(
                f"pitch_px: expected grid line spacing in projector pixels, 4 .. 4096, found {self.pitch_px}"
            )

    def capture_pattern(self) -> dict[str, Any]:
        """The capture-format pattern entry the projector shows."""
        if self.pattern == "fringe":
            return {
                "kind": "sinusoid",
                "axis": self.axis,
                "frequency": self.frequency,
                "steps": 1,
                "step": 0,
                "phase_rad": math.radians(self.phase_deg),
            }
        if self.pattern == "grid":
            return {"kind": "grid", "pitch_px": self.pitch_px}
        return {"kind": "flat", "level": 1.0 if self.pattern == "white" else 0.0}

    @property
    def fringe_axis(self) -> str | None:
        return self.axis if self.pattern == "fringe" else None


@dataclass
class LiveSettings:
    """How live frames are drawn: saturated pixels in red, and the camera or the modulation map."""

    overlay: bool = True
    view: str = "camera"  # camera | modulation


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
        live_fps: float = 20.0,
    ) -> None:
        self.config = config
        self.data = data
        self.publish = publish
        self.fault_injection = fault_injection
        self.live_interval_s = 1.0 / live_fps
        self.exposure_us = float(config.camera.exposure_us)
        self.gain: float | None = config.camera.gain
        self.projector = ProjectorSetting()
        self.live = LiveSettings()
        self.calibration: str | None = None
        calibrations = data.names("calibrations")
        if calibrations:
            self.calibration = calibrations[0]
        self.device_error: str | None = None
        self.jobs = Jobs(lambda message: publish(message, None))
        self.current: Job | None = None  # the acquisition running
        self.results: OrderedDict[str, ResultView] = OrderedDict()
        self._results_lock = threading.Lock()
        self.latest: dict[str, Any] | None = None  # the newest result shown: name, job, final
        self.fps = 0.0
        self.frames = 0
        self._watchers = 0
        self._tasks: queue.Queue[tuple[Callable[[], Any], Future[Any]]] = queue.Queue()
        self._acquiring = threading.Lock()
        self._processing = ThreadPoolExecutor(max_workers=1, thread_name_prefix="console-process")
        self._stopping = threading.Event()
        self._devices: RigDevices | None = None
        self._stack: contextlib.ExitStack | None = None
        self._fault: str | None = None
        self._reopen_at = 0.0
        self._idle = True
        self._frame_times: list[float] = []
        self._answer: threading.Event | None = None
        self.prompt: dict[str, str] | None = None  # the calibration prompt waiting for the operator
        self._worker = threading.Thread(target=self._run, name="rig-worker", daemon=True)

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Start the worker thread and open the rig on it (an opening error is shown, not raised)."""
        self._worker.start()
        with contextlib.suppress(RigError, DeviceError, OSError):
            self.call(self._open)

    def close(self) -> None:
        """Stop every job, close the devices, stop the threads (Ctrl-C, app shutdown)."""
        self.jobs.stop(reason="the console is shutting down")
        self._stopping.set()
        if self._worker.is_alive():
            self._worker.join(timeout=30)
        self._processing.shutdown(wait=True, cancel_futures=True)

    def call(self, fn: Callable[[], Any], timeout_s: float = 60.0) -> Any:
        """Run ``fn`` on the worker thread (the devices' thread) and return its result."""
        if self._stopping.is_set():
            raise RigError("the console is shutting down")
        future: Future[Any] = Future()
        self._tasks.put((fn, future))
        return future.result(timeout=timeout_s)

    def _run(self) -> None:
        next_frame = 0.0
        while not self._stopping.is_set():
            live = self._watchers > 0
            wait = max(0.0, next_frame - time.monotonic()) if live else 0.2
            try:
                fn, future = self._tasks.get(timeout=wait)
            except queue.Empty:
                fn = None
            if fn is not None:
                if future.set_running_or_notify_cancel():
                    try:
                        future.set_result(fn())
                    except BaseException as exc:  # noqa: BLE001 - handed to the caller's thread
                        future.set_exception(exc)
                continue
            if live:
                next_frame = time.monotonic() + self.live_interval_s
                self._live_frame()
            elif not self._idle:
                self._go_idle()
        while True:  # requests that arrived during shutdown
            try:
                _, future = self._tasks.get_nowait()
            except queue.Empty:
                break
            future.set_exception(RigError("the console is shutting down"))
        self._close_rig()

    # ------------------------------------------------------------------ devices (worker thread)
    def _open(self) -> RigDevices:
        if self._devices is not None:
            return self._devices
        stack = contextlib.ExitStack()
        fault, self._fault = self._fault, None
        try:
            devices = stack.enter_context(open_rig(self.config, scene="object", fault=fault))
            devices.camera.exposure_us = self.exposure_us
            if self.gain is not None:
                devices.camera.gain = self.gain
            else:
                self.gain = float(devices.camera.gain)
            self.exposure_us = float(devices.camera.exposure_us)
            devices.projector.show(self.projector.capture_pattern())
        except (RigError, DeviceError, OSError, ValueError) as exc:
            with contextlib.suppress(Exception):
                stack.close()
            self._device_failed(exc, "opening the rig")
            raise
        self._devices, self._stack = devices, stack
        self.device_error = None
        self._idle = False
        log.info("console: rig open")
        self._publish_status()
        return devices

    def _close_rig(self) -> None:
        stack, self._stack, self._devices = self._stack, None, None
        if stack is not None:
            try:
                stack.close()
            except Exception as exc:  # noqa: BLE001 - a device that is gone may fail to close; the rig is closed anyway
                log.warning("console: closing the rig: %s", exc)
            log.info("console: rig closed")

    def _device_failed(self, exc: BaseException, during: str) -> None:
        """Close the rig after a device error and tell the page; the next use opens it again."""
        message = f"{during}: {exc}"
        log.warning("console: %s", message)
        self.device_error = message
        self._reopen_at = time.monotonic() + REOPEN_AFTER_S
        self._close_rig()
        self.publish({"type": "error", "source": "device", "message": message}, None)
        self._publish_status()

    def _go_idle(self) -> None:
        """No page watches: stop the camera and darken the projector."""
        self._idle = True
        devices = self._devices
        if devices is None:
            return
        try:
            devices.camera.stop()
            devices.projector.show({"kind": "flat", "level": 0.0})
        except DeviceError as exc:
            self._device_failed(exc, "going idle")

    def _live_frame(self) -> None:
        if self._devices is None and time.monotonic() < self._reopen_at:
            return
        try:
            devices = self._open()
            if self._idle:
                devices.projector.show(self.projector.capture_pattern())
                self._idle = False
            image = grab_frame(devices.camera, timeout_s=self.config.scan.fetch_timeout_s)
        except (RigError, DeviceError, OSError) as exc:
            if self._devices is not None:
                self._device_failed(exc, "live view")
            return
        max_value = devices.camera.pixel_format.max_value
        figures = frame_figures(image, max_value, self.projector.fringe_axis)
        picture = self._live_picture(figures)
        ok, jpeg = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        now = time.monotonic()
        self._frame_times = [t for t in self._frame_times if now - t < 2.0] + [now]
        self.fps = (
            (len(self._frame_times) - 1) / max(now - self._frame_times[0], 1e-6) if len(self._frame_times) > 1 else 0.0
        )
        self.frames += 1
        header = {
            "type": "frame",
            "frame": self.frames,
            "width": int(image.shape[1]),
            "height": int(image.shape[0]),
            "mean": figures.mean,
            "saturated_fraction": figures.saturated_fraction,
            "focus": figures.focus,
            "histogram": figures.histogram,
            "valid_fraction": figures.valid_fraction,
            "fps": self.fps,
            "exposure_us": self.exposure_us,
            "gain": self.gain,
            "view": self.live.view if figures.modulation is not None else "camera",
            "overlay": self.live.overlay,
        }
        if ok:
            self.publish(header, jpeg.tobytes())

    def _live_picture(self, figures: Any) -> np.ndarray:
        """The picture sent to the page: the frame (saturation in red) or the modulation map."""
        if self.live.view == "modulation" and figures.modulation is not None:
            top = float(np.percentile(figures.modulation, 99)) or 1.0
            picture = colour_map(figures.modulation, 0.0, top)
            picture[~figures.valid] //= 3  # where the pipeline would drop the phase
            return picture
        grey = figures.levels
        if not (self.live.overlay and figures.saturated_fraction > 0):
            return grey
        picture = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        picture[figures.saturated] = (0, 0, 255)
        return picture

    # ------------------------------------------------------------------ page presence
    def watch(self, delta: int) -> None:
        """A page starts (+1) or stops (-1) watching the live view."""
        self._watchers = max(0, self._watchers + delta)

    # ------------------------------------------------------------------ settings
    def _refuse_while_acquiring(self, what: str) -> None:
        if self.current is not None:
            raise Busy(f"busy: {what} cannot change while {self.current.kind} {self.current.name} runs")

    def set_exposure(self, exposure_us: float | None = None, gain: float | None = None) -> dict[str, Any]:
        """Camera exposure (us) and gain for the live view and the next scans."""
        self._refuse_while_acquiring("the exposure")
        if exposure_us is not None and not (math.isfinite(exposure_us) and 1 <= exposure_us <= 10_000_000):
            raise RigError(f"exposure_us: expected 1 .. 10000000 us, found {exposure_us}")
        if gain is not None and not (math.isfinite(gain) and gain >= 0):
            raise RigError(f"gain: expected a value >= 0, found {gain}")

        def apply() -> None:
            devices = self._open()
            if exposure_us is not None:
                devices.camera.exposure_us = exposure_us
                self.exposure_us = float(devices.camera.exposure_us)
            if gain is not None:
                devices.camera.gain = gain
                self.gain = float(devices.camera.gain)

        self.call(apply)
        self._publish_status()
        return {"exposure_us": self.exposure_us, "gain": self.gain}

    def set_projector(self, setting: ProjectorSetting) -> dict[str, Any]:
        """Show a pattern between scans (alignment, exposure checks, the live modulation map)."""
        self._refuse_while_acquiring("the projector pattern")
        setting.check()

        def apply() -> None:
            devices = self._open()
            devices.projector.show(setting.capture_pattern())  # show() refuses a bad pattern first
            self.projector = setting

        self.call(apply)
        self._publish_status()
        return self.projector.__dict__ | {"capture_pattern": self.projector.capture_pattern()}

    def set_live(self, overlay: bool | None = None, view: str | None = None) -> dict[str, Any]:
        if view is not None and view not in ("camera", "modulation"):
            raise RigError(f"view: expected camera or modulation, found {view!r}")
        if overlay is not None:
            self.live = replace(self.live, overlay=overlay)
        if view is not None:
            self.live = replace(self.live, view=view)
        return self.live.__dict__

    def set_calibration(self, name: str | None) -> str | None:
        """The calibration scans are processed with (a name in DATA/calibrations, or None: phase only)."""
        if name is not None:
            self.data.existing("calibrations", name)
        self.calibration = name
        self._publish_status()
        return name

    def inject_fault(self, fault: str) -> None:
        """Reopen the simulated rig with a named device fault (only with ``fault_injection``)."""
        from rig.hardware.simulated import FAULTS

        if not self.fault_injection:
            raise RigError("fault injection is not enabled for this console")
        if not self.config.simulated:
            raise RigError("faults can only be injected into the simulated rig")
        if fault not in FAULTS:
            raise RigError(f"fault: expected one of {', '.join(FAULTS)}, found {fault!r}")
        self._refuse_while_acquiring("the rig")

        def reopen() -> None:
            self._close_rig()
            self._fault = fault
            self._reopen_at = 0.0

        self.call(reopen)

    # ------------------------------------------------------------------ jobs
    def _job(self, kind: str, name: str, client: str | None) -> Job:
        return self.jobs.start(kind, name, client)

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
        self._acquisition_slot()
        try:
            name, path = self._new_entry("captures", name, "scan")
            job = self._job("scan", name, client)
            self.current = job
            self._tasks.put((lambda: self._scan(job, path, process, options), Future()))
        except BaseException:
            self._acquiring.release()
            raise
        self._publish_status()
        return job

    def _scan(self, job: Job, path: Path, process: bool, options: ProcessOptions | None) -> None:
        """Worker thread: the acquisition itself, then hand the capture to processing."""
        from rig.acquisition.scan import scan_with

        def acquire() -> None:
            devices = self._open()
            devices.camera.stop()  # the live view's software-trigger acquisition
            patterns = self.config.scan.patterns()
            reporter = Reporter(f"scan {job.name}", sink=self.jobs.sink(job, "scan"), cancel=job.token)
            reporter.begin(len(patterns), f"scan {job.name}")
            scan_with(devices, path, patterns, progress=reporter, exposure_us=self.exposure_us, gain=self.gain)

        try:
            error = self.jobs.run(job, acquire, then_finish=not process)
        finally:
            self.current = None
            self._acquiring.release()
        if error is not None:
            if not isinstance(error, Cancelled) and self._devices is not None and _is_device_fault(error):
                self._device_failed(error, f"scan {job.name}")
        else:
            self._restore_projector()
            if process:
                self.jobs.update(job, stage="processing", result=job.name)
                self._queue_processing(job, path, job.name, options, True)
            else:
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
        return self._start_session(
            "calibrate", "calibrations", name, "cal", client, lambda job, path: self._calibrate(job, path, plan)
        )

    def _start_session(
        self,
        kind: str,
        folder: str,
        name: str | None,
        prefix: str,
        client: str | None,
        work: Callable[[Job, Path], None],
    ) -> Job:
        """Take the acquisition slot and queue ``work(job, DATA/folder/NAME)`` (a calibration, a verification)."""
        self._acquisition_slot()
        try:
            name, path = self._new_entry(folder, name, prefix)
            job = self._job(kind, name, client)
            self.current = job
            self._tasks.put((lambda: work(job, path), Future()))
        except BaseException:
            self._acquiring.release()
            raise
        self._publish_status()
        return job

    def _run_session(self, job: Job, run: Callable[[], None]) -> None:
        """Worker thread: a session that opens the rig itself, so the console's rig is closed meanwhile."""
        self._close_rig()
        try:
            self.jobs.run(job, run)
        finally:
            self.current = None
            self._acquiring.release()
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
        return self._start_session(
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

    def _restore_projector(self) -> None:
        if self._devices is not None:
            try:
                self._devices.projector.show(self.projector.capture_pattern())
            except DeviceError as exc:
                self._device_failed(exc, "projector")

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
        job = self._job("process", name, client)
        self._queue_processing(job, path, name, options, False, salvage)
        self._publish_status()
        return job

    def _queue_processing(self, job: Job, *args: Any) -> None:
        """Hand ``job`` to the processing thread; if it is gone (shutting down), the job fails there and then."""
        try:
            self._processing.submit(self._process, job, *args)
        except RuntimeError as exc:
            self.jobs.finish(job, RigError(f"not processed: {exc}"))

    def discard(self, capture: str) -> str:
        """Move an interrupted scan's folder into DATA/trash (nothing is deleted); its new place."""
        moved = self.data.to_trash("captures", capture)
        self._publish_status()
        return moved

    def _process(
        self,
        job: Job,
        capture: Path,
        name: str,
        options: ProcessOptions | None,
        quick_first: bool,
        salvage: bool = False,
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
            calibration = self.data.existing("calibrations", self.calibration) if self.calibration else None
            quick = show_quick if quick_first else None
            result = api.process(capture, calibration, options, reporter, salvage=salvage, quick=quick)
            view = ResultView.from_result(name, result)
            self._show(view, job, final=True)
            api.write_outputs(result, self.data.path("results", name))
            view.saved = True
            self.jobs.update(job, result=name)
            self.publish({"type": "saved", "name": name, "job": job.id}, None)

        self.jobs.run(job, run)
        self._publish_status()

    def _keep(self, view: ResultView) -> None:
        """Hold ``view`` in memory as the newest result, dropping the oldest beyond RESULTS_KEPT."""
        with self._results_lock:
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
        with self._results_lock:
            view = self.results.get(name)
        if view is not None:
            return view
        path = self.data.existing("results", name)
        view = ResultView.from_directory(name, path)
        self._keep(view)
        return view

    def stop(self, job_id: str | None = None) -> list[str]:
        """Cancel ``job_id`` (default: every running job); returns the ids asked to stop."""
        return self.jobs.stop(job_id)

    # ------------------------------------------------------------------ state
    def devices(self) -> list[dict[str, Any]]:
        """Each device's backend, name, state and details."""
        config, devices = self.config, self._devices
        state = "open" if devices is not None else ("fault" if self.device_error else "closed")
        rows = [
            {
                "role": "projector",
                "backend": config.projector.backend,
                "state": state,
                "name": devices.projector.name if devices else None,
                "detail": f"{config.projector.width}x{config.projector.height}",
            },
            {
                "role": "camera",
                "backend": config.camera.backend,
                "state": state,
                "name": devices.camera.name if devices else None,
                "detail": f"{config.camera.width}x{config.camera.height} {config.camera.pixel_format}",
            },
            {
                "role": "trigger",
                "backend": config.trigger.backend,
                "state": state,
                "name": type(devices.trigger).__name__ if devices else None,
                "detail": "camera software trigger"
                if config.trigger.backend == "software"
                else (config.trigger.port or "simulated box"),
            },
        ]
        return rows

    def status(self) -> dict[str, Any]:
        """What the rig does, its settings, the running jobs and the newest result (any thread)."""
        current = self.current
        running = self.jobs.running()
        acquisition = self.jobs.get(current.id) if current is not None else None
        if current is not None:
            state = "calibrating" if current.kind == "calibrate" else "scanning"
        elif running:
            state = "processing"
        elif self.device_error and self._devices is None:
            state = "fault"
        elif self._watchers and self._devices is not None:
            state = "live"
        else:
            state = "idle"
        return {
            "state": state,
            "busy": current is not None,
            "acquisition": acquisition,
            "jobs": running,
            "latest_result": self.latest,
            "device_error": self.device_error,
            "devices": self.devices(),
            "exposure_us": self.exposure_us,
            "gain": self.gain,
            "projector": dict(self.projector.__dict__),
            "live": {"watchers": self._watchers, "fps": round(self.fps, 1), **self.live.__dict__},
            "calibration": self.calibration,
            "prompt": self.prompt,
            "calibrations": self.data.names("calibrations"),
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
