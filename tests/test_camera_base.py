"""Rules the Camera base class owns, with a scripted in-test backend (no simulation)."""

from __future__ import annotations

import collections

import numpy as np
import pytest

from drivers.camera import Camera, Frame, PixelFormat, StaleFrameError, TriggerMode, TriggerSource
from drivers.errors import DeviceTimeoutError, ProtocolError, UnsupportedFeatureError


class ScriptedCamera(Camera):
    """Delivers the frames a test queues; a 6 x 4 sensor; a clock the test sets."""

    def __init__(self, **kwargs) -> None:
        super().__init__("scripted", **kwargs)
        self.queued: collections.deque[Frame] = collections.deque()
        self.clock = 0.0
        self.exposure_pushed: list[float] = []

    sensor_size = (6, 4)

    def now(self) -> float:
        return self.clock

    def _open(self) -> None: ...
    def _close(self) -> None: ...
    def _start(self) -> None: ...
    def _stop(self) -> None: ...
    def _do_trigger(self) -> None: ...

    def _set_trigger(self, source, mode) -> None:
        if source is TriggerSource.HARDWARE_FALLING:
            raise UnsupportedFeatureError("scripted: no falling edge")

    def _set_exposure_us(self, value: float) -> float:
        self.exposure_pushed.append(value)
        return round(value, -1)  # the device rounds to 10 us

    def _fetch(self, timeout_s: float) -> Frame:
        if not self.queued:
            raise DeviceTimeoutError("scripted: nothing queued")
        return self.queued.popleft()


def frame(frame_id: int, t: float, shape=(4, 6), dtype=np.uint8) -> Frame:
    return Frame(np.zeros(shape, dtype), frame_id, t, 100.0)


def test_wrong_image_shape_or_dtype_is_a_protocol_error() -> None:
    with ScriptedCamera() as camera:
        camera.start()
        camera.queued.extend([frame(0, 0.0, shape=(6, 4)), frame(1, 0.0, dtype=np.uint16)])
        with pytest.raises(ProtocolError, match=r"\(6, 4\) uint8, expected \(4, 6\) uint8"):
            camera.fetch()
        with pytest.raises(ProtocolError, match="uint16"):
            camera.fetch()


def test_burst_frames_answer_one_trigger_without_false_staleness() -> None:
    with ScriptedCamera() as camera:
        camera.burst_length = 3
        camera.set_trigger(TriggerSource.SOFTWARE, TriggerMode.BURST)
        camera.start()
        camera.clock = 1.0
        camera.trigger()
        camera.clock = 2.0
        camera.trigger()
        camera.queued.extend([frame(i, 1.0 + 0.1 * i) for i in range(3)] + [frame(3, 1.5)])
        assert [camera.fetch().frame_id for _ in range(3)] == [0, 1, 2]
        with pytest.raises(StaleFrameError):  # exposed at 1.5 s, its trigger came at 2.0 s
            camera.fetch()


def test_device_rounding_is_reported() -> None:
    camera = ScriptedCamera()
    camera.exposure_us = 1234.0  # before open: pushed on open
    with camera:
        assert camera.exposure_pushed == [1234.0] and camera.exposure_us == 1230.0
        camera.exposure_us = 5678
        assert camera.exposure_us == 5680.0


def test_refused_trigger_keeps_the_previous_one() -> None:
    with ScriptedCamera() as camera:
        camera.set_trigger(TriggerSource.HARDWARE_RISING)
        with pytest.raises(UnsupportedFeatureError):
            camera.set_trigger(TriggerSource.HARDWARE_FALLING)
        assert camera.trigger_source is TriggerSource.HARDWARE_RISING


def test_pixel_format_and_policy_are_validated() -> None:
    with pytest.raises(ValueError, match="on_sequence_error"):
        ScriptedCamera(on_sequence_error="ignore")
    camera = ScriptedCamera()
    with pytest.raises(UnsupportedFeatureError, match="MONO16"):
        camera.pixel_format = PixelFormat.MONO16
    with pytest.raises(ValueError, match="burst_length"):
        camera.burst_length = 0
