"""Device: the lifecycle every family base inherits (open once, roll back a failed open, closed
even when closing fails, errors that name the device)."""

from __future__ import annotations

import math

import pytest

from drivers.device import Device, check_timeout_s
from drivers.errors import IncompatibleStateError


class Recorder(Device):
    family = "recorder"

    def __init__(self, fail_after_open: bool = False, fail_close: bool = False) -> None:
        super().__init__("rec-1")
        self.calls: list[str] = []
        self.fail_after_open = fail_after_open
        self.fail_close = fail_close

    def _open(self) -> None:
        self.calls.append("open")

    def _after_open(self) -> None:
        self.calls.append("after_open")
        if self.fail_after_open:
            raise OSError("handshake failed")

    def _close(self) -> None:
        self.calls.append("close")
        if self.fail_close:
            raise OSError("close failed")

    def poke(self) -> None:
        self._require_open("poke")


def test_open_is_idempotent_and_close_too() -> None:
    device = Recorder()
    device.open()
    device.open()
    device.close()
    device.close()
    assert device.calls == ["open", "after_open", "close"]
    assert not device.is_open


def test_failed_after_open_closes_again_and_propagates() -> None:
    device = Recorder(fail_after_open=True)
    with pytest.raises(OSError, match="handshake failed"):
        device.open()
    assert device.calls == ["open", "after_open", "close"]
    assert not device.is_open


def test_device_is_closed_even_when_closing_fails() -> None:
    device = Recorder(fail_close=True)
    device.open()
    with pytest.raises(OSError, match="close failed"):
        device.close()
    assert not device.is_open
    device.close()  # nothing left to close
    assert device.calls.count("close") == 1


def test_context_manager_returns_the_device_and_closes_on_error() -> None:
    device = Recorder()
    with pytest.raises(KeyError):
        with device as entered:
            assert entered is device and device.is_open
            raise KeyError("inside")
    assert not device.is_open and device.calls[-1] == "close"


def test_not_open_error_names_device_action_and_family() -> None:
    device = Recorder()
    with pytest.raises(IncompatibleStateError, match=r"^rec-1: cannot poke: recorder not open") as info:
        device.poke()
    assert str(device) == "rec-1" and "open()" in str(info.value)


def test_default_name_is_the_class_name() -> None:
    class Bare(Device):
        def _open(self) -> None: ...

        def _close(self) -> None: ...

    assert Bare().name == "Bare"


@pytest.mark.parametrize("bad", [0.0, -1.0, math.inf, math.nan])
def test_check_timeout_rejects_non_finite_or_non_positive(bad: float) -> None:
    with pytest.raises(ValueError, match="timeout_s"):
        check_timeout_s(bad)


def test_check_timeout_returns_float() -> None:
    assert check_timeout_s(2) == 2.0 and isinstance(check_timeout_s(2), float)
