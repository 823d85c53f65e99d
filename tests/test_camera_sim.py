"""The simulated camera: contract, what it sees of the projector's rendered frames, injected faults."""

from __future__ import annotations

import threading

import numpy as np
import pytest
from contracts import CameraContract

from drivers.camera import (
    DroppedFrameError,
    DuplicateFrameError,
    PixelFormat,
    StaleFrameError,
    TriggerMode,
    TriggerSource,
)
from drivers.errors import DeviceNotFoundError, DeviceTimeoutError
from drivers.projector import Projector
from mock_devices.camera import CameraFaults, SimulatedCamera
from mock_devices.synth import Appearance, RigGeometry, true_absolute_phase

# An 80 x 60 camera under a 128 x 96 projector, with the synthesiser's default field of view.
GEOMETRY = RigGeometry(
    pixel_mm=0.4 * 1024 / 80, camera_width=80, camera_height=60, projector_width=128, projector_height=96
)
CLEAN = Appearance(gain=200.0, bit_depth=8)  # no noise, no ambient, linear projector


class FlatProjector(Projector):
    """A minimal in-test projector whose frames are the analytic pattern (no GPU needed)."""

    def _open(self) -> None: ...
    def _show(self, pattern) -> None: ...
    def _wait(self, timeout_s: float) -> bool:
        return True

    def _close(self) -> None: ...


def gl_projector(bits: int = 32):
    pytest.importorskip("moderngl", reason="moderngl is not installed")
    from drivers.projector_gl import GLProjector

    projector = GLProjector(GEOMETRY.projector_size, bits=bits)
    try:
        projector.open()
    except DeviceNotFoundError as exc:
        pytest.skip(f"no headless OpenGL: {exc}")
    return projector


def snap(camera: SimulatedCamera, projector: Projector, pattern: dict):
    projector.show(pattern)
    projector.wait_shown()
    camera.trigger()
    return camera.fetch(timeout_s=0.5)


class TestSimulatedCamera(CameraContract):
    fetch_timeout_s = 0.5

    def make_camera(self):
        return SimulatedCamera(None, GEOMETRY, appearance=CLEAN, rng=np.random.default_rng(0))


@pytest.mark.parametrize("gamma, ambient, reflectivity", [(1.0, 0.0, 1.0), (2.2, 0.1, 0.6)])
def test_flat_levels_follow_the_photometric_model(gamma: float, ambient: float, reflectivity: float) -> None:
    """DN = round(gain r (ambient + level^gamma)) exactly when there is no noise."""
    appearance = Appearance(gain=200.0, gamma=gamma, ambient=ambient, reflectivity=reflectivity, bit_depth=8)
    projector = gl_projector()
    with projector, SimulatedCamera(projector, GEOMETRY, appearance=appearance) as camera:
        camera.start()
        for level in (0.0, 0.25, 0.5, 1.0):
            frame = snap(camera, projector, {"kind": "flat", "level": level})
            expected = np.rint(200.0 * reflectivity * (ambient + level**gamma))
            assert np.all(frame.image == expected), (level, np.unique(frame.image), expected)


def test_gamma_lut_linearises_the_loop() -> None:
    """A LUT x^(1/gamma) on the projector cancels a projector gamma: DN linear in the level."""
    gamma = 2.2
    projector = gl_projector(bits=32)
    projector.set_gamma_lut(np.linspace(0.0, 1.0, 1024) ** (1.0 / gamma))
    appearance = Appearance(gain=200.0, gamma=gamma, bit_depth=16)
    with projector, SimulatedCamera(projector, GEOMETRY, appearance=appearance) as camera:
        camera.pixel_format = PixelFormat.MONO16
        camera.start()
        levels = np.array([0.1, 0.3, 0.5, 0.7, 0.9])
        means = [snap(camera, projector, {"kind": "flat", "level": x}).image.mean() for x in levels]
    # Linear interpolation inside the LUT bends the curve a little: within 0.5 % of full scale.
    np.testing.assert_allclose(means, 200.0 * levels, atol=1.0)


def test_signal_scales_with_exposure_and_gain() -> None:
    projector = FlatProjector(GEOMETRY.projector_size)
    with projector, SimulatedCamera(projector, GEOMETRY, appearance=CLEAN, reference_exposure_us=10_000) as camera:
        projector.show({"kind": "flat", "level": 0.5})
        camera.start()
        base = snap(camera, projector, {"kind": "flat", "level": 0.5}).image.astype(float)
        camera.stop()
        camera.exposure_us = 20_000
        camera.gain = 1.5
        camera.start()
        frame = snap(camera, projector, {"kind": "flat", "level": 0.5})
    assert np.all(base == 100) and np.all(frame.image == 255)  # 100 * 2 * 1.5 saturates 8 bits
    assert frame.exposure_us == 20_000


@pytest.mark.parametrize("axis", ["x", "y"])
def test_camera_sees_the_rendered_fringes_through_the_scene(axis: str) -> None:
    """4-step fringes rendered by moderngl, seen on a ramp scene: the wrapped phase is the truth."""
    rows, cols = GEOMETRY.camera_shape
    scene = np.tile(np.linspace(0.0, 40.0, cols), (rows, 1))
    frequency = 4
    projector = gl_projector(bits=8)
    with (
        projector,
        SimulatedCamera(projector, GEOMETRY, scene, appearance=Appearance(gain=250.0, bit_depth=12)) as camera,
    ):
        camera.pixel_format = PixelFormat.MONO12
        camera.start()
        stack = np.stack(
            [
                snap(
                    camera, projector, {"kind": "sinusoid", "axis": axis, "frequency": frequency, "steps": 4, "step": j}
                ).image
                for j in range(4)
            ]
        ).astype(float)
        mapping = camera.mapping
    shifts = 2 * np.pi * np.arange(4) / 4
    wrapped = np.arctan2(-np.tensordot(np.sin(shifts), stack, 1), np.tensordot(np.cos(shifts), stack, 1))
    if axis == "x":
        truth = true_absolute_phase(mapping, GEOMETRY, frequency)
    else:
        truth = 2 * np.pi * frequency * mapping.v / GEOMETRY.projector_height
    error = np.angle(np.exp(1j * (wrapped - truth)))[mapping.lit]
    # 8-bit projector levels and bilinear resampling of 32 projector px per fringe: < 0.03 rad
    assert np.max(np.abs(error)) < 0.03


def test_dark_without_a_pattern_and_ambient_adds_up() -> None:
    appearance = Appearance(gain=200.0, ambient=0.05, bit_depth=8)
    with SimulatedCamera(None, GEOMETRY, appearance=appearance) as camera:
        camera.start()
        camera.trigger()
        assert np.all(camera.fetch(timeout_s=0.1).image == 10)


def test_noise_is_seeded() -> None:
    appearance = Appearance(gain=200.0, snr_db=20.0)
    images = []
    for seed in (1, 1, 2):
        projector = FlatProjector(GEOMETRY.projector_size)
        with (
            projector,
            SimulatedCamera(projector, GEOMETRY, appearance=appearance, rng=np.random.default_rng(seed)) as cam,
        ):
            cam.pixel_format = PixelFormat.MONO16
            cam.start()
            images.append(snap(cam, projector, {"kind": "flat", "level": 0.5}).image.astype(float))
    assert np.array_equal(images[0], images[1]) and not np.array_equal(images[0], images[2])
    # 20 dB on a level of 100 DN: sigma = 10 DN
    assert 9.0 < images[0].std() < 11.0 and abs(images[0].mean() - 100.0) < 1.0


def test_roi_crops_the_sensor() -> None:
    projector = FlatProjector(GEOMETRY.projector_size)
    pattern = {"kind": "sinusoid", "axis": "x", "frequency": 3, "steps": 4, "step": 0}
    with projector, SimulatedCamera(projector, GEOMETRY, appearance=CLEAN) as camera:
        camera.start()
        full = snap(camera, projector, pattern).image
        camera.stop()
        camera.roi = (10, 5, 32, 20)
        camera.start()
        crop = snap(camera, projector, pattern).image
    assert crop.shape == (20, 32) and (camera.width, camera.height) == (32, 20)
    np.testing.assert_array_equal(crop, full[5:25, 10:42])


def test_projector_size_must_match_geometry() -> None:
    with pytest.raises(ValueError, match="projector size"):
        SimulatedCamera(FlatProjector((64, 48)), GEOMETRY)
    with pytest.raises(ValueError, match="scene_height_mm"):
        SimulatedCamera(None, GEOMETRY, np.zeros((5, 5)))


class TestHardwareTrigger:
    def test_pulse_index_is_carried(self) -> None:
        with SimulatedCamera(None, GEOMETRY, appearance=CLEAN) as camera:
            camera.set_trigger(TriggerSource.HARDWARE_RISING)
            camera.start()
            for index in (0, 1, 2):
                camera.pulse(index)
            frames = [camera.fetch(timeout_s=0.1) for _ in range(3)]
        assert [(f.frame_id, f.trigger_index) for f in frames] == [(0, 0), (1, 1), (2, 2)]

    def test_pulses_are_ignored_unless_armed_for_them(self) -> None:
        with SimulatedCamera(None, GEOMETRY, appearance=CLEAN) as camera:
            camera.pulse(0)  # not started
            camera.start()
            camera.pulse(1)  # software source
            with pytest.raises(DeviceTimeoutError):
                camera.fetch(timeout_s=0.05)

    def test_pulse_from_another_thread_wakes_fetch(self) -> None:
        with SimulatedCamera(None, GEOMETRY, appearance=CLEAN) as camera:
            camera.set_trigger(TriggerSource.HARDWARE_FALLING)
            camera.start()
            timer = threading.Timer(0.05, camera.pulse, args=(4,))
            timer.start()
            frame = camera.fetch(timeout_s=5.0)
            timer.join()
        assert frame.trigger_index == 4

    def test_burst_per_pulse(self) -> None:
        with SimulatedCamera(None, GEOMETRY, appearance=CLEAN) as camera:
            camera.burst_length = 3
            camera.set_trigger(TriggerSource.HARDWARE_RISING, TriggerMode.BURST)
            camera.start()
            camera.pulse(9)
            frames = [camera.fetch(timeout_s=0.1) for _ in range(3)]
        assert [f.frame_id for f in frames] == [0, 1, 2] and {f.trigger_index for f in frames} == {9}
        assert frames[0].timestamp_s < frames[1].timestamp_s < frames[2].timestamp_s


def faulty(faults: CameraFaults, policy: str = "raise") -> SimulatedCamera:
    return SimulatedCamera(None, GEOMETRY, appearance=CLEAN, faults=faults, on_sequence_error=policy)


class TestFaults:
    def test_dropped_frame_is_detected_and_carries_the_next_frame(self) -> None:
        with faulty(CameraFaults(drop={1})) as camera:
            camera.start()
            assert [camera.trigger() for _ in range(3)]
            assert camera.fetch(timeout_s=0.1).frame_id == 0
            with pytest.raises(DroppedFrameError) as info:
                camera.fetch(timeout_s=0.1)
            assert info.value.missing == 1 and info.value.frame.frame_id == 2
            with pytest.raises(DeviceTimeoutError):
                camera.fetch(timeout_s=0.05)

    def test_flag_policy_returns_the_frame_marked(self) -> None:
        with faulty(CameraFaults(drop={0}, duplicate={2}), policy="flag") as camera:
            camera.start()
            for _ in range(3):
                camera.trigger()
            frames = [camera.fetch(timeout_s=0.1) for _ in range(3)]
        assert [f.frame_id for f in frames] == [1, 2, 2]
        assert [type(f.sequence_error) for f in frames] == [DroppedFrameError, type(None), DuplicateFrameError]

    def test_duplicate_frame_is_detected(self) -> None:
        with faulty(CameraFaults(duplicate={0})) as camera:
            camera.start()
            camera.trigger()
            camera.trigger()
            assert camera.fetch(timeout_s=0.1).frame_id == 0
            with pytest.raises(DuplicateFrameError, match="frame id 0"):
                camera.fetch(timeout_s=0.1)
            assert camera.fetch(timeout_s=0.1).frame_id == 1

    def test_stale_frame_is_detected(self) -> None:
        with faulty(CameraFaults(stale={1})) as camera:
            camera.start()
            camera.trigger()
            camera.fetch(timeout_s=0.1)
            camera.trigger()
            with pytest.raises(StaleFrameError, match="before its trigger"):
                camera.fetch(timeout_s=0.1)

    def test_missed_trigger_times_out_then_recovers(self) -> None:
        with faulty(CameraFaults(timeout_on={0})) as camera:
            camera.start()
            camera.trigger()
            with pytest.raises(DeviceTimeoutError, match="no frame"):
                camera.fetch(timeout_s=0.05)
            camera.trigger()
            assert camera.fetch(timeout_s=0.1).frame_id == 0

    def test_device_disappears_mid_scan(self) -> None:
        camera = faulty(CameraFaults(disappear_after=2))
        with camera:
            camera.start()
            for _ in range(2):
                camera.trigger()
                camera.fetch(timeout_s=0.1)
            with pytest.raises(DeviceNotFoundError, match="disappeared"):
                camera.trigger()
            with pytest.raises(DeviceNotFoundError):
                camera.fetch(timeout_s=0.1)
        assert not camera.is_open
        with pytest.raises(DeviceNotFoundError):
            camera.open()

    def test_disappearing_under_hardware_trigger_fails_the_waiting_fetch(self) -> None:
        with faulty(CameraFaults(disappear_after=0)) as camera:
            camera.set_trigger(TriggerSource.HARDWARE_RISING)
            camera.start()
            camera.pulse(0)
            with pytest.raises(DeviceNotFoundError):
                camera.fetch(timeout_s=1.0)


def test_exposures_take_no_real_time_unless_asked() -> None:
    slept: list[float] = []
    with SimulatedCamera(None, GEOMETRY, appearance=CLEAN, sleep=slept.append) as camera:
        camera.exposure_us = 2500
        camera.start()
        for _ in range(2):
            camera.trigger()
            camera.fetch(timeout_s=0.1)
        clock = camera.now()
    assert slept == [0.0025, 0.0025]
    assert clock == pytest.approx(2 * (0.0025 + 0.001))  # the camera clock: exposure + readout each
