"""UVC (USB video class) cameras and video streams through ``cv2.VideoCapture``.

A software trigger grabs the next frame of the stream (``BURST``: ``burst_length`` frames);
frames are converted to 8-bit grey and cropped to the ROI in software. UVC cameras have no
trigger input, so hardware triggers are refused. Exposure and gain go through
``CAP_PROP_EXPOSURE`` / ``CAP_PROP_GAIN``, whose units depend on the OS backend (V4L2: exposure
in units of 100 us); a stream that ignores them (a video file) keeps the requested values and
says so in the log.

``source`` is a device index (``0`` for /dev/video0) or anything VideoCapture opens by name: a
video file, an image sequence (``frames/%03d.png``) or a stream URL, which is how the backend is
tested without a camera.
"""

from __future__ import annotations

import collections
import logging
from typing import Any

import cv2
import numpy as np

from drivers.camera import Camera, Frame, TriggerMode, TriggerSource
from drivers.errors import DeviceNotFoundError, DeviceTimeoutError, IncompatibleStateError, UnsupportedFeatureError

log = logging.getLogger(__name__)

V4L2_EXPOSURE_UNIT_US = 100.0
V4L2_MANUAL_EXPOSURE = 1  # V4L2_EXPOSURE_MANUAL, as CAP_PROP_AUTO_EXPOSURE takes it on Linux


class OpenCVCamera(Camera):
    """A camera or video stream read with OpenCV.

    Parameters
    ----------
    source : int or str
        Device index or a name VideoCapture can open (file path, image-sequence pattern, URL).
    api_preference : int, optional
        ``cv2.CAP_*`` backend (default ``cv2.CAP_ANY``).
    buffer_frames : int
        Driver buffer size asked for (``CAP_PROP_BUFFERSIZE``): 1 keeps grabs fresh on cameras.
    """

    def __init__(
        self,
        source: int | str = 0,
        *,
        api_preference: int | None = None,
        buffer_frames: int = 1,
        name: str | None = None,
        on_sequence_error: str = "raise",
    ) -> None:
        super().__init__(name or f"OpenCV camera {source!r}", on_sequence_error=on_sequence_error)
        self.source = source
        self.api_preference = api_preference
        self.buffer_frames = buffer_frames
        self._cap: Any = None  # cv2.VideoCapture while open
        self._size: tuple[int, int] | None = None
        self._queue: collections.deque[Frame] = collections.deque()
        self._next_id = 0
        self._failed_grab: str | None = None

    @property
    def is_device(self) -> bool:
        """True for a camera index, False for a file / stream name."""
        return isinstance(self.source, int)

    @property
    def sensor_size(self) -> tuple[int, int]:
        if self._size is None:
            raise IncompatibleStateError(f"{self.name}: frame size unknown until opened")
        return self._size

    def _open(self) -> None:

        api = cv2.CAP_ANY if self.api_preference is None else self.api_preference
        cap = cv2.VideoCapture(self.source, api)
        if not cap.isOpened():
            cap.release()
            what = f"camera index {self.source}" if self.is_device else f"video source {self.source!r}"
            raise DeviceNotFoundError(f"{self.name}: OpenCV cannot open {what} (absent, busy or no permission)")
        if self.is_device:
            cap.set(cv2.CAP_PROP_BUFFERSIZE, self.buffer_frames)
        width, height = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        if width < 1 or height < 1:
            cap.release()
            raise DeviceNotFoundError(f"{self.name}: the source reports no frame size ({width}x{height})")
        self._cap = cap
        self._size = (width, height)
        log.info("%s: opened through %s at %dx%d", self.name, cap.getBackendName(), width, height)

    def _close(self) -> None:
        if self._cap is not None:
            self._cap.release()
        self._cap = None
        self._queue.clear()

    def _set_property(self, prop: int, value: float, what: str) -> bool:
        ok = bool(self._cap.set(prop, value))
        if not ok:
            log.info("%s: the source does not take %s; keeping %g as a nominal value", self.name, what, value)
        return ok

    def _set_exposure_us(self, value: float) -> float | None:

        if self.is_device:
            self._set_property(cv2.CAP_PROP_AUTO_EXPOSURE, V4L2_MANUAL_EXPOSURE, "manual exposure")
        if self._set_property(cv2.CAP_PROP_EXPOSURE, value / V4L2_EXPOSURE_UNIT_US, "exposure"):
            return float(self._cap.get(cv2.CAP_PROP_EXPOSURE)) * V4L2_EXPOSURE_UNIT_US
        return None

    def _set_gain(self, value: float) -> float | None:

        if self._set_property(cv2.CAP_PROP_GAIN, value, "gain"):
            return float(self._cap.get(cv2.CAP_PROP_GAIN))
        return None

    def _set_roi(self, roi: tuple[int, int, int, int]) -> None:
        """Software crop: UVC has no sensor ROI."""

    def _set_trigger(self, source: TriggerSource, mode: TriggerMode) -> None:
        if source is not TriggerSource.SOFTWARE:
            raise UnsupportedFeatureError(f"{self.name}: UVC / OpenCV sources have no hardware trigger input")

    def _start(self) -> None:
        self._queue.clear()
        self._next_id = 0
        self._failed_grab = None

    def _stop(self) -> None:
        self._queue.clear()

    def _do_trigger(self) -> None:

        count = self._burst_length if self._trigger_mode is TriggerMode.BURST else 1
        trigger_index = self.trigger_count - 1  # trigger() notes the trigger before this hook
        x, y, w, h = self.roi
        for _ in range(count):
            started = self.now()
            if not self._cap.grab():
                self._failed_grab = "the source gave no frame (end of the video, or the device was lost)"
                return
            ok, image = self._cap.retrieve()
            if not ok or image is None:
                self._failed_grab = "a grabbed frame could not be decoded"
                return
            if image.ndim == 3:
                image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
            image = np.ascontiguousarray(image[y : y + h, x : x + w], dtype=np.uint8)
            self._queue.append(Frame(image, self._next_id, started, self._exposure_us, trigger_index))
            self._next_id += 1

    def _fetch(self, timeout_s: float) -> Frame:
        if self._queue:
            return self._queue.popleft()
        # grabbing is synchronous: with nothing queued no frame can arrive later
        reason = self._failed_grab or "no frame was triggered"
        self._failed_grab = None
        raise DeviceTimeoutError(f"{self.name}: no frame: {reason}")
