"""PylonCamera against pylon's own camera emulator (PYLON_CAMEMU), and (opt-in,
``--device camera-pylon[:SERIAL]``) a real Basler camera."""

from __future__ import annotations

import os

# pylon reads PYLON_CAMEMU when its transport layers load, i.e. on the first pypylon import.
os.environ.setdefault("PYLON_CAMEMU", "1")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402
from contracts import CameraContract, device_option  # noqa: E402

from drivers.camera import PixelFormat, TriggerMode, TriggerSource  # noqa: E402
from drivers.errors import DeviceNotFoundError, DeviceTimeoutError, IncompatibleStateError, UnsupportedFeatureError  # noqa: E402

pytest.importorskip("pypylon.pylon", reason="pypylon is not installed (optional extra 'pylon')")
cv2 = pytest.importorskip("cv2", reason="OpenCV is needed to write the emulator's image files")

from drivers.camera_pylon import PylonCamera  # noqa: E402

WIDTH, HEIGHT, COUNT = 64, 48, 4


def emulator_images() -> np.ndarray:
    """Distinct 8-bit images: a ramp shifted by 50 grey levels per image."""
    ramp = (np.add.outer(np.arange(HEIGHT), np.arange(WIDTH)) * 3) % 180
    return np.stack([(ramp + 50 * k) % 256 for k in range(COUNT)]).astype(np.uint8)


@pytest.fixture(scope="module")
def image_folder(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("camemu")
    for k, image in enumerate(emulator_images()):
        cv2.imwrite(str(folder / f"{k:03d}.png"), image)
    return folder


def emulator_features(folder: Path) -> dict[str, object]:
    """The camera emulator showing the images of ``folder`` at WIDTH x HEIGHT."""
    return {
        "ImageFilename": str(folder),
        "ImageFileMode": "On",
        "TestImageSelector": "Off",
        "OffsetX": 0,
        "OffsetY": 0,
        "Width": WIDTH,
        "Height": HEIGHT,
    }


def emulated(folder: Path, **kwargs) -> PylonCamera:
    return PylonCamera(device_class="BaslerCamEmu", features=emulator_features(folder), **kwargs)


def _emulator_problem() -> str | None:
    try:
        with PylonCamera(device_class="BaslerCamEmu"):
            return None
    except DeviceNotFoundError as exc:
        return f"pylon camera emulator unavailable (PYLON_CAMEMU set after pypylon loaded?): {exc}"


EMULATOR_PROBLEM = _emulator_problem()
needs_emulator = pytest.mark.skipif(EMULATOR_PROBLEM is not None, reason=str(EMULATOR_PROBLEM))


@needs_emulator
class TestPylonEmulator(CameraContract):
    @pytest.fixture(autouse=True)
    def _folder(self, image_folder: Path) -> None:
        self.folder = image_folder

    def make_camera(self):
        return emulated(self.folder)


class TestPylonDevice(CameraContract):
    """A real Basler camera: ``pytest --device camera-pylon[:SERIAL]``."""

    @pytest.fixture(autouse=True)
    def _device(self, request: pytest.FixtureRequest) -> None:
        address = device_option(request, "camera-pylon")
        if address is None:
            pytest.skip("no Basler camera requested (run with --device camera-pylon[:SERIAL])")
        self.serial = address or None

    def make_camera(self):
        return PylonCamera(self.serial, device_class=None if self.serial else "BaslerUsb")


@needs_emulator
def test_served_images_come_back_in_order(image_folder: Path) -> None:
    with emulated(image_folder) as camera:
        assert (camera.width, camera.height) == (WIDTH, HEIGHT)
        camera.start()
        frames = []
        for _ in range(COUNT + 1):
            camera.trigger()
            frames.append(camera.fetch(timeout_s=5.0))
    assert [f.frame_id for f in frames] == list(range(COUNT + 1))
    expected = emulator_images()
    np.testing.assert_array_equal(np.stack([f.image for f in frames]), np.concatenate([expected, expected[:1]]))


@needs_emulator
def test_settings_reach_the_camera(image_folder: Path) -> None:
    camera = emulated(image_folder)
    camera.exposure_us = 2500.0  # before open: pushed on open
    with camera:
        assert camera.exposure_us == pytest.approx(2500.0)
        assert camera._read("ExposureTime") == pytest.approx(2500.0)
        camera.exposure_us = 1234.5  # the emulator rounds to whole microseconds
        assert camera.exposure_us == camera._read("ExposureTime") == pytest.approx(1234.5, abs=0.5)
        camera.set_trigger(TriggerSource.HARDWARE_FALLING)
        assert (camera._read("TriggerSource"), camera._read("TriggerActivation")) == ("Line1", "FallingEdge")
        camera.set_trigger(TriggerSource.SOFTWARE)
        assert camera._read("TriggerSource") == "Software"


@needs_emulator
def test_hardware_trigger_waits_for_the_line(image_folder: Path) -> None:
    """Under a Line1 trigger nothing arrives (no pulse) and software triggers are refused."""
    with emulated(image_folder) as camera:
        camera.set_trigger(TriggerSource.HARDWARE_RISING)
        camera.start()
        with pytest.raises(IncompatibleStateError):
            camera.trigger()
        with pytest.raises(DeviceTimeoutError):
            camera.fetch(timeout_s=0.3)


@needs_emulator
def test_mono12_frames_are_16_bit(image_folder: Path) -> None:
    with emulated(image_folder) as camera:
        assert PixelFormat.MONO12 in camera.supported_pixel_formats
        camera.pixel_format = PixelFormat.MONO12
        camera.start()
        camera.trigger()
        frame = camera.fetch(timeout_s=5.0)
    assert frame.image.dtype == np.uint16 and frame.image.shape == (HEIGHT, WIDTH)
    assert 0 < frame.image.max() <= 4095


@needs_emulator
def test_burst_is_refused_by_the_emulator(image_folder: Path) -> None:
    with emulated(image_folder) as camera:
        with pytest.raises(UnsupportedFeatureError, match="burst"):
            camera.set_trigger(TriggerSource.SOFTWARE, TriggerMode.BURST)


@needs_emulator
def test_unknown_serial_is_device_not_found() -> None:
    with pytest.raises(DeviceNotFoundError, match="no pylon camera"):
        PylonCamera("no-such-serial").open()


# -- what a real Basler USB3 camera does that the emulator does not (issue 15) -----------------
# mock_devices.pylon_camera.UsbCameraQuirks overrides only those nodes of the emulator.


def quirky(folder: Path, **quirks) -> PylonCamera:
    from pypylon import pylon

    from mock_devices.pylon_camera import UsbCameraQuirks

    info = pylon.DeviceInfo()
    info.SetDeviceClass("BaslerCamEmu")
    inner = pylon.InstantCamera(pylon.TlFactory.GetInstance().CreateFirstDevice(info))
    return PylonCamera(camera=UsbCameraQuirks(inner, **quirks), features=emulator_features(folder))


@needs_emulator
def test_auto_gain_is_switched_off_and_gain_set_in_db(image_folder: Path) -> None:
    # auto gain on makes Gain read-only; a USB camera has no GainRaw to fall back to
    with quirky(image_folder, gain_auto="Continuous", gain_raw=False) as camera:
        assert camera._read("GainAuto") == "Off"
        camera.gain = 6.0
        assert camera.gain_unit == "dB"
        assert camera._read("Gain") == pytest.approx(6.0, abs=0.1)


@needs_emulator
def test_emulator_gain_is_the_db_feature(image_folder: Path) -> None:
    with emulated(image_folder) as camera:
        camera.gain = 3.0
        assert camera.gain_unit == "dB" and camera._read("Gain") == pytest.approx(3.0, abs=0.1)


@needs_emulator
def test_other_trigger_selectors_are_switched_off(image_folder: Path) -> None:
    # an AcquisitionStart trigger left on (pylon's default configuration not loaded) holds frames
    with quirky(image_folder, acquisition_start="On") as camera:
        camera.set_trigger(TriggerSource.SOFTWARE)
        camera.start()
        camera.trigger()
        assert camera.fetch(timeout_s=5.0).frame_id == 0
        camera.stop()
        camera._write("TriggerSelector", "AcquisitionStart")
        assert camera._read("TriggerMode") == "Off"


@needs_emulator
def test_emulator_trigger_selectors_other_than_the_active_one_are_off(image_folder: Path) -> None:
    with emulated(image_folder) as camera:
        camera._write("TriggerSelector", "ExposureStart")
        camera._write("TriggerMode", "On")
        camera.set_trigger(TriggerSource.SOFTWARE)
        for selector in camera._symbolics("TriggerSelector"):
            camera._write("TriggerSelector", selector)
            assert camera._read("TriggerMode") == ("On" if selector == "FrameStart" else "Off"), selector


@needs_emulator
def test_frame_exposed_before_its_trigger_is_stale_on_the_camera_clock(image_folder: Path) -> None:
    from drivers.camera import StaleFrameError

    with quirky(image_folder, stale_frames=1) as camera:
        camera.start()
        camera.trigger()
        with pytest.raises(StaleFrameError, match="before its trigger"):
            camera.fetch(timeout_s=5.0)
        camera.trigger()
        frame = camera.fetch(timeout_s=5.0)
        assert frame.frame_id == 1 and frame.timestamp_s <= camera.now()


@needs_emulator
def test_software_trigger_without_trigger_ready_support(image_folder: Path) -> None:
    with quirky(image_folder, can_wait_for_trigger_ready=False) as camera:
        camera.start()
        camera.trigger()
        assert camera.fetch(timeout_s=5.0).frame_id == 0
