"""Basler cameras through pypylon (optional extra ``pylon``).

Runs unchanged against pylon's camera emulator: set ``PYLON_CAMEMU=<count>`` in the environment
*before* pypylon is first imported and pick the emulator with ``device_class="BaslerCamEmu"``;
the emulator serves images from a folder with ``features={"ImageFilename": folder,
"ImageFileMode": "On", "TestImageSelector": "Off"}``.

Frame ids are the camera's BlockID (0-based; GigE counts from 1, normalised here), so frames the
camera or the transport lost show up as gaps. ``Frame.timestamp_s`` is the host's monotonic
time when the frame was retrieved (the device tick clock differs per model and is 0 on the
emulator). An incomplete transfer is logged and skipped: the next frame's id gap reports it.
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
    ) -> None:
        label = serial or device_class or "first found"
        super().__init__(name or f"pylon camera ({label})", on_sequence_error=on_sequence_error)
        self.serial = serial
        self.device_class = device_class
        self.trigger_line = trigger_line
        self.features = dict(features or {})
        self._cam: Any = None
        self._block_origin = 0
        self._formats: tuple[PixelFormat, ...] = (PixelFormat.MONO8,)
        self._exposure_node = "ExposureTime"
        self._gain_node = "Gain"

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
        return bool(genicam.IsWritable(node) if writable else genicam.IsAvailable(node))

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
            device = pylon.TlFactory.GetInstance().CreateFirstDevice(info)
            cam = pylon.InstantCamera(device)
            cam.Open()
        except genicam.GenericException as exc:
            raise DeviceNotFoundError(f"{self.name}: no pylon camera matches: {exc}") from exc
        self._cam = cam
        try:
            found = cam.GetDeviceInfo()
            self._block_origin = 1 if found.GetDeviceClass() == "BaslerGigE" else 0
            log.info("%s: opened %s (%s)", self.name, found.GetFriendlyName(), found.GetSerialNumber())
            symbolics = set(cam.PixelFormat.Symbolics)
            self._formats = tuple(f for f, n in PIXEL_FORMAT_NAMES.items() if n in symbolics) or (PixelFormat.MONO8,)
            self._exposure_node = "ExposureTime" if self._has("ExposureTime") else "ExposureTimeAbs"
            self._gain_node = "Gain" if self._has("Gain", writable=True) else "GainRaw"
            for feature, value in self.features.items():
                self._write(feature, value)
        except BaseException:
            cam.Close()
            self._cam = None
            raise

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
        return tuple(int(self._read(n)) for n in ("OffsetX", "OffsetY", "Width", "Height"))

    def _read_exposure_us(self) -> float | None:
        return float(self._read(self._exposure_node))

    def _set_exposure_us(self, value: float) -> float | None:
        self._write(self._exposure_node, float(value))
        return float(self._read(self._exposure_node))

    def _read_gain(self) -> float | None:
        return float(self._read(self._gain_node))

    def _set_gain(self, value: float) -> float | None:
        self._write(self._gain_node, int(round(value)) if self._gain_node == "GainRaw" else float(value))
        return float(self._read(self._gain_node))

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
        if source is not TriggerSource.SOFTWARE and self.trigger_line not in self._cam.TriggerSource.Symbolics:
            raise UnsupportedFeatureError(f"{self.name}: no trigger input {self.trigger_line}")
        selectors = set(self._cam.TriggerSelector.Symbolics)
        active, idle = ("FrameBurstStart", "FrameStart") if burst else ("FrameStart", "FrameBurstStart")
        if idle in selectors:
            self._write("TriggerSelector", idle)
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
            if not self._cam.WaitForFrameTriggerReady(1000, pylon.TimeoutHandling_Return):
                raise DeviceTimeoutError(f"{self.name}: camera not ready for a trigger within 1 s")
            self._cam.ExecuteSoftwareTrigger()
        except _genicam().GenericException as exc:
            self._raise_removed(exc)
            raise DeviceError(f"{self.name}: software trigger failed: {exc}") from exc

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
                    return Frame(image, frame_id, time.monotonic(), self._exposure_us)
                log.warning("%s: incomplete frame (block %d): %s", self.name, result.BlockID, result.ErrorDescription)
            finally:
                result.Release()
            if time.monotonic() >= deadline:
                raise DeviceTimeoutError(f"{self.name}: no complete frame within {timeout_s:g} s")
