"""Contract tests every projector, camera and trigger-box backend passes (real or simulated).

Mix a contract into one test class per backend and give it a factory::

    class TestGLProjector(ProjectorContract):
        def make_projector(self, size):
            return GLProjector(size)

Real hardware is opt-in: ``pytest --device camera-opencv:0`` (see ``device_option``).
"""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from drivers import trigger_protocol as tp
from drivers.camera import Camera, Frame, PixelFormat, TriggerMode, TriggerSource
from drivers.errors import DeviceTimeoutError, IncompatibleStateError, UnsupportedFeatureError
from drivers.projector import Projector, apply_gamma_lut
from drivers.trigger_box import Polarity, TriggerBox
from processing.projection.patterns import pattern_image

SIZE = (128, 96)

# One pattern of every kind and option of capture-format.md, and the projector-only alignment grid.
PATTERNS = [
    {"kind": "sinusoid", "axis": "x", "frequency": 5, "steps": 6, "step": 1},
    {
        "kind": "sinusoid",
        "axis": "y",
        "frequency": 3,
        "steps": 4,
        "step": 3,
        "offset": 0.4,
        "amplitude": 0.3,
        "phase_rad": math.pi,
    },
    {"kind": "sinusoid", "axis": "x", "frequency": 40, "steps": 3, "step": 0, "shift_rad": 1.1},
    {"kind": "gray", "axis": "x", "bit": 0, "bits": 7},
    {"kind": "gray", "axis": "x", "bit": 6, "bits": 7},
    {"kind": "gray", "axis": "y", "bit": 2, "bits": 5, "inverted": True},
    {"kind": "binary", "axis": "x", "bit": 4, "bits": 6},
    {"kind": "gray", "axis": "x", "bit": 3, "bits": 5, "period_px": 7, "inverted": True},
    {"kind": "binary", "axis": "y", "bit": 2, "bits": 4, "period_px": 3.5},
    {"kind": "flat", "level": 0.0},
    {"kind": "flat", "level": 0.3},
    {"kind": "flat", "level": 1.0},
    {
        "kind": "speckle-sinusoid",
        "axis": "x",
        "frequency": 8,
        "steps": 3,
        "step": 2,
        "seed": 4,
        "dot_px": 3,
        "speckle_gain": 0.3,
    },
    {"kind": "grid", "pitch_px": 16},
    {"kind": "grid", "pitch_px": 7, "line_px": 3, "crosshair_px": 5, "level": 0.8, "background": 0.1},
]


def pattern_id(pattern: dict) -> str:
    return "-".join(f"{k}={v}" for k, v in pattern.items() if k != "kind").join((pattern["kind"] + "[", "]"))


def device_option(request: pytest.FixtureRequest, family: str) -> str | None:
    """The address given with ``--device FAMILY[:ADDRESS]`` ('' if none), or None if not asked for."""
    for entry in request.config.getoption("--device", default=None) or []:
        name, _, address = entry.partition(":")
        if name == family:
            return address
    return None


def speckle_available() -> bool:
    try:
        import processing.projection.speckle  # noqa: F401
    except ImportError:
        return False
    return True


def expected_drive(pattern: dict, size: tuple[int, int], lut: np.ndarray | None = None) -> np.ndarray:
    """What a projector must put out: the pattern maths clipped to [0, 1], then the LUT."""
    if pattern["kind"] == "speckle-sinusoid" and not speckle_available():
        pytest.skip("processing.projection.speckle is not available: speckle-sinusoid cannot be checked")
    return apply_gamma_lut(pattern_image(pattern, size), lut)


class ProjectorContract:
    """Behaviour every :class:`Projector` backend shares.

    Set ``renders_frames = False`` for a backend whose ``last_frame`` is always None and
    ``tolerance`` to the largest allowed difference from ``processing.projection.patterns``.
    """

    renders_frames = True
    tolerance = 1.0 / 255.0

    def make_projector(self, size: tuple[int, int]) -> Projector:
        raise NotImplementedError

    @pytest.fixture
    def projector(self):
        projector = self.make_projector(SIZE)
        yield projector
        projector.close()

    def test_size_is_width_height(self, projector: Projector) -> None:
        assert projector.size == SIZE
        assert (projector.width, projector.height) == SIZE

    def test_show_needs_open(self, projector: Projector) -> None:
        with pytest.raises(IncompatibleStateError):
            projector.show(PATTERNS[0])

    def test_wait_before_show_is_refused(self, projector: Projector) -> None:
        with projector:
            with pytest.raises(IncompatibleStateError):
                projector.wait_shown()

    def test_open_close_are_idempotent_and_context_managed(self, projector: Projector) -> None:
        with projector as opened:
            assert opened is projector and projector.is_open
            projector.open()
            assert projector.is_open
        assert not projector.is_open
        projector.close()
        with pytest.raises(IncompatibleStateError):
            projector.show(PATTERNS[0])

    @pytest.mark.parametrize(
        "bad",
        [
            {"kind": "checkerboard"},
            {"kind": "sinusoid", "axis": "x", "steps": 4, "step": 0},
            {"kind": "gray", "axis": "z", "bit": 0, "bits": 4},
        ],
        ids=["unknown-kind", "missing-frequency", "bad-axis"],
    )
    def test_bad_pattern_names_the_problem(self, projector: Projector, bad: dict) -> None:
        with projector:
            with pytest.raises(ValueError, match="pattern|axis"):
                projector.show(bad)

    @pytest.mark.parametrize(
        "lut",
        [np.array([0.5]), np.array([0.0, 1.5]), np.ones((4, 4)) * 0.5, np.array([0.0, np.nan])],
        ids=["one-entry", "above-one", "2-d", "nan"],
    )
    def test_bad_lut_is_refused(self, projector: Projector, lut: np.ndarray) -> None:
        with pytest.raises(ValueError, match="lut"):
            projector.set_gamma_lut(lut)

    def test_timeout_must_be_finite(self, projector: Projector) -> None:
        with projector:
            projector.show(PATTERNS[0])
            with pytest.raises(ValueError, match="timeout_s"):
                projector.wait_shown(timeout_s=math.inf)

    def test_last_frame_is_none_before_show(self, projector: Projector) -> None:
        with projector:
            assert projector.last_frame() is None

    @pytest.mark.parametrize("pattern", PATTERNS, ids=pattern_id)
    def test_renders_the_pattern_maths(self, projector: Projector, pattern: dict) -> None:
        if not self.renders_frames:
            pytest.skip(f"{type(projector).__name__} cannot hand back what it shows")
        expected = expected_drive(pattern, SIZE)
        with projector:
            projector.show(pattern)
            projector.wait_shown(timeout_s=5.0)
            frame = projector.last_frame()
        assert frame is not None and frame.shape == (SIZE[1], SIZE[0]) and frame.dtype == np.float32
        np.testing.assert_allclose(frame, expected, atol=self.tolerance, rtol=0)

    @pytest.mark.parametrize("pattern", [PATTERNS[0], PATTERNS[1], PATTERNS[-3], PATTERNS[-1]], ids=pattern_id)
    def test_gamma_lut_is_applied(self, projector: Projector, pattern: dict) -> None:
        if not self.renders_frames:
            pytest.skip(f"{type(projector).__name__} cannot hand back what it shows")
        lut = np.linspace(0.0, 1.0, 1024) ** (1.0 / 2.2)  # inverse of a 2.2 display gamma
        expected = expected_drive(pattern, SIZE, lut)
        with projector:
            projector.set_gamma_lut(lut)
            projector.show(pattern)
            projector.wait_shown(timeout_s=5.0)
            corrected = projector.last_frame()
            projector.set_gamma_lut(None)
            projector.show(pattern)
            projector.wait_shown(timeout_s=5.0)
            plain = projector.last_frame()
        np.testing.assert_allclose(corrected, expected, atol=self.tolerance, rtol=0)
        # the LUT made a visible difference (mid-grey goes up by ~0.23 under 1/2.2)
        assert np.max(corrected - plain) > 0.1

    def test_lut_set_before_open_is_kept(self, projector: Projector) -> None:
        if not self.renders_frames:
            pytest.skip(f"{type(projector).__name__} cannot hand back what it shows")
        lut = np.array([0.0, 0.25, 1.0])  # piecewise linear: 0.5 -> 0.25
        projector.set_gamma_lut(lut)
        with projector:
            projector.show({"kind": "flat", "level": 0.5})
            projector.wait_shown(timeout_s=5.0)
            frame = projector.last_frame()
        np.testing.assert_allclose(frame, 0.25, atol=self.tolerance)

    def test_counts_shown_patterns(self, projector: Projector) -> None:
        with projector:
            for pattern in PATTERNS[:3]:
                projector.show(pattern)
                projector.wait_shown(timeout_s=5.0)
            assert projector.shown_count == 3
            assert projector.pattern == PATTERNS[2]


class CameraContract:
    """Behaviour every :class:`Camera` backend shares.

    ``make_camera`` returns an unopened camera that produces a frame for each software trigger.
    """

    fetch_timeout_s = 5.0

    def make_camera(self) -> Camera:
        raise NotImplementedError

    @pytest.fixture
    def camera(self):
        camera = self.make_camera()
        yield camera
        camera.close()

    def grab_one(self, camera: Camera) -> Frame:
        camera.trigger()
        return camera.fetch(timeout_s=self.fetch_timeout_s)

    def test_needs_open_and_start(self, camera: Camera) -> None:
        with pytest.raises(IncompatibleStateError):
            camera.start()
        with camera:
            with pytest.raises(IncompatibleStateError):
                camera.trigger()
            with pytest.raises(IncompatibleStateError):
                camera.fetch(timeout_s=0.1)
        assert not camera.is_open

    def test_software_trigger_gives_numbered_frames(self, camera: Camera) -> None:
        with camera:
            camera.set_trigger(TriggerSource.SOFTWARE)
            camera.start()
            frames = [self.grab_one(camera) for _ in range(3)]
            shape, dtype = (camera.height, camera.width), camera.pixel_format.dtype
        assert [f.frame_id for f in frames] == [0, 1, 2]
        for frame in frames:
            assert frame.image.shape == shape and frame.image.dtype == dtype
            assert frame.exposure_us > 0 and frame.sequence_error is None
        times = [f.timestamp_s for f in frames]
        assert times == sorted(times)

    def test_restart_numbers_from_zero(self, camera: Camera) -> None:
        with camera:
            camera.start()
            self.grab_one(camera)
            self.grab_one(camera)
            camera.stop()
            camera.start()
            assert self.grab_one(camera).frame_id == 0

    def test_no_trigger_no_frame(self, camera: Camera) -> None:
        with camera:
            camera.start()
            with pytest.raises(DeviceTimeoutError):
                camera.fetch(timeout_s=0.2)

    def test_software_trigger_refused_under_hardware_source(self, camera: Camera) -> None:
        with camera:
            try:
                camera.set_trigger(TriggerSource.HARDWARE_RISING)
            except UnsupportedFeatureError:
                pytest.skip(f"{camera.name} has no hardware trigger")
            camera.start()
            with pytest.raises(IncompatibleStateError, match="software trigger"):
                camera.trigger()

    def test_settings_are_locked_while_acquiring(self, camera: Camera) -> None:
        with camera:
            camera.start()
            with pytest.raises(IncompatibleStateError):
                camera.set_trigger(TriggerSource.SOFTWARE)
            with pytest.raises(IncompatibleStateError):
                camera.roi = camera.roi
            with pytest.raises(IncompatibleStateError):
                camera.pixel_format = camera.pixel_format

    def test_bad_settings_name_the_setting(self, camera: Camera) -> None:
        with camera:
            with pytest.raises(ValueError, match="exposure_us"):
                camera.exposure_us = -5
            with pytest.raises(ValueError, match="gain"):
                camera.gain = math.nan
            width, height = camera.sensor_size
            with pytest.raises(ValueError, match="roi"):
                camera.roi = (0, 0, width + 1, height)
            camera.start()
            with pytest.raises(ValueError, match="timeout_s"):
                camera.fetch(timeout_s=0)

    def test_roi_is_inside_the_sensor_and_settable(self, camera: Camera) -> None:
        with camera:
            sensor_w, sensor_h = camera.sensor_size
            x, y, w, h = camera.roi
            assert 0 <= x and 0 <= y and x + w <= sensor_w and y + h <= sensor_h
            assert (camera.width, camera.height) == (w, h)
            try:
                camera.roi = (x, y, w // 2, h // 2)
            except UnsupportedFeatureError:
                pytest.skip(f"{camera.name} has no ROI")
            camera.start()
            frame = self.grab_one(camera)
        assert frame.image.shape == (h // 2, w // 2)

    def test_unsupported_pixel_format_is_refused(self, camera: Camera) -> None:
        with camera:
            missing = [f for f in PixelFormat if f not in camera.supported_pixel_formats]
            if not missing:
                pytest.skip(f"{camera.name} supports every pixel format")
            with pytest.raises(UnsupportedFeatureError, match=missing[0].name):
                camera.pixel_format = missing[0]

    def test_burst_or_refusal(self, camera: Camera) -> None:
        with camera:
            camera.burst_length = 3
            try:
                camera.set_trigger(TriggerSource.SOFTWARE, TriggerMode.BURST)
            except UnsupportedFeatureError:
                assert camera.trigger_mode is TriggerMode.ONCE
                return
            camera.start()
            camera.trigger()
            frames = [camera.fetch(timeout_s=self.fetch_timeout_s) for _ in range(3)]
            assert [f.frame_id for f in frames] == [0, 1, 2]
            with pytest.raises(DeviceTimeoutError):
                camera.fetch(timeout_s=0.2)


class TriggerBoxContract:
    """Behaviour every :class:`TriggerBox` backend shares, simulated or real.

    ``make_box`` returns an unopened box (the serial driver on a fake box's pseudo-terminal, or on
    a real board's port).
    """

    def make_box(self) -> TriggerBox:
        raise NotImplementedError

    def test_open_negotiates_our_version(self) -> None:
        with self.make_box() as box:
            assert box.is_open
            assert box.hello() == tp.PROTOCOL_VERSION
        assert not box.is_open

    def test_configure_arm_fire_status(self) -> None:
        with self.make_box() as box:
            box.reset()
            box.configure(pulse_width_us=150, delay_us=20, polarity=Polarity.ACTIVE_HIGH)
            box.arm(2)
            assert box.status().state == "ARMED"
            assert [box.fire(), box.fire()] == [0, 1]
            status = box.status()
            assert (status.state, status.fired, status.pulse_width_us, status.delay_us) == ("DONE", 2, 150, 20)
            with pytest.raises(IncompatibleStateError):
                box.fire()
            box.reset()
            assert box.status().state == "IDLE"

    def test_reset_disarms_and_restores_the_default_pulse(self) -> None:
        with self.make_box() as box:
            box.reset()
            default = box.status()
            box.configure(pulse_width_us=default.pulse_width_us + 7, delay_us=default.delay_us + 3)
            box.arm(3)
            box.reset()
            status = box.status()
            assert (status.state, status.fired) == ("IDLE", 0)
            assert (status.pulse_width_us, status.delay_us) == (default.pulse_width_us, default.delay_us)
            with pytest.raises(IncompatibleStateError):
                box.fire()

    @pytest.mark.parametrize(
        ("call", "argument"),
        [
            (lambda box: box.configure(pulse_width_us=0), "pulse_width_us"),
            (lambda box: box.configure(pulse_width_us=tp.MAX_PULSE_WIDTH_US + 1), "pulse_width_us"),
            (lambda box: box.configure(pulse_width_us=100, delay_us=-1), "delay_us"),
            (lambda box: box.configure(pulse_width_us=100, delay_us=tp.MAX_DELAY_US + 1), "delay_us"),
            (lambda box: box.arm(0), "count"),
            (lambda box: box.arm(tp.MAX_ARM_COUNT + 1), "count"),
        ],
    )
    def test_bad_arguments_name_the_argument_and_change_nothing(self, call, argument: str) -> None:
        with self.make_box() as box:
            box.reset()
            before = box.status()
            with pytest.raises(ValueError, match=argument):
                call(box)
            assert box.status() == before

    def test_arming_twice_is_refused(self) -> None:
        with self.make_box() as box:
            box.reset()
            box.arm(1)
            with pytest.raises(IncompatibleStateError):
                box.arm(1)
            box.reset()

    def test_ping_measures_a_round_trip(self) -> None:
        with self.make_box() as box:
            assert 0 < box.ping() < 1.0

    def test_reopening_reboots_cleanly_and_keeps_the_polarity(self) -> None:
        with self.make_box() as box:
            box.configure(pulse_width_us=100, polarity=Polarity.ACTIVE_LOW)
        time.sleep(0.05)
        with self.make_box() as box:  # an Uno reboots here; open waits for its banner
            status = box.status()
            assert (status.state, status.polarity, status.missed) == ("IDLE", Polarity.ACTIVE_LOW, 0)
            box.configure(pulse_width_us=100, polarity=Polarity.ACTIVE_HIGH)

    def test_closed_box_refuses_commands(self) -> None:
        box = self.make_box()
        for command in (box.status, box.ping, box.reset, box.fire, lambda: box.arm(1)):
            with pytest.raises(IncompatibleStateError):
                command()
