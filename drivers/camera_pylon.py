"""Basler cameras through pypylon (optional extra ``pylon``).

Runs unchanged against pylon's camera emulator: set ``PYLON_CAMEMU=<count>`` in the environment
*before* pypylon is first imported and pick the emulator with ``device_class="BaslerCamEmu"``;
the emulator serves images from a folder with ``features={"ImageFilename": folder,
"ImageFileMode": "On", "TestImageSelector": "Off"}``.

Frame ids are the camera's BlockID (0-based; GigE counts from 1, normalised here), so frames the
camera or the transport lost show up as gaps. Where the camera has a latchable clock
(``TimestampLatch``/``TimestampLatchValue`` on USB3, ``GevTimestampControlLatch``/
``GevTimestampValue`` on GigE) ``Frame.timestamp_s`` is the frame's own timestamp (the
``Timestamp`` chunk when the camera has chunks, else the grab result's) on that clock, and
:meth:`PylonCamera.now` latches the same clock, so a frame exposed before its trigger raises
``StaleFrameError``; without one (pylon's emulator) it is the host's retrieval time and that
check cannot fire. An incomplete transfer is logged and skipped: the next frame's id gap reports
it.

Gain: auto gain (``GainAuto``) is switched off on open, before the gain is read or set; the gain
is the ``Gain`` feature in dB where the camera has it, else ``GainRaw`` in device units
(``gain_unit`` says which). Setting a trigger switches every other trigger selector
(``AcquisitionStart``, ``FrameBurstStart``, ...) off explicitly instead of relying on pylon's
default configuration.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.camera import Camera, Frame, PixelFormat, TriggerMode, TriggerSource
from drivers.errors import DeviceError, DeviceNotFoundError, DeviceTimeoutError, UnsupportedFeatureError

log = logging.getLogger(__name__)

PIXEL_FORMAT_NAMES = {
    PixelFormat.MONO8: "Mono8",
    PixelFormat.MONO10: "Mono10",
    PixelFormat.MONO12: "Mono12",
    PixelFormat.MONO16: "Mono16",
}
ACTIVATION = {TriggerSource.HARDWARE_RISING: "RisingEdge", TriggerSource.HARDWARE_FALLING: "FallingEdge"}


def _pylon() -> Any:
    try:
        from pypylon import pylon
    except ImportError as exc:
        raise DeviceNotFoundError("pypylon is not installed (pip install 'fpp-rig[pylon]')") from exc
    return pylon


def _genicam() -> Any:
    from pypylon import genicam

    return genicam


class PylonCamera(Camera):
    """A Basler camera (or pylon's emulator).

    Parameters
    ----------
    serial : str, optional
        Serial number; default the first camera found.
    device_class : str, optional
        Transport, e.g. ``"BaslerUsb"``, ``"BaslerGigE"``, ``"BaslerCamEmu"``.
    trigger_line : str
        Input line for hardware triggers.
    features : mapping, optional
        GenICam features set in order after opening (name -> value).
    camera : pylon.InstantCamera, optional
        A camera (not yet opened) to use instead of looking one up by ``serial`` /
        ``device_class``; anything with InstantCamera's interface.
    """

    def __init__(
        self,
        serial: str | None = None,
        *,
        device_class: str | None = None,
        trigger_line: str = "Line1",
        features: Mapping[str, Any] | None = None,
        name: str | None = None,
        on_sequence_error: str = "raise",
        camera: Any = None,
    ) -> None:
        label = serial or device_class or "first found"
        super().__init__(name or f"pylon camera ({label})", on_sequence_error=on_sequence_error)
        self.serial = serial
        self.device_class = device_class
        self.trigger_line = trigger_line
        self.features = dict(features or {})
        self._given_camera = camera
        self._cam: Any = None
        self._block_origin = 0
        self._formats: tuple[PixelFormat, ...] = (PixelFormat.MONO8,)
        self._exposure_node = "ExposureTime"
        self._gain_node = "Gain"
        self._clock: tuple[str, str, float] | None = None  # latch command, value node, ticks/s
        self._chunk_timestamps = False

    @property
    def gain_unit(self) -> str:
        """Unit of :attr:`gain`: ``"dB"`` (the Gain feature) or ``"device units"`` (GainRaw)."""
        return "dB" if self._gain_node == "Gain" else "device units"

    # -- GenICam access with errors wrapped -----------------------------------------------------
    def _node(self, name: str) -> Any:
        try:
            return self._cam.GetNodeMap().GetNode(name)
        except _genicam().GenericException:
            return None

    def _has(self, name: str, writable: bool = False) -> bool:
        genicam = _genicam()
        node = self._node(name)
        if node is None:
            return False
        try:
            mode = node.GetAccessMode()
        except genicam.GenericException:
            return False
        return bool(genicam.IsWritable(mode) if writable else genicam.IsAvailable(mode))

    def _symbolics(self, name: str) -> list[str]:
        return list(self._node(name).Symbolics) if self._has(name) else []

    def _write(self, name: str, value: Any) -> None:
        genicam = _genicam()
        if not self._has(name, writable=True):
            raise UnsupportedFeatureError(f"{self.name}: feature {name} is not writable on this camera")
        try:
            self._node(name).SetValue(value)
        except genicam.GenericException as exc:
            raise DeviceError(f"{self.name}: setting {name} = {value!r} failed: {exc}") from exc

    def _read(self, name: str) -> Any:
        return self._node(name).GetValue()

    # -- hooks ----------------------------------------------------------------------------------
    @property
    def sensor_size(self) -> tuple[int, int]:
        return (int(self._read("WidthMax")), int(self._read("HeightMax")))

    @property
    def supported_pixel_formats(self) -> tuple[PixelFormat, ...]:
        return self._formats

    def _open(self) -> None:
        pylon = _pylon()
        genicam = _genicam()
        info = pylon.DeviceInfo()
        if self.serial:
            info.SetSerialNumber(self.serial)
        if self.device_class:
            info.SetDeviceClass(self.device_class)
        try:
            if self._given_camera is not None:
                cam = self._given_camera
            else:
                cam = pylon.InstantCamera(pylon.TlFactory.GetInstance().CreateFirstDevice(info))
            cam.Open()
        except genicam.GenericException as exc:
            raise DeviceNotFoundError(f"{self.name}: no pylon camera matches: {exc}") from exc
        self._cam = cam
        try:
            found = cam.GetDeviceInfo()
            self._block_origin = 1 if found.GetDeviceClass() == "BaslerGigE" else 0
            log.info("%s: opened %s (%s)", self.name, found.GetFriendlyName(), found.GetSerialNumber())
            symbolics = set(self._symbolics("PixelFormat"))
            self._formats = tuple(f for f, n in PIXEL_FORMAT_NAMES.items() if n in symbolics) or (PixelFormat.MONO8,)
            self._exposure_node = "ExposureTime" if self._has("ExposureTime") else "ExposureTimeAbs"
            for feature, value in self.features.items():
                self._write(feature, value)
            self._gain_off_auto()
            self._clock = self._find_clock()
            self._chunk_timestamps = self._clock is not None and self._enable_timestamp_chunk()
        except BaseException:
            cam.Close()
            self._cam = None
            raise

    def _gain_off_auto(self) -> None:
        """Switch auto gain off (while it runs, Gain is read-only), then pick the gain node."""
        if self._has("GainAuto", writable=True) and self._read("GainAuto") != "Off":
            log.info("%s: switching auto gain (%s) off", self.name, self._read("GainAuto"))
            self._write("GainAuto", "Off")
        if self._has("Gain"):
            self._gain_node = "Gain"
        elif self._has("GainRaw"):
            self._gain_node = "GainRaw"
        else:
            raise UnsupportedFeatureError(f"{self.name}: the camera has neither Gain nor GainRaw")
        log.info("%s: gain is %s in %s", self.name, self._gain_node, self.gain_unit)

    def _find_clock(self) -> tuple[str, str, float] | None:
        """The camera's latchable timestamp clock: (latch command, value node, ticks per s)."""
        if self._has("TimestampLatch") and self._has("TimestampLatchValue"):
            return ("TimestampLatch", "TimestampLatchValue", 1e9)  # USB3 Vision: nanoseconds
        if all(self._has(n) for n in ("GevTimestampControlLatch", "GevTimestampValue", "GevTimestampTickFrequency")):
            return ("GevTimestampControlLatch", "GevTimestampValue", float(self._read("GevTimestampTickFrequency")))
        log.info("%s: no camera clock; frame times are host retrieval times", self.name)
        return None

    def _enable_timestamp_chunk(self) -> bool:
        if not self._has("ChunkModeActive", writable=True) or "Timestamp" not in self._symbolics("ChunkSelector"):
            return False
        self._write("ChunkModeActive", True)
        self._write("ChunkSelector", "Timestamp")
        self._write("ChunkEnable", True)
        return True

    def now(self) -> float:
        """The camera's clock in seconds where it has a latchable one, else the host's."""
        if self._cam is None or self._clock is None:
            return super().now()
        latch, value, ticks_per_s = self._clock
        try:
            self._node(latch).Execute()
            return int(self._read(value)) / ticks_per_s
        except _genicam().GenericException as exc:
            raise DeviceError(f"{self.name}: reading the camera clock failed: {exc}") from exc

    def _frame_time(self, result: Any) -> float:
        if self._clock is None:
            return time.monotonic()
        ticks = None
        if self._chunk_timestamps and result.IsChunkDataAvailable():
            ticks = result.GetChunkDataNodeMap().GetNode("ChunkTimestamp").GetValue()
        if ticks is None:
            ticks = result.GetTimeStamp()
        return int(ticks) / self._clock[2]

    def _close(self) -> None:
        if self._cam is None:
            return
        try:
            if self._cam.IsGrabbing():
                self._cam.StopGrabbing()
            self._cam.Close()
        except _genicam().GenericException as exc:
            raise DeviceError(f"{self.name}: close failed: {exc}") from exc
        finally:
            self._cam = None

    def _read_roi(self) -> tuple[int, int, int, int] | None:
        x, y, w, h = (int(self._read(n)) for n in ("OffsetX", "OffsetY", "Width", "Height"))
        return x, y, w, h

    def _read_exposure_us(self) -> float | None:
        return float(self._read(self._exposure_node))

    def _read_exposure_limits_us(self) -> tuple[float, float] | None:
        node = self._node(self._exposure_node)
        try:
            return (float(node.GetMin()), float(node.GetMax()))
        except (AttributeError, _genicam().GenericException):  # a node without limits (or an emulator's)
            return None

    def _set_exposure_us(self, value: float) -> float | None:
        self._write(self._exposure_node, float(value))
        return float(self._read(self._exposure_node))

    def _read_gain(self) -> float | None:
        return float(self._read(self._gain_node))

    def _set_gain(self, value: float) -> float | None:
        self._write(self._gain_node, int(round(value)) if self._gain_node == "GainRaw" else float(value))
        accepted = float(self._read(self._gain_node))
        log.info("%s: %s set to %g %s", self.name, self._gain_node, accepted, self.gain_unit)
        return accepted

    def _set_roi(self, roi: tuple[int, int, int, int]) -> None:
        x, y, w, h = roi
        for name, value in (("Width", w), ("Height", h), ("OffsetX", x), ("OffsetY", y)):
            increment = int(self._node(name).GetInc()) if self._has(name) else 1
            if value % increment:
                raise UnsupportedFeatureError(f"{self.name}: {name} must be a multiple of {increment}, found {value}")
        self._write("OffsetX", 0)
        self._write("OffsetY", 0)
        self._write("Width", w)
        self._write("Height", h)
        self._write("OffsetX", x)
        self._write("OffsetY", y)

    def _set_pixel_format(self, value: PixelFormat) -> None:
        self._write("PixelFormat", PIXEL_FORMAT_NAMES[value])

    def _set_trigger(self, source: TriggerSource, mode: TriggerMode) -> None:
        burst = mode is TriggerMode.BURST
        if burst and not self._has("AcquisitionBurstFrameCount", writable=True):
            raise UnsupportedFeatureError(f"{self.name}: this camera has no frame-burst trigger")
        if source is not TriggerSource.SOFTWARE and self.trigger_line not in self._symbolics("TriggerSource"):
            raise UnsupportedFeatureError(f"{self.name}: no trigger input {self.trigger_line}")
        active = "FrameBurstStart" if burst else "FrameStart"
        # every other selector (AcquisitionStart, FrameBurstStart, ExposureStart, ...) off, explicitly:
        # one left on (pylon's default configuration is not always loaded) would hold frames back
        for selector in self._symbolics("TriggerSelector"):
            if selector != active:
                self._write("TriggerSelector", selector)
                if self._has("TriggerMode", writable=True) and self._read("TriggerMode") != "Off":
                    log.info("%s: trigger %s was on; switching it off", self.name, selector)
                    self._write("TriggerMode", "Off")
        self._write("TriggerSelector", active)
        self._write("TriggerMode", "On")
        if source is TriggerSource.SOFTWARE:
            self._write("TriggerSource", "Software")
        else:
            self._write("TriggerSource", self.trigger_line)
            self._write("TriggerActivation", ACTIVATION[source])
        if burst:
            self._write("AcquisitionBurstFrameCount", self._burst_length)

    def _start(self) -> None:
        pylon = _pylon()
        try:
            self._cam.StartGrabbing(pylon.GrabStrategy_OneByOne)
        except _genicam().GenericException as exc:
            raise DeviceError(f"{self.name}: start grabbing failed: {exc}") from exc

    def _stop(self) -> None:
        try:
            self._cam.StopGrabbing()
        except _genicam().GenericException as exc:
            raise DeviceError(f"{self.name}: stop grabbing failed: {exc}") from exc

    def _do_trigger(self) -> None:
        pylon = _pylon()
        try:
            # cameras (and transports) that cannot report trigger readiness raise if asked
            if self._cam.CanWaitForFrameTriggerReady():
                ready = self._cam.WaitForFrameTriggerReady(1000, pylon.TimeoutHandling_Return)
            else:
                ready = self._poll_frame_trigger_wait(1.0)
            if not ready:
                raise DeviceTimeoutError(f"{self.name}: camera not ready for a trigger within 1 s")
            self._cam.ExecuteSoftwareTrigger()
        except _genicam().GenericException as exc:
            self._raise_removed(exc)
            raise DeviceError(f"{self.name}: software trigger failed: {exc}") from exc

    def _poll_frame_trigger_wait(self, timeout_s: float) -> bool:
        """Readiness from AcquisitionStatus[FrameTriggerWait] where the camera has it, else True."""
        if "FrameTriggerWait" not in self._symbolics("AcquisitionStatusSelector"):
            return True
        self._write("AcquisitionStatusSelector", "FrameTriggerWait")
        deadline = time.monotonic() + timeout_s
        while not self._read("AcquisitionStatus"):
            if time.monotonic() > deadline:
                return False
            time.sleep(0.001)
        return True

    def _raise_removed(self, exc: BaseException | None = None) -> None:
        if self._cam is not None and self._cam.IsCameraDeviceRemoved():
            raise DeviceNotFoundError(f"{self.name}: camera removed") from exc

    def _fetch(self, timeout_s: float) -> Frame:
        pylon = _pylon()
        deadline = time.monotonic() + timeout_s
        while True:
            remaining_ms = max(1, math.ceil((deadline - time.monotonic()) * 1000))
            try:
                result = self._cam.RetrieveResult(remaining_ms, pylon.TimeoutHandling_Return)
            except _genicam().GenericException as exc:
                self._raise_removed(exc)
                raise DeviceError(f"{self.name}: retrieving a frame failed: {exc}") from exc
            if result is None or not result.IsValid():
                self._raise_removed()
                raise DeviceTimeoutError(f"{self.name}: no frame within {timeout_s:g} s")
            try:
                if result.GrabSucceeded():
                    image = np.array(result.Array, dtype=self._pixel_format.dtype, copy=True)
                    frame_id = int(result.BlockID) - self._block_origin
                    return Frame(image, frame_id, self._frame_time(result), self._exposure_us)
                log.warning("%s: incomplete frame (block %d): %s", self.name, result.BlockID, result.ErrorDescription)
            finally:
                result.Release()
            if time.monotonic() >= deadline:
                raise DeviceTimeoutError(f"{self.name}: no complete frame within {timeout_s:g} s")
