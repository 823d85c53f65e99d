"""The acquisition loop: pattern -> project -> wait shown -> trigger -> fetch -> store.

Every pattern gets exactly one frame, and a frame is stored under a pattern only when it is known
to answer the trigger fired while that pattern was on screen:

- the trigger path says which trigger index each trigger's frame carries (the trigger box's pulse
  index, or the count of software triggers). A pattern owns the window of triggers fired while it
  was shown (its first attempt to its latest retry): a frame whose index falls in the window shows
  the pattern, even if it answers an earlier attempt; an older index is a late frame of the
  previous pattern and is discarded; a newer one cannot happen and stops the scan;
- a camera that does not report trigger indices is checked by frame id instead: ids count frames
  since the camera started and a frame never has an id above its trigger's rank, so a frame whose
  id falls in the pattern's window of trigger ranks was exposed while the pattern was shown;
- duplicated frames are discarded; a timeout, a dropped or stale frame or a garbled reply makes
  the loop show the same pattern again and fire a new trigger, ``retries`` times at most (a
  camera without trigger indices is restarted first, so its frame ids match the triggers again);
- a device that fails for good (unplugged, closed) stops the scan at once with its error.

Frames go to disk through :class:`rig.store.capture.CaptureWriter` on a writer thread, so encoding and
fsync overlap the next exposure; the capture becomes complete only when every pattern has its
frame. An error or Ctrl-C leaves the temporary ``*.incomplete-*`` directory, never a capture
that claims to be complete. Camera settings changed for the scan are restored afterwards.
"""

from __future__ import annotations

import contextlib
import logging
import queue
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from drivers.camera import (
    Camera,
    DroppedFrameError,
    DuplicateFrameError,
    Frame,
    StaleFrameError,
    TriggerMode,
    TriggerSource,
)
from drivers.errors import (
    DeviceError,
    DeviceTimeoutError,
    ProtocolError,
    WaitTimeoutError,
)
from drivers.projector import Projector
from rig.errors import CaptureError
from rig.events import ProgressSink
from rig.hardware.trigger_paths import TriggerPath
from rig.store.capture import CaptureWriter
from rig.store.exposures import EXPOSURE_KEY

FrameHandler = Callable[[int, np.ndarray], None]  # (pattern index, stored image), as each frame arrives

log = logging.getLogger(__name__)

# Errors after which showing the pattern again and firing a new trigger may succeed.
RETRYABLE_ERRORS: tuple[type[Exception], ...] = (
    DeviceTimeoutError,
    WaitTimeoutError,
    DroppedFrameError,
    StaleFrameError,
    ProtocolError,
)


class AcquisitionError(CaptureError):
    """A pattern got no trustworthy frame within its retries; the capture stays incomplete."""


@dataclass(frozen=True)
class AcquisitionSettings:
    """Per-step deadlines and the retry budget of a scan."""

    show_timeout_s: float = 1.0
    fetch_timeout_s: float = 2.0
    retries: int = 2
    keepalive_s: float = 0.5  # longest silence towards the trigger hardware while waiting for a frame

    def __post_init__(self) -> None:
        for name in ("show_timeout_s", "fetch_timeout_s", "keepalive_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected > 0 s, found {getattr(self, name)}")
        if self.retries < 0:
            raise ValueError(f"retries: expected >= 0, found {self.retries}")


# --------------------------------------------------------------------------- staging


@contextlib.contextmanager
def staged_camera(
    camera: Camera,
    source: TriggerSource,
    mode: TriggerMode = TriggerMode.ONCE,
    exposure_us: float | None = None,
    gain: float | None = None,
) -> Iterator[Camera]:
    """Configure ``camera`` for a scan and start it; stop and restore the old settings afterwards.

    If configuring fails half-way, what was already changed is rolled back before the error
    propagates.
    """
    restore: list[Callable[[], None]] = []
    try:
        old_source, old_mode = camera.trigger_source, camera.trigger_mode
        camera.set_trigger(source, mode)
        restore.append(lambda: camera.set_trigger(old_source, old_mode))
        if exposure_us is not None:
            old_exposure = camera.exposure_us
            camera.exposure_us = exposure_us
            restore.append(lambda: setattr(camera, "exposure_us", old_exposure))
        if gain is not None:
            old_gain = camera.gain
            camera.gain = gain
            restore.append(lambda: setattr(camera, "gain", old_gain))
        camera.start()
        restore.append(camera.stop)
        yield camera
    finally:
        for undo in reversed(restore):
            try:
                undo()
            except DeviceError as exc:  # the device may be gone; the scan's own error matters more
                log.warning("%s: could not restore a setting after the scan: %s", camera.name, exc)


# --------------------------------------------------------------------------- writer thread


class BackgroundWriter:
    """Feeds frames to a :class:`CaptureWriter` from one thread, so disk work overlaps exposures.

    ``put`` re-raises, in the caller's thread, any error the writer hit; :meth:`close` waits for
    every queued frame. Use as a context manager inside the CaptureWriter's ``with``.
    """

    _STOP = object()

    def __init__(self, writer: CaptureWriter, depth: int = 4) -> None:
        self.writer = writer
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=depth)
        self._error: BaseException | None = None
        self.busy_s = 0.0
        self._thread = threading.Thread(target=self._run, name="capture-writer", daemon=True)

    def __enter__(self) -> BackgroundWriter:
        self._thread.start()
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        self.close(raise_error=exc_type is None)

    def _run(self) -> None:
        while True:
            item = self._queue.get()
            if item is self._STOP:
                return
            if self._error is not None:
                continue  # drain without writing after a failure
            pattern, image, metadata = item
            started = time.perf_counter()
            try:
                self.writer.add_frame(pattern, image, **metadata)
            except BaseException as exc:  # handed to the scanning thread by put()/close()
                self._error = exc
            self.busy_s += time.perf_counter() - started

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            raise self._error

    def put(self, pattern: int, image: np.ndarray, metadata: Mapping[str, Any]) -> None:
        self._raise_if_failed()
        self._queue.put((pattern, image, dict(metadata)))

    def close(self, raise_error: bool = True) -> None:
        if self._thread.is_alive():
            self._queue.put(self._STOP)
            self._thread.join()
        if raise_error:
            self._raise_if_failed()


class InlineWriter:
    """Same interface as :class:`BackgroundWriter`, writing each frame at once in the caller's thread."""

    def __init__(self, writer: CaptureWriter) -> None:
        self.writer = writer
        self.busy_s = 0.0

    def __enter__(self) -> InlineWriter:
        return self

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        pass

    def put(self, pattern: int, image: np.ndarray, metadata: Mapping[str, Any]) -> None:
        started = time.perf_counter()
        self.writer.add_frame(pattern, image, **metadata)
        self.busy_s += time.perf_counter() - started


# --------------------------------------------------------------------------- the loop


@dataclass
class StepTimes:
    """Seconds spent in each step of the loop, summed over the scan."""

    show_s: float = 0.0  # projector: render / upload and wait until shown
    trigger_s: float = 0.0  # firing the trigger
    fetch_s: float = 0.0  # camera: waiting for the exposure and read-out
    store_s: float = 0.0  # handing the frame over to the writer (queueing)
    finish_s: float = 0.0  # waiting for the writer and committing the capture


@dataclass
class ScanResult:
    """What a scan produced and what it cost."""

    path: Path
    frames: list[dict[str, Any]]
    attempts: int
    discarded: int
    wall_s: float
    times: StepTimes = field(default_factory=StepTimes)
    writer_busy_s: float = 0.0
    exposure_plan: Any = None  # rig.acquisition.exposure_plan.ExposurePlan when the assistant chose the exposures


def _pattern_label(index: int, total: int, pattern: Mapping[str, Any]) -> str:
    keys = ", ".join(f"{k}={pattern[k]}" for k in ("frequency", "step", "bit", "level") if k in pattern)
    return f"pattern {index} of {total} ({pattern.get('kind')}{': ' + keys if keys else ''})"


class _TriggerLog:
    """Triggers fired since the camera started: their count, and the index the next one will carry."""

    def __init__(self) -> None:
        self.fired = 0  # rank of the next trigger since the camera started
        self.next_index = 0  # trigger index after the last one the trigger path reported
        self.indexed: bool | None = None  # whether the camera's frames carry trigger indices (None: no frame yet)


def _restart_camera(camera: Camera, trigger: TriggerPath, triggers: _TriggerLog, label: str) -> None:
    """Stop and start the camera before a retry: queued frames are dropped and frame ids restart.

    Needed where frames carry no trigger index: a missed trigger uses no frame id, so ids would
    lag behind the trigger ranks for the rest of the scan; a restart puts them back in step.
    """
    log.info("%s: restarting %s so frame ids match triggers again", label, camera.name)
    camera.stop()
    camera.start()
    triggers.fired = 0
    if trigger.indices_restart_with_camera:
        triggers.next_index = 0


@dataclass(frozen=True)
class _Window:
    """Triggers fired while one pattern was shown: indices and ranks, first and last (inclusive)."""

    first_index: int
    last_index: int
    first_rank: int
    last_rank: int

    def classify(self, frame: Frame) -> str:
        """'ours' if ``frame`` was exposed by one of these triggers, 'late' if by an earlier one, else 'ahead'."""
        if frame.trigger_index is not None:
            value, low, high = int(frame.trigger_index), self.first_index, self.last_index
        else:  # frame ids never exceed their trigger's rank (missed triggers use no id)
            value, low, high = int(frame.frame_id), self.first_rank, self.last_rank
        if value < low:
            return "late"
        return "ours" if value <= high else "ahead"


def acquire_pattern(
    index: int,
    pattern: Mapping[str, Any],
    total: int,
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    settings: AcquisitionSettings,
    triggers: _TriggerLog,
    times: StepTimes,
) -> tuple[Frame, int, int]:
    """The frame of one pattern: (frame, attempts used, frames discarded)."""
    label = _pattern_label(index, total, pattern)
    first_index, first_rank = triggers.next_index, triggers.fired
    discarded = 0
    last_error: Exception | None = None
    for attempt in range(1, settings.retries + 2):
        # A restart realigns frame ids with triggers; after a failure on the first trigger since the
        # camera started it would only meet the same state (and a camera whose first frame after a
        # start is bad, the same fault, for ever): the retry then goes on without one.
        if last_error is not None and not triggers.indexed and triggers.fired > 1:
            _restart_camera(camera, trigger, triggers, label)
            first_index, first_rank = triggers.next_index, triggers.fired
        try:
            started = time.perf_counter()
            projector.show(pattern)
            projector.wait_shown(settings.show_timeout_s)
            shown = time.perf_counter()
            triggers.fired += 1
            fired_index = trigger.fire()
            triggers.next_index = fired_index + 1
            fired = time.perf_counter()
            times.show_s += shown - started
            times.trigger_s += fired - shown
            window = _Window(first_index, fired_index, first_rank, triggers.fired - 1)
            try:
                frame, dropped = _fetch_answer(camera, trigger, window, settings, label)
            finally:
                times.fetch_s += time.perf_counter() - fired
            discarded += dropped
            triggers.indexed = frame.trigger_index is not None
            return frame, attempt, discarded
        except RETRYABLE_ERRORS as exc:
            last_error = exc
            log.warning("%s: attempt %d of %d failed: %s", label, attempt, settings.retries + 1, exc)
    raise AcquisitionError(
        f"{label}: no frame after {settings.retries + 1} attempt(s); last error: {last_error}"
    ) from last_error


def _fetch_answer(
    camera: Camera, trigger: TriggerPath, window: _Window, settings: AcquisitionSettings, label: str
) -> tuple[Frame, int]:
    """Fetch until a frame exposed by one of the pattern's triggers arrives; (frame, frames discarded).

    Waits in slices of ``keepalive_s``, keeping the trigger hardware alive in between.
    """
    timeout_s = settings.fetch_timeout_s
    deadline = time.monotonic() + timeout_s
    discarded = 0
    timeout_message = f"{camera.name}: no frame for trigger {window.last_index} within {timeout_s:g} s ({label})"
    while True:
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            raise DeviceTimeoutError(timeout_message)
        try:
            frame = camera.fetch(min(remaining, settings.keepalive_s))
        except DeviceTimeoutError:
            if deadline - time.monotonic() <= 0:
                raise DeviceTimeoutError(timeout_message) from None
            trigger.keepalive()
            continue
        except DuplicateFrameError as exc:
            log.info("%s: discarding duplicate frame %d", label, exc.frame.frame_id)
            discarded += 1
            continue
        except DroppedFrameError as exc:
            # The lost frame may be an earlier attempt's; keep this one only if it provably shows the pattern.
            if window.classify(exc.frame) != "ours":
                raise
            log.info("%s: %s; frame %d still shows this pattern", label, exc, exc.frame.frame_id)
            frame = exc.frame
        if frame.sequence_error is not None and not isinstance(frame.sequence_error, DroppedFrameError):
            if isinstance(frame.sequence_error, DuplicateFrameError):
                discarded += 1
                continue
            raise frame.sequence_error
        verdict = window.classify(frame)
        if verdict == "ours":
            return frame, discarded
        if verdict == "late":
            log.info("%s: discarding late frame %d (trigger %s)", label, frame.frame_id, frame.trigger_index)
            discarded += 1
            continue
        raise ProtocolError(
            f"{camera.name}: frame {frame.frame_id} (trigger {frame.trigger_index}) is newer than every trigger "
            f"fired for {label} ({window})"
        )


def acquire_in_memory(
    patterns: Sequence[Mapping[str, Any]],
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    settings: AcquisitionSettings,
    exposure_us: float | None = None,
) -> list[Frame]:
    """One frame per pattern, kept in memory (a pre-capture: nothing is written), the camera staged
    at ``exposure_us`` and restored afterwards; the same checks and retries as a scan."""
    frames: list[Frame] = []
    with staged_camera(camera, trigger.source, TriggerMode.ONCE, exposure_us):
        trigger.prepare(len(patterns) * (settings.retries + 1))
        try:
            triggers, times = _TriggerLog(), StepTimes()
            for index, pattern in enumerate(patterns):
                frame, _, _ = acquire_pattern(
                    index, pattern, len(patterns), projector, camera, trigger, settings, triggers, times
                )
                frames.append(frame)
        finally:
            trigger.finish()
    return frames


def frame_metadata(frame: Frame, attempts: int) -> dict[str, Any]:
    """Per-frame keys stored in capture.json beside pattern, file and sha256."""
    meta: dict[str, Any] = {
        "timestamp_s": round(float(frame.timestamp_s), 6),
        "exposure_us": float(frame.exposure_us),
        "frame_id": int(frame.frame_id),
    }
    if frame.trigger_index is not None:
        meta["trigger_index"] = int(frame.trigger_index)
    if attempts > 1:
        meta["attempts"] = attempts
    return meta


def _change_exposure(camera: Camera, trigger: TriggerPath, triggers: _TriggerLog, exposure_us: float) -> None:
    """Between two exposures' sequences: stop the camera, set the next exposure, start it again.

    Once per exposure, not per frame: many cameras accept a new exposure only while stopped, and a
    hardware-triggered sequence (trigger box, DLP pattern sequence) runs at one exposure throughout.
    """
    log.info("%s: exposure %g us for the next sequence", camera.name, exposure_us)
    camera.stop()
    camera.exposure_us = exposure_us
    camera.start()
    triggers.fired = 0
    if trigger.indices_restart_with_camera:
        triggers.next_index = 0


def _capture_writer(
    path: str | Path,
    patterns: Sequence[Mapping[str, Any]],
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    scene: str,
    extra: Mapping[str, Any] | None,
    overwrite: bool,
) -> CaptureWriter:
    """The capture's writer, its manifest naming the devices and the camera's staged settings."""
    camera_info = {"width": camera.width, "height": camera.height, "bit_depth": camera.pixel_format.bit_depth}
    projector_info = {"width": projector.width, "height": projector.height}
    capture_extra = {"devices": {"projector": projector.name, "camera": camera.name, "trigger": type(trigger).__name__}}
    capture_extra.update(extra or {})
    return CaptureWriter(
        path, camera_info, projector_info, patterns, scene=scene, extra=capture_extra, overwrite=overwrite
    )


def _acquire_all(
    patterns: Sequence[Mapping[str, Any]],
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    settings: AcquisitionSettings,
    times: StepTimes,
    background: BackgroundWriter | InlineWriter,
    records: list[dict[str, Any]],
    progress: ProgressSink | None,
    on_frame: FrameHandler | None = None,
) -> tuple[int, int]:
    """One frame per pattern, handed to the writer (and ``on_frame``) in order; returns (attempts, discarded frames)."""
    attempts_total = discarded_total = 0
    triggers = _TriggerLog()
    for index, pattern in enumerate(patterns):
        planned = pattern.get(EXPOSURE_KEY)
        if planned is not None and float(planned) != camera.exposure_us:
            _change_exposure(camera, trigger, triggers, float(planned))
        frame, attempts, discarded = acquire_pattern(
            index, pattern, len(patterns), projector, camera, trigger, settings, triggers, times
        )
        attempts_total += attempts
        discarded_total += discarded
        stored = time.perf_counter()
        meta = frame_metadata(frame, attempts)
        background.put(index, frame.image, meta)
        records.append({"pattern": index, **meta})
        if on_frame is not None:
            on_frame(index, frame.image)
        times.store_s += time.perf_counter() - stored
        if progress is not None:
            progress.step(f"frame {index + 1}")
    return attempts_total, discarded_total


def run_scan(
    path: str | Path,
    patterns: Sequence[Mapping[str, Any]],
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    settings: AcquisitionSettings = AcquisitionSettings(),
    scene: str = "object",
    extra: Mapping[str, Any] | None = None,
    exposure_us: float | None = None,
    gain: float | None = None,
    progress: ProgressSink | None = None,
    overwrite: bool = False,
    background_writer: bool = True,
    on_frame: FrameHandler | None = None,
) -> ScanResult:
    """Acquire one frame per pattern and write the capture at ``path`` atomically.

    Parameters
    ----------
    path : path
        The capture directory to create (must not exist unless ``overwrite``).
    patterns : sequence of capture-format pattern dicts
        Projected in order. Patterns carrying ``exposure_us`` (a scan at several exposures,
        :func:`rig.store.exposures.with_exposures`) set the camera's exposure for their sequence.
    projector, camera : opened devices
    trigger : TriggerPath
        How exposures are started (:class:`SoftwareTrigger`, :class:`BoxTrigger`); the camera's
        trigger source is set to match for the scan.
    settings : AcquisitionSettings
        Deadlines and retries.
    scene, extra : str, mapping
        capture.json's ``scene`` and extra top-level keys.
    exposure_us, gain : float, optional
        Camera settings for the scan (restored afterwards); None keeps the current ones.
    progress : ProgressSink, optional
        Stepped once per stored frame.
    overwrite : bool
        Replace an existing capture at ``path``.
    background_writer : bool
        Encode and write frames on a writer thread while the next one is acquired (default);
        False writes each frame before the next pattern is shown.
    on_frame : callable(pattern_index, image), optional
        Called with each stored frame as it arrives (the console processes the frames held in
        memory while the capture is still being written). The image must not be modified.
    """
    if not patterns:
        raise ValueError("patterns: expected at least one pattern to scan")
    if patterns[0].get(EXPOSURE_KEY) is not None:  # several exposures: staged from the first, restored after
        exposure_us = float(patterns[0][EXPOSURE_KEY])
    started = time.perf_counter()
    times = StepTimes()
    records: list[dict[str, Any]] = []
    with staged_camera(camera, trigger.source, TriggerMode.ONCE, exposure_us, gain):
        writer = _capture_writer(path, patterns, projector, camera, trigger, scene, extra, overwrite)
        with writer:
            sink = BackgroundWriter(writer) if background_writer else InlineWriter(writer)
            with sink as background:
                trigger.prepare(len(patterns) * (settings.retries + 1))
                try:
                    attempts_total, discarded_total = _acquire_all(
                        patterns, projector, camera, trigger, settings, times, background, records, progress, on_frame
                    )
                finally:
                    trigger.finish()
                finishing = time.perf_counter()
            writer_busy = background.busy_s
        times.finish_s = time.perf_counter() - finishing
    return ScanResult(
        path=Path(path),
        frames=records,
        attempts=attempts_total,
        discarded=discarded_total,
        wall_s=time.perf_counter() - started,
        times=times,
        writer_busy_s=writer_busy,
    )


def acquire_stack(
    patterns: Sequence[Mapping[str, Any]],
    projector: Projector,
    camera: Camera,
    trigger: TriggerPath,
    settings: AcquisitionSettings = AcquisitionSettings(),
    exposure_us: float | None = None,
    gain: float | None = None,
) -> np.ndarray:
    """One frame per pattern, held in memory and written nowhere: (N, H, W) in pattern order.

    The same acquisition as :func:`run_scan` (trigger path, deadlines, retries, camera staged and
    restored) for what is shown and thrown away: the console's live 3-D view.
    """
    if not patterns:
        raise ValueError("patterns: expected at least one pattern to acquire")
    times = StepTimes()
    triggers = _TriggerLog()
    images: list[np.ndarray] = []
    with staged_camera(camera, trigger.source, TriggerMode.ONCE, exposure_us, gain):
        trigger.prepare(len(patterns) * (settings.retries + 1))
        try:
            for index, pattern in enumerate(patterns):
                frame, _, _ = acquire_pattern(
                    index, pattern, len(patterns), projector, camera, trigger, settings, triggers, times
                )
                images.append(frame.image)
        finally:
            trigger.finish()
    return np.stack(images)
