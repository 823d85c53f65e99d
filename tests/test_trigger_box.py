"""Trigger box: exact lines on the wire (through pyserial on a pty), faults, heartbeat, versions."""

from __future__ import annotations

import time

import pytest

from drivers import trigger_protocol as tp
from drivers.errors import (
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    IncompatibleStateError,
    ProtocolError,
    UnsupportedFeatureError,
    WaitTimeoutError,
)
from drivers.trigger_box import (
    ExposureSource,
    Polarity,
    SerialTriggerBox,
    TriggerBox,
    TriggerBoxRefusedError,
)
from mock_devices.trigger_box import FakeTriggerBox, TriggerFaults
from tests.contracts import TriggerBoxContract, device_option
from tests.protocol import expected_protocol, expected_serial_protocol

HELLO = (b"1 HELLO 2*41\n", b"1 OK 2 box-fw/2.1*6C\n")


def opened(port: str, **kwargs) -> SerialTriggerBox:
    kwargs.setdefault("boot_timeout_s", 0)  # scripted peers send no READY banner
    box = SerialTriggerBox(port, **kwargs)
    box.open()
    return box


# -- line format ------------------------------------------------------------------------------


def test_checksum_is_xor_of_body_bytes():
    # '1'^' '^'H'^'E'^'L'^'L'^'O'^' '^'1' = 0x42, worked by hand
    assert tp.frame("1 HELLO 1") == b"1 HELLO 1*42\n"


@pytest.mark.parametrize(
    "line",
    [
        b"1 OK*17\n",  # wrong checksum
        b"1 OK*16",  # no terminator
        b"1 OK\n",  # no checksum
        b"1 \xffK*16\n",  # not ASCII
        b"x OK*" + b"%02X" % tp.checksum(b"x OK") + b"\n",  # id not a number
        b"1 MAYBE*" + b"%02X" % tp.checksum(b"1 MAYBE") + b"\n",  # neither OK nor ERR
        b"1 ERR 3 STATE*" + b"%02X" % tp.checksum(b"1 ERR 3 STATE") + b"\n",  # code/name disagree
    ],
)
def test_malformed_lines_are_rejected(line):
    with pytest.raises(tp.LineError):
        tp.parse_incoming(line)


def test_event_and_error_lines_parse():
    assert tp.parse_incoming(b"! PULSE 1*4F\n") == tp.Event("PULSE", ("1",))
    reply = tp.parse_incoming(b"2 ERR 3 NOT_ARMED ARM first*15\n")
    assert (reply.id, reply.ok, reply.code, reply.text) == (2, False, tp.ErrorCode.NOT_ARMED, "ARM first")


# -- exact exchanges --------------------------------------------------------------------------


def test_open_sends_hello_and_keeps_firmware_id():
    with expected_serial_protocol([HELLO]) as port:
        box = opened(port)
        assert box.firmware == "box-fw/2.1"
        box.close()


def test_full_exposure_sequence_lines():
    exchanges = [
        HELLO,
        (b"2 PING*02\n", b"2 OK*16\n"),
        (b"3 CONFIG 250 40 NEG*46\n", b"3 OK 250 40 NEG*48\n"),
        (b"4 ARM 2 SW*7C\n", b"4 OK 2 SW*26\n"),
        (b"5 FIRE*0D\n", b"! PULSE 0*4E\n5 OK 0*01\n"),
        (b"6 FIRE*0E\n", b"! PULSE 1*4F\n6 OK 1*03\n! DONE 2*13\n"),
        (b"7 STATUS*03\n", b"7 OK st=DONE n=2 fired=2 miss=0 w=250 d=40 pol=NEG src=SW*4B\n"),
    ]
    with expected_protocol(SerialTriggerBox, exchanges, boot_timeout_s=0) as box:
        box.ping()
        box.configure(pulse_width_us=250, delay_us=40, polarity=Polarity.ACTIVE_LOW)
        box.arm(2)
        assert [box.fire(), box.fire()] == [0, 1]
        status = box.status()
        assert (status.state, status.armed, status.fired) == ("DONE", 2, 2)
        assert (status.pulse_width_us, status.delay_us, status.polarity) == (250, 40, Polarity.ACTIVE_LOW)
        assert box.pulses_seen() == [0, 1]
        assert [e.name for e in box.events][-1] == "DONE"


def test_stale_reply_with_old_id_is_skipped():
    exchanges = [HELLO, (b"2 ARM 1 SW*79\n", b"1 OK 1 box-fw/2.1*6F\n2 OK 1 SW*23\n")]
    with expected_serial_protocol(exchanges) as port, opened(port) as box:
        box.arm(1)


def test_garbled_reply_is_retried_with_the_same_id():
    exchanges = [
        HELLO,
        (b"2 ARM 1 SW*79\n", b"2 OK 1 SW*24\n"),  # bad checksum
        (b"2 ARM 1 SW*79\n", b"2 OK 1 SW*23\n"),
    ]
    with expected_serial_protocol(exchanges) as port, opened(port) as box:
        box.arm(1)


def test_request_garbled_on_the_way_is_resent():
    exchanges = [HELLO, (b"2 PING*02\n", b"0 ERR 6 BAD_CHECKSUM request rejected*09\n"), (b"2 PING*02\n", b"2 OK*16\n")]
    with expected_serial_protocol(exchanges) as port, opened(port) as box:
        box.ping()


def test_partial_line_at_the_deadline_counts_as_garbled():
    exchanges = [HELLO, (b"2 PING*02\n", b"2 O"), (b"2 PING*02\n", b"2 OK*16\n")]
    with expected_serial_protocol(exchanges) as port, opened(port, timeout_s=0.05) as box:
        box.ping()


def test_retries_are_bounded_and_error_names_port_and_command():
    garbled = b"2 OK*17\n"
    exchanges = [HELLO] + [(b"2 PING*02\n", garbled)] * 3
    with expected_serial_protocol(exchanges) as port, opened(port, retries=2) as box:
        with pytest.raises(ProtocolError, match=rf"{port}.*PING"):
            box.ping()


def test_missing_reply_times_out_after_retries():
    exchanges = [HELLO] + [(b"2 PING*02\n", None)] * 2
    with expected_serial_protocol(exchanges) as port, opened(port, timeout_s=0.05, retries=1) as box:
        start = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=rf"{port}.*no reply to PING"):
            box.ping()
        assert time.monotonic() - start < 0.5


@pytest.mark.parametrize(
    "reply, error",
    [
        (b"2 ERR 4 STATE already armed RESET first*02\n", IncompatibleStateError),
        (b"2 ERR 2 BAD_ARGUMENT 0 outside 1..65535*0A\n", TriggerBoxRefusedError),
    ],
)
def test_error_replies_map_to_device_errors(reply, error):
    with expected_serial_protocol([HELLO, (b"2 ARM 1 SW*79\n", reply)]) as port:
        with opened(port) as box, pytest.raises(error, match="ARM refused"):
            box.arm(1)


def test_hello_has_its_own_longer_deadline_for_booting_boards():
    exchanges = [(b"1 HELLO 2*41\n", None), HELLO]  # the first HELLO is lost while booting
    with expected_serial_protocol(exchanges) as port:
        box = SerialTriggerBox(port, timeout_s=0.02, command_timeouts={"HELLO": 0.1}, boot_timeout_s=0)
        start = time.monotonic()
        box.open()
        assert time.monotonic() - start >= 0.1
        box.close()
    with pytest.raises(ValueError, match="command_timeouts"):
        SerialTriggerBox("loop://", command_timeouts={"FLY": 1.0})


def test_box_version_other_than_ours_is_refused_and_port_closed():
    with expected_serial_protocol([(b"1 HELLO 2*41\n", b"1 OK 1 box-fw/2.1*6F\n")]) as port:
        box = SerialTriggerBox(port, boot_timeout_s=0)
        with pytest.raises(UnsupportedFeatureError, match="protocol 1.*speaks 2"):
            box.open()
        assert not box.is_open


def test_host_checks_arguments_and_state_before_sending():
    with expected_serial_protocol([HELLO]) as port, opened(port) as box:
        with pytest.raises(ValueError, match="pulse_width_us"):
            box.configure(pulse_width_us=0)
        with pytest.raises(ValueError, match="count"):
            box.arm(0)
        with pytest.raises(IncompatibleStateError, match="FIRE before ARM"):
            box.fire()
    with pytest.raises(IncompatibleStateError, match="closed"):
        box.ping()


def test_missing_port_names_port_and_remedy():
    with pytest.raises(DeviceNotFoundError, match=r"/dev/nonexistent-tty.*dialout"):
        SerialTriggerBox("/dev/nonexistent-tty").open()


# -- against the fake box (same protocol, firmware behaviour) ---------------------------------


def test_fake_box_pulses_reach_on_pulse_in_order():
    seen = []
    with FakeTriggerBox(on_pulse=seen.append) as fake, SerialTriggerBox(fake.port) as box:
        box.configure(pulse_width_us=100)
        box.arm(4)
        assert [box.fire() for _ in range(4)] == [0, 1, 2, 3]
        assert box.status().state == "DONE"
        with pytest.raises(IncompatibleStateError, match="NOT_ARMED"):
            box.fire()
    assert seen == [0, 1, 2, 3]


def test_dropped_fire_reply_is_retried_without_a_second_pulse():
    seen = []
    faults = TriggerFaults(drop_reply_on={"FIRE"})
    with (
        FakeTriggerBox(on_pulse=seen.append, faults=faults) as fake,
        SerialTriggerBox(fake.port, timeout_s=0.05) as box,
    ):
        box.arm(2)
        assert box.fire() == 0
        assert box.fire() == 1
        assert box.status().fired == 2
    assert seen == [0, 1]
    assert fake.received.count(b"3 FIRE*0B\n") == 2  # the request was sent twice


def test_garbled_replies_from_fake_box_are_recovered():
    seen = []
    faults = TriggerFaults(garble_reply_on={"FIRE", "ARM"})
    with FakeTriggerBox(on_pulse=seen.append, faults=faults) as fake, SerialTriggerBox(fake.port) as box:
        box.arm(3)
        assert [box.fire() for _ in range(3)] == [0, 1, 2]
    assert seen == [0, 1, 2]


def test_persistently_garbled_replies_raise_protocol_error():
    faults = TriggerFaults(garble_reply_on={"STATUS"}, garble_times=10)
    with FakeTriggerBox(faults=faults) as fake, SerialTriggerBox(fake.port, retries=2) as box:
        with pytest.raises(ProtocolError, match="garbled reply to STATUS"):
            box.status()


def test_stalled_box_times_out():
    with FakeTriggerBox(faults=TriggerFaults(stall=1)) as fake:
        with SerialTriggerBox(fake.port, timeout_s=0.05, retries=1) as box:
            with pytest.raises(DeviceTimeoutError, match="no reply to ARM"):
                box.arm(1)


def test_box_that_disappears_raises_device_error():
    with FakeTriggerBox(faults=TriggerFaults(disconnect_after=2)) as fake:
        box = SerialTriggerBox(fake.port, timeout_s=0.1)
        box.open()
        box.arm(2)
        with pytest.raises(DeviceError, match=rf"{fake.port}.*FIRE"):
            box.fire()
        box.close()


def test_fault_requests_are_checked():
    with pytest.raises(ValueError, match="unknown command"):
        TriggerFaults(garble_reply_on={"fire"})
    with pytest.raises(ValueError, match="drop_times"):
        TriggerFaults(drop_reply_on={"FIRE"}, drop_times=0)


def test_version_mismatch_with_fake_box_is_refused():
    with FakeTriggerBox(protocol_version=3) as fake:
        with pytest.raises(UnsupportedFeatureError, match="VERSION box speaks 3"):
            SerialTriggerBox(fake.port).open()


def test_external_sync_fires_armed_exposures():
    seen = []
    with FakeTriggerBox(on_pulse=seen.append) as fake, SerialTriggerBox(fake.port) as box:
        box.arm(3, ExposureSource.EXTERNAL_SYNC)
        with pytest.raises(IncompatibleStateError, match="EXT"):
            box.fire()
        for _ in range(3):
            fake.sync_in()
            time.sleep(0.002)  # longer than a pulse (100 us): none is missed
        box.wait_done(timeout_s=1.0)
        assert box.pulses_seen() == [0, 1, 2]
        fake.sync_in()  # not armed any more: ignored
    assert seen == [0, 1, 2]


def test_wait_done_gives_up_with_wait_timeout():
    with FakeTriggerBox() as fake, SerialTriggerBox(fake.port) as box:
        box.arm(2, ExposureSource.EXTERNAL_SYNC)
        fake.sync_in()
        with pytest.raises(WaitTimeoutError, match="no DONE"):
            box.wait_done(timeout_s=0.05)


def test_watchdog_disarms_a_silent_host_and_heartbeat_prevents_it():
    with FakeTriggerBox(watchdog_s=0.2) as fake, SerialTriggerBox(fake.port) as box:
        box.arm(5, ExposureSource.EXTERNAL_SYNC)
        for _ in range(15):  # 0.3 s of heartbeats, every 0.02 s
            time.sleep(0.02)
            box.ping()
        assert box.status().state == "ARMED"
        time.sleep(0.35)
        assert box.status().state == "IDLE"
        assert "WATCHDOG" in [e.name for e in box.events]


def test_on_pulse_failure_surfaces_when_fake_closes():
    def broken(index: int) -> None:
        raise ValueError("camera exploded")

    fake = FakeTriggerBox(on_pulse=broken)
    with SerialTriggerBox(fake.port) as box:
        box.arm(1)
        assert box.fire() == 0  # the box itself keeps working
    with pytest.raises(RuntimeError, match="on_pulse") as info:
        fake.close()
    assert isinstance(info.value.__cause__, ValueError)


def test_unreadable_requests_are_answered_with_id_zero():
    with FakeTriggerBox() as fake, SerialTriggerBox(fake.port) as box:
        port = box._port
        port.write(b"7 PING*00\n")  # wrong checksum
        port.write(b"x" * 120 + b"\n")  # too long
        port.write(b"0 PING*" + b"%02X" % tp.checksum(b"0 PING") + b"\n")  # id 0 is reserved
        time.sleep(0.05)
    assert fake.sent[-3:] == [
        b"0 ERR 6 BAD_CHECKSUM request rejected*09\n",
        b"0 ERR 7 SYNTAX request rejected*14\n",
        b"0 ERR 7 SYNTAX request rejected*14\n",
    ]


def test_fake_box_answers_the_wire_format_exactly():
    with FakeTriggerBox() as fake, SerialTriggerBox(fake.port) as box:
        box.arm(1)
        box.fire()
        box.reset()
    assert fake.received == [b"1 HELLO 2*41\n", b"2 ARM 1 SW*79\n", b"3 FIRE*0B\n", b"4 RESET*41\n"]
    assert fake.sent == [
        b"! READY 2*58\n",
        b"1 OK 2 fpp-trigger-box/2.0.0*51\n",
        b"2 OK 1 SW*23\n",
        b"! PULSE 0*4E\n",
        b"3 OK 0*07\n",
        b"! DONE 1*10\n",
        b"4 OK*10\n",
    ]


# -- contract: every TriggerBox backend, simulated or real ------------------------------------


class TestFakeTriggerBox(TriggerBoxContract):
    """The real serial driver against mock_devices' fake box on a pseudo-terminal."""

    @pytest.fixture(autouse=True)
    def _fake(self):
        with FakeTriggerBox() as fake:
            self.fake = fake
            yield

    def make_box(self) -> TriggerBox:
        return SerialTriggerBox(self.fake.port)


class TestTriggerBoxOnDevice(TriggerBoxContract):
    """A real box: ``pytest --device trigger-box:/dev/ttyACM0``."""

    @pytest.fixture(autouse=True)
    def _device(self, request: pytest.FixtureRequest) -> None:
        address = device_option(request, "trigger-box")
        if not address:
            pytest.skip("no trigger box requested (run with --device trigger-box:PORT)")
        self.port = address

    def make_box(self) -> TriggerBox:
        return SerialTriggerBox(self.port, timeout_s=2.0)


# -- what an Arduino Uno does that a box always listening would not (issue 15) ----------------


def test_open_waits_for_the_banner_of_a_board_that_resets_on_open():
    # the Uno reboots when the port opens (DTR); its bootloader drops what arrives meanwhile
    # (boot 1.5 s, HELLO deadline 1 s: margins wide enough for a loaded machine, the order kept)
    with FakeTriggerBox(boot_s=1.5) as fake:
        box = SerialTriggerBox(fake.port, command_timeouts={"HELLO": 1.0}, retries=0)
        box.open()  # no HELLO lost, no retry needed although HELLO's deadline is shorter
        assert fake.boots == 2 and fake.received[0] == tp.frame("1 HELLO 2")
        box.close()


def test_board_without_reset_is_opened_without_waiting_long():
    with FakeTriggerBox(reset_on_open=False) as fake:
        with SerialTriggerBox(fake.port, boot_timeout_s=0.05) as box:
            assert box.firmware.startswith("fpp-trigger-box/")


def test_negative_polarity_idles_inactive_from_boot():
    # a camera armed on a falling edge must not see one at reset: the box keeps its polarity
    with FakeTriggerBox() as fake:
        with SerialTriggerBox(fake.port) as box:
            box.configure(pulse_width_us=100, polarity=Polarity.ACTIVE_LOW)
            assert fake.pin_level == 1
        time.sleep(0.3)  # the fake notices a closed port by polling (10 ms; margin for a loaded machine)
        with SerialTriggerBox(fake.port) as box:  # reopening resets the board
            assert fake.boots == 3
            assert fake.pin_level == 1  # idle high before any CONFIG
            box.reset()
            assert box.status().polarity is Polarity.ACTIVE_LOW and fake.pin_level == 1


def test_missed_sync_edges_are_reported_and_ringing_ignored():
    box_fw = FakeTriggerBox(reset_on_open=False)
    with box_fw as fake, SerialTriggerBox(fake.port, boot_timeout_s=0) as box:
        box.configure(pulse_width_us=1000, delay_us=0)
        box.arm(3, ExposureSource.EXTERNAL_SYNC)
        firmware = fake._firmware
        with fake._lock:  # edges at chosen times (seconds): pulse, ringing, missed, pulse
            for at in (10.0, 10.000005, 10.0005, 10.002):
                fake._emit(firmware.sync_edge(at))
        status = box.status()
        assert (status.fired, status.missed) == (2, 1)
        assert box.missed_edges() == 1
        assert box.pulses_seen() == [0, 1]


def test_status_reply_fits_the_line_limit_at_its_longest():
    from mock_devices.trigger_box import _BoxFirmware

    firmware = _BoxFirmware(tp.PROTOCOL_VERSION, None, 0.0, tp.Polarity.ACTIVE_LOW)
    firmware.hello_done = True
    firmware.state, firmware.armed, firmware.fired, firmware.missed = "ARMED", 65535, 65535, 65535
    firmware.width_us = firmware.delay_us = tp.MAX_PULSE_WIDTH_US
    firmware.source = tp.ExposureSource.EXTERNAL_SYNC
    reply = firmware.handle_line(tp.encode_request(65535, "STATUS"), 0.0).reply
    assert reply is not None and len(reply) <= tp.MAX_LINE_BYTES
    tp.parse_incoming(reply)
