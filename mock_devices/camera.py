"""A simulated camera that sees what the projector driver actually rendered, on a virtual scene.

Each exposure takes the projector's current frame (``projector.last_frame()``: drive levels after
the gamma LUT), maps it onto the camera pixels through the rig geometry
(:func:`mock_devices.synth.projector_coordinates`, computed once per scene) and exposes it with
the scene's reflectivity, ambient light, the projector's gamma, the exposure time, gain and noise
(:func:`mock_devices.synth.expose`). Triggers come from :meth:`Camera.trigger` (software) or from
:meth:`SimulatedCamera.pulse` (the fake trigger box's exposure pulse, any thread).

Faults are injected through ``faults=CameraFaults(...)``; the frame-sequence checks that catch
them belong to :class:`drivers.camera.Camera`, not to this mock. Exposures take no real time:
the camera has its own clock that advances by each exposure.
"""

from __future__ import annotations

import collections
import logging
import threading
from collections.abc import Callable, Collection
from dataclasses import dataclass, field, replace

import numpy as np

from drivers.camera import Camera, Frame, PixelFormat, TriggerMode, TriggerSource
from drivers.errors import DeviceNotFoundError, DeviceTimeoutError
from drivers.projector import Projector, apply_gamma_lut
from mock_devices.synth import (
    Appearance,
    ProjectorMap,
    RigGeometry,
    expose,
    projector_coordinates,
    sample_projector_image,
)
from processing.projection.patterns import pattern_image

log = logging.getLogger(__name__)

READOUT_S = 1e-3  # camera-clock time between the end of one exposure and the next possible start


@dataclass(frozen=True)
class CameraFaults:
    """Faults by exposure index (0-based, counted from ``start()``, every exposure counts).

    timeout_on: exposures whose trigger is missed (no frame, no frame id used).
    drop: exposures whose frame is lost in transport (its frame id is skipped).
    duplicate: exposures whose frame is delivered twice.
    stale: exposures delivered with the previous exposure's timestamp (a frame from before the trigger).
    disappear_after: the device vanishes after this many exposures (DeviceNotFoundError).

    Indices count again from 0 after every ``start()``: ``timeout_on={0}`` is a camera whose first
    frame after every start is missed, ``stale={0}`` one whose first frame is left over from before.
    """

    timeout_on: Collection[int] = field(default_factory=frozenset)
    drop: Collection[int] = field(default_factory=frozenset)
    duplicate: Collection[int] = field(default_factory=frozenset)
    stale: Collection[int] = field(default_factory=frozenset)
    disappear_after: int | None = None


class SimulatedCamera(Camera):
    """Camera of the simulated rig.

    Parameters
    ----------
    projector : Projector or None
        Whose frames light the scene; None (or nothing shown yet) means darkness plus ambient.
        If the projector cannot hand back its frame, its last pattern is rendered from
        ``processing.projection.patterns`` through its gamma LUT.
    geometry : RigGeometry
        Rig geometry; its camera size is the sensor, its projector size must match the projector.
    scene_height_mm : (H, W) array, optional
        Height map seen by the camera; default the flat reference plane.
    appearance : Appearance
        Reflectivity, ambient, projector gamma, noise (``snr_db``) and ``gain`` (DN for projector
        intensity 1 at ``reference_exposure_us`` and camera gain 1). Its ``bit_depth`` is replaced
        by the pixel format's.
    reference_exposure_us : float
        Exposure at which ``appearance.gain`` holds; the signal scales with exposure_us / this.
    exposure_limits_us : (float, float)
        Shortest and longest exposure the simulated sensor accepts (as a real camera's limits).
    faults : CameraFaults, optional
    rng : numpy Generator, optional
        Noise source (seed it for reproducible frames).
    sleep : callable, optional
        Called with each exposure's duration in seconds; ``time.sleep`` makes exposures take real
        time (default: they take none, only the camera's own clock advances).
    """

    def __init__(
        self,
        projector: Projector | None,
        geometry: RigGeometry,
        scene_height_mm: np.ndarray | None = None,
        appearance: Appearance = Appearance(),
        *,
        reference_exposure_us: float = 10_000.0,
        exposure_limits_us: tuple[float, float] = (20.0, 1_000_000.0),
        faults: CameraFaults | None = None,
        rng: np.random.Generator | None = None,
        sleep: Callable[[float], None] | None = None,
        name: str | None = None,
        on_sequence_error: str = "raise",
    ) -> None:
        super().__init__(name or "simulated camera", on_sequence_error=on_sequence_error)
        if projector is not None and tuple(projector.size) != geometry.projector_size:
            raise ValueError(
                f"geometry: projector size {geometry.projector_size} differs from the projector's {tuple(projector.size)}"
            )
        if not reference_exposure_us > 0:
            raise ValueError(f"reference_exposure_us: expected > 0, found {reference_exposure_us}")
        self.projector = projector
        self.geometry = geometry
        self.appearance = appearance
        self.reference_exposure_us = float(reference_exposure_us)
        low, high = (float(v) for v in exposure_limits_us)
        if not 0 < low <= high:
            raise ValueError(f"exposure_limits_us: expected 0 < shortest <= longest, found {exposure_limits_us}")
        self.limits_us = (low, high)
        self.faults = faults or CameraFaults()
        self.rng = rng if rng is not None else np.random.default_rng()
        self.sleep = sleep
        self._mapping: ProjectorMap | None = None
        self.set_scene(scene_height_mm)
        self._exposure_us = reference_exposure_us
        self._lock = threading.Condition()
        self._queue: collections.deque[Frame] = collections.deque()
        self._clock_s = 0.0
        self._exposures = 0
        self._next_id = 0
        self._software_triggers = 0
        self._gone = False
        self._armed = False

    # -- the scene ------------------------------------------------------------------------------
    def set_scene(self, height_mm: np.ndarray | None) -> None:
        """Put a new scene (camera-sized height map, None: reference plane) under the camera."""
        shape = self.geometry.camera_shape
        height = np.zeros(shape) if height_mm is None else np.asarray(height_mm, dtype=np.float64)
        if height.shape != shape:
            raise ValueError(f"scene_height_mm: expected shape {shape} (camera rows, cols), found {height.shape}")
        self._mapping = projector_coordinates(height, self.geometry)

    @property
    def mapping(self) -> ProjectorMap:
        assert self._mapping is not None
        return self._mapping

    def _projected(self) -> np.ndarray:
        """Drive levels reaching each camera pixel from the projector's current frame."""
        frame = None
        projector = self.projector
        if projector is not None:
            frame = projector.last_frame()
            if frame is None and projector.is_open and projector.pattern is not None:
                frame = apply_gamma_lut(pattern_image(projector.pattern, projector.size), projector.gamma_lut)
        if frame is None:
            return np.zeros(self.geometry.camera_shape, dtype=np.float32)
        return sample_projector_image(frame, self.mapping)

    def _render(self) -> np.ndarray:
        fmt = self._pixel_format
        gain = self.appearance.gain * self._gain * self._exposure_us / self.reference_exposure_us
        appearance = replace(self.appearance, gain=gain, bit_depth=fmt.bit_depth)
        image = expose(self._projected(), self.mapping, appearance, self.rng)
        x, y, w, h = self._roi or (0, 0, *self.sensor_size)
        return np.ascontiguousarray(image[y : y + h, x : x + w], dtype=fmt.dtype)

    # -- the trigger input ----------------------------------------------------------------------
    def pulse(self, trigger_index: int) -> None:
        """Hardware trigger input: one exposure pulse from the trigger box (ignored unless armed for it)."""
        with self._lock:
            if self._gone or not self._armed or self._trigger_source is TriggerSource.SOFTWARE:
                log.debug("%s: pulse %d ignored (not armed for hardware triggers)", self.name, trigger_index)
                return
            self.note_trigger(self._clock_s)
            self._expose_burst(int(trigger_index))

    def _expose_burst(self, trigger_index: int) -> None:
        count = self._burst_length if self._trigger_mode is TriggerMode.BURST else 1
        for _ in range(count):
            self._expose_one(trigger_index)
        self._lock.notify_all()

    def _expose_one(self, trigger_index: int) -> None:
        index = self._exposures
        faults = self.faults
        if faults.disappear_after is not None and index >= faults.disappear_after:
            self._gone = True
            log.warning("%s: device disappeared after %d exposures", self.name, index)
            return
        self._exposures += 1
        start_s = self._clock_s
        self._clock_s += self._exposure_us * 1e-6 + READOUT_S
        if self.sleep is not None:
            self.sleep(self._exposure_us * 1e-6)
        if index in faults.timeout_on:
            log.debug("%s: exposure %d: trigger missed (fault)", self.name, index)
            return
        frame = Frame(self._render(), self._next_id, start_s, self._exposure_us, trigger_index)
        self._next_id += 1
        if index in faults.stale:
            frame.timestamp_s = start_s - self._exposure_us * 1e-6 - READOUT_S
        if index in faults.drop:
            log.debug("%s: exposure %d: frame %d lost (fault)", self.name, index, frame.frame_id)
            return
        self._queue.append(frame)
        if index in faults.duplicate:
            self._queue.append(replace(frame, image=frame.image.copy()))

    # -- hooks ----------------------------------------------------------------------------------
    @property
    def sensor_size(self) -> tuple[int, int]:
        return (self.geometry.camera_width, self.geometry.camera_height)

    @property
    def supported_pixel_formats(self) -> tuple[PixelFormat, ...]:
        return (PixelFormat.MONO8, PixelFormat.MONO12, PixelFormat.MONO16)

    def now(self) -> float:
        return self._clock_s

    def _read_exposure_limits_us(self) -> tuple[float, float] | None:
        return self.limits_us

    def _check_present(self) -> None:
        if self._gone:
            raise DeviceNotFoundError(f"{self.name}: device disappeared (after {self._exposures} exposures)")

    def _open(self) -> None:
        with self._lock:
            self._check_present()

    def _close(self) -> None:
        with self._lock:
            self._armed = False
            self._queue.clear()

    def _set_roi(self, roi: tuple[int, int, int, int]) -> None:
        self._check_present()

    def _set_trigger(self, source: TriggerSource, mode: TriggerMode) -> None:
        self._check_present()

    def _start(self) -> None:
        with self._lock:
            self._check_present()
            self._queue.clear()
            self._exposures = self._next_id = self._software_triggers = 0
            self._armed = True

    def _stop(self) -> None:
        with self._lock:
            self._armed = False
            self._queue.clear()

    def _do_trigger(self) -> None:
        with self._lock:
            self._check_present()
            index = self._software_triggers
            self._software_triggers += 1
            self._expose_burst(index)
            self._check_present()

    def _fetch(self, timeout_s: float) -> Frame:
        with self._lock:
            if not self._lock.wait_for(lambda: self._queue or self._gone, timeout=timeout_s):
                raise DeviceTimeoutError(f"{self.name}: no frame within {timeout_s:g} s")
            if not self._queue:
                self._check_present()
            return self._queue.popleft()
