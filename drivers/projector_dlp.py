"""A DLP LightCrafter 4500 used as the scan's projector: video mode over HDMI, control over USB.

The patterns reach the DMD through the projector's video input, drawn by a display projector
(``WindowProjector`` on the LightCrafter's monitor; in tests any :class:`Projector`). The
controller is woken and put in video mode over USB for the scan, and its health (status
registers) is read over USB after every pattern is shown, so a projector that drops off the bus,
overheats or loses its LEDs stops the scan with its own error instead of producing dark frames.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.dlp import DisplayMode, DlpController
from drivers.errors import DeviceError
from drivers.projector import Projector

log = logging.getLogger(__name__)


class DlpVideoProjector(Projector):
    """Shows patterns through ``display`` while ``controller`` keeps the DLP in video mode.

    Parameters
    ----------
    display : Projector
        Draws the patterns on the DLP's video input (its size is the projector's).
    controller : DlpController
        The DLP's USB control channel (e.g. ``LightCrafter4500()``).
    check_health : bool
        Read the controller's status after each pattern is shown (default).
    """

    def __init__(
        self, display: Projector, controller: DlpController, *, check_health: bool = True, name: str | None = None
    ) -> None:
        super().__init__(display.size, name or "DLP LightCrafter 4500 (video mode)")
        self.display = display
        self.controller = controller
        self.check_health = check_health

    def _open(self) -> None:
        self.controller.open()
        try:
            self.controller.wake()
            self.controller.set_display_mode(DisplayMode.VIDEO)
            self.display.open()
        except BaseException:
            self.controller.close()
            raise

    def _close(self) -> None:
        try:
            self.display.close()
        finally:
            self.controller.close()

    def _set_gamma_lut(self, lut: np.ndarray | None) -> None:
        self.display.set_gamma_lut(lut)

    def _show(self, pattern: Mapping[str, Any]) -> None:
        self.display.show(pattern)

    def _wait(self, timeout_s: float) -> bool:
        self.display.wait_shown(timeout_s)
        if self.check_health:
            status = self.controller.status()
            log.debug("%s: status %s", self.controller, status)
            if not status.healthy:
                raise DeviceError(f"{self.controller}: unhealthy: {'; '.join(status.problems)}")
        return True

    def _last_frame(self) -> np.ndarray | None:
        return self.display.last_frame()
