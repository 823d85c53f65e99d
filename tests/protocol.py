"""Byte-level protocol tests in the style of pymeasure's ``expected_protocol``.

A test lists the exact exchanges ``[(sent, reply), ...]`` a driver call must produce; the peer
answers each expected ``sent`` with its ``reply`` (``None``: no reply) and the test fails on the
first unexpected byte string or if an exchange is left over when the block ends.

- :func:`expected_serial_protocol` serves the script on a pseudo-terminal (the driver opens the
  yielded path through pyserial, as it would a real port): exchanges are lines.
- :func:`expected_usb_protocol` is a pyusb backend: exchanges are interrupt-OUT reports and the
  interrupt-IN report that answers them.
- :func:`expected_protocol` picks one of those for a driver class and yields the driver, opened.
"""

from __future__ import annotations

import contextlib
import inspect
import os
import select
import threading
import tty
from collections.abc import Iterator, Sequence

from mock_devices.dlp_usb import VirtualHidBackend

Exchange = tuple[bytes, "bytes | None"]


def _show(data: bytes) -> str:
    """Lines as text; HID reports as hex without their zero padding."""
    if data.endswith(b"\n"):
        return repr(data)
    return data.rstrip(b"\x00").hex(" ") or "(zeros)"


class ExchangeScript:
    """The expected exchanges and what actually happened."""

    def __init__(self, exchanges: Sequence[Exchange]) -> None:
        self._pending = list(exchanges)
        self.errors: list[str] = []
        self.lock = threading.Lock()

    def respond(self, sent: bytes) -> bytes | None:
        with self.lock:
            if not self._pending:
                self.errors.append(f"unexpected {_show(sent)}: no exchange left")
                return None
            expected, reply = self._pending.pop(0)
            if sent != expected:
                self.errors.append(f"sent {_show(sent)}, expected {_show(expected)}")
                self._pending.clear()
                return None
            return reply

    def check(self) -> None:
        with self.lock:
            problems = list(self.errors)
            if self._pending:
                problems.append(f"{len(self._pending)} exchange(s) left over, next: {_show(self._pending[0][0])}")
        assert not problems, "; ".join(problems)


@contextlib.contextmanager
def expected_serial_protocol(exchanges: Sequence[Exchange]) -> Iterator[str]:
    """Yield a pty path whose peer follows ``exchanges`` line by line."""
    script = ExchangeScript(exchanges)
    master, slave = os.openpty()
    tty.setraw(slave)
    stop = threading.Event()

    def serve() -> None:
        buffer = b""
        while not stop.is_set():
            ready, _, _ = select.select([master], [], [], 0.01)
            if not ready:
                continue
            try:
                buffer += os.read(master, 1024)
            except OSError:
                continue
            while b"\n" in buffer:
                line, buffer = buffer.split(b"\n", 1)
                reply = script.respond(line + b"\n")
                if reply:
                    os.write(master, reply)

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    try:
        yield os.ttyname(slave)
    except Exception as exc:
        if script.errors:  # the driver failed because the exchange went off script: say how
            raise AssertionError("; ".join(script.errors)) from exc
        raise
    finally:
        stop.set()
        thread.join(timeout=2.0)
        os.close(master)
        os.close(slave)
    script.check()


class ScriptedHidBackend(VirtualHidBackend):
    """A pyusb backend whose device follows a script of (OUT report, IN report) exchanges."""

    def __init__(self, script: ExchangeScript) -> None:
        super().__init__()
        self.script = script

    def _on_out_report(self, report: bytes) -> bytes | None:
        reply = self.script.respond(report)
        if self.script.errors:
            raise AssertionError("; ".join(self.script.errors))
        return reply


@contextlib.contextmanager
def expected_usb_protocol(exchanges: Sequence[Exchange]) -> Iterator[ScriptedHidBackend]:
    """Yield a pyusb backend whose device follows ``exchanges`` report by report."""
    script = ExchangeScript(exchanges)
    yield ScriptedHidBackend(script)
    script.check()


@contextlib.contextmanager
def expected_protocol(driver_class: type, exchanges: Sequence[Exchange], **kwargs: object) -> Iterator[object]:
    """pymeasure's form: yield an opened ``driver_class`` whose peer follows ``exchanges``.

    Serial drivers (constructor argument ``url``) get a scripted pty, USB drivers (``backend``)
    a scripted pyusb backend; ``kwargs`` go to the constructor. Opening is part of the script
    (e.g. the trigger box's HELLO).
    """
    parameters = inspect.signature(driver_class).parameters
    if "url" in parameters:
        with expected_serial_protocol(exchanges) as port, driver_class(port, **kwargs) as driver:
            yield driver
    elif "backend" in parameters:
        with expected_usb_protocol(exchanges) as backend, driver_class(backend=backend, **kwargs) as driver:
            yield driver
    else:
        raise TypeError(f"{driver_class.__name__} takes neither url nor backend")
