"""TI DLPC350 (DLP LightCrafter 4500) USB HID packets, as the DLPC350 Programmer's Guide
(DLPU010) describes them; encoding and decoding only, no I/O.

One HID report is 64 bytes (report ID 0 is implicit on the interrupt endpoints)::

    request: flags | sequence | length LSB | length MSB | CMD3 | CMD2 | data ... (zero padded)
    reply:   flags | sequence | length LSB | length MSB | data ...

- flags: bit 7 read (1) / write (0); bit 6 reply requested; bit 5 error (set by the controller
  in a reply when it could not execute the command); bits 2:0 destination (0 = main processor).
- length: bytes after the 4-byte header: 2 command bytes + data for a request, data for a reply.
- the 16-bit USB command ``0xCMD2CMD3`` travels LSB first (CMD3 then CMD2); multi-byte fields
  in the data are little-endian.
- a request longer than one report (more than 58 data bytes, e.g. a whole pattern LUT) goes on
  in further 64-byte reports that carry the rest of the message and no header, as TI's host API
  sends it; the controller answers once, after the last report.
- sequence: TI's host numbers writes and sends reads with sequence 0; echoing the sequence in the
  reply is documented for the DLPC900 only, so a host must not rely on it.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass

USB_VENDOR_ID = 0x0451
USB_PRODUCT_ID = 0x6401
REPORT_SIZE = 64
HEADER_SIZE = 4
MAX_DATA_IN_REQUEST = REPORT_SIZE - HEADER_SIZE - 2
#: Data bytes of the longest message the driver sends (a full 128-entry pattern LUT).
MAX_MESSAGE_DATA = 3 * 128

FLAG_READ = 0x80
FLAG_REPLY = 0x40
FLAG_ERROR = 0x20
DESTINATION_MAIN = 0x00


class Command(enum.IntEnum):
    """USB commands (CMD2 << 8 | CMD3) used by the driver, from DLPU010."""

    POWER_CONTROL = 0x0200  # 1 byte: 0 normal, 1 standby
    HARDWARE_STATUS = 0x1A0A  # read, 1 byte
    SYSTEM_STATUS = 0x1A0B  # read, 1 byte
    MAIN_STATUS = 0x1A0C  # read, 1 byte
    LUT_VALIDATE = 0x1A1A  # write 0x00 starts validation; read returns the status bits
    DISPLAY_MODE = 0x1A1B  # 1 byte: 0 video, 1 pattern sequence
    PATTERN_SOURCE = 0x1A22  # 1 byte: 0 video port (24-bit RGB / FPD-link), 3 flash
    PATTERN_TRIGGER_MODE = 0x1A23  # 1 byte: 0 VSYNC, 1 internal / TRIG_IN_1/2
    PATTERN_START_STOP = 0x1A24  # 1 byte: 0 stop, 1 pause, 2 start
    EXPOSURE_FRAME_PERIOD = 0x1A29  # 8 bytes: exposure us (u32), frame period us (u32)
    LUT_CONTROL = 0x1A31  # 4 bytes, see LutControl
    MAILBOX_ADDRESS = 0x1A32  # 1 byte: LUT offset 0..127
    MAILBOX_CONTROL = 0x1A33  # 1 byte: 0 close, 1 image index, 2 pattern LUT
    MAILBOX_DATA = 0x1A34  # 3 bytes per pattern LUT entry, see PatternEntry


class SequenceAction(enum.IntEnum):
    STOP = 0
    PAUSE = 1
    START = 2


class Mailbox(enum.IntEnum):
    CLOSED = 0
    IMAGE_INDEX = 1
    PATTERN_LUT = 2


class TriggerType(enum.IntEnum):
    """Trigger of one LUT entry (byte 0 bits 1:0)."""

    INTERNAL = 0
    EXTERNAL_POSITIVE = 1
    EXTERNAL_NEGATIVE = 2
    CONTINUE = 3  # no trigger: continue from the previous pattern


class Led(enum.IntFlag):
    """LED select of one LUT entry (byte 1 bits 6:4)."""

    NONE = 0
    RED = 1
    GREEN = 2
    BLUE = 4
    WHITE = 7


class Validation(enum.IntFlag):
    """Bits of the LUT validation status (read of 0x1A1A)."""

    EXPOSURE_OR_PERIOD_INVALID = 0x01
    PATTERN_NUMBER_INVALID = 0x02
    TRIGGER_OUT1_WARNING = 0x04
    POST_VECTOR_WARNING = 0x08
    PERIOD_EXPOSURE_DIFFERENCE_WARNING = 0x10
    BUSY = 0x80


VALIDATION_TEXT = {
    Validation.EXPOSURE_OR_PERIOD_INVALID: "selected exposure or frame period settings are invalid",
    Validation.PATTERN_NUMBER_INVALID: "selected pattern numbers in the LUT are invalid",
    Validation.TRIGGER_OUT1_WARNING: "warning: continuous TRIG_OUT_1 request or overlapping black sectors",
    Validation.POST_VECTOR_WARNING: "warning: post vector not inserted before an externally triggered vector",
    Validation.PERIOD_EXPOSURE_DIFFERENCE_WARNING: "warning: frame period and exposure differ by less than 230 us",
}
VALIDATION_ERRORS = Validation.EXPOSURE_OR_PERIOD_INVALID | Validation.PATTERN_NUMBER_INVALID

#: Limits of the DLPC350 pattern sequencer (DLPU010).
MAX_LUT_ENTRIES = 128
#: 1-bit pattern number 24 is no bit plane but a black fill (TI's host API accepts 0..24).
BLACK_FILL_PATTERN = 24
#: The controller holds two 24-bit images in its frame buffers; a flash sequence cycling through
#: more images loads each from flash at its buffer swap, which takes up to ~200 ms (TI's
#: LightCrafter hosts, e.g. SLStudio, add this to the frame period beyond two images).
FRAME_BUFFERS = 2
FLASH_IMAGE_LOAD_US = 200_000
MAX_PATTERNS_TO_DISPLAY = 256
MAX_IMAGE_INDEXES = 64
MAX_PATTERNS_PER_IMAGE = 24  # 1-bit patterns in one 24-bit image
#: Patterns of a given bit depth that fit in one 24-bit image (G, R, B planes packed).
PATTERNS_PER_IMAGE = {1: 24, 2: 12, 3: 8, 4: 6, 5: 4, 6: 4, 7: 3, 8: 3}
#: Minimum exposure per bit depth in microseconds (DLPU010, pattern exposure table).
MIN_EXPOSURE_US = {1: 235, 2: 700, 3: 1570, 4: 1700, 5: 2000, 6: 2500, 7: 4500, 8: 8333}
#: Exposure shorter than the frame period must leave at least this gap (dark time) in us.
MIN_DARK_TIME_US = 230
MAX_PERIOD_US = 0xFFFFFFFF


class PacketError(ValueError):
    """A report does not follow the DLPC350 HID packet format."""


@dataclass(frozen=True)
class Request:
    """A decoded host request (what the controller, or a fake of it, receives)."""

    flags: int
    sequence: int
    command: int
    data: bytes

    @property
    def is_read(self) -> bool:
        return bool(self.flags & FLAG_READ)

    @property
    def wants_reply(self) -> bool:
        return bool(self.flags & FLAG_REPLY)


@dataclass(frozen=True)
class Reply:
    """A decoded controller reply; ``data`` is the payload its length field covers."""

    flags: int
    sequence: int
    data: bytes

    @property
    def error(self) -> bool:
        return bool(self.flags & FLAG_ERROR)


def encode_request(command: int, sequence: int, data: bytes = b"", read: bool = False, reply: bool = True) -> bytes:
    """One 64-byte report carrying ``command`` with ``data`` (at most 58 bytes)."""
    if len(data) > MAX_DATA_IN_REQUEST:
        raise PacketError(
            f"{len(data)} data bytes do not fit one report (at most {MAX_DATA_IN_REQUEST}); use encode_message"
        )
    return encode_message(command, sequence, data, read=read, reply=reply)[0]


def encode_message(
    command: int, sequence: int, data: bytes = b"", read: bool = False, reply: bool = True
) -> list[bytes]:
    """The 64-byte reports carrying ``command`` with ``data``: the first has the header, the
    command and up to 58 data bytes; continuation reports carry the next 64 bytes each."""
    if len(data) > MAX_MESSAGE_DATA:
        raise PacketError(f"{len(data)} data bytes exceed the longest message ({MAX_MESSAGE_DATA})")
    flags = (FLAG_READ if read else 0) | (FLAG_REPLY if reply else 0) | DESTINATION_MAIN
    message = struct.pack("<BBHH", flags, sequence & 0xFF, len(data) + 2, command) + bytes(data)
    return [message[k : k + REPORT_SIZE].ljust(REPORT_SIZE, b"\x00") for k in range(0, len(message), REPORT_SIZE)]


def message_size(first_report: bytes) -> int:
    """Bytes of the whole message (header included) that ``first_report`` starts; reports
    needed: ``ceil(message_size / 64)``."""
    if len(first_report) < HEADER_SIZE:
        raise PacketError(f"request of {len(first_report)} bytes is shorter than its header")
    (length,) = struct.unpack_from("<H", first_report, 2)
    return HEADER_SIZE + length


def decode_request(report: bytes) -> Request:
    """Parse a request (one report, or a first report and its continuations joined);
    ``PacketError`` if its header or length field is inconsistent."""
    if len(report) < HEADER_SIZE + 2:
        raise PacketError(f"request of {len(report)} bytes is shorter than its header")
    flags, sequence, length = struct.unpack_from("<BBH", report)
    if length < 2 or HEADER_SIZE + length > len(report):
        raise PacketError(f"request length field {length} does not fit a {len(report)}-byte report")
    (command,) = struct.unpack_from("<H", report, HEADER_SIZE)
    return Request(flags, sequence, command, bytes(report[HEADER_SIZE + 2 : HEADER_SIZE + length]))


def encode_reply(sequence: int, data: bytes = b"", error: bool = False, read: bool = True) -> bytes:
    """One 64-byte reply report answering request ``sequence`` (the controller's side)."""
    flags = (FLAG_READ if read else 0) | (FLAG_ERROR if error else 0)
    header = struct.pack("<BBH", flags, sequence & 0xFF, len(data))
    return (header + bytes(data)).ljust(REPORT_SIZE, b"\x00")


def decode_reply(report: bytes) -> Reply:
    """Parse a reply report; ``PacketError`` if it is shorter than its header or length field."""
    if len(report) < HEADER_SIZE:
        raise PacketError(f"reply of {len(report)} bytes is shorter than its 4-byte header")
    flags, sequence, length = struct.unpack_from("<BBH", report)
    if HEADER_SIZE + length > len(report):
        raise PacketError(f"reply length field {length} exceeds the {len(report)}-byte report")
    return Reply(flags, sequence, bytes(report[HEADER_SIZE : HEADER_SIZE + length]))


@dataclass(frozen=True)
class PatternEntry:
    """One entry of the pattern LUT (3 bytes in mailbox 2).

    ``pattern_number`` selects bit planes of the current 24-bit image: for bit depth b it is in
    ``0 .. PATTERNS_PER_IMAGE[b] - 1`` (G planes first, then R, then B); 1-bit pattern 24 is a
    black fill (``BLACK_FILL_PATTERN``), white when inverted. ``buffer_swap`` moves to
    the next 24-bit image (video frame or flash image) before this pattern.
    """

    pattern_number: int
    bit_depth: int = 1
    leds: Led = Led.WHITE
    trigger: TriggerType = TriggerType.INTERNAL
    invert: bool = False
    insert_black: bool = False
    buffer_swap: bool = False
    trigger_out_prev: bool = False

    def pack(self) -> bytes:
        if not 0 <= self.pattern_number <= 0x3F:
            raise PacketError(f"pattern_number {self.pattern_number} does not fit 6 bits")
        if not 1 <= self.bit_depth <= 8:
            raise PacketError(f"bit_depth {self.bit_depth} outside 1..8")
        byte0 = (self.pattern_number << 2) | int(self.trigger)
        byte1 = (int(self.leds) << 4) | self.bit_depth
        byte2 = (
            int(self.invert)
            | int(self.insert_black) << 1
            | int(self.buffer_swap) << 2
            | int(self.trigger_out_prev) << 3
        )
        return bytes((byte0, byte1, byte2))

    @classmethod
    def unpack(cls, data: bytes) -> PatternEntry:
        if len(data) != 3:
            raise PacketError(f"pattern LUT entry has {len(data)} bytes, expected 3")
        return cls(
            pattern_number=data[0] >> 2,
            trigger=TriggerType(data[0] & 0x03),
            bit_depth=data[1] & 0x0F,
            leds=Led((data[1] >> 4) & 0x07),
            invert=bool(data[2] & 1),
            insert_black=bool(data[2] & 2),
            buffer_swap=bool(data[2] & 4),
            trigger_out_prev=bool(data[2] & 8),
        )


@dataclass(frozen=True)
class LutControl:
    """Pattern display LUT control (0x1A31): counts are sent minus one."""

    lut_entries: int
    repeat: bool
    patterns_to_display: int
    image_indexes: int = 1

    def pack(self) -> bytes:
        return bytes((self.lut_entries - 1, int(self.repeat), self.patterns_to_display - 1, self.image_indexes - 1))

    @classmethod
    def unpack(cls, data: bytes) -> LutControl:
        if len(data) != 4:
            raise PacketError(f"LUT control has {len(data)} bytes, expected 4")
        return cls(
            lut_entries=(data[0] & 0x7F) + 1,
            repeat=bool(data[1] & 1),
            patterns_to_display=data[2] + 1,
            image_indexes=(data[3] & 0x3F) + 1,
        )


def pack_exposure(exposure_us: int, frame_period_us: int) -> bytes:
    """Data of EXPOSURE_FRAME_PERIOD: two little-endian u32 in microseconds."""
    return struct.pack("<II", exposure_us, frame_period_us)


def unpack_exposure(data: bytes) -> tuple[int, int]:
    """(exposure_us, frame_period_us) from the data of EXPOSURE_FRAME_PERIOD."""
    if len(data) != 8:
        raise PacketError(f"exposure/frame period has {len(data)} bytes, expected 8")
    exposure, period = struct.unpack("<II", data)
    return exposure, period


def describe_validation(bits: int) -> list[str]:
    """Human-readable explanation of each set validation bit."""
    return [text for flag, text in VALIDATION_TEXT.items() if bits & flag]


#: Hardware status (read of 0x1A0A): bit 0 is set once internal initialization succeeded; these
#: bits flag errors.
HARDWARE_STATUS_INIT_OK = 0x01
HARDWARE_ERROR_BITS = {
    1: "incompatible controller or DMD",
    2: "DMD reset controller error",
    3: "forced swap error",
    6: "sequencer abort",
    7: "sequencer error",
}
#: System status (read of 0x1A0B): bit 0 is set when the internal memory test passed.
SYSTEM_STATUS_MEMORY_OK = 0x01


class MainStatus(enum.IntFlag):
    """Bits of the main status (read of 0x1A0C)."""

    PARKED = 0x01  # DMD micromirrors parked
    SEQUENCER_RUNNING = 0x02
    VIDEO_FROZEN = 0x04
    GAMMA_CORRECTION = 0x08  # gamma correction enabled (bit 3 means "interface locked" on a DLPC900)
