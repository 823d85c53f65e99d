"""OpenCVCamera through real cv2.VideoCapture backends: a lossless video file, an image sequence,
and (opt-in, ``--device camera-opencv[:INDEX]``) a real UVC camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from contracts import CameraContract, device_option

from drivers.camera import TriggerMode, TriggerSource
from drivers.errors import DeviceNotFoundError, DeviceTimeoutError, UnsupportedFeatureError

cv2 = pytest.importorskip("cv2", reason="OpenCV is not installed")

from drivers.camera_opencv import OpenCVCamera  # noqa: E402

WIDTH, HEIGHT, COUNT = 64, 48, 12


def test_frames(count: int = COUNT) -> np.ndarray:
    """Distinct 8-bit frames: a diagonal ramp shifted by 17 grey levels per frame."""
    ramp = (np.add.outer(np.arange(HEIGHT), np.arange(WIDTH)) * 2) % 200
    return np.stack([(ramp + 17 * k) % 256 for k in range(count)]).astype(np.uint8)


test_frames.__test__ = False  # a helper, not a test


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The frames written as a lossless FFV1 video by cv2.VideoWriter."""
    path = tmp_path_factory.mktemp("video") / "frames.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 10.0, (WIDTH, HEIGHT), isColor=False)
    if not writer.isOpened():
        pytest.skip("this OpenCV build cannot write FFV1 video (no FFmpeg backend)")
    for image in test_frames():
        writer.write(image)
    writer.release()
    return path


@pytest.fixture(scope="module")
def image_sequence(tmp_path_factory: pytest.TempPathFactory) -> str:
    folder = tmp_path_factory.mktemp("sequence")
    for k, image in enumerate(test_frames(4)):
        cv2.imwrite(str(folder / f"{k:03d}.png"), image)
    return str(folder / "%03d.png")


class TestOpenCVCameraOnVideoFile(CameraContract):
    @pytest.fixture(autouse=True)
    def _source(self, video: Path) -> None:
        self.video = video

    def make_camera(self):
        return OpenCVCamera(str(self.video))


class TestOpenCVCameraOnDevice(CameraContract):
    """A real UVC camera: ``pytest --device camera-opencv:0``."""

    @pytest.fixture(autouse=True)
    def _device(self, request: pytest.FixtureRequest) -> None:
        address = device_option(request, "camera-opencv")
        if address is None:
            pytest.skip("no UVC camera requested (run with --device camera-opencv[:INDEX])")
        self.index = int(address or 0)

    def make_camera(self):
        return OpenCVCamera(self.index)


def test_frames_come_back_exactly_in_order(video: Path) -> None:
    with OpenCVCamera(str(video)) as camera:
        assert camera.sensor_size == (WIDTH, HEIGHT)
        camera.start()
        images = []
        for _ in range(COUNT):
            camera.trigger()
            images.append(camera.fetch().image)
    np.testing.assert_array_equal(np.stack(images), test_frames())


def test_roi_and_burst(video: Path) -> None:
    with OpenCVCamera(str(video)) as camera:
        camera.roi = (8, 4, 20, 10)
        camera.burst_length = 3
        camera.set_trigger(TriggerSource.SOFTWARE, TriggerMode.BURST)
        camera.start()
        camera.trigger()
        frames = [camera.fetch() for _ in range(3)]
    assert [f.frame_id for f in frames] == [0, 1, 2] and {f.trigger_index for f in frames} == {0}
    np.testing.assert_array_equal(np.stack([f.image for f in frames]), test_frames()[:3, 4:14, 8:28])


def test_end_of_video_is_a_clear_timeout(video: Path) -> None:
    with OpenCVCamera(str(video)) as camera:
        camera.start()
        for _ in range(COUNT):
            camera.trigger()
            camera.fetch()
        camera.trigger()
        with pytest.raises(DeviceTimeoutError, match="end of the video"):
            camera.fetch()


def test_image_sequence_backend(image_sequence: str) -> None:
    with OpenCVCamera(image_sequence, api_preference=cv2.CAP_IMAGES) as camera:
        camera.start()
        camera.trigger()
        camera.trigger()
        first, second = camera.fetch(), camera.fetch()
    np.testing.assert_array_equal(np.stack([first.image, second.image]), test_frames(2))


def test_missing_source_names_it(tmp_path: Path) -> None:
    missing = tmp_path / "nothing.avi"
    camera = OpenCVCamera(str(missing))
    with pytest.raises(DeviceNotFoundError, match="nothing.avi"):
        camera.open()
    assert not camera.is_open


def test_absent_device_index() -> None:
    with pytest.raises(DeviceNotFoundError, match="camera index 63"):
        OpenCVCamera(63).open()


def test_hardware_trigger_is_unsupported(video: Path) -> None:
    with OpenCVCamera(str(video)) as camera:
        with pytest.raises(UnsupportedFeatureError, match="hardware trigger"):
            camera.set_trigger(TriggerSource.HARDWARE_RISING)
        assert camera.trigger_source is TriggerSource.SOFTWARE
