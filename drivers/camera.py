"""Abstract camera, in the manner of python-microscope and industrial SDKs.

The base class owns the rules: open (:class:`~drivers.device.Device`) and started state, argument
checks, logging, and the checks on the frame sequence (dropped, duplicated and stale frames). Backends fill in the private hooks.

Frame ids count from 0 at each :meth:`Camera.start` (backends normalise their SDK's counter);
``Frame.timestamp_s`` is the start of the exposure on the camera's clock, :meth:`Camera.now`.
"""

from __future__ import annotations

import abc
import collections
import enum
import logging
import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivers.device import Device, check_timeout_s
from drivers.errors import DeviceError, IncompatibleStateError, ProtocolError, UnsupportedFeatureError

log = logging.getLogger(__name__)


class TriggerSource(enum.Enum):
    """What starts an exposure."""

    SOFTWARE = "software"
    HARDWARE_RISING = "hardware-rising"
    HARDWARE_FALLING = "hardware-falling"


class TriggerMode(enum.Enum):
    """How many frames one trigger produces: one, or a burst of ``Camera.burst_length`` frames."""

    ONCE = "once"
    BURST = "burst"


class PixelFormat(enum.Enum):
    """Single-channel pixel formats; values are the bit depth."""

    MONO8 = 8
    MONO10 = 10
    MONO12 = 12
    MONO16 = 16

    @property
    def bit_depth(self) -> int:
        return int(self.value)

    @property
    def dtype(self) -> np.dtype:
        return np.dtype(np.uint8) if self.value <= 8 else np.dtype(np.uint16)

    @property
    def max_value(self) -> int:
        return (1 << self.value) - 1


class FrameSequenceError(DeviceError):
    """The frame sequence is broken; ``frame`` is the frame that revealed it (still usable)."""

    def __init__(self, message: str, frame: Frame) -> None:
        super().__init__(message)
        self.frame = frame


class DroppedFrameError(FrameSequenceError):
    """One or more frames were lost before ``frame`` (gap in frame ids); ``missing`` says how many."""

    def __init__(self, message: str, frame: Frame, missing: int) -> None:
        super().__init__(message, frame)
        self.missing = missing


class DuplicateFrameError(FrameSequenceError):
    """The camera delivered a frame id it had already delivered."""


class StaleFrameError(FrameSequenceError):
    """The frame was exposed before the trigger it should answer."""


@dataclass
class Frame:
    """One image with its bookkeeping.

    ``image`` is (height, width) of the pixel format's dtype; ``sequence_error`` is set instead of
    raising when the camera was built with ``on_sequence_error="flag"``.
    """

    image: np.ndarray
    frame_id: int
    timestamp_s: float
    exposure_us: float
    trigger_index: int | None = None
    sequence_error: FrameSequenceError | None = None


SEQUENCE_POLICIES = ("raise", "flag")


class Camera(Device):
    """A single-channel camera.

    Parameters
    ----------
    name : str, optional
        Used in log lines and error messages.
    on_sequence_error : {"raise", "flag"}
        What :meth:`fetch` does with a dropped, duplicated or stale frame: raise the
        :class:`FrameSequenceError` subclass (which carries the frame), or return the frame with
        ``sequence_error`` set and log a warning.
    """

    family = "camera"

    def __init__(self, name: str | None = None, *, on_sequence_error: str = "raise") -> None:
        if on_sequence_error not in SEQUENCE_POLICIES:
            raise ValueError(f"on_sequence_error: expected one of {SEQUENCE_POLICIES}, found {on_sequence_error!r}")
        super().__init__(name)
        self.on_sequence_error = on_sequence_error
        self._is_started = False
        self._exposure_us = 10_000.0
        self._gain = 1.0
        self._roi: tuple[int, int, int, int] | None = None
        self._pixel_format = PixelFormat.MONO8
        self._trigger_source = TriggerSource.SOFTWARE
        self._trigger_mode = TriggerMode.ONCE
        self._burst_length = 1
        self._set_before_open: set[str] = set()
        self._reset_sequence()

    # -- state ------------------------------------------------------------------------------------
    @property
    def is_started(self) -> bool:
        return self._is_started

    def close(self) -> None:
        """Stop if needed and disconnect. Closing a closed camera does nothing."""
        try:
            self.stop()
        finally:
            super().close()

    # -- settings ---------------------------------------------------------------------------------
    @property
    @abc.abstractmethod
    def sensor_size(self) -> tuple[int, int]:
        """Full sensor (width, height) in pixels; valid once open."""

    @property
    def supported_pixel_formats(self) -> tuple[PixelFormat, ...]:
        return (PixelFormat.MONO8,)

    @property
    def exposure_us(self) -> float:
        """Exposure time in microseconds, as the device accepted it once open."""
        return self._exposure_us

    @exposure_us.setter
    def exposure_us(self, value: float) -> None:
        value = float(value)
        if not (math.isfinite(value) and value > 0):
            raise ValueError(f"exposure_us: expected a finite time > 0, found {value}")
        if self._is_open:
            low, high = self.exposure_limits_us
            if not low <= value <= high:
                raise ValueError(f"exposure_us: expected {low:g} .. {high:g} us ({self.name}), found {value:g}")
        self._exposure_us = self._push_setting("exposure_us", value, self._set_exposure_us)
        log.debug("%s: exposure %.1f us", self.name, self._exposure_us)

    @property
    def exposure_limits_us(self) -> tuple[float, float]:
        """(shortest, longest) exposure in microseconds the device accepts (open: the device's own;
        unknown limits read as (0, inf))."""
        limits = self._read_exposure_limits_us() if self._is_open else None
        return (0.0, math.inf) if limits is None else (float(limits[0]), float(limits[1]))

    @property
    def gain(self) -> float:
        """Gain in the backend's unit (simulated and UVC: a factor; pylon: the Gain feature, dB)."""
        return self._gain

    @gain.setter
    def gain(self, value: float) -> None:
        value = float(value)
        if not (math.isfinite(value) and value >= 0):
            raise ValueError(f"gain: expected a finite value >= 0, found {value}")
        self._gain = self._push_setting("gain", value, self._set_gain)

    @property
    def roi(self) -> tuple[int, int, int, int]:
        """Region of interest (x, y, width, height) in sensor pixels (known once opened)."""
        if self._roi is None:
            raise IncompatibleStateError(f"{self.name}: ROI unknown until the camera is opened")
        return self._roi

    @roi.setter
    def roi(self, value: tuple[int, int, int, int]) -> None:
        self._require_open("set the ROI")
        self._require_stopped("set the ROI")
        x, y, w, h = (int(c) for c in value)
        sw, sh = self.sensor_size
        if x < 0 or y < 0 or w < 1 or h < 1 or x + w > sw or y + h > sh:
            raise ValueError(f"roi: expected (x, y, w, h) inside the {sw}x{sh} sensor, found {tuple(value)}")
        self._set_roi((x, y, w, h))
        self._roi = (x, y, w, h)

    @property
    def width(self) -> int:
        return self.roi[2]

    @property
    def height(self) -> int:
        return self.roi[3]

    @property
    def pixel_format(self) -> PixelFormat:
        return self._pixel_format

    @pixel_format.setter
    def pixel_format(self, value: PixelFormat) -> None:
        if not isinstance(value, PixelFormat):
            raise ValueError(f"pixel_format: expected a PixelFormat, found {value!r}")
        self._require_stopped("change the pixel format")
        if value not in self.supported_pixel_formats:
            raise UnsupportedFeatureError(
                f"{self.name}: pixel format {value.name} not supported "
                f"(supported: {', '.join(f.name for f in self.supported_pixel_formats)})"
            )
        if self._is_open:
            self._set_pixel_format(value)
        self._pixel_format = value

    @property
    def trigger_source(self) -> TriggerSource:
        return self._trigger_source

    @property
    def trigger_mode(self) -> TriggerMode:
        return self._trigger_mode

    @property
    def burst_length(self) -> int:
        """Frames per trigger in ``TriggerMode.BURST``."""
        return self._burst_length

    @burst_length.setter
    def burst_length(self, value: int) -> None:
        if isinstance(value, bool) or int(value) != value or int(value) < 1:
            raise ValueError(f"burst_length: expected an integer >= 1, found {value!r}")
        self._require_stopped("change the burst length")
        self._burst_length = int(value)
        if self._is_open:
            self._set_trigger(self._trigger_source, self._trigger_mode)

    @property
    def trigger_count(self) -> int:
        """Triggers noted since start()."""
        return self._trigger_count

    def set_trigger(self, source: TriggerSource, mode: TriggerMode = TriggerMode.ONCE) -> None:
        """Choose what starts an exposure; ``UnsupportedFeatureError`` if the device can't do it."""
        if not isinstance(source, TriggerSource) or not isinstance(mode, TriggerMode):
            raise ValueError(f"set_trigger: expected TriggerSource and TriggerMode, found {source!r}, {mode!r}")
        self._require_stopped("change the trigger")
        if self._is_open:
            self._set_trigger(source, mode)
        self._trigger_source, self._trigger_mode = source, mode
        log.debug("%s: trigger %s, %s", self.name, source.name, mode.name)

    # -- acquisition ------------------------------------------------------------------------------
    def start(self) -> None:
        """Arm the camera for triggers; frame ids restart at 0."""
        self._require_open("start")
        if self._is_started:
            raise IncompatibleStateError(f"{self.name}: already started")
        self._reset_sequence()
        self._start()
        self._is_started = True
        log.debug("%s: started", self.name)

    def stop(self) -> None:
        """Disarm; frames not yet fetched are discarded. Stopping a stopped camera does nothing."""
        if not self._is_started:
            return
        try:
            self._stop()
        finally:
            self._is_started = False
            log.debug("%s: stopped", self.name)

    def trigger(self) -> None:
        """Software trigger: start one exposure (a burst in BURST mode)."""
        self._require_started("trigger")
        if self._trigger_source is not TriggerSource.SOFTWARE:
            raise IncompatibleStateError(
                f"{self.name}: software trigger while the trigger source is {self._trigger_source.name}"
            )
        self.note_trigger(self.now())
        self._do_trigger()

    def note_trigger(self, time_s: float) -> None:
        """Record that a trigger arrived at ``time_s`` (camera clock), for the stale-frame check.

        :meth:`trigger` calls it; backends that learn of hardware triggers may call it too.
        """
        frames = self._burst_length if self._trigger_mode is TriggerMode.BURST else 1
        self._pending_triggers.extend([float(time_s)] * frames)
        self._trigger_count += 1

    def fetch(self, timeout_s: float = 1.0) -> Frame:
        """The next frame; ``DeviceTimeoutError`` if none arrives within ``timeout_s``.

        Raises (or flags, see ``on_sequence_error``) :class:`DroppedFrameError`,
        :class:`DuplicateFrameError` or :class:`StaleFrameError`.
        """
        self._require_started("fetch a frame")
        timeout_s = check_timeout_s(timeout_s)
        frame = self._fetch(timeout_s)
        self._check_image(frame)
        problem = self._check_sequence(frame)
        if problem is None:
            return frame
        if self.on_sequence_error == "raise":
            raise problem
        log.warning("%s", problem)
        frame.sequence_error = problem
        return frame

    def now(self) -> float:
        """The camera clock in seconds (host monotonic clock unless the backend has its own)."""
        return time.monotonic()

    # -- checks owned by the base -----------------------------------------------------------------
    def _reset_sequence(self) -> None:
        self._last_frame_id: int | None = None
        self._pending_triggers: collections.deque[float] = collections.deque()
        self._trigger_count = 0

    def _check_image(self, frame: Frame) -> None:
        fmt = self._pixel_format
        expected = (self.height, self.width)
        if frame.image.shape != expected or frame.image.dtype != fmt.dtype:
            raise ProtocolError(
                f"{self.name}: frame {frame.frame_id} is {frame.image.shape} {frame.image.dtype}, "
                f"expected {expected} {fmt.dtype} for {fmt.name}"
            )

    def _check_sequence(self, frame: Frame) -> FrameSequenceError | None:
        last = self._last_frame_id
        expected_id = 0 if last is None else last + 1
        if last is not None and frame.frame_id <= last:
            return DuplicateFrameError(
                f"{self.name}: frame id {frame.frame_id} delivered again (last was {last})", frame
            )
        self._last_frame_id = frame.frame_id
        missing = frame.frame_id - expected_id
        # each frame (dropped or not) answers one pending trigger, oldest first
        for _ in range(min(missing, len(self._pending_triggers))):
            self._pending_triggers.popleft()
        answered = self._pending_triggers.popleft() if self._pending_triggers else None
        if missing > 0:
            return DroppedFrameError(
                f"{self.name}: {missing} frame(s) dropped before frame {frame.frame_id}", frame, missing
            )
        if answered is not None and frame.timestamp_s < answered:
            return StaleFrameError(
                f"{self.name}: frame {frame.frame_id} exposed at {frame.timestamp_s:.6f} s, "
                f"before its trigger at {answered:.6f} s",
                frame,
            )
        return None

    def _require_started(self, action: str) -> None:
        self._require_open(action)
        if not self._is_started:
            raise IncompatibleStateError(f"{self.name}: cannot {action}: acquisition not started")

    def _require_stopped(self, action: str) -> None:
        if self._is_started:
            raise IncompatibleStateError(f"{self.name}: cannot {action} while acquiring; stop() first")

    def _after_open(self) -> None:
        """Read the ROI, push pixel format and trigger; exposure and gain if set before open(), else read them."""
        roi = self._read_roi()
        x, y, w, h = (0, 0, *self.sensor_size) if roi is None else (int(c) for c in roi)
        self._roi = (x, y, w, h)
        if self._pixel_format not in self.supported_pixel_formats:
            self._pixel_format = self.supported_pixel_formats[0]
        self._set_pixel_format(self._pixel_format)
        self._exposure_us = self._sync_setting(
            "exposure_us", self._exposure_us, self._set_exposure_us, self._read_exposure_us
        )
        self._gain = self._sync_setting("gain", self._gain, self._set_gain, self._read_gain)
        self._set_trigger(self._trigger_source, self._trigger_mode)

    def _push_setting(self, setting: str, value: float, push: Callable[[float], float | None]) -> float:
        """Send ``value`` to an open device and return what it accepted; if closed, note it for open()."""
        if not self._is_open:
            self._set_before_open.add(setting)
            return value
        return _accepted(value, push(value))

    def _sync_setting(
        self, setting: str, value: float, push: Callable[[float], float | None], read: Callable[[], float | None]
    ) -> float:
        """At open: push ``value`` if it was set before open(), else take the device's own value."""
        return _accepted(value, push(value) if setting in self._set_before_open else read())

    # -- hooks (and Device's _open / _close) ------------------------------------------------------
    @abc.abstractmethod
    def _set_trigger(self, source: TriggerSource, mode: TriggerMode) -> None:
        """Configure triggering (and ``burst_length`` in BURST mode); UnsupportedFeatureError if impossible."""

    @abc.abstractmethod
    def _start(self) -> None:
        """Arm the device; the next frame gets id 0."""

    @abc.abstractmethod
    def _stop(self) -> None:
        """Disarm the device and drop queued frames."""

    @abc.abstractmethod
    def _do_trigger(self) -> None:
        """Issue a software trigger."""

    @abc.abstractmethod
    def _fetch(self, timeout_s: float) -> Frame:
        """Wait for the next frame; DeviceTimeoutError after ``timeout_s``."""

    def _set_exposure_us(self, value: float) -> float | None:
        """Set the exposure; return the value the device accepted (None: as asked)."""
        return None

    def _set_gain(self, value: float) -> float | None:
        """Set the gain; return the value the device accepted (None: as asked)."""
        return None

    def _read_roi(self) -> tuple[int, int, int, int] | None:
        """The device's ROI at open (None: the full sensor)."""
        return None

    def _read_exposure_us(self) -> float | None:
        """The device's exposure at open (None: keep the base's default)."""
        return None

    def _read_exposure_limits_us(self) -> tuple[float, float] | None:
        """The device's (shortest, longest) exposure in microseconds (None: unknown)."""
        return None

    def _read_gain(self) -> float | None:
        """The device's gain at open, in the backend's unit (None: keep the base's default)."""
        return None

    def _set_roi(self, roi: tuple[int, int, int, int]) -> None:
        """Set the region of interest (already checked against the sensor)."""
        if roi != (0, 0, *self.sensor_size):
            raise UnsupportedFeatureError(f"{self.name}: ROI not supported")

    def _set_pixel_format(self, value: PixelFormat) -> None:
        """Set the pixel format (already checked against ``supported_pixel_formats``)."""


def _accepted(asked: float, actual: float | None) -> float:
    """What a setting hook reports the device took (``None``: as asked)."""
    return asked if actual is None else float(actual)
