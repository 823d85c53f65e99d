"""The console's live 3-D view: continuous scanning with a short pattern set, processed as it comes.

While it is on and a page watches, the rig's worker thread acquires one short set after another
(:func:`rig.acquisition.loop.acquire_stack`: nothing is written) instead of live camera frames.
Each set goes to a processing thread of its own, which always takes the newest set waiting (a
slow machine drops sets, it never falls behind), processes it in memory (:func:`rig.api.process`
of a :class:`rig.api.FrameStack`, no fringe-order correction) and publishes a ``live3d`` message
with the point cloud (:meth:`rig.console.results.ResultView.cloud`), the rate of sets shown and
the latency from a set's last frame to its cloud being sent.

The short set is the configured scan's two lowest fringe frequencies with all their phase steps
(4-step (1, 8) of the default (1, 8, 64) x 4 scan): the lower one unwraps the higher one. With a
calibration that needs a reference plane, its reference capture holds those patterns too; their
frames are copied into a calibration of the same numbers in a temporary folder, which the
pipeline reads (and caches) as any other.
"""

from __future__ import annotations

import logging
import shutil
import tempfile
import threading
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from drivers.errors import DeviceError
from rig.config import RigConfig
from rig.console.devices import Publish, RigHolder
from rig.console.results import ResultView
from rig.errors import RigError
from rig.pipeline.plan import ProcessOptions
from rig.store.capture import pattern_signature

log = logging.getLogger(__name__)

CLOUD_POINTS = 1 << 16  # points sent per set (a regular subset of the valid pixels)
RATE_WINDOW_S = 2.0  # the rate shown is over this many seconds
RETRY_S = 0.2  # pause before the next set after the rig could not give one
OPTIONS = ProcessOptions(correction="none")
LIVE_FREQUENCIES = 2


def live_patterns(config: RigConfig) -> list[dict[str, Any]]:
    """The configured scan's sinusoids of its two lowest frequencies, every phase step, in scan order."""
    sinusoids = [p for p in config.scan.patterns() if p.get("kind") == "sinusoid"]
    frequencies = sorted({float(p["frequency"]) for p in sinusoids})[:LIVE_FREQUENCIES]
    if len(frequencies) < LIVE_FREQUENCIES:
        raise RigError(
            "live 3-D: expected a phase-shifting scan with at least two fringe frequencies in the rig "
            f"config ([scan] frequencies), found {len(frequencies)}"
        )
    return [p for p in sinusoids if float(p["frequency"]) in frequencies]


def live_calibration(calibration_dir: Path, patterns: list[dict[str, Any]], into: Path) -> Path:
    """A copy of the calibration in ``calibration_dir`` whose reference capture holds only ``patterns``.

    Their frames are taken from the calibration's own reference capture (the numbers, tables and
    reference plane are the calibration's); a calibration without a reference plane is returned
    as it is. :class:`rig.errors.RigError` if the reference lacks one of the patterns.
    """
    from calibration.store import write_calibration
    from rig import api
    from rig.store.capture import write_capture

    calibration = api.load_calibration(calibration_dir)
    if calibration.reference is None:
        return calibration_dir
    reference = api.load_capture(calibration_dir / calibration.reference)
    index = {_signature(p): i for i, p in enumerate(reference.patterns)}
    missing = [p for p in patterns if _signature(p) not in index]
    if missing:
        raise RigError(
            f"live 3-D: the reference plane of calibration {calibration_dir.name} has no frame for "
            f"{len(missing)} of the live patterns (e.g. {missing[0]}); calibrate with this scan's patterns"
        )
    frames = reference.load_frames([index[_signature(p)] for p in patterns])
    into.mkdir(parents=True, exist_ok=True)
    for item in calibration_dir.iterdir():  # tables beside calibration.json (not the reference capture)
        if item.is_file() and not item.is_symlink():
            shutil.copy2(item, into / item.name)
    write_capture(
        into / "reference",
        frames,
        patterns,
        reference.manifest["projector"],
        scene="reference",
        bit_depth=reference.bit_depth,
    )
    write_calibration(into, replace(calibration, reference="reference", path=None))
    return into


def _signature(pattern: dict[str, Any]) -> str:
    return repr(sorted(pattern_signature(pattern).items()))


class Live3D:
    """Continuous scan-and-process of the rig held by ``rig`` while on and ``watched()``; see the module docstring.

    ``calibration`` gives the chosen calibration's directory (None: phase only), read for each set;
    while ``paused()`` (a scan's results are being computed) no set is taken.
    """

    def __init__(
        self,
        rig: RigHolder,
        publish: Publish,
        watched: Callable[[], bool],
        calibration: Callable[[], Path | None],
        paused: Callable[[], bool] = lambda: False,
    ) -> None:
        self.rig = rig
        self.publish = publish
        self.watched = watched
        self.calibration = calibration
        self.paused = paused
        self._wait_s = 0.0  # before the next set: none while sets come, a pause after a failure
        self.on = False
        self.sets = 0
        self.rate_hz = 0.0
        self.latency_s: float | None = None
        self.error: str | None = None
        self._patterns: list[dict[str, Any]] = []
        self._lock = threading.Lock()
        self._pending: tuple[np.ndarray, float, tuple[int, int], int] | None = None
        self._busy = False
        self._shown: list[float] = []
        self._derived: tuple[Path | None, Path | None] = (None, None)  # (calibration, its live copy)
        self._scratch: Path | None = None
        self._thread = ThreadPoolExecutor(max_workers=1, thread_name_prefix="console-live-3d")

    # ------------------------------------------------------------------ switching
    def set(self, on: bool) -> dict[str, Any]:
        """Switch the live 3-D view on or off (off: the live camera view again); returns :meth:`describe`."""
        if on and not self.on:
            self._patterns = live_patterns(self.rig.config)
            self.sets, self.rate_hz, self.latency_s, self.error, self._shown = 0, 0.0, None, None, []
        if not on and self.on:
            self.rig.submit(self.rig.restore_projector)
        self.on = on
        return self.describe()

    def close(self) -> None:
        """Stop processing and remove the temporary calibration copy."""
        self.on = False
        self._thread.shutdown(wait=True, cancel_futures=True)
        if self._scratch is not None:
            shutil.rmtree(self._scratch, ignore_errors=True)

    def describe(self) -> dict[str, Any]:
        """The live 3-D part of the console's status."""
        return {
            "on": self.on,
            "patterns": len(self._patterns) if self.on else len(_safe_patterns(self.rig.config)),
            "sets": self.sets,
            "rate_hz": round(self.rate_hz, 2),
            "latency_ms": None if self.latency_s is None else round(1000 * self.latency_s),
            "error": self.error,
        }

    # ------------------------------------------------------------------ LiveFeed (worker thread)
    @property
    def watching(self) -> bool:
        return self.on and self.watched() and not self.paused()

    def interval_s(self) -> float:
        return self._wait_s  # one set after another (acquiring paces it), or a pause after a failure

    def tick(self) -> None:
        """Acquire one set and hand it to the processing thread (replacing a set still waiting)."""
        from rig.acquisition.loop import AcquisitionSettings, acquire_stack

        self._wait_s = RETRY_S
        devices = self.rig.live_devices()
        if devices is None:
            return
        scan = self.rig.config.scan
        settings = AcquisitionSettings(scan.show_timeout_s, scan.fetch_timeout_s, scan.retries)
        try:
            devices.camera.stop()  # the live view's software-trigger acquisition, if it ran
            frames = acquire_stack(
                self._patterns, devices.projector, devices.camera, devices.trigger, settings,
                self.rig.exposure_us, self.rig.gain,
            )  # fmt: skip
        except (RigError, DeviceError, OSError) as exc:
            if self.rig.devices is not None:
                self.rig.device_failed(exc, "live 3-D")
            return
        self._wait_s = 0.0
        projector = (devices.projector.width, devices.projector.height)
        item = (frames, time.monotonic(), projector, devices.camera.pixel_format.bit_depth)
        with self._lock:
            self._pending = item
            if self._busy:
                return
            self._busy = True
        try:
            self._thread.submit(self._drain)
        except RuntimeError:  # shutting down
            pass

    # ------------------------------------------------------------------ processing thread
    def _drain(self) -> None:
        while True:
            with self._lock:
                item, self._pending = self._pending, None
                if item is None:
                    self._busy = False
                    return
            self._process(*item)

    def _process(self, frames: np.ndarray, acquired: float, projector: tuple[int, int], bit_depth: int) -> None:
        from rig import api

        try:
            stack = api.FrameStack(frames, self._patterns, projector, bit_depth, name="live-3d")
            result = api.process(stack, self._calibration(), OPTIONS)
            cloud, headers = ResultView.from_result("live 3-D", result).cloud(CLOUD_POINTS)
        except (RigError, OSError, ValueError) as exc:  # pointing at nothing, a calibration that does not fit
            self.error = str(exc)
            self.publish({"type": "live3d", "error": self.error}, None)
            return
        now = time.monotonic()
        self._shown = [t for t in self._shown if now - t < RATE_WINDOW_S] + [now]
        shown = self._shown
        self.rate_hz = (len(shown) - 1) / max(now - shown[0], 1e-6) if len(shown) > 1 else 0.0
        self.latency_s, self.error = now - acquired, None
        self.sets += 1
        low, high = (float(v) for v in headers["X-Range"].split(","))
        message = {
            "type": "live3d",
            "set": self.sets,
            "rate_hz": self.rate_hz,
            "latency_ms": 1000 * self.latency_s,
            "points": int(headers["X-Points"]),
            "step": int(headers["X-Step"]),
            "range": [low, high],
            "unit": headers["X-Unit"],
            "axis_unit": headers["X-Axis-Unit"],
            "patterns": len(self._patterns),
            "width": int(frames.shape[2]),
            "height": int(frames.shape[1]),
        }
        self.publish(message, cloud)

    def _calibration(self) -> Path | None:
        """The chosen calibration as the live patterns need it (its copy is made once per calibration)."""
        chosen = self.calibration()
        source, derived = self._derived
        if chosen is None or chosen == source:
            return derived if chosen is not None else None
        if self._scratch is None:
            self._scratch = Path(tempfile.mkdtemp(prefix="rig-live-3d-"))
        into = self._scratch / f"{len(list(self._scratch.iterdir()))}"
        derived = live_calibration(chosen, self._patterns, into)
        self._derived = (chosen, derived)
        return derived


def _safe_patterns(config: RigConfig) -> list[dict[str, Any]]:
    try:
        return live_patterns(config)
    except RigError:
        return []
