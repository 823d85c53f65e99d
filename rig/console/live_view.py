"""The console's live view: camera frames on the software trigger, their figures, drawn for the page.

Runs on the rig's worker thread between tasks while at least one page watches
(:class:`rig.console.devices.RigHolder` calls :meth:`LiveView.tick`). Each frame is published as a
``frame`` message with its figures (:func:`rig.acquisition.live.frame_figures`) and a JPEG of
the camera picture (saturated pixels in red) or of the fringe modulation map.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import cv2
import numpy as np

from drivers.errors import DeviceError
from rig.acquisition.live import frame_figures, grab_frame
from rig.console.devices import Publish, RigHolder
from rig.errors import RigError
from rig.store.result_files import colour_map

JPEG_QUALITY = 80
LIVE_FPS = 25.0  # highest live frame rate: 20 a second to follow a part by hand, with headroom
LIVE_VIEWS = ("camera", "modulation")
FPS_WINDOW_S = 2.0  # the frame rate shown is over this many seconds


@dataclass
class LiveSettings:
    """How live frames are drawn: saturated pixels in red, and the camera or the modulation map."""

    overlay: bool = True
    view: str = "camera"  # camera | modulation


class LiveView:
    """Live frames of the rig held by ``rig`` for the pages that watch, at most ``fps`` a second.

    ``paused()``: whether to leave the machine to other work for now (no frame, the rig stays as it is).
    """

    def __init__(
        self, rig: RigHolder, publish: Publish, fps: float = LIVE_FPS, paused: Callable[[], bool] = lambda: False
    ) -> None:
        self.rig = rig
        self.publish = publish
        self.paused = paused
        self.settings = LiveSettings()
        self.watchers = 0
        self.fps = 0.0
        self.frames = 0
        self._interval_s = 1.0 / fps
        self._frame_times: list[float] = []

    @property
    def watching(self) -> bool:
        return self.watchers > 0

    def interval_s(self) -> float:
        return self._interval_s

    def watch(self, delta: int) -> None:
        """A page starts (+1) or stops (-1) watching the live view."""
        self.watchers = max(0, self.watchers + delta)

    def set(self, overlay: bool | None = None, view: str | None = None) -> dict[str, Any]:
        """Change how frames are drawn; returns the settings."""
        if view is not None and view not in LIVE_VIEWS:
            raise RigError(f"view: expected camera or modulation, found {view!r}")
        if overlay is not None:
            self.settings = replace(self.settings, overlay=overlay)
        if view is not None:
            self.settings = replace(self.settings, view=view)
        return self.settings.__dict__

    def tick(self) -> None:
        """Worker thread: take one frame and publish it (a device error closes the rig instead); none
        while ``paused()`` (a scan's results are being computed: they come first)."""
        if self.paused():
            return
        devices = self.rig.live_devices()
        if devices is None:
            return
        try:
            image = grab_frame(devices.camera, timeout_s=self.rig.config.scan.fetch_timeout_s)
        except (RigError, DeviceError, OSError) as exc:
            if self.rig.devices is not None:
                self.rig.device_failed(exc, "live view")
            return
        projector = self.rig.projector
        figures = frame_figures(image, devices.camera.pixel_format.max_value, projector.fringe_axis)
        picture = self._picture(figures)
        ok, jpeg = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
        self._count_frame()
        header = {
            "type": "frame",
            "frame": self.frames,
            "width": int(image.shape[1]),
            "height": int(image.shape[0]),
            "mean": figures.mean,
            "saturated_fraction": figures.saturated_fraction,
            "focus": figures.focus,
            "histogram": figures.histogram,
            "valid_fraction": figures.valid_fraction,
            "fps": self.fps,
            "exposure_us": self.rig.exposure_us,
            "gain": self.rig.gain,
            "view": self.settings.view if figures.modulation is not None else "camera",
            "overlay": self.settings.overlay,
        }
        if ok:
            self.publish(header, jpeg.tobytes())

    def _count_frame(self) -> None:
        now = time.monotonic()
        self._frame_times = [t for t in self._frame_times if now - t < FPS_WINDOW_S] + [now]
        times = self._frame_times
        self.fps = (len(times) - 1) / max(now - times[0], 1e-6) if len(times) > 1 else 0.0
        self.frames += 1

    def _picture(self, figures: Any) -> np.ndarray:
        """The picture sent to the page: the frame (saturation in red) or the modulation map."""
        if self.settings.view == "modulation" and figures.modulation is not None:
            top = float(np.percentile(figures.modulation[::4, ::4], 99)) or 1.0  # a colour scale: a sample will do
            picture = colour_map(figures.modulation, 0.0, top)
            picture[~figures.valid] //= 3  # where the pipeline would drop the phase
            return picture
        grey = figures.levels
        if not (self.settings.overlay and figures.saturated_fraction > 0):
            return grey
        picture = cv2.cvtColor(grey, cv2.COLOR_GRAY2BGR)
        picture[figures.saturated] = (0, 0, 255)
        return picture

    def describe(self) -> dict[str, Any]:
        """The live part of the console's status."""
        return {"watchers": self.watchers, "fps": round(self.fps, 1), **self.settings.__dict__}
