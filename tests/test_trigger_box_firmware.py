"""The firmware and the fake box behave alike: trigger_box.ino, compiled for the PC against a
stand-in Arduino.h (firmware/trigger_box/host), and the fake's state machine get the same input
and must write the same bytes. Skipped where no C++ compiler is installed."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from drivers import trigger_protocol as tp
from mock_devices.trigger_box import _BoxFirmware

FIRMWARE = Path(__file__).resolve().parents[1] / "firmware" / "trigger_box"


@pytest.fixture(scope="module")
def firmware_binary(tmp_path_factory) -> Path:
    compiler = shutil.which("g++") or shutil.which("clang++")
    if compiler is None:
        pytest.skip("no C++ compiler (g++ or clang++) to build the firmware for the host")
    binary = tmp_path_factory.mktemp("firmware") / "trigger_box"
    subprocess.run(
        [compiler, "-std=c++17", "-Wall", "-Wextra", "-Werror", "-O1", f"-I{FIRMWARE / 'host'}",
         "-x", "c++", str(FIRMWARE / "trigger_box.ino"), "-x", "none",
         str(FIRMWARE / "host" / "host_main.cpp"), "-o", str(binary)],
        check=True, capture_output=True, timeout=120)
    return binary


def req(request_id: int, command: str, *args: object) -> tuple[str, bytes]:
    return ("L", tp.encode_request(request_id, command, *args).rstrip(b"\n"))


def raw(text: bytes) -> tuple[str, bytes]:
    return ("L", text)


def run_firmware(binary: Path, steps) -> list[bytes]:
    script = b"".join(kind.encode() + (b" " + arg if arg else b"") + b"\n" for kind, arg in steps)
    done = subprocess.run([str(binary)], input=script, capture_output=True, timeout=30, check=True)
    return done.stdout.splitlines(keepends=True)


def run_fake(steps) -> list[bytes]:
    now = 0.0
    box = _BoxFirmware(tp.PROTOCOL_VERSION, watchdog_s=10.0, now=now)
    lines = [tp.encode_event("READY", tp.PROTOCOL_VERSION)]
    for kind, arg in steps:
        if kind == "L":
            lines += box.handle_line(arg + b"\n", now).lines()
        elif kind == "S":
            lines += box.sync_edge().lines()
        elif kind == "T":
            now += int(arg) / 1000
            lines += box.tick(now).lines()
    return lines


SCENARIOS = {
    "scan": [req(1, "HELLO", 1), req(2, "CONFIG", 250, 40, "NEG"), req(3, "ARM", 3),
             req(4, "FIRE"), req(4, "FIRE"), req(4, "STATUS"), req(5, "FIRE"), req(6, "STATUS"),
             req(7, "FIRE"),
             req(8, "FIRE"), req(9, "RESET"), req(10, "STATUS")],
    "refusals": [req(1, "FIRE"), req(2, "HELLO", 2), req(3, "HELLO", "x"), req(4, "HELLO", 1),
                 req(5, "JUMP"), req(6, "CONFIG", 0, 0, "POS"), req(7, "CONFIG", 5, 5, "UP"),
                 req(8, "ARM", 0), req(9, "ARM", 2, "BOTH"), req(10, "ARM", 2),
                 req(11, "CONFIG", 10, 0, "POS"), req(12, "ARM", 1), req(13, "fire", 1),
                 req(14, "fire"), req(15, "PING", 3), req(16, "PING")],
    "sync": [req(1, "HELLO", 1), ("S", b""), req(2, "ARM", 2, "EXT"), req(3, "FIRE"), ("S", b""),
             req(4, "STATUS"), ("S", b""), ("S", b""), req(5, "STATUS")],
    "watchdog": [req(1, "HELLO", 1), req(2, "ARM", 4, "EXT"), ("S", b""), ("T", b"9000"),
                 req(3, "PING"),
                 ("T", b"9000"), req(4, "STATUS"), ("T", b"10100"), req(5, "STATUS")],
    "garbage": [raw(b"1 HELLO 1*43"), raw(b"1 HELLO 1"), raw(b"x" * 120),
                raw(tp.frame("0 PING").rstrip(b"\n")), raw(tp.frame("3  PING").rstrip(b"\n")),
                raw(tp.frame("3 PI#NG").rstrip(b"\n")), raw(tp.frame("70000 PING").rstrip(b"\n")),
                raw(tp.frame("5").rstrip(b"\n")), raw(tp.frame("6 PING").rstrip(b"\n") + b"\r")],
}


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_firmware_and_fake_write_the_same_bytes(firmware_binary, name):
    steps = SCENARIOS[name]
    fake = run_fake(steps)
    assert run_firmware(firmware_binary, steps) == fake
    assert len(fake) > len(steps) // 2  # the scenario produced output to compare
