"""Abstract projector: shows capture-format patterns (the typed model of processing/projection/patterns.py).

The base class owns the rules (open/closed state from :class:`~drivers.device.Device`, argument
checks, logging, the gamma LUT's meaning); a backend fills in the hooks ``_open``, ``_show``,
``_wait``, ``_close``, ``_set_gamma_lut`` if it applies the LUT itself and, if it can hand back
what it rendered, ``_last_frame``.

Gamma pre-correction: a 1-D LUT of N >= 2 entries maps the desired intensity x in [0, 1] to a
drive level. Entry i is the drive level for x = i / (N - 1); values in between are linearly
interpolated (:func:`apply_gamma_lut` is the numpy definition, shaders must agree with it).
"""

from __future__ import annotations

import abc
import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from drivers.device import Device, check_timeout_s
from drivers.errors import IncompatibleStateError, WaitTimeoutError
from processing.projection.patterns import Pattern, PatternError, as_pattern

log = logging.getLogger(__name__)


def validate_gamma_lut(lut: np.ndarray | None) -> np.ndarray | None:
    """Check a gamma LUT and return it as float32 (N,) in [0, 1]; ``None`` means identity."""
    if lut is None:
        return None
    arr = np.asarray(lut, dtype=np.float64)
    if arr.ndim != 1 or arr.size < 2:
        raise ValueError(f"lut: expected a 1-D array of at least 2 entries, found shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or arr.min() < 0.0 or arr.max() > 1.0:
        raise ValueError(f"lut: expected finite drive levels in [0, 1], found range [{arr.min()}, {arr.max()}]")
    return arr.astype(np.float32)


def apply_gamma_lut(image: np.ndarray, lut: np.ndarray | None) -> np.ndarray:
    """Drive levels for desired intensities ``image`` (any shape, clipped to [0, 1]) through ``lut``.

    Entry i of the LUT is the drive level for intensity i / (N - 1), linear in between;
    ``lut=None`` is the identity. Returns float32 like ``image``.
    """
    x = np.clip(np.asarray(image, dtype=np.float64), 0.0, 1.0)
    if lut is None:
        return x.astype(np.float32)
    lut = np.asarray(lut, dtype=np.float64)
    positions = np.arange(lut.size, dtype=np.float64)
    return np.interp(x * (lut.size - 1), positions, lut).astype(np.float32)


def validate_pattern(pattern: Pattern | Mapping[str, Any]) -> Pattern:
    """The typed pattern of ``pattern`` (a Pattern or its capture.json entry); ``ValueError`` naming the problem.

    Every pattern kind can be shown at any projector size.
    """
    try:
        return as_pattern(pattern)
    except PatternError as exc:
        kind = pattern.get("kind") if isinstance(pattern, Mapping) else None
        if not exc.key:
            raise ValueError(f"pattern: {exc.detail}") from None
        if exc.key == "kind":
            raise ValueError(f"pattern kind: {exc.detail}") from None
        if exc.missing:
            raise ValueError(f"pattern {kind!r}: missing key {exc.key!r}") from None
        raise ValueError(f"pattern {kind!r}: {exc}") from None


class Projector(Device):
    """A projector that shows one pattern at a time.

    Parameters
    ----------
    size : (width, height)
        Resolution in pixels.
    name : str, optional
        Used in log lines and error messages.
    """

    family = "projector"

    def __init__(self, size: tuple[int, int], name: str | None = None) -> None:
        width, height = (int(s) for s in size)
        if width < 1 or height < 1:
            raise ValueError(f"size: expected (width, height) >= 1, found {tuple(size)}")
        super().__init__(name)
        self.size: tuple[int, int] = (width, height)
        self._gamma_lut: np.ndarray | None = None
        self._pattern: Pattern | None = None
        self._shown_count = 0

    # -- public API: state checks and logging, then the hook -------------------------------------
    @property
    def width(self) -> int:
        return self.size[0]

    @property
    def height(self) -> int:
        return self.size[1]

    @property
    def pattern(self) -> Pattern | None:
        """The pattern last passed to :meth:`show`, typed (None before the first)."""
        return self._pattern

    @property
    def shown_count(self) -> int:
        """How many patterns were shown since :meth:`open`."""
        return self._shown_count

    @property
    def gamma_lut(self) -> np.ndarray | None:
        return None if self._gamma_lut is None else self._gamma_lut.copy()

    def show(self, pattern: Pattern | Mapping[str, Any]) -> None:
        """Start showing ``pattern`` (a Pattern or its capture.json entry); see :meth:`wait_shown`."""
        self._require_open("show a pattern")
        model = validate_pattern(pattern)
        log.debug("%s: show %s", self.name, model)
        self._show(model)
        self._pattern = model
        self._shown_count += 1

    def wait_shown(self, timeout_s: float = 1.0) -> None:
        """Block until the last shown pattern is on screen (vsync / GPU fence).

        Raises ``WaitTimeoutError`` when ``timeout_s`` runs out first; a backend raises
        ``DeviceTimeoutError`` if the device's own deadline passed.
        """
        self._require_open("wait for a pattern")
        if self._pattern is None:
            raise IncompatibleStateError(f"{self.name}: wait_shown() before any show()")
        timeout_s = check_timeout_s(timeout_s)
        if not self._wait(timeout_s):
            raise WaitTimeoutError(f"{self.name}: pattern not on screen within {timeout_s:g} s")

    def last_frame(self) -> np.ndarray | None:
        """The frame last rendered, (H, W) float32 drive levels in [0, 1] after gamma pre-correction.

        None before the first :meth:`show` or if the backend cannot read back what it shows.
        """
        if not self._is_open or self._pattern is None:
            return None
        return self._last_frame()

    def set_gamma_lut(self, lut: np.ndarray | None) -> None:
        """Set the gamma pre-correction (see the module docstring); ``None`` restores the identity.

        Applies to patterns shown from now on.
        """
        lut = validate_gamma_lut(lut)
        self._gamma_lut = lut
        log.debug("%s: gamma LUT %s", self.name, "identity" if lut is None else f"{lut.size} entries")
        if self._is_open:
            self._set_gamma_lut(lut)

    def _after_open(self) -> None:
        self._pattern = None
        self._shown_count = 0
        if self._gamma_lut is not None:
            self._set_gamma_lut(self._gamma_lut)

    # -- hooks (and Device's _open / _close) ------------------------------------------------------
    @abc.abstractmethod
    def _show(self, pattern: Pattern) -> None:
        """Render / load ``pattern`` (typed, so valid) with the current gamma LUT."""

    @abc.abstractmethod
    def _wait(self, timeout_s: float) -> bool:
        """Wait until the pattern is on screen; False if ``timeout_s`` ran out."""

    def _last_frame(self) -> np.ndarray | None:
        """The rendered drive levels (H, W) float32, or None if the backend cannot read them back."""
        return None

    def _set_gamma_lut(self, lut: np.ndarray | None) -> None:
        """Upload a validated LUT (float32 (N,)) or None; default: nothing to upload."""
