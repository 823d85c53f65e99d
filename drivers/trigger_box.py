"""Trigger box drivers: the family base and the serial host driver (protocol v2).

The box turns a software command (``FIRE``) or an edge on its sync input into one exposure pulse
of configured width, delay and polarity. Protocol: docs/trigger-protocol.md; line format:
:mod:`drivers.trigger_protocol`.

Usage::

    with SerialTriggerBox("/dev/ttyACM0") as box:      # open() negotiates the version
        box.configure(pulse_width_us=200, delay_us=0, polarity=Polarity.ACTIVE_HIGH)
        box.arm(n_patterns)
        for k in range(n_patterns):
            ...show pattern k...
            assert box.fire() == k
"""

from __future__ import annotations

import abc
import collections
import logging
import time
from collections.abc import Mapping
from dataclasses import dataclass

import serial

from drivers import trigger_protocol as tp
from drivers.device import Device, check_timeout_s
from drivers.errors import (
    DeviceError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    IncompatibleStateError,
    ProtocolError,
    UnsupportedFeatureError,
    WaitTimeoutError,
)
from drivers.trigger_protocol import ExposureSource, Polarity

__all__ = [
    "ExposureSource",
    "Polarity",
    "SerialTriggerBox",
    "TriggerBox",
    "TriggerBoxRefusedError",
    "TriggerBoxStatus",
]

log = logging.getLogger(__name__)

try:  # pyserial's POSIX backend lets termios errors through when a tty vanishes
    import termios

    _PORT_ERRORS: tuple[type[BaseException], ...] = (serial.SerialException, OSError, termios.error)
except ImportError:  # Windows
    _PORT_ERRORS = (serial.SerialException, OSError)

# opening the port can also fail on its settings (pyserial raises ValueError for a bad baud rate or timeout)
_OPEN_ERRORS: tuple[type[BaseException], ...] = (*_PORT_ERRORS, ValueError)


class TriggerBoxRefusedError(DeviceError, ValueError):
    """The box rejected an argument (``ERR 2 BAD_ARGUMENT``)."""


@dataclass(frozen=True)
class TriggerBoxStatus:
    """What ``STATUS`` reports."""

    state: str  # IDLE, ARMED or DONE
    armed: int  # exposures requested by the last ARM
    fired: int  # exposures fired since the last ARM
    pulse_width_us: int
    delay_us: int
    polarity: Polarity
    source: ExposureSource
    missed: int = 0  # sync edges since the last ARM that arrived while a pulse was pending


class TriggerBox(Device):
    """Family base: public methods check state and log; backends implement ``_open``, ``_close``
    and the ``_do_`` hooks. :meth:`open` negotiates the protocol version (:meth:`hello`)."""

    family = "trigger box"

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        self._armed_count = 0

    def _after_open(self) -> None:
        self.hello()

    def hello(self) -> int:
        """Negotiate the protocol version; returns the version both sides speak."""
        self._require_open("HELLO")
        version = self._do_hello(tp.PROTOCOL_VERSION)
        log.info("%s speaks trigger protocol %d", self, version)
        return version

    def ping(self) -> float:
        """Heartbeat; returns the round-trip time in seconds. Send one at least every second
        while armed: the box disarms itself after a few seconds of silence (its watchdog)."""
        self._require_open("PING")
        start = time.monotonic()
        self._do_ping()
        return time.monotonic() - start

    def configure(self, pulse_width_us: int, delay_us: int = 0, polarity: Polarity = Polarity.ACTIVE_HIGH) -> None:
        """Set the exposure pulse: width and delay (after FIRE or sync edge) in microseconds."""
        self._require_open("CONFIG")
        if not 1 <= int(pulse_width_us) <= tp.MAX_PULSE_WIDTH_US:
            raise ValueError(f"pulse_width_us must be in 1..{tp.MAX_PULSE_WIDTH_US}, got {pulse_width_us}")
        if not 0 <= int(delay_us) <= tp.MAX_DELAY_US:
            raise ValueError(f"delay_us must be in 0..{tp.MAX_DELAY_US}, got {delay_us}")
        log.info("%s: pulse %d us after %d us, %s", self, pulse_width_us, delay_us, polarity.name)
        self._do_configure(int(pulse_width_us), int(delay_us), Polarity(polarity))

    def arm(self, count: int, source: ExposureSource = ExposureSource.SOFTWARE) -> None:
        """Expect ``count`` exposures, started by :meth:`fire` or by the sync input."""
        self._require_open("ARM")
        if not 1 <= int(count) <= tp.MAX_ARM_COUNT:
            raise ValueError(f"count must be in 1..{tp.MAX_ARM_COUNT}, got {count}")
        log.info("%s: armed for %d exposures (%s)", self, count, source.name)
        self._do_arm(int(count), ExposureSource(source))
        self._armed_count = int(count)

    def fire(self) -> int:
        """One software-commanded exposure pulse; returns its index within the current ARM."""
        self._require_open("FIRE")
        if self._armed_count == 0:
            raise IncompatibleStateError(f"{self}: FIRE before ARM")
        index = self._do_fire()
        log.debug("%s: pulse %d", self, index)
        return index

    def status(self) -> TriggerBoxStatus:
        """The box's state, counters and pulse settings."""
        self._require_open("STATUS")
        return self._do_status()

    def reset(self) -> None:
        """Disarm and restore the default pulse settings."""
        self._require_open("RESET")
        self._do_reset()
        self._armed_count = 0

    # -- hooks (and Device's _open / _close) ----------------------------------------------------
    @abc.abstractmethod
    def _do_hello(self, version: int) -> int: ...

    @abc.abstractmethod
    def _do_ping(self) -> None: ...

    @abc.abstractmethod
    def _do_configure(self, pulse_width_us: int, delay_us: int, polarity: Polarity) -> None: ...

    @abc.abstractmethod
    def _do_arm(self, count: int, source: ExposureSource) -> None: ...

    @abc.abstractmethod
    def _do_fire(self) -> int: ...

    @abc.abstractmethod
    def _do_status(self) -> TriggerBoxStatus: ...

    @abc.abstractmethod
    def _do_reset(self) -> None: ...


class _NoReply(Exception):
    pass


class _Garbled(Exception):
    pass


class SerialTriggerBox(TriggerBox):
    """Host driver for the serial trigger box (firmware/trigger_box, protocol v2).

    Parameters
    ----------
    url : str
        Anything ``serial.serial_for_url`` opens: ``/dev/ttyACM0``, a pty path, ``loop://``.
    baudrate : int
        115200 for the reference firmware.
    timeout_s : float
        Deadline of one reply; FIRE adds the configured delay and width.
    command_timeouts : mapping, optional
        Per-command deadlines overriding ``timeout_s``; by default HELLO gets
        ``HELLO_TIMEOUT_S``.
    boot_timeout_s : float
        An Arduino Uno resets when its port is opened (DTR) and its bootloader drops what
        arrives meanwhile; ``open()`` waits up to this long for the ``! READY`` banner before
        sending HELLO (0: send HELLO at once, for boards that do not reset).
    retries : int
        Extra attempts after a missing or garbled reply. A retry resends the same request id,
        which the box answers from its reply cache without acting twice (FIRE never doubles).
    name : str, optional
        Used in log lines and error messages; default ``"trigger box on <url>"``.
    """

    HELLO_TIMEOUT_S = 2.0

    def __init__(
        self,
        url: str,
        baudrate: int = 115200,
        timeout_s: float = 0.5,
        retries: int = 2,
        command_timeouts: Mapping[str, float] | None = None,
        boot_timeout_s: float = 3.0,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"trigger box on {url}")
        if timeout_s <= 0:
            raise ValueError(f"timeout_s must be > 0, got {timeout_s}")
        self.command_timeouts = {"HELLO": max(timeout_s, self.HELLO_TIMEOUT_S)}
        self.command_timeouts.update(command_timeouts or {})
        for command, seconds in self.command_timeouts.items():
            if command not in tp.COMMANDS or seconds <= 0:
                raise ValueError(
                    f"command_timeouts: expected positive seconds for one of "
                    f"{', '.join(tp.COMMANDS)}, got {command}={seconds}"
                )
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        if boot_timeout_s < 0:
            raise ValueError(f"boot_timeout_s must be >= 0, got {boot_timeout_s}")
        self.boot_timeout_s = float(boot_timeout_s)
        self.url = url
        self.baudrate = baudrate
        self.timeout_s = float(timeout_s)
        self.retries = int(retries)
        self._port: serial.SerialBase | None = None
        self._next_id = 0
        self._pulse_us = 0
        self.events: collections.deque[tp.Event] = collections.deque(maxlen=4096)
        self.firmware = ""

    # -- events ---------------------------------------------------------------------------------
    def wait_done(self, timeout_s: float) -> None:
        """Wait for ``! DONE`` (all armed exposures fired, e.g. from the sync input), pinging
        the box meanwhile; raises WaitTimeoutError when ``timeout_s`` runs out first."""
        self._require_open("wait for DONE")
        timeout_s = check_timeout_s(timeout_s)
        deadline = time.monotonic() + timeout_s
        while True:
            if any(e.name == "DONE" for e in self.events):
                return
            if any(e.name == "WATCHDOG" for e in self.events):
                raise IncompatibleStateError(f"{self}: the box disarmed itself (watchdog)")
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise WaitTimeoutError(f"{self}: no DONE within {timeout_s:.3g} s")
            self._drain_events(min(remaining, 0.2))
            self.ping()

    def pulses_seen(self) -> list[int]:
        """Indices of the ``! PULSE`` events received so far (since the last ARM)."""
        return [int(e.tokens[0]) for e in self.events if e.name == "PULSE" and e.tokens]

    def missed_edges(self) -> int:
        """Sync edges the box reported missed (``! MISSED <total>``) since the last ARM."""
        totals = [int(e.tokens[0]) for e in self.events if e.name == "MISSED" and e.tokens and e.tokens[0].isdigit()]
        return max(totals, default=0)

    # -- hooks ----------------------------------------------------------------------------------
    def _open(self) -> None:
        try:
            self._port = serial.serial_for_url(
                self.url, baudrate=self.baudrate, timeout=self.timeout_s, write_timeout=self.timeout_s
            )
            self._port.reset_input_buffer()
        except _OPEN_ERRORS as exc:
            raise DeviceNotFoundError(
                f"cannot open trigger box port {self.url}: {exc}; check the cable, the port name "
                "and that you may open it (Linux: be in the 'dialout' group)"
            ) from exc
        if self.boot_timeout_s > 0:
            self._wait_ready(self.boot_timeout_s)

    def _wait_ready(self, timeout_s: float) -> None:
        """Wait for the ``! READY`` banner of a board that reset on open; anything sent before
        it would be lost in the bootloader. Without a banner (a board that does not reset) the
        HELLO that follows finds out."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            raw = self._read_line(deadline, "the READY banner")
            if not raw.endswith(b"\n"):
                break
            try:
                message = tp.parse_incoming(raw)
            except tp.LineError:
                continue  # bootloader noise
            if isinstance(message, tp.Event) and message.name == "READY":
                log.info("%s booted (protocol %s)", self, " ".join(message.tokens))
                return
        log.info("%s: no READY banner within %.3g s; sending HELLO anyway", self, timeout_s)

    def _close(self) -> None:
        port, self._port = self._port, None
        if port is not None:
            try:
                port.close()
            except _PORT_ERRORS as exc:
                log.warning("%s: error while closing: %s", self, exc)

    def _do_hello(self, version: int) -> int:
        try:
            tokens = self._command("HELLO", version)
        except DeviceTimeoutError as exc:
            raise DeviceTimeoutError(
                f"{exc}; is the trigger box (firmware/trigger_box) on this port and powered?"
            ) from exc
        if not tokens or not tokens[0].isdigit():
            raise ProtocolError(f"{self}: HELLO reply without version: {tokens!r}")
        box_version = int(tokens[0])
        if box_version != version:
            raise UnsupportedFeatureError(
                f"{self}: box speaks trigger protocol {box_version}, this host speaks {version}"
            )
        self.firmware = tokens[1] if len(tokens) > 1 else ""
        return box_version

    def _do_ping(self) -> None:
        self._command("PING")

    def _do_configure(self, pulse_width_us: int, delay_us: int, polarity: Polarity) -> None:
        tokens = self._command("CONFIG", pulse_width_us, delay_us, polarity.value)
        expected = (str(pulse_width_us), str(delay_us), polarity.value)
        if tuple(tokens) != expected:
            raise ProtocolError(f"{self}: CONFIG echoed {tokens!r}, sent {expected!r}")
        self._pulse_us = pulse_width_us + delay_us

    def _do_arm(self, count: int, source: ExposureSource) -> None:
        self.events.clear()
        tokens = self._command("ARM", count, source.value)
        if tuple(tokens) != (str(count), source.value):
            raise ProtocolError(f"{self}: ARM echoed {tokens!r}, sent {(count, source.value)!r}")

    def _do_fire(self) -> int:
        tokens = self._command("FIRE", extra_timeout_s=self._pulse_us * 1e-6)
        if len(tokens) != 1 or not tokens[0].isdigit():
            raise ProtocolError(f"{self}: FIRE reply without pulse index: {tokens!r}")
        return int(tokens[0])

    def _do_status(self) -> TriggerBoxStatus:
        tokens = self._command("STATUS")
        try:
            kv = tp.parse_key_values(tuple(tokens))
            status = TriggerBoxStatus(
                state=kv["st"],
                armed=int(kv["n"]),
                fired=int(kv["fired"]),
                pulse_width_us=int(kv["w"]),
                delay_us=int(kv["d"]),
                polarity=Polarity(kv["pol"]),
                source=ExposureSource(kv["src"]),
                missed=int(kv["miss"]),
            )
        except (tp.LineError, KeyError, ValueError) as exc:
            raise ProtocolError(f"{self}: malformed STATUS reply {tokens!r}: {exc}") from exc
        if status.missed:
            log.warning("%s: %d sync edge(s) missed since ARM (arrived while a pulse was pending)", self, status.missed)
        return status

    def _do_reset(self) -> None:
        self._command("RESET")
        self._pulse_us = 0
        self.events.clear()

    # -- transport ------------------------------------------------------------------------------
    def _command(self, command: str, *args: object, extra_timeout_s: float = 0.0) -> list[str]:
        """Send one request, return the tokens of its OK reply; retries missing/garbled replies."""
        self._next_id = self._next_id % tp.MAX_REQUEST_ID + 1
        request_id = self._next_id
        line = tp.encode_request(request_id, command, *args)
        timeout_s = self.command_timeouts.get(command, self.timeout_s) + extra_timeout_s
        failure: DeviceError | None = None
        for attempt in range(self.retries + 1):
            if attempt:
                log.warning("%s: retrying %s (attempt %d): %s", self, command, attempt + 1, failure)
            self._write(line, command)
            try:
                reply = self._read_reply(request_id, command, timeout_s)
            except _NoReply as exc:
                failure = DeviceTimeoutError(f"{self}: no reply to {command} within {timeout_s:.3g} s ({exc})")
                continue
            except _Garbled as exc:
                failure = ProtocolError(f"{self}: garbled reply to {command}: {exc}")
                continue
            if reply.ok:
                return list(reply.tokens)
            if reply.id == 0:  # the box could not parse our request: it was garbled on the way
                failure = ProtocolError(
                    f"{self}: box could not read {command}: {reply.code.name if reply.code else '?'}"
                )
                continue
            raise self._error_for(command, reply)
        assert failure is not None
        raise failure

    def _error_for(self, command: str, reply: tp.Reply) -> DeviceError:
        code = reply.code
        text = f"{self}: {command} refused: {code.name if code else '?'} {reply.text}".rstrip()
        if code is tp.ErrorCode.BAD_ARGUMENT:
            return TriggerBoxRefusedError(text)
        if code in (tp.ErrorCode.NOT_ARMED, tp.ErrorCode.STATE, tp.ErrorCode.NO_HELLO):
            return IncompatibleStateError(text)
        if code is tp.ErrorCode.VERSION:
            return UnsupportedFeatureError(text)
        return ProtocolError(text)

    def _write(self, line: bytes, command: str) -> None:
        assert self._port is not None
        try:
            written = self._port.write(line)
            self._port.flush()
        except _PORT_ERRORS as exc:
            raise DeviceError(f"{self}: lost the box while sending {command}: {exc}") from exc
        if written is not None and written != len(line):
            raise DeviceTimeoutError(f"{self}: wrote {written} of {len(line)} bytes of {command}")

    def _read_line(self, deadline: float, command: str) -> bytes:
        """One line, or a partial one if the deadline passed (pyserial returns short reads)."""
        assert self._port is not None
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return b""
        try:
            self._port.timeout = remaining
            return self._port.read_until(b"\n", tp.MAX_LINE_BYTES)
        except _PORT_ERRORS as exc:
            raise DeviceError(f"{self}: lost the box (unplugged or reset?) while waiting for {command}: {exc}") from exc

    def _read_reply(self, request_id: int, command: str, timeout_s: float) -> tp.Reply:
        deadline = time.monotonic() + timeout_s
        while True:
            raw = self._read_line(deadline, command)
            if not raw.endswith(b"\n"):
                if raw:
                    raise _Garbled(f"partial line {raw[:40]!r} at the deadline")
                raise _NoReply("nothing received")
            try:
                message = tp.parse_incoming(raw)
            except tp.LineError as exc:
                raise _Garbled(str(exc)) from exc
            if isinstance(message, tp.Event):
                self._record_event(message)
                continue
            if message.id not in (request_id, 0):
                log.info("%s: dropping stale reply to request %d while waiting for %d", self, message.id, request_id)
                continue
            return message

    def _drain_events(self, wait_s: float) -> None:
        """Read lines for up to ``wait_s``; return after the first event."""
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            raw = self._read_line(deadline, "events")
            if not raw.endswith(b"\n"):
                return
            try:
                message = tp.parse_incoming(raw)
            except tp.LineError as exc:
                log.warning("%s: garbled line between commands: %s", self, exc)
                continue
            if isinstance(message, tp.Event):
                self._record_event(message)
                return

    def _record_event(self, event: tp.Event) -> None:
        log.debug("%s: event %s %s", self, event.name, " ".join(event.tokens))
        if event.name == "WATCHDOG":
            log.warning("%s: the box disarmed itself after heartbeat silence", self)
            self._armed_count = 0
        elif event.name == "MISSED":
            log.warning(
                "%s: sync edges missed since ARM: %s (edge while a pulse was pending)", self, " ".join(event.tokens)
            )
        self.events.append(event)
