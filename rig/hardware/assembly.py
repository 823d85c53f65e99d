"""Builds the devices a rig config names, opens them together and closes them in reverse order.

Every backend's module is importable without its optional library (pypylon, glfw) or device
library (libusb): a backend loads them when a config names it and it is opened, so a lab PC
without them still runs the simulated rig. The simulated rig never enters a real rig's code path
except through the same driver interfaces.
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.camera import Camera, PixelFormat
from drivers.camera_opencv import OpenCVCamera
from drivers.camera_pylon import PylonCamera
from drivers.dlp import LightCrafter4500
from drivers.projector import Projector
from drivers.projector_dlp import DlpVideoProjector
from drivers.projector_gl import GLProjector
from drivers.projector_window import WindowProjector
from drivers.trigger_box import SerialTriggerBox
from rig.config import RigConfig
from rig.errors import ConfigError
from rig.hardware.simulated import SimulatedRig, WorldOperator, fault_arguments
from rig.hardware.trigger_paths import BoxTrigger, SoftwareTrigger

if TYPE_CHECKING:
    from calibration.camera import BoardSpec

log = logging.getLogger(__name__)


@dataclass
class RigDevices:
    """Opened devices of one rig, ready for :func:`rig.acquisition.loop.run_scan`."""

    projector: Projector
    camera: Camera
    trigger: SoftwareTrigger | BoxTrigger
    config: RigConfig
    simulation: Any = None  # rig.hardware.simulated.SimulatedRig when the camera is simulated


def load_gamma_lut(config: RigConfig) -> np.ndarray | None:
    """The projector's gamma LUT file (.npy, or text with one drive level per line), or None."""
    path = config.projector.gamma_lut
    if path is None:
        return None
    try:
        lut = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, ndmin=1)
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: cannot read the gamma LUT ([projector] gamma_lut): {exc}") from None
    lut = np.asarray(lut, dtype=np.float64).ravel()
    if lut.size < 2 or not np.all(np.isfinite(lut)) or lut.min() < 0 or lut.max() > 1:
        raise ConfigError(
            f"{path}: gamma LUT: expected at least 2 drive levels in [0, 1], found {lut.size} values "
            f"in [{lut.min() if lut.size else 'nan'}, {lut.max() if lut.size else 'nan'}]"
        )
    return lut


def build_projector(config: RigConfig) -> Projector:
    """The projector driver a config names (not opened)."""
    backend = config.projector.backend
    size = config.projector.size
    if backend == "gl-offscreen":
        return GLProjector(size)
    if backend == "window":
        return WindowProjector(size, monitor=config.projector.monitor)
    if backend == "dlp4500":
        return DlpVideoProjector(WindowProjector(size, monitor=config.projector.monitor), LightCrafter4500())
    raise ConfigError(f"[projector] backend: unknown {backend!r}")


def build_camera(config: RigConfig) -> Camera:
    """A real camera driver a config names (not opened); the simulated camera is built by the simulated rig."""
    backend = config.camera.backend
    if backend == "opencv":
        return OpenCVCamera(config.camera.index)
    if backend == "pylon":
        return PylonCamera(serial=config.camera.serial)
    raise ConfigError(f"[camera] backend: unknown {backend!r}")


def _configure_camera(camera: Camera, config: RigConfig) -> None:
    """Pixel format and ROI (centred, of the configured size) before the scan starts."""

    camera.pixel_format = PixelFormat[config.camera.pixel_format.upper()]
    sensor_w, sensor_h = camera.sensor_size
    width, height = min(config.camera.width, sensor_w), min(config.camera.height, sensor_h)
    if (width, height) != (sensor_w, sensor_h):
        camera.roi = ((sensor_w - width) // 2, (sensor_h - height) // 2, width, height)


def trigger_path(camera: Camera, box: Any | None) -> SoftwareTrigger | BoxTrigger:
    """The camera's software trigger, or the trigger box pulsing its hardware line."""
    return SoftwareTrigger(camera) if box is None else BoxTrigger(box)


def rig_sets_up_scenes(config: RigConfig) -> bool:
    """True when the rig places its own calibration scenes (the simulated rig): no person needed."""
    return config.simulated


def world_operator(devices: RigDevices, board: BoardSpec | None = None) -> Any:
    """The operator that places calibration scenes by itself (simulated rig), or None on a real rig."""
    if devices.simulation is None:
        return None

    return WorldOperator(devices.simulation, board)


def artefact_world(devices: RigDevices, artefacts: Any) -> Any:
    """The operator that places verification artefacts by itself (simulated rig), or None on a real rig."""
    if devices.simulation is None:
        return None
    from rig.hardware.simulated import ArtefactWorld

    return ArtefactWorld(devices.simulation, artefacts)


@contextlib.contextmanager
def open_rig(config: RigConfig, scene: str = "object", fault: str | None = None) -> Iterator[RigDevices]:
    """Open every device of ``config``; ``scene`` chooses what a simulated camera looks at.

    ``fault`` names a device fault of the simulated rig (:data:`rig.hardware.simulated.FAULTS`) to
    open it with; a real rig refuses it.
    """
    if fault is not None and not config.simulated:
        raise ConfigError(f"fault {fault!r}: faults can only be injected into the simulated rig")
    with contextlib.ExitStack() as stack:
        if config.simulated:
            faults = fault_arguments(fault, config) if fault is not None else {}
            simulation = stack.enter_context(SimulatedRig(config, scene=scene, **faults))
            projector, camera, box = simulation.projector, simulation.camera, simulation.trigger_box
        else:
            simulation = None
            projector = build_projector(config)
            stack.enter_context(projector)
            camera = build_camera(config)
            stack.enter_context(camera)
            _configure_camera(camera, config)
            box = None
            if config.trigger.backend == "serial":
                assert config.trigger.port is not None  # rig.config requires it for backend "serial"
                box = SerialTriggerBox(
                    config.trigger.port, baudrate=config.trigger.baudrate, timeout_s=config.trigger.timeout_s
                )
                stack.enter_context(box)
        lut = load_gamma_lut(config)
        if lut is not None:
            projector.set_gamma_lut(lut)
        trigger = trigger_path(camera, box)
        log.info(
            "rig open: projector %s %s, camera %s, trigger %s",
            projector.name,
            projector.size,
            camera.name,
            "software" if box is None else box,
        )
        yield RigDevices(projector, camera, trigger, config, simulation)
