"""DLP controllers: the family base and the TI DLP LightCrafter 4500 (DLPC350) over USB HID.

The base class owns the rules (state checks, the DLPC350 sequencer limits, exposure rules) and
logs; backends implement the ``_do_`` hooks. ``LightCrafter4500`` speaks TI's HID packets
(:mod:`drivers.dlp_protocol`) through pyusb; pass ``backend=`` (e.g.
``mock_devices.dlp_usb.FakeDlpc350Backend()``) to run it without hardware.

Typical use in a scan (patterns stored in the projector's flash, one external trigger per
pattern)::

    sequence = PatternSequence(
        entries=[PatternEntry(k, bit_depth=8, trigger=TriggerType.EXTERNAL_POSITIVE,
                              buffer_swap=(k == 0)) for k in range(3)],
        exposure_us=10_000, frame_period_us=10_000)
    with LightCrafter4500() as dlp, dlp.running(sequence):
        ...  # trigger each pattern; on exit the sequence stops and the old mode returns
"""

from __future__ import annotations

import abc
import contextlib
import enum
import errno
import logging
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import usb.core
import usb.util

from drivers import dlp_protocol as dp
from drivers.device import Device, check_timeout_s
from drivers.dlp_protocol import Command, Led, PatternEntry, TriggerType, Validation
from drivers.errors import (
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    IncompatibleStateError,
    ProtocolError,
    UnsupportedFeatureError,
)

__all__ = [
    "DisplayMode",
    "DlpCommandError",
    "DlpController",
    "DlpLimitError",
    "DlpStatus",
    "DlpValidationError",
    "ExposureError",
    "Led",
    "LightCrafter4500",
    "PatternEntry",
    "PatternSequence",
    "PatternSource",
    "SequenceState",
    "SequenceTrigger",
    "TriggerType",
    "ValidationResult",
    "check_sequence",
]

log = logging.getLogger(__name__)


class DlpLimitError(UnsupportedFeatureError, ValueError):
    """A request exceeds a limit of the controller; the message names the limit."""


class ExposureError(DlpLimitError):
    """Exposure / frame period break the controller's timing rules."""


class DlpValidationError(DeviceError):
    """The controller's own validation of the pattern sequence failed; the message explains."""


class DlpCommandError(DeviceError):
    """The controller answered a command with its error flag set."""


class DisplayMode(enum.IntEnum):
    VIDEO = 0
    PATTERN = 1


class PatternSource(enum.IntEnum):
    """Where the sequencer takes its 24-bit images from."""

    VIDEO_PORT = 0  # streamed over HDMI / FPD-link
    FLASH = 3  # images stored in the projector's flash


class SequenceTrigger(enum.IntEnum):
    """Pattern trigger mode of the whole sequence."""

    VSYNC = 0  # each video frame's VSYNC starts the patterns
    INTERNAL_OR_EXTERNAL = 1  # internal timer or TRIG_IN_1/2, per LUT entry


class SequenceState(enum.Enum):
    STOPPED = "stopped"
    PAUSED = "paused"
    RUNNING = "running"


@dataclass(frozen=True)
class PatternSequence:
    """Everything the sequencer needs for one pattern sequence.

    entries: the pattern LUT, in display order (1..128 entries).
    exposure_us, frame_period_us: per pattern; exposure <= period, and a shorter exposure must
        leave at least 230 us of dark time; exposure at least the minimum for the deepest entry;
        a flash sequence of more than two images needs 200 ms of dark time to load each image.
    patterns_to_display: 1..256 (default: one pass over the entries).
    image_indexes: flash images to use, in order, one per buffer swap (FLASH source only).
    """

    entries: tuple[PatternEntry, ...]
    exposure_us: int
    frame_period_us: int
    repeat: bool = False
    patterns_to_display: int | None = None
    trigger_mode: SequenceTrigger = SequenceTrigger.INTERNAL_OR_EXTERNAL
    source: PatternSource = PatternSource.FLASH
    image_indexes: tuple[int, ...] = (0,)

    def __post_init__(self) -> None:
        object.__setattr__(self, "entries", tuple(self.entries))
        object.__setattr__(self, "image_indexes", tuple(self.image_indexes))

    @property
    def n_display(self) -> int:
        """Patterns the sequencer shows (``patterns_to_display`` or one pass over the entries)."""
        return len(self.entries) if self.patterns_to_display is None else self.patterns_to_display

    @property
    def loads_flash_images(self) -> bool:
        """True when the sequence cycles through more flash images than the frame buffers hold,
        so that each buffer swap waits for an image load (about 200 ms)."""
        return self.source is PatternSource.FLASH and len(self.image_indexes) > dp.FRAME_BUFFERS

    def lut_control(self) -> dp.LutControl:
        """The LUT_CONTROL record that programs this sequence."""
        n_images = len(self.image_indexes) if self.source is PatternSource.FLASH else 1
        return dp.LutControl(len(self.entries), self.repeat, self.n_display, n_images)


@dataclass(frozen=True)
class ValidationResult:
    """The controller's verdict on the programmed sequence (:class:`Validation` bits)."""

    bits: int

    @property
    def ok(self) -> bool:
        return not self.bits & dp.VALIDATION_ERRORS

    @property
    def messages(self) -> list[str]:
        return dp.describe_validation(self.bits)


@dataclass(frozen=True)
class DlpStatus:
    """Hardware, system and main status bytes; ``problems`` names each failure they flag."""

    hardware: int
    system: int
    main: int
    problems: list[str] = field(default_factory=list)

    @property
    def sequencer_running(self) -> bool:
        return bool(self.main & dp.MainStatus.SEQUENCER_RUNNING)

    @property
    def parked(self) -> bool:
        return bool(self.main & dp.MainStatus.PARKED)

    @property
    def gamma_correction(self) -> bool:
        """Video-mode gamma correction enabled (main status bit 3 on the DLPC350)."""
        return bool(self.main & dp.MainStatus.GAMMA_CORRECTION)

    @property
    def healthy(self) -> bool:
        return not self.problems


def check_sequence(sequence: PatternSequence) -> None:
    """Raise DlpLimitError / ExposureError if ``sequence`` breaks a DLPC350 limit or rule."""
    entries = sequence.entries
    if not 1 <= len(entries) <= dp.MAX_LUT_ENTRIES:
        raise DlpLimitError(f"pattern LUT holds 1..{dp.MAX_LUT_ENTRIES} entries, got {len(entries)}")
    if not 1 <= sequence.n_display <= dp.MAX_PATTERNS_TO_DISPLAY:
        raise DlpLimitError(f"patterns_to_display must be in 1..{dp.MAX_PATTERNS_TO_DISPLAY}, got {sequence.n_display}")
    per_image = 0
    for k, entry in enumerate(entries):
        _check_entry(k, entry)
        per_image = 1 if (entry.buffer_swap or k == 0) else per_image + 1
        if per_image > dp.MAX_PATTERNS_PER_IMAGE:
            raise DlpLimitError(
                f"entry {k}: more than {dp.MAX_PATTERNS_PER_IMAGE} patterns from "
                "one 24-bit image; set buffer_swap to move to the next image"
            )
    if sequence.source is PatternSource.FLASH:
        if not 1 <= len(sequence.image_indexes) <= dp.MAX_IMAGE_INDEXES:
            raise DlpLimitError(
                f"image_indexes holds 1..{dp.MAX_IMAGE_INDEXES} flash images, got {len(sequence.image_indexes)}"
            )
        if any(not 0 <= i <= 255 for i in sequence.image_indexes):
            raise DlpLimitError(f"flash image indexes must be 0..255, got {list(sequence.image_indexes)}")
    check_exposure(sequence.exposure_us, sequence.frame_period_us, max(e.bit_depth for e in entries))
    if sequence.loads_flash_images:
        _check_flash_loads(sequence)


def _check_entry(k: int, entry: PatternEntry) -> None:
    """One LUT entry: its bit depth, its pattern number within a 24-bit image, no black after trigger."""
    if entry.bit_depth not in dp.PATTERNS_PER_IMAGE:
        raise DlpLimitError(f"entry {k}: bit_depth must be 1..8, got {entry.bit_depth}")
    limit = dp.PATTERNS_PER_IMAGE[entry.bit_depth]
    black_fill = entry.bit_depth == 1 and entry.pattern_number == dp.BLACK_FILL_PATTERN
    if not (0 <= entry.pattern_number < limit or black_fill):
        raise DlpLimitError(
            f"entry {k}: pattern_number {entry.pattern_number} invalid for "
            f"{entry.bit_depth}-bit patterns (a 24-bit image holds {limit}: 0..{limit - 1}"
            + (f"; {dp.BLACK_FILL_PATTERN} is the black fill)" if entry.bit_depth == 1 else ")")
        )
    if entry.insert_black and entry.trigger_out_prev:
        raise DlpLimitError(f"entry {k}: insert_black cannot be combined with trigger_out_prev")


def _check_flash_loads(sequence: PatternSequence) -> None:
    """More flash images than frame buffers: every buffer swap loads one, in the dark part of the frame."""
    dark_us = sequence.frame_period_us - sequence.exposure_us
    if dark_us < dp.FLASH_IMAGE_LOAD_US:
        raise ExposureError(
            f"{len(sequence.image_indexes)} flash images do not fit the controller's "
            f"{dp.FRAME_BUFFERS} frame buffers: each buffer swap must load an image from "
            f"flash, so the frame period must exceed the exposure by at least "
            f"{dp.FLASH_IMAGE_LOAD_US} us (got {dark_us} us); use a frame period of at "
            f"least {sequence.exposure_us + dp.FLASH_IMAGE_LOAD_US} us or at most "
            f"{dp.FRAME_BUFFERS} images"
        )


def check_exposure(exposure_us: int, frame_period_us: int, bit_depth: int) -> None:
    """Raise ExposureError naming the rule that ``exposure_us`` / ``frame_period_us`` break."""
    minimum = dp.MIN_EXPOSURE_US[bit_depth]
    if exposure_us < minimum:
        raise ExposureError(f"exposure {exposure_us} us below the {minimum} us minimum for {bit_depth}-bit patterns")
    if frame_period_us > dp.MAX_PERIOD_US:
        raise ExposureError(f"frame period {frame_period_us} us does not fit 32 bits")
    if exposure_us > frame_period_us:
        raise ExposureError(f"exposure {exposure_us} us exceeds the frame period {frame_period_us} us")
    if 0 < frame_period_us - exposure_us < dp.MIN_DARK_TIME_US:
        raise ExposureError(
            f"exposure {exposure_us} us must equal the frame period {frame_period_us} us or be "
            f"at least {dp.MIN_DARK_TIME_US} us shorter"
        )


class DlpController(Device):
    """Family base of DLP pattern projectors driven over a control link.

    :meth:`open` reads the controller's power, display mode and sequencer state.
    """

    family = "DLP controller"

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        self._standby = False
        self._mode: DisplayMode | None = None
        self._sequence: PatternSequence | None = None
        self._validated = False
        self._state = SequenceState.STOPPED

    # -- state ----------------------------------------------------------------------------------
    @property
    def sequence(self) -> PatternSequence | None:
        return self._sequence

    @property
    def state(self) -> SequenceState:
        return self._state

    def _after_open(self) -> None:
        self._standby, self._mode, running = self._do_read_state()
        self._state = SequenceState.RUNNING if running else SequenceState.STOPPED
        log.info(
            "%s opened: %s, %s mode, sequence %s",
            self,
            "standby" if self._standby else "awake",
            self._mode.name,
            self._state.value,
        )

    # -- power and mode -------------------------------------------------------------------------
    def standby(self) -> None:
        """Stop the sequence and put the controller in its low-power standby."""
        self._require_open("standby")
        if self._state is not SequenceState.STOPPED:
            self.stop()
        log.info("%s: standby", self)
        self._do_set_power(standby=True)
        self._standby = True

    def wake(self) -> None:
        """Return from standby to normal power."""
        self._require_open("wake")
        log.info("%s: normal power", self)
        self._do_set_power(standby=False)
        self._standby = False

    def set_display_mode(self, mode: DisplayMode) -> None:
        """Switch between video and pattern display (stops a running sequence first)."""
        self._require_awake("set display mode")
        if self._state is not SequenceState.STOPPED:
            self.stop()
        log.info("%s: display mode %s", self, DisplayMode(mode).name)
        self._do_set_display_mode(DisplayMode(mode))
        self._mode = DisplayMode(mode)
        self._validated = False

    # -- pattern sequence -----------------------------------------------------------------------
    def configure_sequence(self, sequence: PatternSequence) -> None:
        """Check ``sequence`` against the limits, stop the sequencer and program it.

        The sequence must be validated (:meth:`validate`) before :meth:`start`. If programming
        fails half-way the controller holds no usable sequence until configured again.
        """
        self._require_awake("configure a pattern sequence")
        if self._mode is not DisplayMode.PATTERN:
            raise IncompatibleStateError(
                f"{self}: pattern sequences need pattern display mode; call set_display_mode(DisplayMode.PATTERN) first"
            )
        check_sequence(sequence)
        if self._state is not SequenceState.STOPPED:
            self.stop()
        log.info(
            "%s: %d LUT entries, exposure %d us, period %d us, %s",
            self,
            len(sequence.entries),
            sequence.exposure_us,
            sequence.frame_period_us,
            "repeat" if sequence.repeat else "once",
        )
        self._sequence, self._validated = None, False
        self._do_write_sequence(sequence)
        self._sequence = sequence

    def validate(self, timeout_s: float = 2.0) -> ValidationResult:
        """Ask the controller to validate the programmed sequence.

        Returns the result (warnings are logged); raises DlpValidationError with the
        controller's reasons when the sequence is invalid.
        """
        self._require_awake("validate")
        if self._sequence is None:
            raise IncompatibleStateError(f"{self}: nothing to validate; configure_sequence first")
        timeout_s = check_timeout_s(timeout_s)
        self._do_start_validation()
        deadline = time.monotonic() + timeout_s
        while True:
            bits = self._do_read_validation()
            if not bits & Validation.BUSY:
                break
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(f"{self}: still validating after {timeout_s:.3g} s")
            time.sleep(0.001)
        result = ValidationResult(bits)
        for message in result.messages:
            log.warning("%s: validation: %s", self, message)
        self._validated = result.ok
        if not result.ok:
            raise DlpValidationError(f"{self}: pattern sequence rejected: " + "; ".join(result.messages))
        return result

    def start(self) -> None:
        """Start the validated sequence."""
        self._require_awake("start")
        if not self._validated:
            raise IncompatibleStateError(
                f"{self}: start needs a validated sequence; configure_sequence and validate first"
            )
        log.info("%s: start sequence", self)
        self._do_sequence(dp.SequenceAction.START)
        self._state = SequenceState.RUNNING

    def pause(self) -> None:
        """Pause the running sequence."""
        self._require_open("pause")
        if self._state is not SequenceState.RUNNING:
            raise IncompatibleStateError(f"{self}: pause needs a running sequence (it is {self._state.value})")
        self._do_sequence(dp.SequenceAction.PAUSE)
        self._state = SequenceState.PAUSED

    def stop(self) -> None:
        """Stop the sequencer (whatever its state)."""
        self._require_open("stop")
        log.info("%s: stop sequence", self)
        self._do_sequence(dp.SequenceAction.STOP)
        self._state = SequenceState.STOPPED

    @contextlib.contextmanager
    def running(self, sequence: PatternSequence) -> Iterator[DlpController]:
        """Run ``sequence`` for the duration of a ``with`` block, then restore.

        Wakes the controller, selects pattern mode, configures, validates and starts; on exit
        (or if any step fails) stops the sequence and restores the previous display mode and
        power state. Errors while restoring are logged; the block's own error wins.
        """
        self._require_open("run a sequence")
        was_standby, old_mode = self._standby, self._mode
        try:
            if was_standby:
                self.wake()
            self.set_display_mode(DisplayMode.PATTERN)
            self.configure_sequence(sequence)
            self.validate()
            self.start()
            yield self
        finally:
            self._restore(was_standby, old_mode)

    def _restore(self, was_standby: bool, old_mode: DisplayMode | None) -> None:
        steps: list[tuple[str, Callable[[], None]]] = [("stop", self.stop)]
        if old_mode is not None and old_mode is not DisplayMode.PATTERN:
            steps.append(("restore display mode", lambda: self.set_display_mode(old_mode)))
        if was_standby:
            steps.append(("return to standby", self.standby))
        for what, step in steps:
            try:
                step()
            except DeviceError as exc:
                log.warning("%s: could not %s after the sequence: %s", self, what, exc)

    def status(self) -> DlpStatus:
        """Read the status bytes and name what they report as failed."""
        self._require_open("status")
        hardware, system, main = self._do_read_status()
        problems = [text for bit, text in dp.HARDWARE_ERROR_BITS.items() if hardware & (1 << bit)]
        if not hardware & dp.HARDWARE_STATUS_INIT_OK:
            problems.append("internal initialization failed")
        if not system & dp.SYSTEM_STATUS_MEMORY_OK:
            problems.append("internal memory test failed")
        return DlpStatus(hardware, system, main, problems)

    # -- checks ---------------------------------------------------------------------------------
    def _require_awake(self, what: str) -> None:
        self._require_open(what)
        if self._standby:
            raise IncompatibleStateError(f"{self}: cannot {what} in standby; call wake() first")

    # -- hooks (and Device's _open / _close) ----------------------------------------------------
    @abc.abstractmethod
    def _do_read_state(self) -> tuple[bool, DisplayMode, bool]:
        """(standby, display mode, sequencer running) as the controller reports them."""

    @abc.abstractmethod
    def _do_set_power(self, standby: bool) -> None: ...

    @abc.abstractmethod
    def _do_set_display_mode(self, mode: DisplayMode) -> None:
        """Switch, and return once the controller reports ``mode`` (a switch is not instant)."""

    @abc.abstractmethod
    def _do_write_sequence(self, sequence: PatternSequence) -> None: ...

    @abc.abstractmethod
    def _do_start_validation(self) -> None: ...

    @abc.abstractmethod
    def _do_read_validation(self) -> int: ...

    @abc.abstractmethod
    def _do_sequence(self, action: dp.SequenceAction) -> None:
        """Start, pause or stop, and return once the sequencer reports the new state."""

    @abc.abstractmethod
    def _do_read_status(self) -> tuple[int, int, int]: ...


def _action_name(value: int) -> str:
    names = {action.value: action.name for action in dp.SequenceAction}
    return names.get(value, f"0x{value:02X}")


_UDEV_HINT = (
    "add a udev rule, e.g. /etc/udev/rules.d/70-lightcrafter.rules: "
    'SUBSYSTEM=="usb", ATTR{idVendor}=="0451", ATTR{idProduct}=="6401", MODE="0660", '
    'GROUP="plugdev"'
)


class LightCrafter4500(DlpController):
    """TI DLP LightCrafter 4500 (DLPC350) over USB HID with pyusb.

    Parameters
    ----------
    backend : usb.backend.IBackend, optional
        Passed to ``usb.core.find``; None lets pyusb pick libusb.
    timeout_s : float
        Deadline of each USB transfer.
    settle_s : float
        Wait after a display-mode switch or a start / pause / stop before reading the state
        back, and between read-backs (TI's hosts wait 100-200 ms; the controller refuses or
        ignores commands while it switches).
    settle_timeout_s : float
        Deadline for the state to read back as requested (the action is re-sent meanwhile).
    name : str, optional
        Used in log lines and error messages.

    Replies are matched on the sequence byte only once the controller has been seen to echo
    it; a DLPC350 that answers with sequence 0 (TI's host never checks it) is read in order.
    """

    EP_OUT = 0x01
    EP_IN = 0x81
    INTERFACE = 0

    def __init__(
        self,
        backend: object | None = None,
        timeout_s: float = 1.0,
        settle_s: float = 0.1,
        settle_timeout_s: float = 2.0,
        name: str | None = None,
    ) -> None:
        super().__init__(name or "DLP LightCrafter 4500 (USB 0451:6401)")
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        if settle_s < 0 or settle_timeout_s <= 0:
            raise ValueError(f"settle_s must be >= 0 and settle_timeout_s > 0, got {settle_s}, {settle_timeout_s}")
        self._backend = backend
        self.timeout_s = float(timeout_s)
        self.settle_s = float(settle_s)
        self.settle_timeout_s = float(settle_timeout_s)
        self._dev: Any = None  # usb.core.Device while open
        self._seq = 0
        self._echoes: bool | None = None  # does the controller echo sequence bytes? (unknown)

    # -- hooks ----------------------------------------------------------------------------------
    def _open(self) -> None:
        try:
            dev = usb.core.find(idVendor=dp.USB_VENDOR_ID, idProduct=dp.USB_PRODUCT_ID, backend=self._backend)
        except usb.core.NoBackendError as exc:
            raise DeviceNotFoundError(
                f"{self}: pyusb found no libusb backend; install libusb (Debian/Ubuntu: apt install libusb-1.0-0)"
            ) from exc
        except usb.core.USBError as exc:
            raise DeviceNotFoundError(f"{self}: USB enumeration failed ({exc}); {_UDEV_HINT}") from exc
        if dev is None:
            raise DeviceNotFoundError(f"{self} not found: plug it in and power it on")
        try:
            try:
                if dev.is_kernel_driver_active(self.INTERFACE):
                    dev.detach_kernel_driver(self.INTERFACE)
            except NotImplementedError:
                pass  # backends without kernel drivers (Windows)
            dev.set_configuration()
            usb.util.claim_interface(dev, self.INTERFACE)
        except usb.core.USBError as exc:
            usb.util.dispose_resources(dev)
            if exc.errno in (errno.EACCES, errno.EPERM):
                raise DeviceNotFoundError(f"{self}: no permission to open it; {_UDEV_HINT}") from exc
            raise DeviceError(f"{self}: cannot claim its HID interface: {exc}") from exc
        self._dev = dev

    def _close(self) -> None:
        self._echoes = None
        dev, self._dev = self._dev, None
        if dev is None:
            return
        try:
            usb.util.release_interface(dev, self.INTERFACE)
        except usb.core.USBError as exc:
            log.warning("%s: releasing the interface failed: %s", self, exc)
        finally:
            usb.util.dispose_resources(dev)

    def _do_read_state(self) -> tuple[bool, DisplayMode, bool]:
        standby = bool(self._read_byte(Command.POWER_CONTROL) & 0x01)
        mode = DisplayMode(self._read_byte(Command.DISPLAY_MODE) & 0x01)
        running = bool(self._read_byte(Command.MAIN_STATUS) & dp.MainStatus.SEQUENCER_RUNNING)
        return standby, mode, running

    def _do_set_power(self, standby: bool) -> None:
        self._write(Command.POWER_CONTROL, bytes([int(standby)]))

    def _do_set_display_mode(self, mode: DisplayMode) -> None:
        self._write_and_confirm(
            Command.DISPLAY_MODE, int(mode), "display mode", lambda value: DisplayMode(value & 0x01).name, resend=False
        )

    def _do_write_sequence(self, sequence: PatternSequence) -> None:
        self._write(Command.PATTERN_SOURCE, bytes([int(sequence.source)]))
        self._write(Command.PATTERN_TRIGGER_MODE, bytes([int(sequence.trigger_mode)]))
        self._write(Command.EXPOSURE_FRAME_PERIOD, dp.pack_exposure(sequence.exposure_us, sequence.frame_period_us))
        self._write(Command.LUT_CONTROL, sequence.lut_control().pack())
        # as TI's host: each LUT in one message from mailbox offset 0 (long ones continue in
        # headerless reports)
        self._write_mailbox(dp.Mailbox.PATTERN_LUT, b"".join(e.pack() for e in sequence.entries))
        if sequence.source is PatternSource.FLASH:
            indexes = bytes(sequence.image_indexes)
            if len(indexes) == 2:  # the firmware plays a two-entry image LUT swapped
                indexes = indexes[::-1]
            self._write_mailbox(dp.Mailbox.IMAGE_INDEX, indexes)

    def _write_mailbox(self, mailbox: dp.Mailbox, data: bytes) -> None:
        self._write(Command.MAILBOX_CONTROL, bytes([mailbox]))
        self._write(Command.MAILBOX_ADDRESS, b"\x00")
        self._write(Command.MAILBOX_DATA, data)
        self._write(Command.MAILBOX_CONTROL, bytes([dp.Mailbox.CLOSED]))

    def _do_start_validation(self) -> None:
        self._write(Command.LUT_VALIDATE, b"\x00")

    def _do_read_validation(self) -> int:
        return self._read_byte(Command.LUT_VALIDATE)

    def _do_sequence(self, action: dp.SequenceAction) -> None:
        # TI's hosts re-send stop until the sequencer reads stopped; pycrafter sends start twice
        # after leaving video mode (the first one may be dropped)
        self._write_and_confirm(Command.PATTERN_START_STOP, int(action), "sequencer", _action_name, resend=True)

    def _write_and_confirm(
        self, command: Command, value: int, what: str, name: Callable[[int], str], resend: bool
    ) -> None:
        """Write ``value``, then read ``command`` back (after ``settle_s``) until it reads
        ``value``; re-send meanwhile if ``resend``. A re-send the controller refuses while it
        is still busy is not an error; the deadline is."""
        self._write(command, bytes([value]))
        deadline = time.monotonic() + self.settle_timeout_s
        while True:
            time.sleep(self.settle_s)
            found = self._read_byte(command)
            if found == value:
                return
            if time.monotonic() > deadline:
                raise DeviceTimeoutError(
                    f"{self}: {what} still reads {name(found)} {self.settle_timeout_s:.3g} s after "
                    f"setting {name(value)}"
                )
            if resend:
                log.info("%s: %s reads %s, sending %s again", self, what, name(found), name(value))
                try:
                    self._write(command, bytes([value]))
                except DlpCommandError as exc:
                    log.info("%s: %s", self, exc)

    def _do_read_status(self) -> tuple[int, int, int]:
        return (
            self._read_byte(Command.HARDWARE_STATUS),
            self._read_byte(Command.SYSTEM_STATUS),
            self._read_byte(Command.MAIN_STATUS),
        )

    # -- transport ------------------------------------------------------------------------------
    def _write(self, command: Command, data: bytes) -> None:
        self._transact(command, data, read=False)

    def _read_byte(self, command: Command) -> int:
        data = self._transact(command, b"", read=True)
        if len(data) < 1:
            raise ProtocolError(f"{self}: empty reply to read of {command.name}")
        return data[0]

    def _transact(self, command: Command, data: bytes, read: bool) -> bytes:
        """Send one request (reply requested; several reports if long) and return the data of
        its reply."""
        if self._dev is None:
            raise IncompatibleStateError(f"{self}: not open")
        self._seq = self._seq % 0xFF + 1  # 1..255: a reply with 0 never looks echoed
        sequence = self._seq
        reports = dp.encode_message(command, sequence, data, read=read, reply=True)
        timeout_ms = max(1, int(self.timeout_s * 1000))
        what = f"{'read' if read else 'write'} {command.name} (0x{int(command):04X})"
        try:
            for report in reports:
                written = self._dev.write(self.EP_OUT, report, timeout_ms)
                if written != len(report):
                    raise ProtocolError(f"{self}: {what}: wrote {written} of {len(report)} bytes")
            for _ in range(4):  # skip at most a few stale replies to earlier requests
                raw = bytes(self._dev.read(self.EP_IN, dp.REPORT_SIZE, timeout_ms))
                try:
                    reply = dp.decode_reply(raw)
                except dp.PacketError as exc:
                    raise ProtocolError(f"{self}: {what}: malformed reply: {exc}") from exc
                if self._echoes is None:  # the first reply tells whether sequences are echoed
                    self._echoes = reply.sequence == sequence
                    log.info(
                        "%s: the controller %s sequence bytes", self, "echoes" if self._echoes else "does not echo"
                    )
                if not self._echoes or reply.sequence == sequence:
                    break
                log.info("%s: dropping reply with sequence %d while waiting for %d", self, reply.sequence, sequence)
            else:
                raise ProtocolError(f"{self}: {what}: no reply carried sequence {sequence}")
        except usb.core.USBTimeoutError as exc:
            raise DeviceTimeoutError(f"{self}: {what}: no answer within {self.timeout_s:.3g} s") from exc
        except usb.core.USBError as exc:
            if exc.errno == errno.ENODEV:
                raise DeviceNotFoundError(f"{self} disconnected during {what}; reconnect it and open again") from exc
            raise DeviceError(f"{self}: USB error during {what}: {exc}") from exc
        if reply.error:
            raise DlpCommandError(f"{self}: controller refused {what} with data {data.hex() or '(none)'}")
        return reply.data
