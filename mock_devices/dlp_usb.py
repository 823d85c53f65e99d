"""A fake DLP LightCrafter 4500 (DLPC350) behind a pyusb backend.

``VirtualHidBackend`` is a ``usb.backend.IBackend`` presenting one USB HID device (descriptors for
device, configuration, interface and two interrupt endpoints) in the manner of pyftdi's
``tests/backend/usbvirt.py``; subclasses decide what the device answers to each OUT report.
``FakeDlpc350Backend`` puts a model of the DLPC350 controller behind it: it parses TI's HID packets,
keeps the controller state (power, display mode, pattern LUT, exposure, validation, sequencer) and
replies to reads. Faults on request: ``Dlpc350Faults``.

Usage::

    backend = FakeDlpc350Backend()
    dlp = LightCrafter4500(backend=backend)   # the real driver, through usb.core.find
"""

from __future__ import annotations

import errno
import logging
from collections import deque
from dataclasses import dataclass, field
from types import SimpleNamespace

import usb.backend
import usb.core
import usb.util

from drivers import dlp_protocol as dp

log = logging.getLogger(__name__)

EP_OUT = 0x01
EP_IN = 0x81


def _device_descriptor(vid: int, pid: int) -> SimpleNamespace:
    return SimpleNamespace(
        bLength=18, bDescriptorType=usb.util.DESC_TYPE_DEVICE, bcdUSB=0x0200,
        bDeviceClass=0, bDeviceSubClass=0, bDeviceProtocol=0, bMaxPacketSize0=64,
        idVendor=vid, idProduct=pid, bcdDevice=0x0100, iManufacturer=0, iProduct=0,
        iSerialNumber=0, bNumConfigurations=1, address=7, bus=1, port_number=3,
        port_numbers=(3,), speed=usb.util.SPEED_FULL)


def _configuration_descriptor() -> SimpleNamespace:
    return SimpleNamespace(
        bLength=9, bDescriptorType=usb.util.DESC_TYPE_CONFIG, wTotalLength=41, bNumInterfaces=1,
        bConfigurationValue=1, iConfiguration=0, bmAttributes=0x80, bMaxPower=50,
        extra_descriptors=[])


def _interface_descriptor() -> SimpleNamespace:
    # HID class; the 9-byte HID class descriptor follows the interface descriptor
    hid = [9, 0x21, 0x11, 0x01, 0x00, 0x01, 0x22, 0x1D, 0x00]
    return SimpleNamespace(
        bLength=9, bDescriptorType=usb.util.DESC_TYPE_INTERFACE, bInterfaceNumber=0,
        bAlternateSetting=0, bNumEndpoints=2, bInterfaceClass=0x03, bInterfaceSubClass=0,
        bInterfaceProtocol=0, iInterface=0, extra_descriptors=hid)


def _endpoint_descriptor(address: int) -> SimpleNamespace:
    return SimpleNamespace(
        bLength=7, bDescriptorType=usb.util.DESC_TYPE_ENDPOINT, bEndpointAddress=address,
        bmAttributes=usb.util.ENDPOINT_TYPE_INTR, wMaxPacketSize=dp.REPORT_SIZE, bInterval=1,
        bRefresh=0, bSynchAddress=0, extra_descriptors=[])


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
        """Answer one OUT report; return the IN report to queue, or None."""
        raise NotImplementedError

    def _before_transfer(self, direction: str) -> None:
        """Hook for faults; raise usb.core.USBError to fail the transfer."""
        if not self.present:
            raise usb.core.USBError("No such device (it may have been disconnected)",
                                    error_code=-4, errno=errno.ENODEV)

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
        if reply is not None:
            self._in_queue.append(bytes(reply).ljust(dp.REPORT_SIZE, b"\x00"))
        return len(report)

    def intr_read(self, dev_handle, ep, intf, buff, timeout):
        self._before_transfer("read")
        if ep != EP_IN:
            raise usb.core.USBError("Pipe error", error_code=-9, errno=errno.EPIPE)
        if not self._in_queue:
            raise usb.core.USBTimeoutError("Operation timed out", error_code=-7,
                                           errno=errno.ETIMEDOUT)
        report = self._in_queue.popleft()
        n = min(len(buff), len(report))
        buff[:n] = type(buff)(buff.typecode, report[:n])
        return n
