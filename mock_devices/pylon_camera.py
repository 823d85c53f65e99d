"""A thin layer over pylon's camera emulator giving it what a real Basler USB3 camera does and the
emulator does not, so that ``drivers.camera_pylon.PylonCamera`` can be tested against it.

pylon's emulator (``PYLON_CAMEMU``) serves images, frame ids and most features, but it has both
``Gain`` and ``GainRaw`` and keeps ``Gain`` writable with auto gain on, has no
``AcquisitionStart`` trigger, no camera clock (timestamps 0) and always reports that it can wait
for trigger readiness. ``UsbCameraQuirks`` wraps an emulator ``InstantCamera`` and overrides only
those nodes and calls; everything else goes to the emulator::

    camera = PylonCamera(camera=UsbCameraQuirks(pylon.InstantCamera(emulator_device)))

Quirks (constructor arguments):

- ``gain_auto``: the initial ``GainAuto`` value; while it is not ``"Off"``, ``Gain`` is read-only.
- ``gain_raw``: keep the emulator's ``GainRaw`` (older GigE); False removes it (USB3 cameras).
- ``acquisition_start``: initial ``TriggerMode`` of an added ``AcquisitionStart`` selector; while
  it is ``"On"`` no frame arrives (nothing sends the acquisition-start trigger).
- ``clock``: give the camera a nanosecond clock (``TimestampLatch``/``TimestampLatchValue``) and
  stamp each frame with the time of its software trigger on that clock.
- ``stale_frames``: the first n frames are stamped one second before their trigger (exposed
  before it, e.g. left over in the camera's buffer).
- ``can_wait_for_trigger_ready``: False makes ``CanWaitForFrameTriggerReady`` false and
  ``WaitForFrameTriggerReady`` raise, as pylon does for cameras that cannot report it (the
  driver then polls ``AcquisitionStatus``; software triggers are held until the emulator is
  ready, since the emulator's status does not show when it is).
"""

from __future__ import annotations

import collections
import time
from collections.abc import Callable
from typing import Any

from pypylon import genicam, pylon


class _Node:
    """A GenICam node: just enough of pypylon's parameter interface for the driver."""

    def __init__(self, access: Callable[[], int]) -> None:
        self._access = access

    def GetAccessMode(self) -> int:
        return self._access()

    def _check(self, write: bool) -> None:
        mode = self._access()
        if not (genicam.IsWritable(mode) if write else genicam.IsReadable(mode)):
            raise genicam.AccessException("node not accessible", __file__, 0)


class _Enum(_Node):
    def __init__(
        self,
        symbolics: list[str],
        get: Callable[[], str],
        set_: Callable[[str], None],
        access: Callable[[], int] = lambda: genicam.RW,
    ) -> None:
        super().__init__(access)
        self.Symbolics = symbolics
        self._get, self._set = get, set_

    def GetValue(self) -> str:
        self._check(write=False)
        return self._get()

    def SetValue(self, value: str) -> None:
        self._check(write=True)
        if value not in self.Symbolics:
            raise genicam.InvalidArgumentException(f"{value} not in {self.Symbolics}", __file__, 0)
        self._set(value)

    def ToString(self) -> str:
        return self.GetValue()


class _Proxy(_Node):
    """An emulator node whose access mode the quirk decides."""

    def __init__(self, inner: Any, access: Callable[[], int]) -> None:
        super().__init__(access)
        self._inner = inner

    def GetValue(self) -> Any:
        self._check(write=False)
        return self._inner.GetValue()

    def SetValue(self, value: Any) -> None:
        self._check(write=True)
        self._inner.SetValue(value)


class _Value(_Node):
    def __init__(self, get: Callable[[], Any]) -> None:
        super().__init__(lambda: genicam.RO)
        self.GetValue = get


class _Command(_Node):
    def __init__(self, run: Callable[[], None]) -> None:
        super().__init__(lambda: genicam.WO)
        self.Execute = run


class _Absent(_Node):
    def __init__(self) -> None:
        super().__init__(lambda: genicam.NI)


class _NodeMap:
    def __init__(self, inner: Any, overrides: dict[str, _Node]) -> None:
        self._inner, self._overrides = inner, overrides

    def GetNode(self, name: str) -> Any:
        return self._overrides[name] if name in self._overrides else self._inner.GetNode(name)


class _Result:
    """A grab result stamped on the fake camera clock."""

    def __init__(self, inner: Any, ticks: int) -> None:
        self._inner, self._ticks = inner, ticks

    def GetTimeStamp(self) -> int:
        return self._ticks

    def IsChunkDataAvailable(self) -> bool:
        return False

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)


class UsbCameraQuirks:
    """An emulator ``InstantCamera`` with the quirks above; passes everything else through."""

    def __init__(
        self,
        inner: Any,
        *,
        gain_auto: str = "Continuous",
        gain_raw: bool = False,
        acquisition_start: str = "On",
        clock: bool = True,
        stale_frames: int = 0,
        can_wait_for_trigger_ready: bool = False,
    ) -> None:
        self._inner = inner
        self.gain_auto = gain_auto
        self.acquisition_start = acquisition_start
        self.stale_frames = stale_frames
        self.can_wait = can_wait_for_trigger_ready
        self._selector = "FrameStart"
        self._latched = 0
        self._trigger_ticks: collections.deque[int] = collections.deque()
        self._clock = clock
        self._node_map: _NodeMap | None = None
        self._keep_gain_raw = gain_raw

    # -- node map -------------------------------------------------------------------------------
    def GetNodeMap(self) -> _NodeMap:
        if self._node_map is None:
            inner = self._inner.GetNodeMap()
            overrides: dict[str, _Node] = {
                "GainAuto": _Enum(
                    ["Off", "Once", "Continuous"],
                    lambda: self.gain_auto,
                    lambda v: setattr(self, "gain_auto", v),
                ),
                "Gain": _Proxy(
                    inner.GetNode("Gain"),
                    lambda: genicam.RW if self.gain_auto == "Off" else genicam.RO,
                ),
                "TriggerSelector": _Enum(
                    ["AcquisitionStart", *inner.GetNode("TriggerSelector").Symbolics],
                    lambda: self._selector,
                    self._select_trigger,
                ),
                "TriggerMode": _Enum(["Off", "On"], self._trigger_mode, self._set_trigger_mode),
            }
            if not self._keep_gain_raw:
                overrides["GainRaw"] = _Absent()
            if self._clock:
                overrides["TimestampLatch"] = _Command(self._latch)
                overrides["TimestampLatchValue"] = _Value(lambda: self._latched)
            self._node_map = _NodeMap(inner, overrides)
        return self._node_map

    def _select_trigger(self, value: str) -> None:
        self._selector = value
        if value != "AcquisitionStart":
            self._inner.GetNodeMap().GetNode("TriggerSelector").SetValue(value)

    def _trigger_mode(self) -> str:
        if self._selector == "AcquisitionStart":
            return self.acquisition_start
        return self._inner.GetNodeMap().GetNode("TriggerMode").GetValue()

    def _set_trigger_mode(self, value: str) -> None:
        if self._selector == "AcquisitionStart":
            self.acquisition_start = value
        else:
            self._inner.GetNodeMap().GetNode("TriggerMode").SetValue(value)

    def _latch(self) -> None:
        self._latched = time.monotonic_ns()

    # -- calls ----------------------------------------------------------------------------------
    def CanWaitForFrameTriggerReady(self) -> bool:
        return self.can_wait

    def WaitForFrameTriggerReady(self, timeout_ms: int, handling: Any) -> bool:
        if not self.can_wait:
            raise genicam.RuntimeException("the camera cannot report trigger readiness", __file__, 0)
        return self._inner.WaitForFrameTriggerReady(timeout_ms, handling)

    def ExecuteSoftwareTrigger(self) -> None:
        self._trigger_ticks.append(time.monotonic_ns())
        # the emulator loses a trigger sent before it is ready, and its AcquisitionStatus does not
        # show that; the camera modelled here reports readiness there, so take the trigger when ready
        self._inner.WaitForFrameTriggerReady(1000, pylon.TimeoutHandling_Return)
        self._inner.ExecuteSoftwareTrigger()

    def RetrieveResult(self, timeout_ms: int, handling: Any) -> Any:
        if self.acquisition_start == "On":
            return None  # waiting for an acquisition-start trigger nobody sends
        result = self._inner.RetrieveResult(timeout_ms, handling)
        if result is None or not self._clock:
            return result
        ticks = self._trigger_ticks.popleft() if self._trigger_ticks else time.monotonic_ns()
        if self.stale_frames > 0:
            self.stale_frames -= 1
            ticks -= 1_000_000_000
        return _Result(result, ticks + 1000)  # exposure starts 1 us after the trigger

    def __getattr__(self, name: str) -> Any:
        return getattr(self._inner, name)
