"""The built-in simulated rig: real drivers and simulated hardware wired like a lab rig.

- projector: the moderngl off-screen projector really renders each pattern (EGL);
- camera: :class:`mock_devices.camera.SimulatedCamera` looks at that rendered frame on a virtual
  scene through the reference-plane geometry of ``[simulation]``;
- trigger: :class:`mock_devices.trigger_box.FakeTriggerBox` serves the trigger-box protocol on a
  real pseudo-terminal, the real :class:`drivers.trigger_box.SerialTriggerBox` drives it, and
  every pulse reaches the camera's hardware input; or the camera's software trigger.

The geometry, photometry and scene helpers here also serve ``rig simulate`` (offline synthesis).
"""

from __future__ import annotations

import contextlib
import re
import zlib
from dataclasses import replace
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.camera import PixelFormat
from drivers.projector_gl import GLProjector
from drivers.trigger_box import SerialTriggerBox
from mock_devices import board_synth, scenes, synth
from mock_devices.camera import CameraFaults, SimulatedCamera
from mock_devices.trigger_box import FakeTriggerBox, TriggerFaults
from rig.config import RigConfig
from rig.errors import ConfigError
from rig.hardware.scenes import check_scene_name

if TYPE_CHECKING:
    from calibration.camera import BoardSpec

PLANE_SCENE = re.compile(r"plane-at-(-?\d+(?:\.\d+)?)mm")
BOARD_SCENE = re.compile(r"board-on-reference|board-view-(\d+)")


def geometry_from_config(config: RigConfig) -> synth.RigGeometry:
    """Reference-plane geometry of ``[simulation]`` with the configured camera and projector sizes."""
    sim = config.simulation
    try:
        return synth.RigGeometry(
            l0_mm=sim.l0_mm,
            d0_mm=sim.d0_mm,
            f0_per_mm=sim.f0_per_mm,
            f0_frequency=sim.f0_frequency,
            pixel_mm=config.pixel_mm(),
            camera_width=config.camera.width,
            camera_height=config.camera.height,
            projector_width=config.projector.width,
            projector_height=config.projector.height,
        )
    except ValueError as exc:
        raise ConfigError(f"{config.source or 'rig config'}: [simulation] {exc}") from None


def appearance_from_config(config: RigConfig) -> synth.Appearance:
    """Photometry of ``[simulation]``: ambient light, projector gamma, camera gain and noise, 8 bit.

    With ``full_well_e`` the noise is the sensor's shot and read noise (:class:`mock_devices.synth.Sensor`).
    """
    sim = config.simulation
    sensor = None
    if sim.full_well_e is not None:
        try:
            sensor = synth.Sensor(full_well_e=sim.full_well_e, read_noise_e=sim.read_noise_e)
        except ValueError as exc:
            raise ConfigError(f"{config.source or 'rig config'}: [simulation] {exc}") from None
    return synth.Appearance(
        ambient=sim.ambient, gamma=sim.gamma, gain=sim.camera_gain, snr_db=sim.snr_db, bit_depth=8, sensor=sensor
    )


def _variant(config: RigConfig) -> dict[str, int]:
    """The scene's ``variant`` parameter from ``[simulation] scene_variant`` (ConfigError for a scene without variants)."""
    variant = config.simulation.scene_variant
    if not variant:
        return {}
    if config.simulation.scene not in scenes.VARIANTS:
        raise ConfigError(
            f"{config.source or 'rig config'}: [simulation] scene_variant: expected 0 for scene "
            f"{config.simulation.scene!r} (variants exist for {', '.join(scenes.VARIANTS)}), found {variant}"
        )
    return {"variant": variant}


def scene_reflectance(config: RigConfig, scene: str, geometry: synth.RigGeometry, height_mm: np.ndarray) -> Any:
    """Reflectance the simulated camera sees for a capture's ``scene`` label (1.0: uniformly matte).

    ``"object"`` is the configured scene; a scene of :data:`mock_devices.scenes.REFLECTANCES` (such as
    ``shiny-and-dark``) brings its own map, any other scene is matte.
    """
    name, variant = (config.simulation.scene, _variant(config).get("variant", 0)) if scene == "object" else (scene, 0)
    reflectance = scenes.scene_reflectance(name, height_mm, geometry.pixel_mm, geometry.l0_mm, geometry.d0_mm, variant)
    return appearance_from_config(config).reflectivity if reflectance is None else reflectance


def scene_height(config: RigConfig, scene: str, geometry: synth.RigGeometry) -> np.ndarray:
    """Height map (mm) in front of the simulated rig for a capture's ``scene`` label.

    ``"object"``: the configured scene; ``"reference"``: the reference plane (zero);
    ``"plane-at-25mm"``: a flat plane at that height (calibration); a scene name from
    :data:`mock_devices.scenes.SCENES` is accepted too.
    """
    h, w, pixel_mm = geometry.camera_height, geometry.camera_width, geometry.pixel_mm
    if scene == "object":
        check_scene_name(config.simulation.scene, str(config.source) if config.source is not None else "rig config")
        return scenes.make_scene(config.simulation.scene, h, w, pixel_mm, **_variant(config))
    if scene == "reference":
        return np.zeros((h, w))
    match = PLANE_SCENE.fullmatch(scene)
    if match:
        level = float(match.group(1))
        if level >= geometry.l0_mm:
            raise ConfigError(f"--scene {scene}: expected a plane below l0_mm = {geometry.l0_mm}")
        return scenes.flat(h, w, pixel_mm, level_mm=level)
    if scene in scenes.SCENES:
        return scenes.make_scene(scene, h, w, pixel_mm)
    raise ConfigError(
        f"--scene: expected 'object', 'reference', 'plane-at-<height>mm' or one of {', '.join(scenes.SCENES)} "
        f"for the simulated rig, found {scene!r}"
    )


# Named device faults the simulated rig can be opened with (the console's fault drill, its tests):
# each is a readable failure a real rig shows, raised by the real driver code paths.
FAULTS = {
    "camera-gone": "the camera disappears after 3 exposures (unplugged)",
    "trigger-timeout": "the trigger box stops answering (hung firmware)",
}


def fault_arguments(fault: str, config: RigConfig) -> dict[str, Any]:
    """:class:`SimulatedRig` arguments injecting the named fault of :data:`FAULTS`."""

    if fault == "camera-gone":
        return {"camera_faults": CameraFaults(disappear_after=3)}
    if fault == "trigger-timeout":
        if config.trigger.backend == "software":
            raise ConfigError("fault trigger-timeout: the rig uses the camera's software trigger ([trigger] backend)")
        return {"trigger_faults": TriggerFaults(stall=True)}
    raise ConfigError(f"fault: expected one of {', '.join(FAULTS)}, found {fault!r}")


class SimulatedRig:
    """Opens the simulated rig of ``config`` looking at ``scene``; closes everything on exit.

    Attributes once entered: ``projector`` (GLProjector), ``camera`` (SimulatedCamera),
    ``trigger_box`` (the SerialTriggerBox driver on the fake box's pty, or None for the
    software trigger) and ``fake_box`` (the FakeTriggerBox behind it).
    """

    def __init__(
        self,
        config: RigConfig,
        scene: str = "object",
        camera_faults: Any = None,
        trigger_faults: Any = None,
        fake_box_options: dict[str, Any] | None = None,
    ) -> None:
        self.config = config
        self.scene = scene
        self.geometry = geometry_from_config(config)
        self.height_mm = scene_height(config, scene, self.geometry)
        self.camera_faults = camera_faults
        self.trigger_faults = trigger_faults
        self.fake_box_options = dict(fake_box_options or {})  # more FakeTriggerBox arguments (watchdog_s, ...)
        self.projector: Any = None
        self.camera: Any = None
        self.trigger_box: Any = None
        self.fake_box: Any = None
        self._stack = contextlib.ExitStack()

    def description(self) -> dict[str, Any]:
        """What capture.json records about the simulation (scene and geometry), for provenance."""
        sim, g = self.config.simulation, self.geometry
        return {
            "scene": sim.scene if self.scene == "object" else self.scene,
            **({"scene_variant": sim.scene_variant} if self.scene == "object" and sim.scene_variant else {}),
            "snr_db": sim.snr_db,
            "seed": sim.seed,
            "l0_mm": g.l0_mm,
            "d0_mm": g.d0_mm,
            "f0_per_mm": g.f0_per_mm,
            "f0_frequency": g.f0_frequency,
            "pixel_mm": g.pixel_mm,
            "max_height_mm": float(np.max(self.height_mm)),
        }

    def __enter__(self) -> SimulatedRig:

        try:
            # GLProjector reads each frame back when it is shown, in the thread that owns its
            # OpenGL context: the camera, exposed from the trigger box's thread, never touches GL.
            self.projector = self._stack.enter_context(GLProjector(self.config.projector.size, name="GLProjector"))
            appearance = replace(
                appearance_from_config(self.config),
                reflectivity=scene_reflectance(self.config, self.scene, self.geometry, self.height_mm),
            )
            self.camera = SimulatedCamera(
                self.projector,
                self.geometry,
                self.height_mm,
                appearance,
                reference_exposure_us=self.config.camera.exposure_us,
                faults=self.camera_faults,
                rng=np.random.default_rng([self.config.simulation.seed, zlib.crc32(self.scene.encode())]),
            )
            self._stack.enter_context(self.camera)
            self.camera.pixel_format = PixelFormat[self.config.camera.pixel_format.upper()]
            if self.config.trigger.backend != "software":
                self._open_trigger_box()
        except BaseException:
            self._stack.close()
            raise
        return self

    def place(self, scene: str, board: BoardSpec | None = None) -> None:
        """Put ``scene`` in front of the open rig, as an operator would between two scans.

        Plane and object labels as for :func:`scene_height`; ``board-on-reference`` and
        ``board-view-N`` lay ``board`` flat on the reference plane or hold it tilted (view N), as
        a printed target whose albedo the camera sees under the projector's light.
        """
        reflectivity: float | np.ndarray = appearance_from_config(self.config).reflectivity
        match = BOARD_SCENE.fullmatch(scene)
        if match:
            if board is None:
                raise ConfigError(f"scene {scene!r}: the simulated rig needs the board's layout to show it")
            height = np.zeros(self.geometry.camera_shape)
            reflectivity = board_albedo(self.config, board, int(match.group(1) or 0))
        else:
            height = scene_height(self.config, scene, self.geometry)
            reflectivity = scene_reflectance(self.config, scene, self.geometry, height)
        self.camera.set_scene(height)
        self.camera.appearance = replace(self.camera.appearance, reflectivity=reflectivity)
        self.scene, self.height_mm = scene, height

    def _open_trigger_box(self) -> None:

        self.fake_box = self._stack.enter_context(
            FakeTriggerBox(on_pulse=self.camera.pulse, faults=self.trigger_faults, **self.fake_box_options)
        )
        self.trigger_box = self._stack.enter_context(
            SerialTriggerBox(
                self.fake_box.port, baudrate=self.config.trigger.baudrate, timeout_s=self.config.trigger.timeout_s
            )
        )

    def __exit__(self, *exc: object) -> None:
        self._stack.close()


def board_albedo(config: RigConfig, board: BoardSpec, index: int) -> np.ndarray:
    """Albedo (0..1) the simulated camera sees of a board: flat on the plane (index 0) or tilted.

    The simulated camera looks straight down at l0 with ``pixel_mm`` per pixel on the plane: a
    pinhole of focal l0 / pixel_mm without distortion. Poses are seeded by the config and index.
    """

    g = geometry_from_config(config)
    camera = board_synth.PinholeCamera.simple(g.camera_width, g.camera_height, g.l0_mm / g.pixel_mm)
    size = (board.squares[0] * board.square_mm, board.squares[1] * board.square_mm)
    rng = np.random.default_rng([config.simulation.seed, index])
    if index == 0:
        rvec, tvec = board_synth.board_pose(0.0, 0.0, 2.0, (0.0, 0.0, g.l0_mm), size)
    else:
        tilt = rng.uniform(-30, 30, size=2)
        shift = rng.uniform(-0.15, 0.15, size=2) * g.camera_width * g.pixel_mm
        centre = (shift[0], shift[1] * 0.7, g.l0_mm * rng.uniform(0.8, 0.95))
        rvec, tvec = board_synth.board_pose(tilt[0], tilt[1], rng.uniform(-10, 10), centre, size)
    px_per_mm = max(2.0, 2.0 / g.pixel_mm)
    if board.kind == "chessboard":
        texture = board_synth.chessboard_texture(board.squares, board.square_mm, px_per_mm, board.square_mm)
    else:
        texture = board_synth.charuco_texture(
            board.squares,
            board.square_mm,
            board.marker_mm or 0.7 * board.square_mm,
            px_per_mm,
            board.square_mm,
            board.dictionary,
        )
    image = board_synth.render_board_view(
        texture, px_per_mm, board.square_mm, camera, rvec, tvec, gain=255.0, offset=0.0, noise_dn=0.0
    )
    return image.astype(np.float64) / 255.0


# Why the simulated rig cannot acquire a stereo session (rig calibrate and the console say it).
STEREO_REFUSAL = (
    "--model stereo: the built-in simulated rig's camera follows the reference-plane geometry, not a "
    "pinhole; a stereo session needs a real rig (or --from a stored session)"
)


class WorldOperator:
    """The simulated rig's hands in a calibration session: it places planes and boards itself.

    Implements the calibration :class:`rig.calibrate.operator.Operator` protocol, so a session on
    the simulated rig runs unattended through the same acquisition code as on a real rig.
    """

    def __init__(self, rig: SimulatedRig, board: BoardSpec | None = None) -> None:
        self.rig = rig
        self.board_spec = board

    def plane(self, height_mm: float) -> None:
        self.rig.place("reference" if height_mm == 0 else f"plane-at-{height_mm:g}mm")

    def board(self, index: int, on_plane: bool) -> None:
        self.rig.place("board-on-reference" if on_plane else f"board-view-{index}", self.board_spec)

    def pose(self, index: int) -> None:
        raise ConfigError(STEREO_REFUSAL)

    def clear(self) -> None:
        self.rig.place("reference")


def artefact_shapes(placement: Any, artefacts: Any) -> list[Any]:
    """The ray-cast shapes of a verification placement (:class:`rig.verify.guideline.Placement`).

    A sphere, two spheres joined by a bar a fifth of their diameter thick, or a flat plate, with
    the calibrated sizes of ``artefacts`` (:class:`rig.verify.artefacts.Artefacts`).
    """
    from mock_devices import artefacts as shapes

    if placement.kind == "sphere":
        return [shapes.Sphere(placement.centres[0], artefacts.sphere_diameter_mm / 2)]
    if placement.kind == "ball-bar":
        radius = artefacts.ball_bar_sphere_diameter_mm / 2
        first, second = placement.centres
        bar = shapes.Cylinder(first, second, radius / 5)
        return [shapes.Sphere(first, radius), shapes.Sphere(second, radius), bar]
    if placement.kind == "plane":
        return [
            shapes.Plate(
                placement.centres[0],
                placement.along,
                placement.across,
                artefacts.plane_length_mm,
                artefacts.plane_width_mm,
            )
        ]
    raise ConfigError(f"placement: expected a sphere, ball-bar or plane, found {placement.kind!r}")


class ArtefactWorld:
    """The simulated rig's hands in a verification session: it puts each artefact where it is asked.

    Implements :class:`rig.verify.operator.Operator`, so that `rig verify` runs unattended on
    the simulated rig through the same acquisition code as with a person at a real rig.
    """

    def __init__(self, rig: SimulatedRig, artefacts: Any) -> None:
        self.rig = rig
        self.artefacts = artefacts

    def place(self, placement: Any) -> None:
        from mock_devices.artefacts import ray_cast_heights

        g = self.rig.geometry
        shapes = artefact_shapes(placement, self.artefacts)
        height = ray_cast_heights(g.camera_height, g.camera_width, g.pixel_mm, g.l0_mm, shapes)
        self.rig.camera.set_scene(height)
        matte = appearance_from_config(self.rig.config).reflectivity
        self.rig.camera.appearance = replace(self.rig.camera.appearance, reflectivity=matte)
        self.rig.scene, self.rig.height_mm = placement.name, height
