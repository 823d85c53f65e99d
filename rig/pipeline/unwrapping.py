"""The one registry of unwrapping methods ``rig process --unwrap`` offers.

Each entry (:class:`UnwrapMethod`) declares what it needs from the capture's pattern groups (how
many sinusoid frequencies along the fringe axis, whether they must be whole fringe counts, Gray
planes) and returns one type, :class:`processing.unwrap.temporal.UnwrapResult`. The phase stage
(:func:`rig.pipeline.stages.stage_phase`) checks the needs, hands the entry an
:class:`UnwrapInputs` and turns the result into the capture's unwrapped phase; the CLI's choices,
the console's options (:func:`rig.pipeline.registry.available_options`) and the docs list the
entries. A new method is one entry here: copy ``two-frequency`` for a temporal method or
``spatial`` for one that needs a single wrapped phase.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from processing.unwrap import temporal
from processing.unwrap.temporal import UnwrapResult
from rig.errors import ProcessingError


class ConventionCheck(Protocol):
    """Refuse images whose phase convention differs from the capture's (the phase stage supplies it)."""

    def __call__(
        self,
        evidence: str,
        maps: Sequence[np.ndarray],
        freqs: Sequence[float],
        stripes: np.ndarray | None = None,
        bits: int = 0,
        cell_periods: float | None = None,
    ) -> None: ...


@dataclass(frozen=True)
class GrayPlanes:
    """Captured code bit planes along the fringe axis (most significant first) and how to threshold them.

    ``binary``: a plain binary code, not Gray. ``cell``: the width of one code cell as a fraction
    of the axis (``1 / 2**bits`` unless the patterns give ``period_px``); ``cell_px`` in pixels.
    """

    planes: np.ndarray
    inverted: np.ndarray | None
    threshold: np.ndarray | None
    bits: int
    binary: bool = False
    cell: float | None = None
    cell_px: float | None = None

    @property
    def cell_fraction(self) -> float:
        """One cell's width as a fraction of the axis."""
        return self.cell if self.cell is not None else 1.0 / (1 << self.bits)


@dataclass(frozen=True)
class UnwrapInputs:
    """What an unwrapping method gets: the wrapped phases it reads and what it declared it needs.

    ``phases`` and ``frequencies``: the frequencies the method reads (the highest ones, lowest
    first; whole numbers as ints when the method needs whole fringe counts). ``valid``: the
    modulation mask. ``gray``: the Gray planes when the method needs ``"gray"``. ``params``: the
    run's ``--param`` entries. ``check_convention``: call with the method's own evidence of the
    phase convention (heterodyne residuals, Gray period boundaries). ``info``: where the method
    says what it did, for report.json's ``stage_info``.
    """

    phases: list[np.ndarray]
    frequencies: list[Any]
    valid: np.ndarray
    params: Mapping[str, Any]
    check_convention: ConventionCheck
    gray: GrayPlanes | None = None
    info: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class UnwrapMethod:
    """One registered unwrapping method; calling it calls ``run``.

    ``frequencies``: sinusoid frequencies along the fringe axis it needs at least; it reads the
    highest ``frequencies`` of them, or all when ``all_frequencies``. ``whole``: the frequencies
    must be whole fringe counts. ``needs``: pattern groups beyond the sinusoids (``"gray"``).
    ``fused``: a temporal method :func:`processing.unwrap.fused_pass.fringe_pass` can run in the same
    pass as phase shifting (one of :data:`processing.unwrap.temporal.TEMPORAL_METHODS`). ``rescue``:
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
    stripes = temporal.decode_stripes(gray.planes, inverted=gray.inverted, threshold=gray.threshold, binary=gray.binary)
    frequencies = [float(f) for f in inputs.frequencies]
    cell = gray.cell_fraction
    try:
        rung = temporal.code_rung(frequencies, cell)
    except ValueError:
        cell_text = f"{gray.cell_px:g} px" if gray.cell_px is not None else f"1/{1 << gray.bits} of the axis"
        periods = ", ".join(f"{1.0 / (f * cell):.3g}" for f in frequencies)
        raise ProcessingError(
            f"--unwrap gray: the code's cells ({cell_text}) are wider than every fringe period ({periods} cells) "
            "and every beat of two frequencies; expected a period or beat of at least one cell"
        ) from None
    evidence = [i for i, f in enumerate(frequencies) if f * cell <= 1.0 + 1e-9]  # captured periods of >= 1 cell
    if evidence:
        index = evidence[-1]
        inputs.check_convention(
            "gray", [inputs.phases[index]], [frequencies[index]], stripes, gray.bits, frequencies[index] * cell
        )
    inputs.info["code"] = {
        "kind": "binary" if gray.binary else "gray",
        "bits": gray.bits,
        "cell_px": gray.cell_px,
        "resolves": f"beat {rung.frequency:g}" if len(rung.pair) == 2 else f"frequency {rung.frequency:g}",
        "cells_per_period": round(rung.cells_per_period, 6),
        # how far (in periods) a decoded cell may be off its border before the order is wrong: 0 when
        # cells and periods share their borders (r = 1), where the bits' border side decides
        "margin_periods": 0.0 if rung.aligned else round(0.5 - 0.5 / rung.cells_per_period, 6),
    }
    side = None
    if rung.aligned:  # cells and periods share borders: the code's bits say which side of one a pixel is
        side = temporal.border_side(gray.planes, stripes, gray.inverted, gray.threshold, gray.binary)
    return temporal.unwrap_coded(inputs.phases, frequencies, stripes, cell, side=side, **_max_residual(inputs.params))


def _spatial(inputs: UnwrapInputs) -> UnwrapResult:
    from processing.unwrap.spatial import unwrap_spatial  # scipy: ~0.3 s the default path of rig process does not pay

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
        "Gray- or binary-code bit planes resolve the fringe period (or beat of two frequencies) their cells "
        "match; higher frequencies follow hierarchically (plain, complementary, any cell width)",
        all_frequencies=True,
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
    "two-frequency for 2 coprime, heterodyne or three-frequency for 3, gray where a code runs along the axis "
    "and no other method fits"
)

# What --unwrap accepts: auto (rig.pipeline.plan.choose_unwrap picks an entry) and every entry.
UNWRAP_METHODS: tuple[str, ...] = ("auto", *REGISTRY)


def help_text() -> str:
    """One line per method for ``--help``."""
    return "; ".join([f"auto: {AUTO_DESCRIPTION}", *(f"{m.name}: {m.description}" for m in REGISTRY.values())])
