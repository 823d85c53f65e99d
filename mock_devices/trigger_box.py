"""A fake trigger box on a pseudo-terminal, speaking the same protocol as the firmware.

``FakeTriggerBox`` opens a pty pair, serves the master side from a thread and exposes the slave
path as ``.port``: the real host driver (``drivers.trigger_box.SerialTriggerBox``) opens it through
pyserial like any serial port. ``_BoxFirmware`` mirrors ``firmware/trigger_box/trigger_box.ino``
line for line in behaviour (state machine, replay of a repeated request id, watchdog); it holds no
host logic. Faults are requested through ``TriggerFaults``.

Each exposure pulse calls ``on_pulse(index)`` (index within the current ARM, from 0): the
acquisition loop wires the simulated camera's ``pulse(trigger_index)`` there. Pulses are not timed
in real time unless ``realtime=True``.

Like an Arduino Uno, the box reboots whenever the port is opened (DTR): for ``boot_s`` it reads
and drops whatever arrives (the bootloader), then prints ``! READY <version>``; the settings are
lost except the output polarity, which the firmware keeps in EEPROM so that the output idles at
the right level from the first instruction (``pin_level``). A sync edge closer than
``LOCKOUT_US`` to the previous one is ringing and ignored; one while a pulse is pending or active
is missed, counted in STATUS and reported as ``! MISSED <total>``.
"""

from __future__ import annotations

import logging
import os
import select
import threading
import time
import tty
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers import trigger_protocol as tp

log = logging.getLogger(__name__)

FIRMWARE_ID = "fpp-trigger-box/2.0.0"
DEFAULT_PULSE_WIDTH_US = 100
DEFAULT_WATCHDOG_S = 10.0
LOCKOUT_US = 20  # sync edges closer than this are ringing
DEFAULT_BOOT_S = 0.1  # a real Uno's bootloader takes about 0.5-1.6 s


@dataclass(frozen=True)
class TriggerFaults:
    """Faults the fake box injects.

    garble_reply_on / drop_reply_on
        Command names (``"FIRE"``, ...) whose reply is corrupted / not sent; each affected request
        id is hit ``garble_times`` / ``drop_times`` times, later repeats of that id go through.
    stall
        ``True``: never answer; an int n: answer the first n requests, then go silent (the box
        still reads, like hung firmware).
    disconnect_after
        The box answers this many requests, then disappears (the pty is closed) when the next
        one arrives, as if unplugged.
    """

    garble_reply_on: frozenset[str] | set[str] = field(default_factory=frozenset)
    garble_times: int = 1
    drop_reply_on: frozenset[str] | set[str] = field(default_factory=frozenset)
    drop_times: int = 1
    stall: bool | int = False
    disconnect_after: int | None = None

    def __post_init__(self) -> None:
        for name in ("garble_reply_on", "drop_reply_on"):
            unknown = set(getattr(self, name)) - set(tp.COMMANDS)
            if unknown:
                raise ValueError(
                    f"TriggerFaults.{name}: unknown command(s) {sorted(unknown)}, "
                    f"expected some of {', '.join(tp.COMMANDS)}"
                )
        for name in ("garble_times", "drop_times"):
            if getattr(self, name) < 1:
                raise ValueError(f"TriggerFaults.{name} must be >= 1, got {getattr(self, name)}")
        if self.stall is not True and self.stall is not False and int(self.stall) < 0:
            raise ValueError(f"TriggerFaults.stall must be a bool or a count >= 0, got {self.stall}")
        if self.disconnect_after is not None and self.disconnect_after < 0:
            raise ValueError(f"TriggerFaults.disconnect_after must be >= 0, got {self.disconnect_after}")

    def stall_after(self) -> int | None:
        if self.stall is True:
            return 0
        if self.stall is False:
            return None
        return int(self.stall)


@dataclass
class _Output:
    """What the firmware writes in answer to one input, in wire order: before, reply, after."""

    before: list[bytes] = field(default_factory=list)
    reply: bytes | None = None
    after: list[bytes] = field(default_factory=list)
    pulses: list[int] = field(default_factory=list)
    command: str = ""
    request_id: int = 0

    def lines(self) -> list[bytes]:
        return [*self.before, *([self.reply] if self.reply is not None else []), *self.after]


class _BoxFirmware:
    """The box's protocol state machine, as the firmware implements it."""

    def __init__(
        self,
        protocol_version: int,
        watchdog_s: float | None,
        now: float,
        polarity: tp.Polarity = tp.Polarity.ACTIVE_HIGH,
    ) -> None:
        self.protocol_version = protocol_version
        self.watchdog_s = watchdog_s
        self.hello_done = False
        self.last_request = b""  # the last executed request line, as received
        self.last_reply = b""
        self.last_line_at = now
        self.polarity = polarity  # kept in EEPROM: survives RESET and reboots
        self.last_edge_at: float | None = None
        self.busy_until = 0.0
        self._defaults()

    def _defaults(self) -> None:
        self.width_us = DEFAULT_PULSE_WIDTH_US
        self.delay_us = 0
        self.state = "IDLE"
        self.source = tp.ExposureSource.SOFTWARE
        self.armed = 0
        self.fired = 0
        self.missed = 0

    @property
    def pin_level(self) -> int:
        """Electrical level of the pulse output: 1 high, 0 low.

        Pulses are not drawn on the pin here, so it rests at the polarity's idle level: low when
        pulses are active high, high when they are active low.
        """
        return int(self.polarity is not tp.Polarity.ACTIVE_HIGH)

    # -- input ----------------------------------------------------------------------------------
    def handle_line(self, line: bytes, now: float) -> _Output:
        self.last_line_at = now
        out = _Output()
        try:
            request = tp.parse_request(line)
        except tp.LineError as exc:
            checksum_bad = isinstance(exc, tp.ChecksumError)
            code = tp.ErrorCode.BAD_CHECKSUM if checksum_bad else tp.ErrorCode.SYNTAX
            out.reply = tp.encode_error(0, code, "request rejected")
            return out
        out.command, out.request_id = request.command, request.id
        raw = line.rstrip(b"\n").removesuffix(b"\r")
        if raw == self.last_request:
            out.reply = self.last_reply  # a retransmission: answer again, never act twice
            return out
        out.reply = self._execute(request, out)
        self.last_request, self.last_reply = raw, out.reply
        return out

    def sync_edge(self, now: float) -> _Output:
        out = _Output()
        if self.last_edge_at is not None and now - self.last_edge_at < LOCKOUT_US * 1e-6:
            return out  # ringing
        self.last_edge_at = now
        if self.state != "ARMED" or self.source is not tp.ExposureSource.EXTERNAL_SYNC:
            return out
        if now < self.busy_until:  # a pulse is pending or active
            self.missed += 1
            out.before.append(tp.encode_event("MISSED", self.missed))
            return out
        self.busy_until = now + (self.delay_us + self.width_us) * 1e-6
        self._pulse(out)
        return out

    def tick(self, now: float) -> _Output:
        out = _Output()
        if self.state == "ARMED" and self.watchdog_s is not None and now - self.last_line_at > self.watchdog_s:
            self.state, self.armed, self.fired, self.missed = "IDLE", 0, 0, 0
            out.before.append(tp.encode_event("WATCHDOG"))
        return out

    # -- commands -------------------------------------------------------------------------------
    def _execute(self, request: tp.Request, out: _Output) -> bytes:
        rid, cmd, args = request.id, request.command, request.args
        if cmd not in tp.COMMANDS:
            return tp.encode_error(rid, tp.ErrorCode.UNKNOWN_COMMAND, cmd)
        if not self.hello_done and cmd not in ("HELLO", "PING"):
            return tp.encode_error(rid, tp.ErrorCode.NO_HELLO, "send HELLO first")
        try:
            return getattr(self, "_cmd_" + cmd.lower())(rid, args, out)
        except _BadArgument as exc:
            log.debug("fake trigger box: %s: %s", cmd, exc)
            return tp.encode_error(rid, tp.ErrorCode.BAD_ARGUMENT, _USAGE[cmd])

    def _cmd_hello(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        (version,) = _ints(args, 1, (0, 255))
        if version != self.protocol_version:
            return tp.encode_error(rid, tp.ErrorCode.VERSION, f"box speaks {self.protocol_version}")
        self.hello_done = True
        return tp.encode_ok(rid, self.protocol_version, FIRMWARE_ID)

    def _cmd_ping(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        _ints(args, 0, (0, 0))
        return tp.encode_ok(rid)

    def _cmd_config(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        if len(args) != 3:
            raise _BadArgument("CONFIG takes width_us delay_us POS|NEG")
        (width,) = _ints(args[:1], 1, (1, tp.MAX_PULSE_WIDTH_US))
        (delay,) = _ints(args[1:2], 1, (0, tp.MAX_DELAY_US))
        try:
            polarity = tp.Polarity(args[2])
        except ValueError:
            raise _BadArgument("polarity must be POS or NEG") from None
        if self.state == "ARMED":
            return tp.encode_error(rid, tp.ErrorCode.STATE, "armed RESET first")
        self.width_us, self.delay_us, self.polarity = width, delay, polarity
        return tp.encode_ok(rid, width, delay, polarity.value)

    def _cmd_arm(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        if len(args) not in (1, 2):
            raise _BadArgument("ARM takes count [SW|EXT]")
        (count,) = _ints(args[:1], 1, (1, tp.MAX_ARM_COUNT))
        try:
            source = tp.ExposureSource(args[1]) if len(args) == 2 else tp.ExposureSource.SOFTWARE
        except ValueError:
            raise _BadArgument("source must be SW or EXT") from None
        if self.state == "ARMED":
            return tp.encode_error(rid, tp.ErrorCode.STATE, "already armed RESET first")
        self.state, self.source, self.armed, self.fired, self.missed = "ARMED", source, count, 0, 0
        return tp.encode_ok(rid, count, source.value)

    def _cmd_fire(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        _ints(args, 0, (0, 0))
        if self.state != "ARMED":
            return tp.encode_error(rid, tp.ErrorCode.NOT_ARMED, "ARM first")
        if self.source is not tp.ExposureSource.SOFTWARE:
            return tp.encode_error(rid, tp.ErrorCode.STATE, "armed for EXT sync")
        index = self._pulse(out, done_after_reply=True)
        return tp.encode_ok(rid, index)

    def _cmd_status(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        _ints(args, 0, (0, 0))
        return tp.encode_ok(
            rid,
            f"st={self.state}",
            f"n={self.armed}",
            f"fired={self.fired}",
            f"miss={self.missed}",
            f"w={self.width_us}",
            f"d={self.delay_us}",
            f"pol={self.polarity.value}",
            f"src={self.source.value}",
        )

    def _cmd_reset(self, rid: int, args: tuple[str, ...], out: _Output) -> bytes:
        _ints(args, 0, (0, 0))
        self._defaults()
        return tp.encode_ok(rid)

    def _pulse(self, out: _Output, done_after_reply: bool = False) -> int:
        index = self.fired
        self.fired += 1
        out.pulses.append(index)
        out.before.append(tp.encode_event("PULSE", index))
        if self.fired == self.armed:
            self.state = "DONE"
            done = tp.encode_event("DONE", self.armed)
            (out.after if done_after_reply else out.before).append(done)
        return index


class _BadArgument(Exception):
    pass


# Texts of BAD_ARGUMENT replies, as the firmware sends them.
_USAGE = {
    "HELLO": "HELLO takes one version",
    "PING": "PING takes no argument",
    "CONFIG": "CONFIG takes width_us delay_us POS or NEG",
    "ARM": "ARM takes count SW or EXT",
    "FIRE": "FIRE takes no argument",
    "STATUS": "STATUS takes no argument",
    "RESET": "RESET takes no argument",
}


def _ints(args: tuple[str, ...], count: int, bounds: tuple[int, int]) -> list[int]:
    if len(args) != count:
        raise _BadArgument(f"expected {count} argument(s), got {len(args)}")
    values = []
    for a in args:
        if not a.isdigit() or len(a) > 7:
            raise _BadArgument(f"not an integer {a}")
        value = int(a)
        if not bounds[0] <= value <= bounds[1]:
            raise _BadArgument(f"{value} outside {bounds[0]}..{bounds[1]}")
        values.append(value)
    return values


class FakeTriggerBox:
    """The trigger box protocol served on a pseudo-terminal; ``.port`` is the path to open.

    Parameters
    ----------
    on_pulse : callable, optional
        Called with the pulse index (within the current ARM) on every exposure pulse.
    faults : TriggerFaults, optional
        Faults to inject (garbled or missing replies, stall, disappearance).
    rng : numpy Generator, optional
        Chooses which byte a garbled reply corrupts; seeded default.
    protocol_version : int
        Version the fake firmware speaks (set to another value to test refusal).
    watchdog_s : float or None
        Silence after which an armed box disarms itself (``! WATCHDOG``); None disables.
    realtime : bool
        Sleep through delay + width of each pulse (off by default: tests stay fast).
    reset_on_open : bool
        Reboot whenever the port is opened, as an Uno does (DTR); False: a board that does not.
        The fake sees the port closed by polling every 10 ms: a reopen faster than that is
        not noticed.
    boot_s : float
        How long a reboot takes: input is dropped meanwhile, then ``! READY`` is sent.
    polarity : Polarity
        The polarity kept in the box's EEPROM from an earlier CONFIG (the idle level at boot).
    """

    def __init__(
        self,
        on_pulse: Callable[[int], None] | None = None,
        faults: TriggerFaults | None = None,
        rng: np.random.Generator | None = None,
        protocol_version: int = tp.PROTOCOL_VERSION,
        watchdog_s: float | None = DEFAULT_WATCHDOG_S,
        realtime: bool = False,
        reset_on_open: bool = True,
        boot_s: float = DEFAULT_BOOT_S,
        polarity: tp.Polarity = tp.Polarity.ACTIVE_HIGH,
    ) -> None:
        self.on_pulse = on_pulse
        self.faults = faults or TriggerFaults()
        self._rng = rng if rng is not None else np.random.default_rng(0)
        self._realtime = realtime
        self._protocol_version, self._watchdog_s = protocol_version, watchdog_s
        self._firmware = _BoxFirmware(protocol_version, watchdog_s, time.monotonic(), polarity)
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._master, self._slave = os.openpty()
        tty.setraw(self._slave)
        self.port = os.ttyname(self._slave)
        self.reset_on_open = reset_on_open
        self.boot_s = boot_s
        self.boots = 1  # times the board started (power-up included)
        self._booting_until: float | None = None
        self._port_open = False
        self.received: list[bytes] = []  # every line the box read, for tests and debugging
        self.sent: list[bytes] = []  # every line the box wrote
        self.pulses: list[int] = []
        self.callback_error: BaseException | None = None
        self._requests_answered = 0
        self._garbled: dict[int, int] = {}
        self._dropped: dict[int, int] = {}
        self._gone = False
        if reset_on_open:  # no one holds the port yet: the board's banner went nowhere
            os.close(self._slave)
            self._slave = -1
        else:
            self._write(tp.encode_event("READY", protocol_version))  # the boot banner
        self._thread = threading.Thread(target=self._serve, name="fake-trigger-box", daemon=True)
        self._thread.start()

    # -- public ---------------------------------------------------------------------------------
    def sync_in(self) -> None:
        """Simulate one edge on the box's SYNC_IN pin (e.g. the DLP's TRIG_OUT)."""
        with self._lock:
            if not self._gone:
                self._emit(self._firmware.sync_edge(time.monotonic()))

    @property
    def state(self) -> str:
        return self._firmware.state

    @property
    def pin_level(self) -> int:
        """Electrical level of the pulse output now (1 high, 0 low)."""
        return self._firmware.pin_level

    def _reboot(self, now: float) -> None:
        """DTR reset: RAM state lost, the EEPROM polarity kept; input dropped while booting."""
        self.boots += 1
        polarity = self._firmware.polarity
        self._firmware = _BoxFirmware(self._protocol_version, self._watchdog_s, now, polarity)
        self._booting_until = now + self.boot_s

    def close(self) -> None:
        """Stop the serving thread, close the pty; re-raise an error raised by ``on_pulse``."""
        self._stop.set()
        self._thread.join(timeout=2.0)
        with self._lock:
            self._close_fds()
        if self.callback_error is not None:
            error, self.callback_error = self.callback_error, None
            raise RuntimeError("on_pulse callback of the fake trigger box failed") from error

    def __enter__(self) -> FakeTriggerBox:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- serving --------------------------------------------------------------------------------
    def _serve(self) -> None:
        buffer = b""
        while not self._stop.is_set():
            try:
                ready, _, _ = select.select([self._master], [], [], 0.01)
            except (OSError, ValueError):
                return  # fds closed under us (disconnect fault)
            with self._lock:
                if self._gone:
                    return
                buffer, answer = self._receive(bool(ready), buffer)
                if answer:
                    buffer = self._answer(buffer)

    def _receive(self, ready: bool, buffer: bytes) -> tuple[bytes, bool]:
        """Read what arrived into ``buffer``; returns it and whether its lines are answered now."""
        if self.reset_on_open:
            return self._receive_resetting(ready, buffer, time.monotonic())
        if ready:
            try:
                buffer += self._read_available()
            except OSError:
                pass  # no process holds the slave open (EIO); keep waiting
        return buffer, True

    def _receive_resetting(self, ready: bool, buffer: bytes, now: float) -> tuple[bytes, bool]:
        """As :meth:`_receive` for a board that opening the port resets: its bootloader eats what
        arrives until it is up and says READY."""
        data = b""
        if ready:
            try:
                data = self._read_available()
            except OSError:  # EIO: no process holds the port open
                self._port_open = False
                self._stop.wait(0.005)
                return b"", False
        if not self._port_open:  # opened since the last look: DTR resets the board
            self._port_open = True
            self._reboot(now)
        if self._booting_until is not None:
            if now < self._booting_until:
                return buffer, False  # the bootloader eats what arrives
            self._booting_until = None
            self._write(tp.encode_event("READY", self._protocol_version))
            return b"", False
        return buffer + data, True

    def _read_available(self) -> bytes:
        """What the port holds now, without waiting. ``select`` reports a port no one holds as readable
        (EIO); opened between that report and the read, a blocking read would wait for the host's first
        line while the board, not knowing it was opened, never boots nor sends READY."""
        os.set_blocking(self._master, False)
        try:
            return os.read(self._master, 1024)
        except BlockingIOError:
            return b""
        finally:
            os.set_blocking(self._master, True)

    def _answer(self, buffer: bytes) -> bytes:
        """Handle every whole line of ``buffer`` (and one too long), then let the firmware tick;
        returns what is left of the buffer."""
        while b"\n" in buffer and not self._gone:
            line, buffer = buffer.split(b"\n", 1)
            self._handle(line + b"\n")
        if len(buffer) > tp.MAX_LINE_BYTES:  # a line too long: answered as SYNTAX
            self._handle(buffer + b"\n")
            buffer = b""
        if not self._gone:  # input first: a late thread must not fire the watchdog
            self._emit(self._firmware.tick(time.monotonic()))
        return buffer

    def _handle(self, line: bytes) -> None:
        self.received.append(line)
        limit = self.faults.disconnect_after
        if limit is not None and self._requests_answered >= limit:
            log.info("fake trigger box disappears after answering %d requests", limit)
            self._gone = True
            self._close_fds()
            return
        stall_after = self.faults.stall_after()
        if stall_after is not None and self._requests_answered >= stall_after:
            return  # hung firmware: the line is read but neither executed nor answered
        out = self._firmware.handle_line(line, time.monotonic())
        self._requests_answered += 1
        self._apply_reply_faults(out)
        self._emit(out)

    def _apply_reply_faults(self, out: _Output) -> None:
        rid, cmd = out.request_id, out.command
        if out.reply is None:
            return
        if cmd in self.faults.drop_reply_on and self._dropped.get(rid, 0) < self.faults.drop_times:
            self._dropped[rid] = self._dropped.get(rid, 0) + 1
            out.reply = None
        elif cmd in self.faults.garble_reply_on and self._garbled.get(rid, 0) < self.faults.garble_times:
            self._garbled[rid] = self._garbled.get(rid, 0) + 1
            out.reply = self._garble(out.reply)

    def _garble(self, line: bytes) -> bytes:
        body_len = line.rindex(b"*")
        pos = int(self._rng.integers(0, body_len))
        new = int(self._rng.integers(0x21, 0x7F))
        if new == line[pos]:
            new = 0x21 if line[pos] != 0x21 else 0x22
        return line[:pos] + bytes([new]) + line[pos + 1 :]

    def _emit(self, out: _Output) -> None:
        pulses = list(out.pulses)
        for line in out.lines():
            if line.startswith(b"! PULSE") and pulses:
                self._fire_pulse(pulses.pop(0))
            self._write(line)

    def _fire_pulse(self, index: int) -> None:
        if self._realtime:
            time.sleep((self._firmware.delay_us + self._firmware.width_us) * 1e-6)
        self.pulses.append(index)
        if self.on_pulse is not None:
            try:
                self.on_pulse(index)
            except Exception as exc:  # surfaced by close(); the box itself keeps running
                log.exception("on_pulse(%d) raised", index)
                if self.callback_error is None:
                    self.callback_error = exc

    def _write(self, line: bytes) -> None:
        if self._gone:
            return
        self.sent.append(line)
        try:
            os.write(self._master, line)
        except OSError:
            log.warning("fake trigger box could not write %r", line)

    def _close_fds(self) -> None:
        for name in ("_master", "_slave"):
            fd = getattr(self, name)
            if fd >= 0:
                try:
                    os.close(fd)
                except OSError:
                    pass
                setattr(self, name, -1)
