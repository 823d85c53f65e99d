"""Rules the Projector base class owns, with a minimal in-test backend."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.errors import IncompatibleStateError, WaitTimeoutError
from drivers.projector import Projector, apply_gamma_lut


class SlowProjector(Projector):
    """Never reports its pattern as shown; records hook calls."""

    def __init__(self, size=(16, 8)) -> None:
        super().__init__(size)
        self.calls: list[str] = []
        self.luts: list[np.ndarray | None] = []

    def _open(self) -> None:
        self.calls.append("open")

    def _show(self, pattern) -> None:
        self.calls.append(f"show {pattern['kind']}")

    def _wait(self, timeout_s: float) -> bool:
        self.calls.append(f"wait {timeout_s:g}")
        return False

    def _close(self) -> None:
        self.calls.append("close")

    def _set_gamma_lut(self, lut) -> None:
        self.luts.append(lut)


def test_caller_timeout_is_wait_timeout_error() -> None:
    with SlowProjector() as projector:
        projector.show({"kind": "flat", "level": 0.5})
        with pytest.raises(WaitTimeoutError, match="0.25 s"):
            projector.wait_shown(timeout_s=0.25)
    assert projector.calls == ["open", "show flat", "wait 0.25", "close"]


def test_bad_pattern_never_reaches_the_backend() -> None:
    with SlowProjector() as projector:
        with pytest.raises(ValueError, match="missing key 'level'"):
            projector.show({"kind": "flat"})
        with pytest.raises(ValueError, match="expected a mapping"):
            projector.show(["flat"])
    assert projector.calls == ["open", "close"]
    assert projector.pattern is None


def test_lut_reaches_the_backend_when_open_and_again_on_reopen() -> None:
    projector = SlowProjector()
    projector.set_gamma_lut(np.linspace(0, 1, 4))
    assert projector.luts == []  # closed: kept for open()
    projector.open()
    projector.close()
    projector.open()
    assert len(projector.luts) == 2 and projector.luts[0].dtype == np.float32
    projector.set_gamma_lut(None)
    assert projector.luts[-1] is None and projector.gamma_lut is None


def test_size_is_validated() -> None:
    with pytest.raises(ValueError, match="size"):
        SlowProjector((0, 8))


def test_wait_needs_a_pattern_and_an_open_projector() -> None:
    projector = SlowProjector()
    with pytest.raises(IncompatibleStateError, match="not open"):
        projector.wait_shown()
    with projector, pytest.raises(IncompatibleStateError, match="before any show"):
        projector.wait_shown()


@pytest.mark.parametrize(
    "x, expected",
    [(0.0, 0.0), (0.5, 0.25), (0.75, 0.625), (1.0, 1.0), (-0.2, 0.0), (1.3, 1.0)],
)
def test_lut_entries_are_evenly_spaced_and_linearly_interpolated(x: float, expected: float) -> None:
    """Entry i of an N-entry LUT is the drive level for i / (N - 1); clipped outside [0, 1]."""
    lut = np.array([0.0, 0.25, 1.0])
    assert apply_gamma_lut(np.array([x]), lut)[0] == pytest.approx(expected)


def test_identity_lut_is_none() -> None:
    image = np.linspace(0, 1, 11)
    np.testing.assert_array_equal(apply_gamma_lut(image, None), image.astype(np.float32))
