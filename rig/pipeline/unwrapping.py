"""The one registry of unwrapping methods ``rig process --unwrap`` offers.

Each entry (:class:`UnwrapMethod`) declares what it needs from the capture's pattern groups (how
many sinusoid frequencies along the fringe axis, whether they must be whole fringe counts, Gray
planes) and returns one type, :class:`processing.temporal.UnwrapResult`. The phase stage
(:func:`rig.pipeline.stages.stage_phase`) checks the needs, hands the entry an
:class:`UnwrapInputs` and turns the result into the capture's unwrapped phase; the CLI's choices,
the console's options (:func:`rig.pipeline.registry.available_options`) and the docs list the
entries. A new method is one entry here: copy ``two-frequency`` for a temporal method or
``spatial`` for one that needs a single wrapped phase.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol

import numpy as np

from processing import temporal
from processing.temporal import UnwrapResult
from rig.errors import ProcessingError


class ConventionCheck(Protocol):
    """Refuse images whose phase convention differs from the capture's (the phase stage supplies it)."""

    def __call__(
        self,
        evidence: str,
        maps: Sequence[np.ndarray],
        freqs: Sequence[int],
        stripes: np.ndarray | None = None,
        bits: int = 0,
    ) -> None: ...


@dataclass(frozen=True)
class GrayPlanes:
    """Captured Gray-code bit planes along the fringe axis (most significant first) and how to threshold them."""

    planes: np.ndarray
    inverted: np.ndarray | None
    threshold: np.ndarray | None
    bits: int


@dataclass(frozen=True)
class UnwrapInputs:
    """What an unwrapping method gets: the wrapped phases it reads and what it declared it needs.

    ``phases`` and ``frequencies``: the frequencies the method reads (the highest ones, lowest
    first; whole numbers as ints when the method needs whole fringe counts). ``valid``: the
    modulation mask. ``gray``: the Gray planes when the method needs ``"gray"``. ``params``: the
    run's ``--param`` entries. ``check_convention``: call with the method's own evidence of the
    phase convention (heterodyne residuals, Gray period boundaries).
    """

    phases: list[np.ndarray]
    frequencies: list[Any]
    valid: np.ndarray
    params: Mapping[str, Any]
    check_convention: ConventionCheck
    gray: GrayPlanes | None = None


@dataclass(frozen=True)
class UnwrapMethod:
    """One registered unwrapping method; calling it calls ``run``.

    ``frequencies``: sinusoid frequencies along the fringe axis it needs at least; it reads the
    highest ``frequencies`` of them, or all when ``all_frequencies``. ``whole``: the frequencies
    must be whole fringe counts. ``needs``: pattern groups beyond the sinusoids (``"gray"``).
    ``fused``: a temporal method :func:`processing.fringe_pass.fringe_pass` can run in the same
    pass as phase shifting (one of :data:`processing.temporal.TEMPORAL_METHODS`). ``rescue``:
    modulated pixels its residual test rejects may be taken back where neighbours vouch for them.
    ``description``: one line for ``--help``, the console and the docs.
    """

    name: str
    run: Callable[[UnwrapInputs], UnwrapResult]
    description: str
    frequencies: int = 1
    all_frequencies: bool = False
    whole: bool = False
    needs: tuple[str, ...] = ()
    fused: bool = False
    rescue: bool = True

    def __call__(self, inputs: UnwrapInputs) -> UnwrapResult:
        return self.run(inputs)


def _max_residual(params: Mapping[str, Any]) -> dict[str, float]:
    """``max_residual`` when given (e.g. --param max_residual=3.14 for rendered data with drifting beats)."""
    return {"max_residual": float(params["max_residual"])} if "max_residual" in params else {}


def _two_frequency(inputs: UnwrapInputs) -> UnwrapResult:
    (f1, f2), (phi1, phi2) = inputs.frequencies, inputs.phases
    return temporal.unwrap_two_frequency(phi1, phi2, f1, f2)


def _three_frequency(inputs: UnwrapInputs) -> UnwrapResult:
    return temporal.unwrap_three_frequency(inputs.phases, inputs.frequencies)


def _hierarchical(inputs: UnwrapInputs) -> UnwrapResult:
    return temporal.unwrap_hierarchical(inputs.phases, inputs.frequencies, **_max_residual(inputs.params))


def _heterodyne(inputs: UnwrapInputs) -> UnwrapResult:
    inputs.check_convention("heterodyne", inputs.phases, inputs.frequencies)
    return temporal.unwrap_heterodyne(inputs.phases, inputs.frequencies, **_max_residual(inputs.params))


def _gray(inputs: UnwrapInputs) -> UnwrapResult:
    gray = inputs.gray
    assert gray is not None  # declared in needs: the phase stage supplies it
    stripes = temporal.decode_gray(gray.planes, inverted=gray.inverted, threshold=gray.threshold)
    frequency = int(inputs.frequencies[-1])
    complementary = (1 << gray.bits) == 2 * frequency
    if not complementary and (1 << gray.bits) != frequency:
        raise ProcessingError(
            f"--unwrap gray: {gray.bits} Gray bits give {1 << gray.bits} stripes; expected the fringe count "
            f"{inputs.frequencies[-1]:g} (or twice it, complementary Gray code)"
        )
    phase = inputs.phases[-1]
    inputs.check_convention("gray", [phase], [frequency], stripes, gray.bits)
    return temporal.unwrap_gray(phase, stripes, gray.bits, frequency, complementary=complementary)


def _spatial(inputs: UnwrapInputs) -> UnwrapResult:
    from processing.spatial import unwrap_spatial  # scipy: ~0.3 s the default path of rig process does not pay

    return unwrap_spatial(inputs.phases[-1], mask=inputs.valid)


_ENTRIES = (
    UnwrapMethod(
        "two-frequency",
        _two_frequency,
        "Ding's number-theoretic method on the two highest frequencies (coprime whole fringe counts)",
        frequencies=2,
        whole=True,
        fused=True,
    ),
    UnwrapMethod(
        "three-frequency",
        _three_frequency,
        "number-theoretic method on the three highest frequencies (no common divisor), pairs combined "
        "by the Chinese remainder theorem",
        frequencies=3,
        whole=True,
        fused=True,
    ),
    UnwrapMethod(
        "hierarchical",
        _hierarchical,
        "unit frequency first, each next frequency unwrapped with the previous absolute phase",
        frequencies=2,
        all_frequencies=True,
        whole=True,
        fused=True,
    ),
    UnwrapMethod(
        "heterodyne",
        _heterodyne,
        "beat phases of close frequencies down to a unit beat (e.g. 64, 58, 53), then hierarchically back up",
        frequencies=2,
        all_frequencies=True,
        whole=True,
        fused=True,
    ),
    UnwrapMethod(
        "gray",
        _gray,
        "Gray-code bit planes give the fringe order of the highest frequency (plain or complementary)",
        needs=("gray",),
        rescue=False,
    ),
    UnwrapMethod(
        "spatial",
        _spatial,
        "quality-guided spatial unwrapping of the highest frequency (phase up to 2 pi k per region, fixed "
        "against the reference plane)",
        rescue=False,
    ),
    UnwrapMethod(
        "ftp",
        _spatial,
        "one frame per frequency: Fourier transform profilometry, then quality-guided spatial unwrapping",
        rescue=False,
    ),
)

REGISTRY: dict[str, UnwrapMethod] = {method.name: method for method in _ENTRIES}

AUTO_DESCRIPTION = (
    "gray or spatial for one frequency (ftp for a single frame), hierarchical when frequency 1 is present, "
    "two-frequency for 2 coprime, heterodyne or three-frequency for 3"
)

# What --unwrap accepts: auto (rig.pipeline.plan.choose_unwrap picks an entry) and every entry.
UNWRAP_METHODS: tuple[str, ...] = ("auto", *REGISTRY)


def help_text() -> str:
    """One line per method for ``--help``."""
    return "; ".join([f"auto: {AUTO_DESCRIPTION}", *(f"{m.name}: {m.description}" for m in REGISTRY.values())])
