"""Trigger paths: how the acquisition loop starts an exposure (the camera's software trigger, or a trigger box).

The hardware assembly (:mod:`rig.hardware.assembly`) builds the path the config names; the
acquisition loop (:mod:`rig.acquisition.loop`) only calls its methods.
"""

from __future__ import annotations

import logging
from typing import Protocol

from drivers.camera import Camera, TriggerSource
from drivers.errors import DeviceError
from drivers.trigger_box import TriggerBox

log = logging.getLogger(__name__)


class TriggerPath(Protocol):
    """How an exposure is started: the camera's trigger source, and firing one trigger."""

    source: TriggerSource
    indices_restart_with_camera: bool  # trigger indices count from 0 again when the camera restarts

    def prepare(self, count: int) -> None:
        """Get ready for at most ``count`` triggers (the camera is already started)."""

    def fire(self) -> int:
        """Start one exposure; return the trigger index the resulting frame will carry."""

    def keepalive(self) -> None:
        """Called while waiting for a frame, at least every ``keepalive_s``."""

    def finish(self) -> None:
        """Leave the trigger hardware idle; called after the scan, whatever its outcome."""


class SoftwareTrigger:
    """The camera's own software trigger; indices count the camera's triggers since it started."""

    source = TriggerSource.SOFTWARE
    indices_restart_with_camera = True

    def __init__(self, camera: Camera) -> None:
        self.camera = camera

    def prepare(self, count: int) -> None:
        pass

    def fire(self) -> int:
        index = self.camera.trigger_count
        self.camera.trigger()
        return index

    def keepalive(self) -> None:
        pass

    def finish(self) -> None:
        pass


class BoxTrigger:
    """A trigger box pulsing the camera's hardware trigger line; indices are the box's pulse indices.

    The box is reset and armed for the whole scan (retries included) before the first pattern,
    pinged while the loop waits for a frame (its watchdog disarms it after a few silent seconds)
    and reset again afterwards, so it never stays armed.
    """

    source = TriggerSource.HARDWARE_RISING
    indices_restart_with_camera = False

    def __init__(self, box: TriggerBox) -> None:
        self.box = box

    def prepare(self, count: int) -> None:
        self.box.reset()
        self.box.arm(count)

    def fire(self) -> int:
        return int(self.box.fire())

    def keepalive(self) -> None:
        """Heartbeat: an armed box disarms itself after a few seconds without a command."""
        self.box.ping()

    def finish(self) -> None:
        try:
            self.box.reset()
        except DeviceError as exc:  # the box may be gone; the scan's own outcome matters more
            log.warning("could not disarm the trigger box after the scan: %s", exc)
