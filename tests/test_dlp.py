"""DLP LightCrafter 4500: exact HID reports, controller state through the fake backend, limits,
faults and the no-device message."""

from __future__ import annotations

import errno

import pytest
import usb.core

from drivers import dlp_protocol as dp
from drivers.dlp import (
    DisplayMode,
    DlpCommandError,
    DlpController,
    DlpLimitError,
    DlpValidationError,
    ExposureError,
    Led,
    LightCrafter4500,
    PatternEntry,
    PatternSequence,
    PatternSource,
    SequenceState,
    TriggerType,
)
from drivers.dlp_protocol import Command
from drivers.errors import (
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    IncompatibleStateError,
    UnsupportedFeatureError,
)
from mock_devices.dlp_usb import Dlpc350Faults, FakeDlpc350Backend
from tests.contracts import device_option
from tests.protocol import expected_protocol


def report(hex_bytes: str) -> bytes:
    """A 64-byte HID report from its leading bytes, written out in hex."""
    return bytes.fromhex(hex_bytes).ljust(64, b"\x00")


def ack(seq: int) -> bytes:
    return report(f"00 {seq:02x} 00 00")


def write_exchange(seq: int, cmd3_cmd2_data: str) -> tuple[bytes, bytes]:
    """A write with reply requested (flags 0x40) and its acknowledgement."""
    payload = bytes.fromhex(cmd3_cmd2_data)
    return (report(f"40 {seq:02x} {len(payload):02x} 00 {cmd3_cmd2_data}"), ack(seq))


def read_exchange(seq: int, cmd3_cmd2: str, data: str) -> tuple[bytes, bytes]:
    """A read (flags 0xC0, length 2) and its reply (flags 0x80) carrying ``data``."""
    n = len(bytes.fromhex(data))
    return (report(f"c0 {seq:02x} 02 00 {cmd3_cmd2}"), report(f"80 {seq:02x} {n:02x} 00 {data}"))


# open() reads power (awake), display mode (video) and main status (sequencer stopped)
OPEN = [read_exchange(1, "00 02", "00"), read_exchange(2, "1b 1a", "00"), read_exchange(3, "0c 1a", "00")]


def one_entry_sequence(**overrides) -> PatternSequence:
    entry = PatternEntry(
        pattern_number=5, bit_depth=1, leds=Led.GREEN, trigger=TriggerType.EXTERNAL_POSITIVE, buffer_swap=True
    )
    kwargs = dict(entries=[entry], exposure_us=10000, frame_period_us=16667, source=PatternSource.VIDEO_PORT)
    kwargs.update(overrides)
    return PatternSequence(**kwargs)


def valid_sequence(n: int = 3, depth: int = 8) -> PatternSequence:
    entries = [
        PatternEntry(k, bit_depth=depth, trigger=TriggerType.EXTERNAL_POSITIVE, buffer_swap=(k == 0)) for k in range(n)
    ]
    return PatternSequence(
        entries=entries, exposure_us=dp.MIN_EXPOSURE_US[depth], frame_period_us=dp.MIN_EXPOSURE_US[depth]
    )


def ready(backend) -> LightCrafter4500:
    dlp = LightCrafter4500(backend=backend)
    dlp.open()
    dlp.wake()
    dlp.set_display_mode(DisplayMode.PATTERN)
    return dlp


# -- packet format ----------------------------------------------------------------------------


def test_request_layout_matches_the_guide():
    # write display mode (USB 0x1A1B) = pattern: flags 0x40 (write, reply), seq, length 3
    # (CMD3, CMD2, 1 data byte), CMD3 = 0x1B then CMD2 = 0x1A, data 0x01
    assert dp.encode_request(Command.DISPLAY_MODE, 7, b"\x01") == report("40 07 03 00 1b 1a 01")
    assert dp.encode_request(Command.MAIN_STATUS, 9, read=True) == report("c0 09 02 00 0c 1a")


def test_pattern_entry_bits():
    entry = PatternEntry(
        pattern_number=5, bit_depth=1, leds=Led.GREEN, trigger=TriggerType.EXTERNAL_POSITIVE, buffer_swap=True
    )
    # byte 0: pattern << 2 | trigger; byte 1: LEDs << 4 | depth; byte 2: swap is bit 2
    assert entry.pack() == bytes([0x15, 0x21, 0x04])
    assert PatternEntry.unpack(entry.pack()) == entry


def test_reply_longer_than_report_is_rejected():
    with pytest.raises(dp.PacketError, match="length field"):
        dp.decode_reply(report("80 01 ff 00"))


# -- exact exchanges --------------------------------------------------------------------------

# set_display_mode(PATTERN) from sequence number 4: write, then read the mode back
TO_PATTERN = [write_exchange(4, "1b 1a 01"), read_exchange(5, "1b 1a", "01")]

CONFIGURE_ONE_ENTRY = [  # configure_sequence(one_entry_sequence()), from sequence number 6
    write_exchange(6, "22 1a 00"),  # data from the video port
    write_exchange(7, "23 1a 01"),  # internal / external trigger
    write_exchange(8, "29 1a 10 27 00 00 1b 41 00 00"),  # 10000 us, 16667 us, LE u32
    write_exchange(9, "31 1a 00 00 00 00"),  # 1 entry, once, 1 pattern, 1 image (minus 1)
    write_exchange(10, "33 1a 02"),  # open the pattern LUT mailbox
    write_exchange(11, "32 1a 00"),  # offset 0
    write_exchange(12, "34 1a 15 21 04"),  # the whole LUT in one message: one entry
    write_exchange(13, "33 1a 00"),  # close
]


def test_open_reads_power_mode_and_sequencer_state():
    exchanges = [read_exchange(1, "00 02", "01"), read_exchange(2, "1b 1a", "01"), read_exchange(3, "0c 1a", "03")]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        assert dlp.state is SequenceState.RUNNING
        with pytest.raises(IncompatibleStateError, match="standby"):
            dlp.configure_sequence(one_entry_sequence())


def test_wake_standby_and_display_mode_reports():
    exchanges = [
        *OPEN,
        write_exchange(4, "00 02 00"),
        write_exchange(5, "1b 1a 01"),
        read_exchange(6, "1b 1a", "00"),  # still switching: read again
        read_exchange(7, "1b 1a", "01"),
        write_exchange(8, "00 02 01"),
    ]
    with expected_protocol(LightCrafter4500, exchanges, settle_s=0) as dlp:
        dlp.wake()
        dlp.set_display_mode(DisplayMode.PATTERN)
        dlp.standby()


def test_configure_sequence_reports():
    exchanges = [*OPEN, *TO_PATTERN, *CONFIGURE_ONE_ENTRY]
    with expected_protocol(LightCrafter4500, exchanges, settle_s=0) as dlp:
        dlp.set_display_mode(DisplayMode.PATTERN)
        dlp.configure_sequence(one_entry_sequence())


def test_validate_polls_until_not_busy_then_start():
    exchanges = [
        *OPEN,
        *TO_PATTERN,
        *CONFIGURE_ONE_ENTRY,
        write_exchange(14, "1a 1a 00"),  # start validation
        read_exchange(15, "1a 1a", "80"),  # busy
        read_exchange(16, "1a 1a", "10"),  # done, with a warning bit
        write_exchange(17, "24 1a 02"),  # start
        read_exchange(18, "24 1a", "00"),  # ignored (first start after video mode)
        write_exchange(19, "24 1a 02"),  # start again
        read_exchange(20, "24 1a", "02"),  # running
        write_exchange(21, "24 1a 01"),
        read_exchange(22, "24 1a", "01"),  # pause
        write_exchange(23, "24 1a 00"),
        read_exchange(24, "24 1a", "00"),  # stop
    ]
    with expected_protocol(LightCrafter4500, exchanges, settle_s=0) as dlp:
        dlp.set_display_mode(DisplayMode.PATTERN)
        dlp.configure_sequence(one_entry_sequence())
        result = dlp.validate()
        assert result.ok
        assert result.messages == ["warning: frame period and exposure differ by less than 230 us"]
        dlp.start()
        dlp.pause()
        dlp.stop()
        assert dlp.state is SequenceState.STOPPED


def test_status_reads_three_registers():
    exchanges = [
        *OPEN,
        read_exchange(4, "0a 1a", "41"),
        read_exchange(5, "0b 1a", "01"),
        read_exchange(6, "0c 1a", "02"),
    ]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        status = dlp.status()
    assert status.sequencer_running and not status.parked
    assert status.problems == ["sequencer abort"]


def test_stale_reply_is_skipped_by_sequence_number():
    # the device answers with an old reply (sequence 3) before the one to this request (4)
    exchanges = [
        *OPEN,
        (report("c0 04 02 00 0a 1a"), report("80 03 01 00 00") + report("80 04 01 00 01")),
        read_exchange(5, "0b 1a", "01"),
        read_exchange(6, "0c 1a", "00"),
    ]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        assert dlp.status().hardware == 0x01


def test_error_flag_in_reply_raises_naming_the_command():
    exchanges = [*OPEN, (report("40 04 03 00 1b 1a 01"), report("20 04 00 00"))]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        with pytest.raises(DlpCommandError, match=r"DISPLAY_MODE \(0x1A1B\)"):
            dlp.set_display_mode(DisplayMode.PATTERN)


def test_validation_failure_is_explained():
    exchanges = [
        *OPEN,
        *TO_PATTERN,
        *CONFIGURE_ONE_ENTRY,
        write_exchange(14, "1a 1a 00"),
        read_exchange(15, "1a 1a", "03"),
    ]
    with expected_protocol(LightCrafter4500, exchanges, settle_s=0) as dlp:
        dlp.set_display_mode(DisplayMode.PATTERN)
        dlp.configure_sequence(one_entry_sequence())
        with pytest.raises(DlpValidationError, match="exposure or frame period.*pattern numbers"):
            dlp.validate()
        with pytest.raises(IncompatibleStateError, match="validated"):
            dlp.start()


# -- controller state through the fake backend ------------------------------------------------


def test_open_detaches_kernel_driver_claims_and_releases():
    backend = FakeDlpc350Backend()
    with LightCrafter4500(backend=backend):
        assert not backend.kernel_driver_active
        assert backend.claimed == {0}
        assert backend.configuration == 1
    assert backend.claimed == set()


def test_full_flow_programs_the_controller():
    backend = FakeDlpc350Backend()
    sequence = PatternSequence(
        entries=[
            PatternEntry(k % 3, bit_depth=8, trigger=TriggerType.EXTERNAL_POSITIVE, buffer_swap=(k % 3 == 0))
            for k in range(6)
        ],
        exposure_us=9000,
        frame_period_us=9500,
        image_indexes=(4, 5),
    )
    with ready(backend) as dlp:
        dlp.configure_sequence(sequence)
        dlp.validate()
        dlp.start()
        assert backend.state.sequencer == "running"
        assert dlp.status().sequencer_running
        state = backend.state
        assert (state.display_mode, state.pattern_source, state.trigger_mode) == (1, 3, 1)
        assert (state.exposure_us, state.frame_period_us) == (9000, 9500)
        assert state.lut_control == dp.LutControl(6, False, 6, 2)
        assert [state.pattern_lut[k] for k in range(6)] == list(sequence.entries)
        assert state.image_lut == {0: 4, 1: 5}
        assert state.mailbox == dp.Mailbox.CLOSED
        dlp.standby()
        assert backend.state.standby and backend.state.sequencer == "stopped"
        assert dlp.status().parked


def test_validation_catches_settings_changed_behind_the_drivers_back():
    backend = FakeDlpc350Backend()
    with ready(backend) as dlp:
        dlp.configure_sequence(valid_sequence(depth=8))
        backend.state.exposure_us = 5000  # e.g. changed from TI's GUI: below the 8-bit minimum
        with pytest.raises(DlpValidationError, match="exposure or frame period settings"):
            dlp.validate()
        assert not backend.state.validated


def test_reconfiguring_stops_a_running_sequence_first():
    backend = FakeDlpc350Backend()
    with ready(backend) as dlp:
        dlp.configure_sequence(valid_sequence())
        dlp.validate()
        dlp.start()
        dlp.configure_sequence(valid_sequence(n=2))
        assert backend.state.sequencer == "stopped"
        assert backend.state.lut_control.lut_entries == 2
        with pytest.raises(IncompatibleStateError, match="validated"):
            dlp.start()


def test_state_rules_refuse_without_traffic():
    backend = FakeDlpc350Backend()
    dlp = LightCrafter4500(backend=backend)
    with pytest.raises(IncompatibleStateError, match="not open"):
        dlp.wake()
    with dlp:
        with pytest.raises(IncompatibleStateError, match="pattern display mode"):
            dlp.configure_sequence(valid_sequence())
        dlp.standby()
        sent = len(backend.requests)
        with pytest.raises(IncompatibleStateError, match="standby"):
            dlp.set_display_mode(DisplayMode.PATTERN)
        with pytest.raises(IncompatibleStateError, match="pause needs a running"):
            dlp.pause()
        assert len(backend.requests) == sent


# -- limits -----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "sequence, message",
    [
        (PatternSequence([PatternEntry(0)] * 129, 235, 235), "1..128 entries"),
        (PatternSequence([PatternEntry(25, bit_depth=1)], 235, 235), r"holds 24: 0\.\.23; 24 is the black fill"),
        (PatternSequence([PatternEntry(3, bit_depth=8)], 8333, 8333), r"holds 3: 0\.\.2"),
        (
            PatternSequence([PatternEntry(k % 24) for k in range(25)], 235, 235),
            "more than 24 patterns from one 24-bit image",
        ),
        (PatternSequence([PatternEntry(0)], 235, 235, patterns_to_display=257), "1..256"),
        (PatternSequence([PatternEntry(0, insert_black=True, trigger_out_prev=True)], 235, 235), "insert_black"),
        (PatternSequence([PatternEntry(0)], 235, 235, image_indexes=()), "1..64 flash images"),
    ],
)
def test_sequencer_limits(sequence, message):
    backend = FakeDlpc350Backend()
    with ready(backend) as dlp:
        sent = len(backend.requests)
        with pytest.raises(DlpLimitError, match=message) as info:
            dlp.configure_sequence(sequence)
        assert len(backend.requests) == sent
    assert isinstance(info.value, ValueError) and isinstance(info.value, UnsupportedFeatureError)


@pytest.mark.parametrize(
    "depth, exposure, period, message",
    [
        (8, 8332, 8332, "below the 8333 us minimum for 8-bit"),
        (1, 234, 1000, "below the 235 us minimum for 1-bit"),
        (1, 2000, 1000, "exceeds the frame period"),
        (1, 1000, 1100, "at least 230 us shorter"),
    ],
)
def test_exposure_rules(depth, exposure, period, message):
    sequence = PatternSequence([PatternEntry(0, bit_depth=depth)], exposure, period)
    with ready(FakeDlpc350Backend()) as dlp, pytest.raises(ExposureError, match=message):
        dlp.configure_sequence(sequence)


@pytest.mark.parametrize("depth, exposure, period", [(1, 235, 235), (1, 1000, 1230), (8, 8333, 20000)])
def test_exposure_rules_accept_boundaries(depth, exposure, period):
    sequence = PatternSequence([PatternEntry(0, bit_depth=depth)], exposure, period)
    with ready(FakeDlpc350Backend()) as dlp:
        dlp.configure_sequence(sequence)
        assert dlp.validate().ok


# -- faults and missing devices ---------------------------------------------------------------


def test_usb_error_is_wrapped_naming_the_command():
    faults = Dlpc350Faults(usb_error_on={Command.PATTERN_START_STOP: errno.EPIPE})
    with LightCrafter4500(backend=FakeDlpc350Backend(faults)) as dlp:
        with pytest.raises(DeviceError, match="USB error during write PATTERN_START_STOP") as info:
            dlp.stop()
    assert isinstance(info.value.__cause__, usb.core.USBError)


def test_failure_while_opening_closes_again():
    backend = FakeDlpc350Backend(Dlpc350Faults(usb_error_on={Command.DISPLAY_MODE: errno.EIO}))
    dlp = LightCrafter4500(backend=backend)
    with pytest.raises(DeviceError, match="read DISPLAY_MODE"):
        dlp.open()
    assert not dlp.is_open and backend.claimed == set() and backend.open_handles == 0


def test_unanswered_command_times_out():
    backend = FakeDlpc350Backend(Dlpc350Faults(timeout_on={Command.HARDWARE_STATUS}))
    with LightCrafter4500(backend=backend, timeout_s=0.01) as dlp:
        with pytest.raises(DeviceTimeoutError, match="HARDWARE_STATUS"):
            dlp.status()


def test_validation_that_never_finishes_times_out():
    backend = FakeDlpc350Backend(Dlpc350Faults(validation_busy_reads=10**9))
    with ready(backend) as dlp:
        dlp.configure_sequence(valid_sequence())
        with pytest.raises(DeviceTimeoutError, match="still validating"):
            dlp.validate(timeout_s=0.02)


def test_controller_refusal_is_reported():
    backend = FakeDlpc350Backend(Dlpc350Faults(refuse={Command.PATTERN_START_STOP}))
    with ready(backend) as dlp:
        dlp.configure_sequence(valid_sequence())
        dlp.validate()
        with pytest.raises(DlpCommandError, match="PATTERN_START_STOP"):
            dlp.start()
        assert dlp.state is SequenceState.STOPPED


def test_device_unplugged_mid_scan():
    backend = FakeDlpc350Backend(Dlpc350Faults(disappear_after=7))
    dlp = ready(backend)  # open (3 reads), wake, display mode: 5 reports; configuring sends more
    with pytest.raises(DeviceNotFoundError, match="disconnected during write"):
        dlp.configure_sequence(valid_sequence())
    dlp.close()
    with pytest.raises(DeviceNotFoundError, match="not found: plug it in"):
        LightCrafter4500(backend=backend).open()


def test_no_device_message_is_one_line_with_what_to_do():
    backend = FakeDlpc350Backend()
    backend.present = False
    with pytest.raises(DeviceNotFoundError) as info:
        LightCrafter4500(backend=backend).open()
    message = str(info.value)
    assert "\n" not in message and "plug it in" in message


def test_permission_denied_points_to_udev_rule():
    backend = FakeDlpc350Backend(Dlpc350Faults(claim_errno=errno.EACCES))
    with pytest.raises(DeviceNotFoundError, match=r"no permission.*udev rule.*0451"):
        LightCrafter4500(backend=backend).open()
    assert backend.open_handles == 0


def test_default_backend_without_a_projector_raises_device_not_found():
    # the real pyusb path: either libusb is missing or no LightCrafter is plugged in here
    with pytest.raises(DeviceNotFoundError, match="libusb|plug it in|permission|udev"):
        LightCrafter4500().open()


# -- contract: every DlpController backend, simulated or real ---------------------------------


class DlpContract:
    """Mix into a class whose ``make_dlp()`` returns an unopened DlpController."""

    def make_dlp(self) -> DlpController:
        raise NotImplementedError

    def test_sequence_runs_and_stops(self):
        with self.make_dlp() as dlp:
            dlp.wake()
            dlp.set_display_mode(DisplayMode.PATTERN)
            dlp.configure_sequence(valid_sequence(n=3, depth=8))
            assert dlp.validate().ok
            dlp.start()
            assert dlp.status().sequencer_running
            dlp.stop()
            assert not dlp.status().sequencer_running
            assert dlp.status().healthy
            dlp.set_display_mode(DisplayMode.VIDEO)

    def test_limits_are_refused_before_sending(self):
        with self.make_dlp() as dlp:
            dlp.wake()
            dlp.set_display_mode(DisplayMode.PATTERN)
            with pytest.raises(ExposureError):
                dlp.configure_sequence(PatternSequence([PatternEntry(0, bit_depth=8)], 1000, 1000))
            with pytest.raises(IncompatibleStateError):
                dlp.start()
            dlp.set_display_mode(DisplayMode.VIDEO)

    def test_closed_controller_refuses(self):
        with pytest.raises(IncompatibleStateError):
            self.make_dlp().status()


class TestFakeLightCrafter(DlpContract):
    def make_dlp(self) -> DlpController:
        return LightCrafter4500(backend=FakeDlpc350Backend())


class TestLightCrafterOnDevice(DlpContract):
    """A real projector: ``pytest --device dlp4500`` (uses flash image 0)."""

    @pytest.fixture(autouse=True)
    def _device(self, request: pytest.FixtureRequest) -> None:
        if device_option(request, "dlp4500") is None:
            pytest.skip("no LightCrafter 4500 requested (run with --device dlp4500)")

    def make_dlp(self) -> DlpController:
        return LightCrafter4500()


def test_running_restores_video_mode_and_standby():
    backend = FakeDlpc350Backend()
    with LightCrafter4500(backend=backend) as dlp:
        dlp.set_display_mode(DisplayMode.VIDEO)
        dlp.standby()
        with dlp.running(valid_sequence()):
            assert backend.state.sequencer == "running"
            assert not backend.state.standby
        assert backend.state.sequencer == "stopped"
        assert backend.state.display_mode == DisplayMode.VIDEO
        assert backend.state.standby


def test_running_rolls_back_when_start_is_refused():
    backend = FakeDlpc350Backend(Dlpc350Faults(refuse={Command.PATTERN_START_STOP}))
    with LightCrafter4500(backend=backend) as dlp:
        dlp.wake()
        dlp.set_display_mode(DisplayMode.VIDEO)
        with pytest.raises(DlpCommandError, match="PATTERN_START_STOP"):
            with dlp.running(valid_sequence()):
                pytest.fail("the block must not run")
        assert backend.state.display_mode == DisplayMode.VIDEO  # restored despite the failure


# -- what a real DLPC350 does that an instant, echoing controller would not (issue 15) ---------


def test_two_image_indexes_play_in_the_order_given():
    # TI's SendImageLut swaps a two-entry image LUT because the firmware plays it swapped
    backend = FakeDlpc350Backend()
    sequence = PatternSequence(
        entries=[PatternEntry(k % 3, bit_depth=8, buffer_swap=(k % 3 == 0)) for k in range(6)],
        exposure_us=9000,
        frame_period_us=9000,
        image_indexes=(4, 5),
    )
    with ready(backend) as dlp:
        dlp.configure_sequence(sequence)
        assert backend.state.image_lut == {0: 4, 1: 5}


def test_mode_switch_waits_for_the_controller_and_reads_the_mode_back():
    backend = FakeDlpc350Backend(busy_s=0.05)
    with LightCrafter4500(backend=backend) as dlp:
        dlp.wake()
        dlp.set_display_mode(DisplayMode.PATTERN)
        assert backend.state.display_mode == DisplayMode.PATTERN  # took effect before returning
        dlp.configure_sequence(valid_sequence())  # not refused as "busy"
        assert backend.refused_while_busy == 0
        reads = [r for r in backend.requests if r.command == Command.DISPLAY_MODE and r.is_read]
        assert len(reads) >= 2  # open, and at least one read back after the switch


def test_start_after_leaving_video_mode_is_repeated_until_running():
    # the first START after a video -> pattern switch is acknowledged and ignored
    backend = FakeDlpc350Backend(busy_s=0.02)
    with LightCrafter4500(backend=backend) as dlp:
        dlp.wake()
        dlp.set_display_mode(DisplayMode.PATTERN)
        dlp.configure_sequence(valid_sequence())
        dlp.validate()
        dlp.start()
        assert backend.state.sequencer == "running"
        assert dlp.status().sequencer_running
        dlp.pause()
        assert backend.state.sequencer == "paused"
        dlp.stop()
        assert backend.state.sequencer == "stopped"
        assert backend.refused_while_busy == 0


def test_switch_that_never_takes_effect_times_out():
    backend = FakeDlpc350Backend(busy_s=10.0)
    with LightCrafter4500(backend=backend, settle_s=0.01, settle_timeout_s=0.05) as dlp:
        dlp.wake()
        with pytest.raises(DeviceTimeoutError, match="display mode still reads VIDEO"):
            dlp.set_display_mode(DisplayMode.PATTERN)


@pytest.mark.parametrize("echo", [False, True])
def test_replies_with_or_without_the_sequence_echoed(echo):
    backend = FakeDlpc350Backend(echo_sequence=echo)
    with ready(backend) as dlp:
        dlp.configure_sequence(valid_sequence())
        assert dlp.validate().ok
        dlp.start()
        assert dlp.status().sequencer_running


def test_controller_that_does_not_echo_is_read_without_matching():
    # reply sequence 0 to every request (as TI's host expects: it sends reads with sequence 0)
    exchanges = [
        (report("c0 01 02 00 00 02"), report("80 00 01 00 00")),
        (report("c0 02 02 00 1b 1a"), report("80 00 01 00 01")),
        (report("c0 03 02 00 0c 1a"), report("80 00 01 00 00")),
        (report("c0 04 02 00 0a 1a"), report("80 00 01 00 41")),
    ]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        assert dlp._read_byte(Command.HARDWARE_STATUS) == 0x41


def test_long_message_continues_in_headerless_reports():
    data = bytes(range(100))
    reports = dp.encode_message(Command.MAILBOX_DATA, 9, data)
    # first: header (length 102 = 0x66), CMD3 CMD2, 58 data bytes; then 42 bytes, zero padded
    assert reports == [bytes.fromhex("40 09 66 00 34 1a") + data[:58], data[58:].ljust(64, b"\x00")]
    with pytest.raises(dp.PacketError, match="use encode_message"):
        dp.encode_request(Command.MAILBOX_DATA, 9, data)


def test_full_lut_and_64_image_indexes_reach_the_controller():
    backend = FakeDlpc350Backend()
    entries = [PatternEntry(k % 3, bit_depth=8, buffer_swap=(k % 2 == 0)) for k in range(128)]
    sequence = PatternSequence(
        entries=entries, exposure_us=9000, frame_period_us=209_000, image_indexes=tuple(range(64))
    )
    with ready(backend) as dlp:
        dlp.configure_sequence(sequence)
        assert [backend.state.pattern_lut[k] for k in range(128)] == entries
        assert backend.state.image_lut == dict(enumerate(range(64)))
        assert dlp.validate().ok


def test_flash_sequence_beyond_two_images_needs_time_to_load_each():
    entries = [PatternEntry(k % 3, bit_depth=8, buffer_swap=(k % 3 == 0)) for k in range(9)]
    short = PatternSequence(entries=entries, exposure_us=9000, frame_period_us=9000, image_indexes=(0, 1, 2))
    backend = FakeDlpc350Backend()
    with ready(backend) as dlp:
        sent = len(backend.requests)
        with pytest.raises(ExposureError, match=r"load an image from flash.*200000 us"):
            dlp.configure_sequence(short)
        assert len(backend.requests) == sent
        loaded = PatternSequence(entries=entries, exposure_us=9000, frame_period_us=209_000, image_indexes=(0, 1, 2))
        dlp.configure_sequence(loaded)
        dlp.validate()
        dlp.start()
        assert dlp.status().healthy
    # two images fit the frame buffers: no load time needed
    two = PatternSequence(entries=entries[:6], exposure_us=9000, frame_period_us=9000, image_indexes=(0, 1))
    with ready(FakeDlpc350Backend()) as dlp, dlp.running(two):
        assert dlp.status().healthy


def test_fake_flags_a_forced_swap_when_images_load_too_slowly():
    # what the controller reports if the rule above is broken (e.g. changed from TI's GUI)
    backend = FakeDlpc350Backend(busy_s=0)
    entries = [PatternEntry(k % 3, bit_depth=8, buffer_swap=(k % 3 == 0)) for k in range(9)]
    with ready(backend) as dlp:
        dlp.configure_sequence(
            PatternSequence(entries=entries, exposure_us=9000, frame_period_us=209_000, image_indexes=(0, 1, 2))
        )
        backend.state.frame_period_us = 9000
        dlp.validate()
        dlp.start()
        assert "forced swap error" in dlp.status().problems


def test_one_bit_black_fill_pattern_24_is_accepted():
    sequence = PatternSequence([PatternEntry(23), PatternEntry(dp.BLACK_FILL_PATTERN)], 235, 235)
    with ready(FakeDlpc350Backend()) as dlp:
        dlp.configure_sequence(sequence)
        assert dlp.validate().ok


def test_main_status_bit_3_is_gamma_correction_on_the_dlpc350():
    assert dp.MainStatus.GAMMA_CORRECTION == 0x08
    exchanges = [
        *OPEN,
        read_exchange(4, "0a 1a", "01"),
        read_exchange(5, "0b 1a", "01"),
        read_exchange(6, "0c 1a", "08"),
    ]
    with expected_protocol(LightCrafter4500, exchanges) as dlp:
        status = dlp.status()
    assert status.gamma_correction and status.healthy
