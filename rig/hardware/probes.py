"""Device probes: what is connected (cameras, serial ports, DLP projectors on USB) and the simulated rig.

Each probe is short and independent: a missing library or permission is reported on its line,
never as a failure of the command.
"""

from __future__ import annotations

import glob
import logging
import sys
from collections.abc import Callable
from dataclasses import dataclass

log = logging.getLogger(__name__)

OPENCV_PROBE_INDICES = 4  # probed where the platform does not list video devices


@dataclass
class Found:
    """One device line: the config values that select it, and what it is."""

    backend: str
    address: str
    description: str


@dataclass
class Probe:
    """What one kind of device search found."""

    title: str
    found: list[Found]
    note: str = ""  # why nothing could be looked for, or a hint


def probe_opencv(timeout_ms: int = 1500) -> Probe:
    """OpenCV (V4L2 / DirectShow / AVFoundation) cameras, opened briefly to read their size."""
    import cv2

    if sys.platform.startswith("linux"):
        nodes = sorted(glob.glob("/dev/video*"), key=lambda p: int(p[len("/dev/video") :] or 0))
        indices = [int(node[len("/dev/video") :]) for node in nodes if node[len("/dev/video") :].isdigit()]
        if not indices:
            return Probe("OpenCV cameras", [], "no /dev/video* device")
    else:
        indices = list(range(OPENCV_PROBE_INDICES))
    found = []
    for index in indices:
        params = [cv2.CAP_PROP_OPEN_TIMEOUT_MSEC, timeout_ms, cv2.CAP_PROP_READ_TIMEOUT_MSEC, timeout_ms]
        capture = cv2.VideoCapture(index, cv2.CAP_ANY, params)
        try:
            if not capture.isOpened():
                continue
            width = int(capture.get(cv2.CAP_PROP_FRAME_WIDTH))
            height = int(capture.get(cv2.CAP_PROP_FRAME_HEIGHT))
            found.append(Found("opencv", f"index = {index}", f"{width}x{height} via {capture.getBackendName()}"))
        finally:
            capture.release()
    return Probe("OpenCV cameras", found, "" if found else f"none answered on index {', '.join(map(str, indices))}")


def probe_pylon() -> Probe:
    """Basler cameras through pypylon (pylon's emulator shows up when PYLON_CAMEMU is set)."""
    try:
        from pypylon import pylon
    except ImportError:
        return Probe("Basler (pylon) cameras", [], "pypylon not installed (pip install 'fpp-rig[pylon]')")
    try:
        devices = pylon.TlFactory.GetInstance().EnumerateDevices()
    except Exception as exc:  # pypylon raises its own GenICam exception types
        log.debug("pylon enumeration failed", exc_info=True)
        return Probe("Basler (pylon) cameras", [], f"pylon could not enumerate devices: {exc}")
    found = [
        Found("pylon", f'serial = "{d.GetSerialNumber()}"', f"{d.GetModelName()} ({d.GetDeviceClass()})")
        for d in devices
    ]
    hint = "" if found else "none found (PYLON_CAMEMU=1 adds an emulated camera)"
    return Probe("Basler (pylon) cameras", found, hint)


def probe_serial() -> Probe:
    """Serial ports, for the trigger box."""
    from serial.tools import list_ports

    found = []
    for port in sorted(list_ports.comports(), key=lambda p: p.device):
        ids = f" [{port.vid:04x}:{port.pid:04x}]" if port.vid is not None and port.pid is not None else ""
        description = port.description if port.description and port.description != "n/a" else "serial port"
        found.append(Found("serial", f'port = "{port.device}"', f"{description}{ids}"))
    return Probe("Serial ports (trigger box)", found, "" if found else "none")


def probe_dlp(backend: object | None = None) -> Probe:
    """TI DLP LightCrafter 4500 controllers on USB (``backend``: a pyusb backend, default libusb)."""
    import usb.core

    from drivers.dlp_protocol import USB_PRODUCT_ID, USB_VENDOR_ID

    try:
        devices = list(usb.core.find(find_all=True, idVendor=USB_VENDOR_ID, idProduct=USB_PRODUCT_ID, backend=backend))
    except usb.core.NoBackendError:
        return Probe("DLP projectors (USB)", [], "no libusb backend installed (install libusb-1.0)")
    except usb.core.USBError as exc:
        return Probe("DLP projectors (USB)", [], f"USB enumeration failed: {exc}")
    found = [
        Found(
            "dlp4500",
            f"bus {d.bus} address {d.address}",
            f"DLP LightCrafter 4500 ({USB_VENDOR_ID:04x}:{USB_PRODUCT_ID:04x})",
        )
        for d in devices
    ]
    return Probe("DLP projectors (USB)", found, "" if found else "none")


def probe_offscreen_gl() -> Probe:
    """Whether moderngl can render off-screen (EGL): what the gl-offscreen projector needs."""
    try:
        import moderngl

        context = moderngl.create_standalone_context(backend="egl")
    except Exception as exc:  # moderngl / glcontext raise plain Exceptions when EGL is missing
        return Probe("Off-screen rendering", [], f"EGL unavailable: {exc}")
    try:
        info = context.info
        renderer = (
            f"OpenGL {context.version_code // 100}.{context.version_code % 100 // 10} ({info.get('GL_RENDERER', '?')})"
        )
    finally:
        context.release()
    return Probe("Off-screen rendering", [Found("gl-offscreen", "EGL", renderer)])


def simulated() -> Probe:
    """The devices of the built-in simulated rig (always there)."""
    return Probe(
        "Simulated rig (rig scan without --config)",
        [
            Found("gl-offscreen", "projector", "moderngl off-screen render of each pattern"),
            Found("simulated", "camera", "sees the rendered pattern on a virtual scene"),
            Found("simulated-serial", "trigger", "the trigger-box protocol on a pseudo-terminal"),
        ],
    )


PROBES: tuple[Callable[[], Probe], ...] = (probe_opencv, probe_pylon, probe_serial, probe_dlp, probe_offscreen_gl)


def format_probe(probe: Probe) -> str:
    """A probe as printed: its title, one indented line per device, then the note."""
    lines = [probe.title]
    for item in probe.found:
        lines.append(f"  {item.backend:<17} {item.address:<28} {item.description}")
    if probe.note:
        lines.append(f"  - {probe.note}")
    return "\n".join(lines)
