"""Fault injection into the acquisition loop: it retries or fails cleanly, never loses or mislabels a frame.

The simulated rig looks at the flat reference plane, noiselessly, under 8 phase shifts of one
sinusoid. The shift of every stored frame is recovered from its pixels (least squares against
the known projector phase of each camera pixel) and must be the shift of the pattern the frame
is stored under: a frame stored under the wrong pattern is off by a multiple of 45 degrees.
"""

from __future__ import annotations

import errno
import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from drivers.camera import TriggerSource
from drivers.dlp import LightCrafter4500
from drivers.dlp_protocol import Command
from drivers.errors import DeviceError, DeviceNotFoundError, DeviceTimeoutError
from drivers.projector_dlp import DlpVideoProjector
from mock_devices.camera import CameraFaults, SimulatedCamera
from mock_devices.dlp_usb import Dlpc350Faults, FakeDlpc350Backend
from mock_devices.trigger_box import TriggerFaults
from processing.patterns import sinusoid_shift
from rig.acquisition.loop import AcquisitionError, AcquisitionSettings, run_scan
from rig.config import CameraConfig, ProjectorConfig, RigConfig, ScanConfig, SimulationConfig, TriggerConfig
from rig.hardware.assembly import trigger_path
from rig.hardware.simulated import SimulatedRig, appearance_from_config
from rig.hardware.trigger_paths import SoftwareTrigger
from rig.store.capture import INCOMPLETE_MARK, read_capture

STEPS = 8
FREQUENCY = 2
SHIFT_TOLERANCE_RAD = 0.05  # 8-bit quantisation of a noiseless frame; neighbours are 0.785 apart

TRIGGERS = ["software", "simulated-serial"]


def small_config(trigger: str, retries: int = 2) -> RigConfig:
    return RigConfig(
        projector=ProjectorConfig(width=96, height=120),
        camera=CameraConfig(width=64, height=48),
        trigger=TriggerConfig(backend=trigger, timeout_s=0.05),
        scan=ScanConfig(frequencies=(FREQUENCY,), steps=STEPS, retries=retries),
        simulation=SimulationConfig(snr_db=None),
    )


def settings(config: RigConfig, fetch_timeout_s: float = 0.2) -> AcquisitionSettings:
    return AcquisitionSettings(show_timeout_s=1.0, fetch_timeout_s=fetch_timeout_s, retries=config.scan.retries)


def scan(tmp_path: Path, trigger: str, retries: int = 2, camera_faults=None, trigger_faults=None, progress=None):
    """Scan the reference plane; return (result or the error raised, the rig's camera mapping, rig)."""
    config = small_config(trigger, retries)
    with SimulatedRig(config, scene="reference", camera_faults=camera_faults, trigger_faults=trigger_faults) as rig:
        path = trigger_path(rig.camera, rig.trigger_box)
        result = run_scan(
            tmp_path / "capture",
            config.scan.patterns(),
            rig.projector,
            rig.camera,
            path,
            settings(config),
            progress=progress,
        )
        return result, rig


def recovered_shift(image: np.ndarray, u: np.ndarray, projector_width: int) -> float:
    """Phase shift of a fringe frame: fit I = a + b cos(phi) + c sin(phi), phi the projector phase."""
    phi = (2 * np.pi * FREQUENCY * u / projector_width).ravel()
    design = np.column_stack([np.ones_like(phi), np.cos(phi), np.sin(phi)])
    (a, b, c), *_ = np.linalg.lstsq(design, image.astype(np.float64).ravel(), rcond=None)
    return float(np.arctan2(-c, b) % (2 * np.pi))  # I = a + B cos(phi + s) = a + B cos s cos phi - B sin s sin phi


def assert_every_frame_matches_its_pattern(capture_path: Path, rig: SimulatedRig) -> None:
    capture = read_capture(capture_path)
    assert capture.complete
    u = rig.camera.mapping.u
    for index, pattern in enumerate(capture.patterns):
        shift = recovered_shift(capture.load_frame(index), u, capture.projector_size[0])
        error = np.angle(np.exp(1j * (shift - sinusoid_shift(pattern))))
        assert abs(error) < SHIFT_TOLERANCE_RAD, f"frame of pattern {index} shows shift {shift:.3f} rad"


@pytest.mark.parametrize("trigger", TRIGGERS)
def test_clean_scan_stores_each_frame_under_its_pattern(tmp_path, trigger):
    result, rig = scan(tmp_path, trigger)
    assert_every_frame_matches_its_pattern(result.path, rig)
    frames = read_capture(result.path).frames
    assert [f["trigger_index"] for f in frames] == list(range(STEPS))
    assert all(f["exposure_us"] == 10000.0 and "timestamp_s" in f for f in frames)
    timestamps = [f["timestamp_s"] for f in frames]
    assert timestamps == sorted(timestamps) and len(set(timestamps)) == STEPS
    assert result.attempts == STEPS and result.discarded == 0


@pytest.mark.parametrize("trigger", TRIGGERS)
@pytest.mark.parametrize(
    ("faults", "retried_pattern"),
    [
        (CameraFaults(timeout_on={2}), 2),  # trigger missed: no frame at all
        (CameraFaults(drop={3}), 3),  # frame lost in transport: id gap on the next one
        (CameraFaults(stale={5}), 5),  # frame exposed before its trigger
    ],
    ids=["timeout", "dropped", "stale"],
)
def test_camera_fault_is_retried_with_the_same_pattern(tmp_path, trigger, faults, retried_pattern):
    result, rig = scan(tmp_path, trigger, camera_faults=faults)
    assert_every_frame_matches_its_pattern(result.path, rig)
    frames = read_capture(result.path).frames
    assert [f.get("attempts", 1) for f in frames] == [2 if i == retried_pattern else 1 for i in range(STEPS)]
    assert result.attempts == STEPS + 1


@pytest.mark.parametrize("trigger", TRIGGERS)
def test_duplicated_frame_is_discarded_not_stored_under_the_next_pattern(tmp_path, trigger):
    result, rig = scan(tmp_path, trigger, camera_faults=CameraFaults(duplicate={4}))
    assert_every_frame_matches_its_pattern(result.path, rig)
    assert result.discarded == 1
    assert result.attempts == STEPS  # a duplicate costs no retry


def test_several_faults_in_one_scan(tmp_path):
    faults = CameraFaults(timeout_on={1}, drop={4}, duplicate={6}, stale={8})
    result, rig = scan(tmp_path, "simulated-serial", camera_faults=faults)
    assert_every_frame_matches_its_pattern(result.path, rig)


class CameraWithoutTriggerIndex(SimulatedCamera):
    """A camera that cannot tell which trigger exposed a frame (like pylon's emulator): frames carry no index."""

    def _fetch(self, timeout_s: float):
        frame = super()._fetch(timeout_s)
        frame.trigger_index = None
        return frame


@pytest.mark.parametrize(
    ("faults", "attempts"),
    [
        # exposure indices count from start(); the loop restarts the camera after each fault
        (CameraFaults(timeout_on={2}), STEPS + 3),  # missed triggers use no frame id
        (CameraFaults(drop={3}), STEPS + 2),  # lost frames do
        (CameraFaults(duplicate={4}), STEPS),
        (CameraFaults(stale={5}), STEPS + 1),
    ],
    ids=["missed-trigger", "dropped", "duplicate", "stale"],
)
def test_camera_without_trigger_indices_is_matched_by_frame_id(tmp_path, faults, attempts):
    config = small_config("software")
    with SimulatedRig(config, scene="reference") as rig:
        camera = CameraWithoutTriggerIndex(
            rig.projector, rig.geometry, rig.height_mm, appearance_from_config(config), faults=faults
        )
        with camera:
            result = run_scan(
                tmp_path / "capture",
                config.scan.patterns(),
                rig.projector,
                camera,
                SoftwareTrigger(camera),
                settings(config),
            )
        assert_every_frame_matches_its_pattern(result.path, rig)
    assert result.attempts == attempts
    assert all("trigger_index" not in f for f in read_capture(result.path).frames)


@pytest.mark.parametrize("trigger", TRIGGERS)
def test_too_many_timeouts_fail_cleanly_and_leave_no_complete_capture(tmp_path, trigger):
    with pytest.raises(AcquisitionError, match=r"pattern 2 of 8 .* no frame after 2 attempt"):
        scan(tmp_path, trigger, retries=1, camera_faults=CameraFaults(timeout_on={2, 3}))
    assert_left_incomplete(tmp_path, frames_written=2)


def assert_left_incomplete(tmp_path: Path, frames_written: int) -> None:
    assert not (tmp_path / "capture").exists()
    (partial,) = tmp_path.glob("capture" + INCOMPLETE_MARK + "*")
    manifest = json.loads((partial / "capture.json").read_text())
    assert manifest["complete"] is False
    assert "interrupted" in manifest
    assert sorted(f["pattern"] for f in manifest["frames"]) == list(range(frames_written))
    salvaged = read_capture(partial, salvage=True)  # what was written is intact and correctly labelled
    assert len(salvaged.frames) == frames_written


def test_garbled_fire_replies_are_retried_without_double_pulses(tmp_path):
    # The driver resends the same request id: the box replays its reply instead of pulsing again.
    faults = TriggerFaults(garble_reply_on={"FIRE"}, garble_times=1)
    result, rig = scan(tmp_path, "simulated-serial", trigger_faults=faults)
    assert_every_frame_matches_its_pattern(result.path, rig)
    assert rig.fake_box.pulses == list(range(STEPS))


def test_lost_fire_replies_are_recovered_by_the_driver_without_double_pulses(tmp_path):
    # Each FIRE reply is lost twice; the driver's third try gets the replayed reply.
    faults = TriggerFaults(drop_reply_on={"FIRE"}, drop_times=2)
    result, rig = scan(tmp_path, "simulated-serial", trigger_faults=faults)
    assert_every_frame_matches_its_pattern(result.path, rig)
    assert rig.fake_box.pulses == list(range(STEPS))


class ReplyLostAfterPulse:
    """The real box driver, except that the FIRE of ``lose`` pulses but its reply never arrives."""

    def __init__(self, box, lose: int) -> None:
        self.box, self.lose, self.calls = box, lose, 0

    def __getattr__(self, name):
        return getattr(self.box, name)

    def fire(self) -> int:
        index = self.box.fire()
        self.calls += 1
        if self.calls == self.lose:
            raise DeviceTimeoutError("trigger box: no reply to FIRE (test: reply lost after the pulse)")
        return index


def test_unacknowledged_pulse_leaves_no_extra_frame_for_the_next_pattern(tmp_path):
    # The box pulsed for pattern 3 but the loop never learnt it: it shows pattern 3 again and
    # fires again. Both frames (triggers 3 and 4) show pattern 3: the first one is stored, the
    # second must be discarded, not stored under pattern 4.
    config = small_config("simulated-serial")
    with SimulatedRig(config, scene="reference") as rig:
        path = trigger_path(rig.camera, ReplyLostAfterPulse(rig.trigger_box, lose=4))
        result = run_scan(
            tmp_path / "capture", config.scan.patterns(), rig.projector, rig.camera, path, settings(config)
        )
        assert_every_frame_matches_its_pattern(result.path, rig)
    frames = read_capture(result.path).frames
    assert [f["trigger_index"] for f in frames] == [0, 1, 2, 3, 5, 6, 7, 8]
    assert result.discarded == 1


def test_trigger_box_is_kept_armed_while_the_loop_waits_for_a_slow_frame(tmp_path):
    # The box disarms itself after 0.3 s without a command; a missed trigger makes the loop wait
    # 1 s for a frame before retrying: without heartbeats the next FIRE would find it disarmed.
    config = small_config("simulated-serial")
    slow = AcquisitionSettings(fetch_timeout_s=1.0, retries=2, keepalive_s=0.1)
    with SimulatedRig(
        config, scene="reference", camera_faults=CameraFaults(timeout_on={2}), fake_box_options={"watchdog_s": 0.3}
    ) as rig:
        path = trigger_path(rig.camera, rig.trigger_box)
        result = run_scan(tmp_path / "capture", config.scan.patterns(), rig.projector, rig.camera, path, slow)
        assert_every_frame_matches_its_pattern(result.path, rig)
        assert not any(e.name == "WATCHDOG" for e in rig.trigger_box.events)
        assert sum(b"PING" in line for line in rig.fake_box.received) >= 5


def test_silent_trigger_box_fails_cleanly(tmp_path):
    # The box answers HELLO, RESET and ARM, then goes silent.
    with pytest.raises(AcquisitionError, match=r"pattern 0 of 8 .* no reply to FIRE"):
        scan(tmp_path, "simulated-serial", retries=1, trigger_faults=TriggerFaults(stall=3))
    assert_left_incomplete(tmp_path, frames_written=0)


def test_trigger_box_unplugged_mid_scan_stops_at_once(tmp_path):
    # HELLO, RESET, ARM, then 3 FIREs: the box vanishes after answering the third.
    with pytest.raises(DeviceError, match="lost the box"):
        scan(tmp_path, "simulated-serial", trigger_faults=TriggerFaults(disconnect_after=6))
    assert_left_incomplete(tmp_path, frames_written=3)


@pytest.mark.parametrize("trigger", TRIGGERS)
def test_camera_disappearing_mid_scan_stops_at_once(tmp_path, trigger):
    with pytest.raises(DeviceNotFoundError, match="disappeared"):
        scan(tmp_path, trigger, camera_faults=CameraFaults(disappear_after=5))
    assert_left_incomplete(tmp_path, frames_written=5)


class InterruptAt:
    """A progress sink that raises KeyboardInterrupt (Ctrl-C) after ``frames`` frames."""

    def __init__(self, frames: int) -> None:
        self.frames = frames
        self.seen = 0

    def step(self, note: str = "", count: int = 1) -> None:
        self.seen += count
        if self.seen == self.frames:
            raise KeyboardInterrupt


def test_ctrl_c_leaves_no_complete_capture(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        scan(tmp_path, "simulated-serial", progress=InterruptAt(4))
    assert_left_incomplete(tmp_path, frames_written=4)


@pytest.mark.parametrize("trigger", TRIGGERS)
def test_devices_are_restored_after_a_failed_scan(tmp_path, trigger):
    config = small_config(trigger)
    with SimulatedRig(config, scene="reference", camera_faults=CameraFaults(timeout_on={0, 1, 2, 3})) as rig:
        rig.camera.exposure_us = 1234.0
        path = trigger_path(rig.camera, rig.trigger_box)
        with pytest.raises(AcquisitionError):
            run_scan(
                tmp_path / "c",
                config.scan.patterns(),
                rig.projector,
                rig.camera,
                path,
                settings(config),
                exposure_us=500.0,
            )
        assert not rig.camera.is_started
        assert rig.camera.trigger_source is TriggerSource.SOFTWARE
        assert rig.camera.exposure_us == 1234.0
        if rig.trigger_box is not None:
            assert rig.trigger_box.status().state == "IDLE"


def test_scan_refuses_to_overwrite_a_capture(tmp_path):
    scan(tmp_path, "software")
    with pytest.raises(Exception, match="already exists"):
        scan(tmp_path, "software")


# --------------------------------------------------------------------------- DLP over USB


def dlp_scan(tmp_path: Path, faults: Callable[[int], Dlpc350Faults] | None = None):
    """Scan through a LightCrafter 4500 in video mode (fake DLPC350 on pyusb) whose HDMI input is the GL display.

    ``faults`` receives the number of USB requests made while opening, and returns the faults
    to inject from then on (the scan's requests are counted from there).
    """
    config = small_config("simulated-serial")
    backend = FakeDlpc350Backend()
    with SimulatedRig(config, scene="reference") as rig:
        dlp = DlpVideoProjector(rig.projector, LightCrafter4500(backend=backend, timeout_s=0.05))
        with dlp:
            opened = len(backend.requests)
            if faults is not None:
                backend.faults = faults(opened)
            path = trigger_path(rig.camera, rig.trigger_box)
            result = run_scan(tmp_path / "capture", config.scan.patterns(), dlp, rig.camera, path, settings(config))
            assert (backend.state.display_mode, backend.state.standby) == (0, False)  # video mode, awake
        return result, rig, backend.requests[opened:]


def test_scan_through_a_dlp_in_video_mode(tmp_path):
    result, rig, requests = dlp_scan(tmp_path)
    assert_every_frame_matches_its_pattern(result.path, rig)
    assert sum(r.command == Command.MAIN_STATUS for r in requests) == STEPS  # health checked once per pattern


def test_dlp_unplugged_mid_scan_stops_at_once(tmp_path):
    # 3 status reads per pattern: the reply to the first request past the limit is lost,
    # during pattern 4's check
    with pytest.raises(DeviceNotFoundError, match="disconnected"):
        dlp_scan(tmp_path, lambda opened: Dlpc350Faults(disappear_after=opened + 3 * 4 + 1))
    assert_left_incomplete(tmp_path, frames_written=4)


def test_dlp_usb_timeouts_are_retried_then_fail_cleanly(tmp_path):
    with pytest.raises(AcquisitionError, match=r"pattern 0 of 8 .* no answer within"):
        dlp_scan(tmp_path, lambda opened: Dlpc350Faults(timeout_on={Command.MAIN_STATUS}))
    assert_left_incomplete(tmp_path, frames_written=0)


def test_dlp_usb_transfer_error_stops_the_scan(tmp_path):
    with pytest.raises(DeviceError, match="USB error during read HARDWARE_STATUS"):
        dlp_scan(tmp_path, lambda opened: Dlpc350Faults(usb_error_on={Command.HARDWARE_STATUS: errno.EPIPE}))
    assert_left_incomplete(tmp_path, frames_written=0)
