"""Line format of the trigger box protocol (version 2), shared by the host driver and the fake box.

Every line is ASCII, ends with ``\\n`` and carries an NMEA-style checksum: ``*HH`` where ``HH`` is
the XOR of every byte before the ``*``, as two upper-case hex digits. See docs/trigger-protocol.md.

- request: ``<id> <COMMAND> [arg ...]*HH``          (id: 1..65535, chosen by the host)
- reply:   ``<id> OK [token ...]*HH``  or  ``<id> ERR <code> <NAME> [text ...]*HH``
- event:   ``! <EVENT> [token ...]*HH``             (unsolicited, e.g. ``! PULSE 3``)

This module only encodes and parses lines; it knows nothing about ports or state.
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

PROTOCOL_VERSION = 2
MAX_LINE_BYTES = 96
MAX_REQUEST_ID = 65535

#: Limits the box accepts (the firmware enforces the same numbers).
MAX_PULSE_WIDTH_US = 1_000_000
MAX_DELAY_US = 1_000_000
MAX_ARM_COUNT = 65535

COMMANDS = ("HELLO", "PING", "CONFIG", "ARM", "FIRE", "STATUS", "RESET")


class ErrorCode(enum.IntEnum):
    """Codes of ``ERR`` replies; the name travels with the code on the wire."""

    UNKNOWN_COMMAND = 1
    BAD_ARGUMENT = 2
    NOT_ARMED = 3
    STATE = 4
    VERSION = 5
    BAD_CHECKSUM = 6
    SYNTAX = 7
    NO_HELLO = 8


class Polarity(enum.Enum):
    """Level of the exposure pulse while active (``POS``: idle low, pulse high)."""

    ACTIVE_HIGH = "POS"
    ACTIVE_LOW = "NEG"


class ExposureSource(enum.Enum):
    """What starts each armed exposure pulse: a FIRE command, or the projector's sync input."""

    SOFTWARE = "SW"
    EXTERNAL_SYNC = "EXT"


class LineError(ValueError):
    """A line could not be parsed (bad syntax, not ASCII, too long)."""


class ChecksumError(LineError):
    """A line's ``*HH`` checksum is missing, malformed or wrong."""


def checksum(body: bytes) -> int:
    """XOR of every byte of ``body``."""
    value = 0
    for byte in body:
        value ^= byte
    return value


def frame(body: str) -> bytes:
    """``body`` with its ``*HH`` checksum and newline appended."""
    raw = body.encode("ascii")
    return raw + b"*%02X\n" % checksum(raw)


def unframe(line: bytes) -> str:
    """The body of one received line after checking terminator, length, checksum and ASCII."""
    if not line.endswith(b"\n"):
        raise LineError(f"line not terminated: {line[:40]!r}")
    if len(line) > MAX_LINE_BYTES:
        raise LineError(f"line of {len(line)} bytes exceeds {MAX_LINE_BYTES}")
    stripped = line[:-1].removesuffix(b"\r")
    body, star, cs = stripped.rpartition(b"*")
    if not star or len(cs) != 2 or any(c not in b"0123456789ABCDEF" for c in cs):
        raise ChecksumError(f"no checksum in {stripped[:40]!r}")
    if checksum(body) != int(cs, 16):
        raise ChecksumError(f"checksum mismatch in {stripped[:40]!r}")
    try:
        text = body.decode("ascii")
    except UnicodeDecodeError as exc:
        raise LineError(f"line is not ASCII: {stripped[:40]!r}") from exc
    if not text.isprintable():
        raise LineError(f"control characters in {stripped[:40]!r}")
    return text


@dataclass(frozen=True)
class Request:
    """A parsed host request (the box's side)."""

    id: int
    command: str
    args: tuple[str, ...]


@dataclass(frozen=True)
class Reply:
    """A parsed reply: ``OK`` with its tokens, or ``ERR`` with ``code`` and ``text``."""

    id: int
    ok: bool
    tokens: tuple[str, ...]
    code: ErrorCode | None = None
    text: str = ""


@dataclass(frozen=True)
class Event:
    """An unsolicited ``!`` line from the box (``PULSE``, ``DONE``, ``WATCHDOG``, ...)."""

    name: str
    tokens: tuple[str, ...]


_TOKEN = re.compile(r"[A-Za-z0-9_.=:/+-]+")


def _tokens(text: str) -> list[str]:
    parts = text.split(" ")
    if not parts[0]:
        raise LineError("empty line")
    if any(not _TOKEN.fullmatch(p) for p in parts):
        raise LineError(f"malformed tokens in {text[:40]!r}")
    return parts


def _parse_id(token: str) -> int:
    if not token.isdigit() or len(token) > 5:
        raise LineError(f"bad request id {token!r}")
    value = int(token)
    if value > MAX_REQUEST_ID:
        raise LineError(f"request id {value} above {MAX_REQUEST_ID}")
    return value


def encode_request(request_id: int, command: str, *args: object) -> bytes:
    """The framed request line; ``ValueError`` if ``request_id`` is outside 1..MAX_REQUEST_ID."""
    if not 1 <= request_id <= MAX_REQUEST_ID:
        raise ValueError(f"request_id must be in 1..{MAX_REQUEST_ID}, got {request_id}")
    return frame(" ".join([str(request_id), command, *(str(a) for a in args)]))


def parse_request(line: bytes) -> Request:
    """Parse a line sent by the host (the box's side); ``LineError`` if it is not a request."""
    parts = _tokens(unframe(line))
    if len(parts) < 2:
        raise LineError(f"request without command: {parts!r}")
    request_id = _parse_id(parts[0])
    if request_id == 0:
        raise LineError("request id 0 is reserved for replies to unparseable requests")
    return Request(request_id, parts[1].upper(), tuple(parts[2:]))


def encode_ok(request_id: int, *tokens: object) -> bytes:
    """The framed ``OK`` reply line."""
    return frame(" ".join([str(request_id), "OK", *(str(t) for t in tokens)]))


def encode_error(request_id: int, code: ErrorCode, text: str = "") -> bytes:
    """The framed ``ERR`` reply line; ``text`` is reduced to the characters tokens may hold."""
    words = [str(request_id), "ERR", str(int(code)), code.name]
    words += [w for w in re.sub(r"[^A-Za-z0-9_.=:/+-]+", " ", text).split() if w]
    return frame(" ".join(words))


def encode_event(name: str, *tokens: object) -> bytes:
    """The framed ``!`` event line."""
    return frame(" ".join(["!", name, *(str(t) for t in tokens)]))


def parse_incoming(line: bytes) -> Reply | Event:
    """Parse a line sent by the box: an event or a reply."""
    text = unframe(line)
    if text.startswith("! "):
        parts = _tokens(text[2:])
        return Event(parts[0], tuple(parts[1:]))
    parts = _tokens(text)
    if len(parts) < 2:
        raise LineError(f"reply without status: {parts!r}")
    request_id = _parse_id(parts[0])
    if parts[1] == "OK":
        return Reply(request_id, True, tuple(parts[2:]))
    if parts[1] == "ERR" and len(parts) >= 4 and parts[2].isdigit():
        try:
            code = ErrorCode(int(parts[2]))
        except ValueError as exc:
            raise LineError(f"unknown error code {parts[2]}") from exc
        if parts[3] != code.name:
            raise LineError(f"error code {code.value} named {parts[3]!r}, expected {code.name}")
        return Reply(request_id, False, (), code, " ".join(parts[4:]))
    raise LineError(f"reply is neither OK nor ERR: {parts[:3]!r}")


def parse_key_values(tokens: tuple[str, ...]) -> dict[str, str]:
    """``("state=ARMED", "remaining=3")`` -> ``{"state": "ARMED", "remaining": "3"}``."""
    result = {}
    for token in tokens:
        key, eq, value = token.partition("=")
        if not eq or not key:
            raise LineError(f"expected key=value, got {token!r}")
        result[key] = value
    return result
