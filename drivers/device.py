"""The lifecycle every device family shares: open / closed state, context manager, state checks.

The family bases (:class:`~drivers.projector.Projector`, :class:`~drivers.camera.Camera`,
:class:`~drivers.trigger_box.TriggerBox`, :class:`~drivers.dlp.DlpController`) derive from
:class:`Device`; their backends implement the hooks ``_open`` and ``_close``. What must happen
once the connection is up (reading settings, negotiating a protocol version) goes in
``_after_open``: if it fails, the device is closed again and the error propagates.
"""

from __future__ import annotations

import abc
import logging
import math
from types import TracebackType
from typing import TypeVar

from drivers.errors import IncompatibleStateError

log = logging.getLogger(__name__)

_D = TypeVar("_D", bound="Device")


class Device(abc.ABC):
    """A device that is opened before use and closed afterwards.

    Parameters
    ----------
    name : str, optional
        Names the device in log lines and error messages (``str(device)``); default the class name.
    """

    #: The family's noun in error messages ("projector", "camera", ...).
    family = "device"

    def __init__(self, name: str | None = None) -> None:
        self.name = name or type(self).__name__
        self._is_open = False

    def __str__(self) -> str:
        return self.name

    @property
    def is_open(self) -> bool:
        return self._is_open

    def open(self) -> None:
        """Connect. Opening an open device does nothing; if any step fails the device stays closed."""
        if self._is_open:
            return
        log.debug("%s: opening", self)
        self._open()
        self._is_open = True
        try:
            self._after_open()
        except BaseException:
            self.close()
            raise

    def close(self) -> None:
        """Disconnect. Closing a closed device does nothing; the device is closed even if this raises."""
        if not self._is_open:
            return
        log.debug("%s: closing", self)
        try:
            self._close()
        finally:
            self._is_open = False

    def __enter__(self: _D) -> _D:
        self.open()
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def _require_open(self, action: str) -> None:
        """Raise ``IncompatibleStateError`` naming ``action`` unless the device is open."""
        if not self._is_open:
            raise IncompatibleStateError(
                f"{self}: cannot {action}: {self.family} not open (closed or never opened); call open() first"
            )

    # -- hooks ------------------------------------------------------------------------------------
    @abc.abstractmethod
    def _open(self) -> None:
        """Acquire the device; raise DeviceNotFoundError (from the library's error) if it is absent."""

    @abc.abstractmethod
    def _close(self) -> None:
        """Release the device."""

    def _after_open(self) -> None:  # noqa: B027  (an optional hook, not abstract)
        """Work that needs the open connection (read settings, negotiate); default nothing."""


def check_timeout_s(timeout_s: float) -> float:
    """``timeout_s`` as a float; ``ValueError`` unless it is a finite number of seconds > 0."""
    timeout_s = float(timeout_s)
    if not (math.isfinite(timeout_s) and timeout_s > 0):
        raise ValueError(f"timeout_s: expected a finite number of seconds > 0, found {timeout_s}")
    return timeout_s
