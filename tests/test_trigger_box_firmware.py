"""The firmware and the fake box behave alike: trigger_box.ino, compiled for the PC against a
stand-in Arduino.h (firmware/trigger_box/host, which emulates Timer1 and INT0), and the fake's
state machine get the same input and must write the same bytes. Skipped where no C++ compiler is
installed. The firmware also builds for the Arduino Uno's ATmega328P with avr-gcc and Debian's
Arduino core (packages gcc-avr, avr-libc, arduino-core-avr; skipped without them), and its
static RAM use is reported."""

from __future__ import annotations

import os
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
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
        [
            compiler,
            "-std=c++17",
            "-Wall",
            "-Wextra",
            "-Werror",
            "-O1",
            f"-I{FIRMWARE / 'host'}",
            "-x",
            "c++",
            str(FIRMWARE / "trigger_box.ino"),
            "-x",
            "none",
            str(FIRMWARE / "host" / "host_main.cpp"),
            "-o",
            str(binary),
        ],
        check=True,
        capture_output=True,
        timeout=120,
    )
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
            lines += box.sync_edge(now).lines()
        elif kind == "E":  # two edges arg microseconds apart
            lines += box.sync_edge(now).lines()
            lines += box.sync_edge(now + int(arg) * 1e-6).lines()
        elif kind == "T":
            now += int(arg) / 1000
            lines += box.tick(now).lines()
        now += 0.001  # each firmware step lasts a little (its loop runs, its pulse finishes)
    return lines


SCENARIOS = {
    "scan": [
        req(1, "HELLO", 2),
        req(2, "CONFIG", 250, 40, "NEG"),
        req(3, "ARM", 3),
        req(4, "FIRE"),
        req(4, "FIRE"),
        req(4, "STATUS"),
        req(5, "FIRE"),
        req(6, "STATUS"),
        req(7, "FIRE"),
        req(8, "FIRE"),
        req(9, "RESET"),
        req(10, "STATUS"),
    ],
    "refusals": [
        req(1, "FIRE"),
        req(2, "HELLO", 1),
        req(3, "HELLO", "x"),
        req(4, "HELLO", 2),
        req(5, "JUMP"),
        req(6, "CONFIG", 0, 0, "POS"),
        req(7, "CONFIG", 5, 5, "UP"),
        req(8, "ARM", 0),
        req(9, "ARM", 2, "BOTH"),
        req(10, "ARM", 2),
        req(11, "CONFIG", 10, 0, "POS"),
        req(12, "ARM", 1),
        req(13, "fire", 1),
        req(14, "fire"),
        req(15, "PING", 3),
        req(16, "PING"),
    ],
    "sync": [
        req(1, "HELLO", 2),
        ("S", b""),
        req(2, "ARM", 2, "EXT"),
        req(3, "FIRE"),
        ("S", b""),
        req(4, "STATUS"),
        ("S", b""),
        ("S", b""),
        req(5, "STATUS"),
    ],
    "watchdog": [
        req(1, "HELLO", 2),
        req(2, "ARM", 4, "EXT"),
        ("S", b""),
        ("T", b"9000"),
        req(3, "PING"),
        ("T", b"9000"),
        req(4, "STATUS"),
        ("T", b"10100"),
        req(5, "STATUS"),
    ],
    "missed": [
        req(1, "HELLO", 2),
        req(2, "CONFIG", 300, 0, "POS"),
        req(3, "ARM", 3, "EXT"),
        ("E", b"100"),
        req(4, "STATUS"),
        ("E", b"5"),
        ("S", b""),
        req(5, "STATUS"),
        req(6, "ARM", 1, "EXT"),
        req(7, "RESET"),
        req(8, "STATUS"),
    ],
    "garbage": [
        raw(b"1 HELLO 1*43"),
        raw(b"1 HELLO 1"),
        raw(b"x" * 120),
        raw(tp.frame("0 PING").rstrip(b"\n")),
        raw(tp.frame("3  PING").rstrip(b"\n")),
        raw(tp.frame("3 PI#NG").rstrip(b"\n")),
        raw(tp.frame("70000 PING").rstrip(b"\n")),
        raw(tp.frame("5").rstrip(b"\n")),
        raw(tp.frame("6 PING").rstrip(b"\n") + b"\r"),
    ],
}


@pytest.mark.parametrize("name", sorted(SCENARIOS))
def test_firmware_and_fake_write_the_same_bytes(firmware_binary, name):
    steps = SCENARIOS[name]
    fake = run_fake(steps)
    assert run_firmware(firmware_binary, steps) == fake
    assert len(fake) > len(steps) // 2  # the scenario produced output to compare


# -- the firmware for the Arduino Uno (ATmega328P) ----------------------------------------------

ARDUINO_AVR = Path("/usr/share/arduino/hardware/arduino/avr")
#: Static RAM (data + bss) the firmware may use of the ATmega328P's 2048 bytes; the rest is stack
#: (the line buffers and formatting need a few hundred bytes of it).
RAM_BUDGET = 1024
#: Not linked: unused by the firmware, and Debian's copy needs DECIMAL_DIG, which avr-libc lacks.
CORE_SKIP = {"WString.cpp"}


def _avr_compile(command: list[str]) -> None:
    done = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"{' '.join(command)}\n{done.stderr}"


def test_firmware_builds_for_the_atmega328p(tmp_path, request):
    tools = [shutil.which(t) for t in ("avr-gcc", "avr-g++", "avr-ar", "avr-size")]
    if None in tools:
        pytest.skip("avr-gcc not installed (Debian: apt install gcc-avr avr-libc arduino-core-avr)")
    core, variant = ARDUINO_AVR / "cores" / "arduino", ARDUINO_AVR / "variants" / "standard"
    if not (core / "Arduino.h").exists():
        pytest.skip(f"no Arduino AVR core at {core} (Debian: apt install arduino-core-avr)")
    gcc, gxx, ar, size = tools
    flags = [
        "-mmcu=atmega328p",
        "-DF_CPU=16000000L",
        "-DARDUINO=10819",
        "-DARDUINO_AVR_UNO",
        "-DARDUINO_ARCH_AVR",
        "-Os",
        "-ffunction-sections",
        "-fdata-sections",
        f"-I{core}",
        f"-I{variant}",
    ]
    cxx = [gxx, "-std=gnu++17", "-fno-exceptions", "-fno-threadsafe-statics", *flags]
    jobs = []
    for source in sorted(core.iterdir()):
        target = str(tmp_path / (source.name + ".o"))
        if source.suffix == ".c":
            jobs.append([gcc, "-std=gnu11", *flags, "-c", str(source), "-o", target])
        elif source.suffix == ".cpp" and source.name not in CORE_SKIP:
            jobs.append([*cxx, "-c", str(source), "-o", target])
        elif source.suffix == ".S":
            jobs.append([gcc, *flags, "-x", "assembler-with-cpp", "-c", str(source), "-o", target])
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
        list(pool.map(_avr_compile, jobs))
    # the core as an archive, as the Arduino tools link it: only what the sketch uses comes in
    # (WInterrupts.c's INT0 vector would clash with the firmware's own)
    archive = tmp_path / "core.a"
    _avr_compile([ar, "rcs", str(archive), *(job[-1] for job in jobs)])
    sketch = tmp_path / "trigger_box.o"
    _avr_compile(
        [
            *cxx,
            "-Wall",
            "-Wextra",
            "-Werror",
            "-x",
            "c++",
            "-include",
            "Arduino.h",
            "-c",
            str(FIRMWARE / "trigger_box.ino"),
            "-o",
            str(sketch),
        ]
    )
    elf = tmp_path / "trigger_box.elf"
    _avr_compile(
        [gcc, "-mmcu=atmega328p", "-Os", "-Wl,--gc-sections", str(sketch), str(archive), "-lm", "-o", str(elf)]
    )
    report = subprocess.run([size, str(elf)], capture_output=True, text=True, check=True).stdout
    text, data, bss = (int(v) for v in report.splitlines()[1].split()[:3])
    summary = (
        f"trigger box firmware for ATmega328P: flash {text + data} of 32256 bytes, "
        f"static RAM {data + bss} of 2048 bytes (data {data}, bss {bss})"
    )
    capture = request.config.pluginmanager.get_plugin("capturemanager")
    reporter = request.config.pluginmanager.get_plugin("terminalreporter")
    if capture is not None and reporter is not None:  # shown in every run, e.g. CI logs
        with capture.global_and_fixture_disabled():
            reporter.write_line(f"\n{summary}")
    request.node.user_properties.append(("avr_size", summary))
    assert text + data <= 32256, summary
    assert data + bss <= RAM_BUDGET, summary
