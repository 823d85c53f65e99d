"""A fake DLP LightCrafter 4500 (DLPC350) behind a pyusb backend.

``VirtualHidBackend`` is a ``usb.backend.IBackend`` presenting one USB HID device (descriptors for
device, configuration, interface and two interrupt endpoints) in the manner of pyftdi's
``tests/backend/usbvirt.py``; subclasses decide what the device answers to each OUT report.
``FakeDlpc350Backend`` puts a model of the DLPC350 controller behind it: it parses TI's HID packets,
keeps the controller state (power, display mode, pattern LUT, exposure, validation, sequencer) and
replies to reads. Faults on request: ``Dlpc350Faults``.

What the model does like the real controller, beyond the packet format (TI's host API in
SLStudio's ``dlpc350_api.cpp`` / ``ProjectorLC4500.cpp`` and pycrafter4500 work around each):

- a long request continues in headerless 64-byte reports and is answered once, after the last;
- replies carry sequence 0 unless ``echo_sequence`` (echoing is documented for the DLPC900 only);
- a display-mode switch or a start / pause / stop takes ``busy_s`` to take effect: until then
  reads report the old state and writes are refused with the error flag;
- the first START after leaving video mode is acknowledged and ignored (pycrafter sends it twice);
- an image-index LUT of exactly two entries is stored swapped (TI's ``SendImageLut`` swaps them
  back); image-index data is accepted at mailbox offset 0 only;
- a running flash sequence cycling through more than two images without 200 ms of dark time for
  each image load raises the "forced swap error" hardware status bit.

Usage::

    backend = FakeDlpc350Backend()
    dlp = LightCrafter4500(backend=backend)   # the real driver, through usb.core.find
"""

from __future__ import annotations

import errno
import logging
import os
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from types import SimpleNamespace

import usb.backend
import usb.core
import usb.util

from drivers import dlp_protocol as dp
from drivers.dlp_protocol import Command

log = logging.getLogger(__name__)

EP_OUT = 0x01
EP_IN = 0x81


def _device_descriptor(vid: int, pid: int) -> SimpleNamespace:
    return SimpleNamespace(
        bLength=18,
        bDescriptorType=usb.util.DESC_TYPE_DEVICE,
        bcdUSB=0x0200,
        bDeviceClass=0,
        bDeviceSubClass=0,
        bDeviceProtocol=0,
        bMaxPacketSize0=64,
        idVendor=vid,
        idProduct=pid,
        bcdDevice=0x0100,
        iManufacturer=0,
        iProduct=0,
        iSerialNumber=0,
        bNumConfigurations=1,
        address=7,
        bus=1,
        port_number=3,
        port_numbers=(3,),
        speed=usb.util.SPEED_FULL,
    )


def _configuration_descriptor() -> SimpleNamespace:
    return SimpleNamespace(
        bLength=9,
        bDescriptorType=usb.util.DESC_TYPE_CONFIG,
        wTotalLength=41,
        bNumInterfaces=1,
        bConfigurationValue=1,
        iConfiguration=0,
        bmAttributes=0x80,
        bMaxPower=50,
        extra_descriptors=[],
    )


def _interface_descriptor() -> SimpleNamespace:
    # HID class; the 9-byte HID class descriptor follows the interface descriptor
    hid = [9, 0x21, 0x11, 0x01, 0x00, 0x01, 0x22, 0x1D, 0x00]
    return SimpleNamespace(
        bLength=9,
        bDescriptorType=usb.util.DESC_TYPE_INTERFACE,
        bInterfaceNumber=0,
        bAlternateSetting=0,
        bNumEndpoints=2,
        bInterfaceClass=0x03,
        bInterfaceSubClass=0,
        bInterfaceProtocol=0,
        iInterface=0,
        extra_descriptors=hid,
    )


def _endpoint_descriptor(address: int) -> SimpleNamespace:
    return SimpleNamespace(
        bLength=7,
        bDescriptorType=usb.util.DESC_TYPE_ENDPOINT,
        bEndpointAddress=address,
        bmAttributes=usb.util.ENDPOINT_TYPE_INTR,
        wMaxPacketSize=dp.REPORT_SIZE,
        bInterval=1,
        bRefresh=0,
        bSynchAddress=0,
        extra_descriptors=[],
    )


class VirtualHidBackend(usb.backend.IBackend):
    """One virtual USB HID device with an interrupt OUT (0x01) and IN (0x81) endpoint."""

    def __init__(self, vid: int = dp.USB_VENDOR_ID, pid: int = dp.USB_PRODUCT_ID) -> None:
        super().__init__()
        self.vid, self.pid = vid, pid
        self.present = True
        self._dev = object()
        self._in_queue: deque[bytes] = deque()
        self.configuration = 0
        self.claimed: set[int] = set()
        self.open_handles = 0
        self.kernel_driver_active = True

    # -- what the device does (subclasses) ------------------------------------------------------
    def _on_out_report(self, report: bytes) -> bytes | None:
        """Answer one OUT report: the IN report(s) to queue (64 bytes each), or None."""
        raise NotImplementedError

    def _before_transfer(self, direction: str) -> None:
        """Hook for faults; raise usb.core.USBError to fail the transfer."""
        if not self.present:
            raise usb.core.USBError("No such device (it may have been disconnected)", error_code=-4, errno=errno.ENODEV)

    # -- enumeration and descriptors ------------------------------------------------------------
    def enumerate_devices(self):
        if self.present:
            yield self._dev

    def get_device_descriptor(self, dev):
        return _device_descriptor(self.vid, self.pid)

    def get_configuration_descriptor(self, dev, config):
        if config != 0:
            raise IndexError(f"no configuration {config}")
        return _configuration_descriptor()

    def get_interface_descriptor(self, dev, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0):
            raise IndexError(f"no interface {intf} alt {alt} in configuration {config}")
        return _interface_descriptor()

    def get_endpoint_descriptor(self, dev, ep, intf, alt, config):
        if (intf, alt, config) != (0, 0, 0) or ep not in (0, 1):
            raise IndexError(f"no endpoint {ep}")
        return _endpoint_descriptor(EP_IN if ep == 0 else EP_OUT)

    # -- device handle --------------------------------------------------------------------------
    def open_device(self, dev):
        if not self.present:
            raise usb.core.USBError("No such device", error_code=-4, errno=errno.ENODEV)
        self.open_handles += 1
        return self._dev

    def close_device(self, dev_handle):
        self.open_handles -= 1

    def set_configuration(self, dev_handle, config_value):
        self.configuration = config_value

    def get_configuration(self, dev_handle):
        return self.configuration

    def set_interface_altsetting(self, dev_handle, intf, altsetting):
        pass

    def claim_interface(self, dev_handle, intf):
        if self.kernel_driver_active:
            raise usb.core.USBError("Resource busy", error_code=-6, errno=errno.EBUSY)
        self.claimed.add(intf)

    def release_interface(self, dev_handle, intf):
        self.claimed.discard(intf)

    def is_kernel_driver_active(self, dev_handle, intf):
        return self.kernel_driver_active

    def detach_kernel_driver(self, dev_handle, intf):
        self.kernel_driver_active = False

    def attach_kernel_driver(self, dev_handle, intf):
        self.kernel_driver_active = True

    def clear_halt(self, dev_handle, ep):
        pass

    def reset_device(self, dev_handle):
        self._in_queue.clear()

    def ctrl_transfer(self, dev_handle, bmRequestType, bRequest, wValue, wIndex, data, timeout):
        return 0  # standard requests succeed (HID SET_IDLE and the like); no string descriptors

    # -- transfers ------------------------------------------------------------------------------
    def intr_write(self, dev_handle, ep, intf, data, timeout):
        self._before_transfer("write")
        if ep != EP_OUT:
            raise usb.core.USBError("Pipe error", error_code=-9, errno=errno.EPIPE)
        report = bytes(data)
        reply = self._on_out_report(report)
        if reply is not None:  # one or more IN reports
            for k in range(0, max(len(reply), 1), dp.REPORT_SIZE):
                self._in_queue.append(bytes(reply[k : k + dp.REPORT_SIZE]).ljust(dp.REPORT_SIZE, b"\x00"))
        return len(report)

    def intr_read(self, dev_handle, ep, intf, buff, timeout):
        self._before_transfer("read")
        if ep != EP_IN:
            raise usb.core.USBError("Pipe error", error_code=-9, errno=errno.EPIPE)
        if not self._in_queue:
            raise usb.core.USBTimeoutError("Operation timed out", error_code=-7, errno=errno.ETIMEDOUT)
        report = self._in_queue.popleft()
        n = min(len(buff), len(report))
        buff[:n] = type(buff)(buff.typecode, report[:n])
        return n


@dataclass(frozen=True)
class Dlpc350Faults:
    """Faults the fake controller injects.

    usb_error_on
        ``{Command: errno}``: the OUT transfer carrying that command raises ``USBError``.
    timeout_on
        Commands the controller never answers (the IN transfer times out).
    refuse
        Commands answered with the error flag set.
    disappear_after
        After this many OUT reports the device is gone: enumeration finds nothing and every
        transfer fails with ENODEV (unplugged mid-scan).
    validation_busy_reads
        Reads of the validation status that report "busy" before the result.
    claim_errno
        Claiming the interface fails with this errno (EACCES: no udev rule / permission).
    """

    usb_error_on: dict[int, int] = field(default_factory=dict)
    timeout_on: frozenset[int] | set[int] = field(default_factory=frozenset)
    refuse: frozenset[int] | set[int] = field(default_factory=frozenset)
    disappear_after: int | None = None
    validation_busy_reads: int = 1
    claim_errno: int | None = None

    def __post_init__(self) -> None:
        for name in ("usb_error_on", "timeout_on", "refuse"):
            for command in getattr(self, name):
                try:
                    Command(command)
                except ValueError:
                    raise ValueError(
                        f"Dlpc350Faults.{name}: 0x{command:04X} is not a command the fake controller knows"
                    ) from None


@dataclass
class Dlpc350State:
    """What the controller holds; tests inspect it."""

    standby: bool = False
    display_mode: int = 0
    pattern_source: int = 0
    trigger_mode: int = 0
    exposure_us: int = 8333
    frame_period_us: int = 8333
    lut_control: dp.LutControl = field(default_factory=lambda: dp.LutControl(1, True, 1, 1))
    mailbox: int = dp.Mailbox.CLOSED
    mailbox_address: int = 0
    pattern_lut: dict[int, dp.PatternEntry] = field(default_factory=dict)
    image_lut: dict[int, int] = field(default_factory=dict)
    validation: int = 0
    validated: bool = False
    sequencer: str = "stopped"
    hardware_status: int = 0x01  # internal initialization successful
    system_status: int = 0x01  # internal memory test passed


_DATA_LENGTH = {
    Command.POWER_CONTROL: 1,
    Command.DISPLAY_MODE: 1,
    Command.PATTERN_SOURCE: 1,
    Command.PATTERN_TRIGGER_MODE: 1,
    Command.PATTERN_START_STOP: 1,
    Command.EXPOSURE_FRAME_PERIOD: 8,
    Command.LUT_CONTROL: 4,
    Command.MAILBOX_ADDRESS: 1,
    Command.MAILBOX_CONTROL: 1,
    Command.LUT_VALIDATE: 1,
}


class FakeDlpc350Backend(VirtualHidBackend):
    """pyusb backend emulating a LightCrafter 4500's DLPC350 controller."""

    def __init__(
        self,
        faults: Dlpc350Faults | None = None,
        *,
        echo_sequence: bool = False,
        busy_s: float = 0.1,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        super().__init__()
        self.faults = faults or Dlpc350Faults()
        self.echo_sequence = echo_sequence
        self.busy_s = busy_s
        self._clock = clock
        self.state = Dlpc350State()
        self.requests: list[dp.Request] = []  # every request parsed, in order
        self.refused_while_busy = 0
        self._out_reports = 0
        self._busy_reads_left = 0
        self._partial = b""  # reports of a long request received so far
        self._busy_until = 0.0
        self._pending: Callable[[], None] | None = None  # the switch that takes effect then
        self._ignore_next_start = False

    def _before_transfer(self, direction: str) -> None:
        limit = self.faults.disappear_after
        if limit is not None and self._out_reports >= limit:
            self.present = False
        super()._before_transfer(direction)

    def claim_interface(self, dev_handle, intf):
        if self.faults.claim_errno is not None:
            code = self.faults.claim_errno
            raise usb.core.USBError(os.strerror(code), error_code=-3, errno=code)
        super().claim_interface(dev_handle, intf)

    def intr_write(self, dev_handle, ep, intf, data, timeout):
        self._before_transfer("write")
        try:
            command = dp.decode_request(bytes(data)).command
        except dp.PacketError:
            command = None
        if command in self.faults.usb_error_on:
            code = self.faults.usb_error_on[command]
            raise usb.core.USBError(os.strerror(code), error_code=-1, errno=code)
        self._out_reports += 1
        return super().intr_write(dev_handle, ep, intf, data, timeout)

    # -- the controller -------------------------------------------------------------------------
    def _on_out_report(self, report: bytes) -> bytes | None:
        message = self._partial + report
        try:
            size = dp.message_size(message)
        except dp.PacketError as exc:
            log.warning("fake DLPC350 ignores a malformed report: %s", exc)
            self._partial = b""
            return None
        if size > len(message):  # continuation reports follow
            self._partial = message
            return None
        self._partial = b""
        try:
            request = dp.decode_request(message)
        except dp.PacketError as exc:
            log.warning("fake DLPC350 ignores a malformed report: %s", exc)
            return None
        self.requests.append(request)
        if request.command in self.faults.timeout_on:
            return None
        self._settle()
        try:
            command = Command(request.command)
        except ValueError:
            command = None
        if command is None or command in self.faults.refuse:
            data, ok = b"", False
        elif request.is_read:
            data, ok = self._read(command)
        elif self._pending is not None:  # still switching: refuse, change nothing
            self.refused_while_busy += 1
            data, ok = b"", False
        else:
            data, ok = b"", self._write(command, request.data)
        if not request.wants_reply:
            return None
        sequence = request.sequence if self.echo_sequence else 0
        return dp.encode_reply(sequence, data, error=not ok, read=request.is_read)

    def _settle(self) -> None:
        """Apply a pending switch once its busy time is over."""
        if self._pending is not None and self._clock() >= self._busy_until:
            pending, self._pending = self._pending, None
            pending()

    def _after_busy(self, effect: Callable[[], None]) -> None:
        if self.busy_s <= 0:
            effect()
        else:
            self._pending, self._busy_until = effect, self._clock() + self.busy_s

    def _read(self, command: Command) -> tuple[bytes, bool]:
        s = self.state
        if command is Command.LUT_VALIDATE:
            if self._busy_reads_left > 0:
                self._busy_reads_left -= 1
                return bytes([s.validation | dp.Validation.BUSY]), True
            return bytes([s.validation]), True
        if command is Command.HARDWARE_STATUS:
            return bytes([s.hardware_status]), True
        if command is Command.SYSTEM_STATUS:
            return bytes([s.system_status]), True
        if command is Command.MAIN_STATUS:
            main = (0x01 if s.standby else 0) | (0x02 if s.sequencer == "running" else 0)
            return bytes([main]), True
        simple = {
            Command.POWER_CONTROL: int(s.standby),
            Command.DISPLAY_MODE: s.display_mode,
            Command.PATTERN_SOURCE: s.pattern_source,
            Command.PATTERN_TRIGGER_MODE: s.trigger_mode,
            Command.PATTERN_START_STOP: {"stopped": 0, "paused": 1, "running": 2}[s.sequencer],
        }
        if command in simple:
            return bytes([simple[command]]), True
        if command is Command.EXPOSURE_FRAME_PERIOD:
            return dp.pack_exposure(s.exposure_us, s.frame_period_us), True
        if command is Command.LUT_CONTROL:
            return s.lut_control.pack(), True
        return b"", False

    def _write(self, command: Command, data: bytes) -> bool:
        """Apply a write command as the controller does; False (a NACK) for what it refuses."""
        expected = _DATA_LENGTH.get(command)
        if expected is not None and len(data) != expected:
            return False
        setter = _WRITES.get(command)
        if setter is None:
            return False
        if command in _SEQUENCE_SETTINGS:
            if self.state.sequencer != "stopped":
                return False  # the guide: stop the sequence before changing it
            self.state.validated = False
        return setter(self, data)

    def _set_power(self, data: bytes) -> bool:
        s = self.state
        if data[0] not in (0, 1):
            return False
        s.standby = bool(data[0])
        if s.standby:
            s.sequencer = "stopped"
        return True

    def _set_display_mode(self, data: bytes) -> bool:
        s = self.state
        if data[0] not in (0, 1):
            return False
        if s.display_mode == 0 and data[0] == 1:
            self._ignore_next_start = True
        self._after_busy(lambda: setattr(s, "display_mode", data[0]))
        return True

    def _set_pattern_source(self, data: bytes) -> bool:
        if data[0] not in (0, 3):
            return False
        self.state.pattern_source = data[0]
        return True

    def _set_trigger_mode(self, data: bytes) -> bool:
        if data[0] > 4:
            return False
        self.state.trigger_mode = data[0]
        return True

    def _set_exposure(self, data: bytes) -> bool:
        self.state.exposure_us, self.state.frame_period_us = dp.unpack_exposure(data)
        return True

    def _set_lut_control(self, data: bytes) -> bool:
        self.state.lut_control = dp.LutControl.unpack(data)
        return True

    def _set_mailbox(self, data: bytes) -> bool:
        if data[0] > 3:
            return False
        self.state.mailbox = data[0]
        return True

    def _set_mailbox_address(self, data: bytes) -> bool:
        if data[0] >= dp.MAX_LUT_ENTRIES:
            return False
        self.state.mailbox_address = data[0]
        return True

    def _validate_lut(self, _data: bytes) -> bool:
        s = self.state
        s.validation = self._validation_bits()
        s.validated = not s.validation & dp.VALIDATION_ERRORS
        self._busy_reads_left = self.faults.validation_busy_reads
        return True

    def _mailbox_data(self, data: bytes) -> bool:
        s = self.state
        if s.mailbox == dp.Mailbox.PATTERN_LUT:
            if not data or len(data) % 3 or s.mailbox_address + len(data) // 3 > dp.MAX_LUT_ENTRIES:
                return False
            for k in range(0, len(data), 3):
                s.pattern_lut[s.mailbox_address] = dp.PatternEntry.unpack(data[k : k + 3])
                s.mailbox_address = (s.mailbox_address + 1) % dp.MAX_LUT_ENTRIES
        elif s.mailbox == dp.Mailbox.IMAGE_INDEX:
            if s.mailbox_address != 0 or not 1 <= len(data) <= dp.MAX_IMAGE_INDEXES:
                return False
            played = data[::-1] if len(data) == 2 else data  # the firmware swaps two entries
            s.image_lut = dict(enumerate(played))
        else:
            return False  # mailbox closed
        s.validated = False
        return True

    def _start_stop(self, action: int) -> bool:
        s = self.state
        if action == dp.SequenceAction.START:
            if s.standby or s.display_mode != 1 or not s.validated:
                return False
            if self._ignore_next_start:  # acknowledged, but the sequencer does not start
                self._ignore_next_start = False
                return True
            self._after_busy(self._run)
        elif action == dp.SequenceAction.PAUSE:
            if s.sequencer != "running":
                return False
            self._after_busy(lambda: setattr(s, "sequencer", "paused"))
        elif action == dp.SequenceAction.STOP:
            self._after_busy(lambda: setattr(s, "sequencer", "stopped"))
        else:
            return False
        return True

    def _run(self) -> None:
        s = self.state
        s.sequencer = "running"
        loads_images = s.pattern_source == 3 and s.lut_control.image_indexes > dp.FRAME_BUFFERS
        if loads_images and s.frame_period_us - s.exposure_us < dp.FLASH_IMAGE_LOAD_US:
            s.hardware_status |= 0x08  # forced swap error: the next image was not loaded in time

    def _validation_bits(self) -> int:
        """The controller's checks of the programmed sequence (DLPU010, validate command)."""
        s = self.state
        bits = 0
        found = [s.pattern_lut.get(k) for k in range(s.lut_control.lut_entries)]
        entries = [e for e in found if e is not None]
        if len(entries) < len(found):
            return int(dp.Validation.PATTERN_NUMBER_INVALID)
        for e in entries:
            limit = dp.PATTERNS_PER_IMAGE.get(e.bit_depth, 0) + (e.bit_depth == 1)  # black fill
            if not 0 <= e.pattern_number < limit:
                bits |= dp.Validation.PATTERN_NUMBER_INVALID
        depths = [e.bit_depth for e in entries if e.bit_depth in dp.MIN_EXPOSURE_US]
        minimum = max((dp.MIN_EXPOSURE_US[d] for d in depths), default=0)
        if s.exposure_us > s.frame_period_us or s.exposure_us < minimum:
            bits |= dp.Validation.EXPOSURE_OR_PERIOD_INVALID
        elif 0 < s.frame_period_us - s.exposure_us < dp.MIN_DARK_TIME_US:
            bits |= dp.Validation.PERIOD_EXPOSURE_DIFFERENCE_WARNING
        if any(e.insert_black and e.trigger_out_prev for e in entries):
            bits |= dp.Validation.TRIGGER_OUT1_WARNING
        return int(bits)


# Settings of the pattern sequence: refused while it runs, and they invalidate the LUT.
_SEQUENCE_SETTINGS = frozenset(
    {
        Command.DISPLAY_MODE,
        Command.PATTERN_SOURCE,
        Command.PATTERN_TRIGGER_MODE,
        Command.EXPOSURE_FRAME_PERIOD,
        Command.LUT_CONTROL,
    }
)
# What each write command does to the controller's state (True: acknowledged).
_WRITES: dict[Command, Callable[[FakeDlpc350Backend, bytes], bool]] = {
    Command.POWER_CONTROL: FakeDlpc350Backend._set_power,
    Command.PATTERN_START_STOP: lambda fake, data: fake._start_stop(data[0]),
    Command.DISPLAY_MODE: FakeDlpc350Backend._set_display_mode,
    Command.PATTERN_SOURCE: FakeDlpc350Backend._set_pattern_source,
    Command.PATTERN_TRIGGER_MODE: FakeDlpc350Backend._set_trigger_mode,
    Command.EXPOSURE_FRAME_PERIOD: FakeDlpc350Backend._set_exposure,
    Command.LUT_CONTROL: FakeDlpc350Backend._set_lut_control,
    Command.MAILBOX_CONTROL: FakeDlpc350Backend._set_mailbox,
    Command.MAILBOX_ADDRESS: FakeDlpc350Backend._set_mailbox_address,
    Command.MAILBOX_DATA: FakeDlpc350Backend._mailbox_data,
    Command.LUT_VALIDATE: FakeDlpc350Backend._validate_lut,
}
