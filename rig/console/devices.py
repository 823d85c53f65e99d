"""The console's hold on the rig: one worker thread that opens the devices and makes every call to them.

Every device call happens on the thread that opened the rig (the off-screen projector's OpenGL
context belongs to it). Requests are queued to it as tasks (:meth:`RigHolder.call` waits for the
answer, :meth:`RigHolder.submit` does not); between tasks, while a page watches, it hands its time
to a live feed (:class:`LiveFeed`: live camera frames, or the live 3-D view); with nobody watching the camera is stopped and the projector
dark. The holder keeps what the operator set (exposure, gain, the projector's pattern) and applies
it whenever it opens the rig. A device error closes the rig and is published as a readable
message; the next request (or live frame, after a short pause) opens the rig again.
"""

from __future__ import annotations

import contextlib
import logging
import math
import queue
import threading
import time
from collections.abc import Callable
from concurrent.futures import Future
from dataclasses import dataclass
from typing import Any, Protocol

from drivers.errors import DeviceError
from rig.config import RigConfig
from rig.errors import RigError
from rig.hardware.assembly import RigDevices, open_rig

log = logging.getLogger(__name__)

Publish = Callable[[dict[str, Any], bytes | None], None]
PROJECTOR_PATTERNS = ("black", "white", "fringe", "grid")
REOPEN_AFTER_S = 2.0  # pause before the live view opens a rig again after a device error
IDLE_POLL_S = 0.2  # how often the worker looks at its queue when nobody watches


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


class LiveFeed(Protocol):
    """What the worker runs between tasks while a page watches (:class:`rig.console.live_view.LiveView`)."""

    @property
    def watching(self) -> bool: ...

    def interval_s(self) -> float: ...

    def tick(self) -> None: ...


class RigHolder:
    """Owns the opened devices of ``config`` and the thread that calls them; see the module docstring.

    ``publish`` receives device errors; ``on_change`` is called when the rig opens or fails (the
    console publishes its status then).
    """

    def __init__(self, config: RigConfig, publish: Publish, on_change: Callable[[], None]) -> None:
        self.config = config
        self.publish = publish
        self.on_change = on_change
        self.exposure_us = float(config.camera.exposure_us)
        self.gain: float | None = config.camera.gain
        self.projector = ProjectorSetting()
        self.device_error: str | None = None
        self.feeds: list[LiveFeed] = []  # between tasks, the first that a page watches gets the time
        self._tasks: queue.Queue[tuple[Callable[[], Any], Future[Any]]] = queue.Queue()
        self._stopping = threading.Event()
        self._devices: RigDevices | None = None
        self._limits: tuple[float, float] = (0.0, math.inf)  # the open camera's exposure limits
        self._stack: contextlib.ExitStack | None = None
        self._fault: str | None = None
        self._reopen_at = 0.0
        self._idle = True
        self._worker = threading.Thread(target=self._run, name="rig-worker", daemon=True)

    @property
    def devices(self) -> RigDevices | None:
        """The open devices, or None while the rig is closed."""
        return self._devices

    # ------------------------------------------------------------------ life cycle
    def start(self) -> None:
        """Start the worker thread and open the rig on it (an opening error is shown, not raised)."""
        self._worker.start()
        with contextlib.suppress(RigError, DeviceError, OSError):
            self.call(self.open)

    def close(self) -> None:
        """Stop the worker thread; it closes the devices on its way out."""
        self._stopping.set()
        if self._worker.is_alive():
            self._worker.join(timeout=30)

    def call(self, fn: Callable[[], Any], timeout_s: float = 60.0) -> Any:
        """Run ``fn`` on the worker thread (the devices' thread) and return its result."""
        return self.submit(fn).result(timeout=timeout_s)

    def submit(self, fn: Callable[[], Any]) -> Future[Any]:
        """Queue ``fn`` for the worker thread without waiting; its future holds the outcome."""
        if self._stopping.is_set():
            raise RigError("the console is shutting down")
        future: Future[Any] = Future()
        self._tasks.put((fn, future))
        return future

    def _run(self) -> None:
        next_frame = 0.0
        while not self._stopping.is_set():
            feed = next((f for f in self.feeds if f.watching), None)
            live = feed is not None
            wait = max(0.0, next_frame - time.monotonic()) if live else IDLE_POLL_S
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
            if feed is not None:
                # a fixed rate: the next frame is due one interval after this one was, not after it ends
                now = time.monotonic()
                next_frame = max(next_frame + feed.interval_s(), now)
                feed.tick()
            elif not self._idle:
                self._go_idle()
        while True:  # requests that arrived during shutdown
            try:
                _, future = self._tasks.get_nowait()
            except queue.Empty:
                break
            future.set_exception(RigError("the console is shutting down"))
        self.close_rig()

    # ------------------------------------------------------------------ devices (worker thread)
    def open(self) -> RigDevices:
        """The open devices, opening the rig with the operator's settings if it is closed."""
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
            self.device_failed(exc, "opening the rig")
            raise
        self._devices, self._stack = devices, stack
        self._limits = devices.camera.exposure_limits_us  # read once, on the devices' thread
        self.device_error = None
        self._idle = False
        log.info("console: rig open")
        self.on_change()
        return devices

    def live_devices(self) -> RigDevices | None:
        """The devices for a live frame, showing the projector's pattern again after idling; None while
        the rig waits to reopen after a device error or fails to open (that failure is published)."""
        if self._devices is None and time.monotonic() < self._reopen_at:
            return None
        try:
            devices = self.open()
            if self._idle:
                devices.projector.show(self.projector.capture_pattern())
                self._idle = False
        except (RigError, DeviceError, OSError) as exc:
            if self._devices is not None:
                self.device_failed(exc, "live view")
            return None
        return devices

    def close_rig(self) -> None:
        """Close the devices (a calibration or verification opens the rig itself meanwhile)."""
        stack, self._stack, self._devices = self._stack, None, None
        if stack is not None:
            try:
                stack.close()
            except Exception as exc:  # noqa: BLE001 - a device that is gone may fail to close; the rig is closed anyway
                log.warning("console: closing the rig: %s", exc)
            log.info("console: rig closed")

    def device_failed(self, exc: BaseException, during: str) -> None:
        """Close the rig after a device error and tell the page; the next use opens it again."""
        message = f"{during}: {exc}"
        log.warning("console: %s", message)
        self.device_error = message
        self._reopen_at = time.monotonic() + REOPEN_AFTER_S
        self.close_rig()
        self.publish({"type": "error", "source": "device", "message": message}, None)
        self.on_change()

    def restore_projector(self) -> None:
        """Show the operator's pattern again (after a scan)."""
        if self._devices is not None:
            try:
                self._devices.projector.show(self.projector.capture_pattern())
            except DeviceError as exc:
                self.device_failed(exc, "projector")

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
            self.device_failed(exc, "going idle")

    # ------------------------------------------------------------------ settings (any thread)
    def set_exposure(self, exposure_us: float | None = None, gain: float | None = None) -> dict[str, Any]:
        """Camera exposure (us) and gain for the live view and the next scans."""
        if exposure_us is not None and not (math.isfinite(exposure_us) and 1 <= exposure_us <= 10_000_000):
            raise RigError(f"exposure_us: expected 1 .. 10000000 us, found {exposure_us}")
        if gain is not None and not (math.isfinite(gain) and gain >= 0):
            raise RigError(f"gain: expected a value >= 0, found {gain}")

        def apply() -> None:
            devices = self.open()
            if exposure_us is not None:
                devices.camera.exposure_us = exposure_us
                self.exposure_us = float(devices.camera.exposure_us)
            if gain is not None:
                devices.camera.gain = gain
                self.gain = float(devices.camera.gain)

        self.call(apply)
        return {"exposure_us": self.exposure_us, "gain": self.gain}

    def exposure_limits_us(self) -> list[float | None]:
        """The open camera's (shortest, longest) exposure in microseconds (read when it opened); None
        where unknown or closed."""
        if self._devices is None:
            return [None, None]
        low, high = self._limits
        return [low if low > 0 else None, high if math.isfinite(high) else None]

    def set_projector(self, setting: ProjectorSetting) -> dict[str, Any]:
        """Show a pattern between scans (alignment, exposure checks, the live modulation map)."""
        setting.check()

        def apply() -> None:
            devices = self.open()
            devices.projector.show(setting.capture_pattern())  # show() refuses a bad pattern first
            self.projector = setting

        self.call(apply)
        return self.projector.__dict__ | {"capture_pattern": self.projector.capture_pattern()}

    def inject_fault(self, fault: str) -> None:
        """Reopen the simulated rig with a named device fault (tests and fault drills)."""
        from rig.hardware.simulated import FAULTS

        if not self.config.simulated:
            raise RigError("faults can only be injected into the simulated rig")
        if fault not in FAULTS:
            raise RigError(f"fault: expected one of {', '.join(FAULTS)}, found {fault!r}")

        def reopen() -> None:
            self.close_rig()
            self._fault = fault
            self._reopen_at = 0.0

        self.call(reopen)

    # ------------------------------------------------------------------ state
    def describe(self) -> list[dict[str, Any]]:
        """Each device's backend, name, state and details."""
        config, devices = self.config, self._devices
        state = "open" if devices is not None else ("fault" if self.device_error else "closed")
        return [
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
