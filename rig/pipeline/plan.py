"""Capture (+ calibration) -> absolute phase, height map, point cloud: the stages of `rig process`.

Each capture (the object, and the calibration's reference plane) goes through the same stages::

    load -> undistort -> denoise -> phase -> correction

then the two meet in ``height`` (:mod:`calibration.models`: thesis eq. 1.15 on Phi_object -
Phi_reference for the reference-plane model) and ``outputs``.
Every stage is a plain function of a :class:`rig.pipeline.state.SceneState` and the
:class:`ProcessOptions`; its wall-clock time goes into report.json. Methods plug in through
registries, so a new method is one entry, not a new code path:

- :data:`rig.pipeline.unwrapping.REGISTRY` ``name -> UnwrapMethod`` (``--unwrap``): what each
  needs of the pattern groups, and ``run(inputs) -> UnwrapResult``;
- :data:`rig.pipeline.stages.DENOISERS` ``name -> Denoiser`` (``--denoise``);
- :data:`rig.pipeline.corrections.REGISTRY` ``name -> CorrectionMethod`` (``--correction``):
  typed entries, ``f(absolute, wrapped, orders, mask, frequency, **params) -> (phase, info)``,
  with what each needs from the calibration (``needs``);
- :data:`rig.pipeline.single_shot_phase.SINGLE_SHOT` ``pattern kind -> f(state, options) -> None``
  filling ``state.wrapped`` and ``state.unwrapped`` for single-shot patterns (``speckle-sinusoid``);
- heights and points come from :mod:`calibration.models` (reference-plane, polynomial, stereo),
  whatever the calibration's model; the reference plane is processed when the model needs it.

:func:`rig.pipeline.registry.available_options` lists every choice for the front-ends.

Automatic choice of the unwrapping method (``--unwrap auto``), from the sinusoid frequencies
along the fringe axis (the axis of the first sinusoid pattern):

1. one frequency: ``gray`` if Gray- or binary-code planes along that axis are present, else
   ``spatial`` (quality-guided); a single frame per frequency: ``ftp`` (Fourier transform
   profilometry, then spatial unwrapping);
2. the lowest frequency is 1: ``hierarchical``;
3. two coprime frequencies: ``two-frequency`` (number-theoretic, Ding);
4. three close frequencies (highest < 2 x lowest) whose beats differ by 1 (64, 58, 53 -> 6, 5
   -> 1): ``heterodyne``; otherwise, three frequencies without a common divisor:
   ``three-frequency``;
5. anything else: ``gray`` when a code runs along the axis (it resolves a period or beat, the
   other frequencies follow hierarchically: non-integer fringe counts too), else an error asking
   for ``--unwrap``.

Methods that use fewer frequencies than captured take the highest ones. Spatial unwrapping gives
phase up to a constant 2 pi k per connected region: the height stage then removes from each region
the multiple of 2 pi nearest its median object-reference difference (right when the reference
plane shows in the region) and says so in the report.
"""

from __future__ import annotations

import inspect
import logging
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from rig.errors import CaptureError, ProcessingError

if TYPE_CHECKING:
    from processing.projection.patterns import Gray, Pattern

log = logging.getLogger(__name__)

TWO_PI = 2.0 * math.pi
# The correction a user gets without asking (every front-end: ProcessOptions() uses it): the best
# measured. The calibration session asks for "none", so its fits see the measured phase.
DEFAULT_CORRECTION = "auto"


# --------------------------------------------------------------------------- options and pattern groups


NOISE_RULE_RATIO = 0.02  # with the noise rule: only pixels under 2 % of the brightest's modulation are shadow outright
RATIO_RULE_RATIO = 0.2  # the modulation-ratio rule's default (and the rule where no phase noise can be predicted)
# The noise rule's bound on the predicted phase sigma (rad) at the phase's frequency (docs/uncertainty.md):
# a fringe keeps its pixels from B >= 10 sqrt(2 / J) sigma_I on (8.7 grey levels for six steps at sigma_I =
# 1.5, 5.8 for twelve), while a pixel with no fringe (a Rayleigh-distributed modulation estimate) passes
# with probability exp(-1 / (2 x 0.1^2)) ~ 2e-22. On the real captures 0.25 and 0.15 rad let in
# wrong surfaces (slmaster-eye's background at 1.3 m behind the 0.73 m plaque) that 0.1 does not.
MAX_PHASE_SIGMA = 0.1


@dataclass
class ProcessOptions:
    """What `rig process` was asked to do; the defaults are `rig process`'s defaults.

    ``params`` carries method-specific settings of plug-in stages (e.g. RPCA's tau) by name.
    """

    unwrap: str = "auto"
    undistort: bool | None = None  # None: when the calibration has camera_matrix + distortion
    denoise: str = "none"
    correction: str = DEFAULT_CORRECTION
    # None: the noise rule decides validity (max_phase_sigma, max_sigma) wherever the phase noise can be
    # predicted, with a modulation floor of NOISE_RULE_RATIO; a number: the modulation-ratio rule with it
    min_modulation_ratio: float | None = None
    # keep pixels whose predicted height sigma (mm) is under this (None: no bound in mm)
    max_sigma: float | None = None
    # the noise rule: keep pixels whose predicted phase sigma (rad) is under this (None: no bound in rad)
    max_phase_sigma: float | None = MAX_PHASE_SIGMA
    # valid regions smaller than this fraction of the largest are dropped (processing.correction.islands); 0 keeps all
    min_island_fraction: float = 0.005
    axis: str | None = None
    params: dict[str, Any] = field(default_factory=dict)

    def noise_rule(self, predictable: bool) -> bool:
        """Whether the predicted noise decides validity: the default wherever the phase noise can be
        predicted (``predictable``: phase-shifted fringes), and whenever ``max_sigma`` is given."""
        return self.max_sigma is not None or (self.min_modulation_ratio is None and predictable)

    def modulation_ratio(self, predictable: bool) -> float:
        """The modulation mask's ratio: a floor under the noise rule, else ``min_modulation_ratio`` (default 0.2)."""
        ratio = RATIO_RULE_RATIO if self.min_modulation_ratio is None else self.min_modulation_ratio
        return min(ratio, NOISE_RULE_RATIO) if self.noise_rule(predictable) else ratio


def accepted_params(function: Callable[..., Any], params: Mapping[str, Any]) -> dict[str, Any]:
    """The ``--param`` entries that ``function`` takes as keyword arguments."""
    accepted = inspect.signature(function).parameters
    return {key: value for key, value in params.items() if key in accepted}


@dataclass
class SinusoidGroup:
    """The frames of one (axis, frequency): ``shifts`` include each pattern's ``phase_rad``.

    With I_j = A + B cos(2 pi f u / W + phase_rad_j + shift_j), phase shifting with
    delta_j = phase_rad_j + shift_j returns 2 pi f u / W directly (the reported convention).
    """

    axis: str
    frequency: float
    indices: list[int]
    shifts: list[float]
    kind: str = "sinusoid"

    @property
    def steps(self) -> int:
        return len(self.indices)


@dataclass
class GrayGroup:
    """Code bit planes along one axis: pattern index of each bit (0 = most significant).

    ``binary``: a plain binary code rather than Gray; ``period_px``: the cell width in projector
    pixels (None: the axis over ``2**bits``).
    """

    axis: str
    bits: int
    planes: dict[int, int] = field(default_factory=dict)
    inverted: dict[int, int] = field(default_factory=dict)
    binary: bool = False
    period_px: float | None = None

    @property
    def code(self) -> str:
        """The pattern kind of the planes: ``gray`` or ``binary``."""
        return "binary" if self.binary else "gray"


@dataclass
class PatternGroups:
    """A capture's patterns grouped for processing."""

    sinusoids: list[SinusoidGroup]
    gray: dict[str, GrayGroup]
    flats: list[tuple[int, float]]
    single_shot: list[SinusoidGroup]

    def along(self, axis: str) -> list[SinusoidGroup]:
        """Sinusoid groups along ``axis``, lowest frequency first."""
        return sorted((g for g in self.sinusoids if g.axis == axis), key=lambda g: g.frequency)


def group_patterns(patterns: Sequence[Pattern | Mapping[str, Any]], where: str = "capture.json") -> PatternGroups:
    """Group patterns by kind: sinusoids per (axis, frequency), Gray planes per axis, flats."""
    from processing.projection.patterns import (  # numpy: not for the parser
        Binary,
        Flat,
        Gray,
        Sinusoid,
        SpeckleSinusoid,
        as_pattern,
    )

    sinusoids: dict[tuple[str, float], SinusoidGroup] = {}
    single: dict[tuple[str, float], SinusoidGroup] = {}
    gray: dict[str, GrayGroup] = {}
    flats: list[tuple[int, float]] = []
    for index, pattern in enumerate(as_pattern(p) for p in patterns):
        if isinstance(pattern, Sinusoid):
            table = single if isinstance(pattern, SpeckleSinusoid) else sinusoids
            key = (pattern.axis, float(pattern.frequency))
            group = table.setdefault(key, SinusoidGroup(pattern.axis, key[1], [], [], pattern.kind))
            group.indices.append(index)
            group.shifts.append(pattern.phase_delay)
        elif isinstance(pattern, Gray):
            group_g = gray.setdefault(
                pattern.axis,
                GrayGroup(pattern.axis, pattern.bits, binary=isinstance(pattern, Binary), period_px=pattern.period_px),
            )
            _check_same_code(group_g, pattern, index, where)
            (group_g.inverted if pattern.inverted else group_g.planes)[pattern.bit] = index
        elif isinstance(pattern, Flat):
            flats.append((index, float(pattern.level)))
    for planes in gray.values():
        missing = [b for b in range(planes.bits) if b not in planes.planes]
        if missing:
            raise CaptureError(
                f"{where}: Gray code along {planes.axis}: expected bits 0..{planes.bits - 1}, missing {missing}"
            )
        if planes.inverted and sorted(planes.inverted) != sorted(planes.planes):
            raise CaptureError(
                f"{where}: Gray code along {planes.axis}: inverted planes must cover the same bits as the normal ones"
            )
    for group in sinusoids.values():
        _check_separable(group, where)
    return PatternGroups(list(sinusoids.values()), gray, flats, list(single.values()))


def _check_same_code(group: GrayGroup, pattern: Gray, index: int, where: str) -> None:
    """Every code plane along one axis belongs to one code: same kind, bits and cell width."""
    kind = "binary" if group.binary else "gray"
    found = {"kind": pattern.kind, "bits": pattern.bits, "period_px": pattern.period_px}
    expected = {"kind": kind, "bits": group.bits, "period_px": group.period_px}
    for key, value in expected.items():
        if found[key] != value:
            raise CaptureError(
                f"{where}: patterns[{index}].{key}: expected {value!r} like the other code planes along "
                f"{group.axis}, found {found[key]!r}"
            )


def _check_separable(group: SinusoidGroup, where: str) -> None:
    """A phase-shifting group whose shifts cannot separate A, B and phi (too few, or all equal) is refused here."""
    import numpy as np

    from processing.phase.shifting import shift_weights

    if group.steps < 3:  # one frame goes to FTP; two are refused by the wrapped-phase stage
        return
    try:
        shift_weights(group.steps, np.asarray(group.shifts, dtype=np.float64))
    except ValueError as exc:
        names = ", ".join(f"patterns[{i}]" for i in group.indices[:8]) + (" ..." if len(group.indices) > 8 else "")
        raise CaptureError(
            f"{where}: {names} (sinusoid {group.axis} frequency {group.frequency:g}, shifts "
            f"{', '.join(f'{s:.3g}' for s in group.shifts[:8])} rad): cannot compute a phase: {exc}"
        ) from None


def _beat_chain_ends_at_one(frequencies: Sequence[float]) -> bool:
    values = sorted(frequencies, reverse=True)
    while len(values) > 1:
        values = sorted({abs(a - b) for a, b in zip(values, values[1:])}, reverse=True)
    return bool(values) and values[0] == 1


def _all_integers(frequencies: Sequence[float]) -> bool:
    return all(float(f).is_integer() for f in frequencies)


def choose_unwrap(groups: PatternGroups, axis: str) -> str:
    """The unwrapping method the pattern set allows (see the module docstring for the rule)."""
    along = groups.along(axis)
    freqs = [g.frequency for g in along]
    if not freqs:
        raise ProcessingError(f"no sinusoid pattern along {axis}: nothing to unwrap")
    if len(freqs) == 1:
        if along[0].steps < 3:
            return "ftp"
        return "gray" if axis in groups.gray else "spatial"
    try:
        return _choose_temporal(freqs)
    except ProcessingError:
        if axis in groups.gray:  # a code along the axis resolves what the frequencies alone cannot
            return "gray"
        raise


def _choose_temporal(freqs: Sequence[float]) -> str:
    """The temporal method several frequencies allow on their own (rules 2 to 5)."""
    if not _all_integers(freqs):
        raise ProcessingError(
            f"frequencies {freqs}: temporal unwrapping needs whole fringe counts; choose --unwrap spatial"
        )
    ints = [int(f) for f in freqs]
    if ints[0] == 1:
        return "hierarchical"
    if len(ints) == 2 and math.gcd(*ints) == 1:
        return "two-frequency"
    if len(ints) == 3:
        if ints[2] < 2 * ints[0] and _beat_chain_ends_at_one(ints):
            return "heterodyne"
        if math.gcd(*ints) == 1:
            return "three-frequency"
    from rig.pipeline.unwrapping import REGISTRY  # numpy: not for the parser

    raise ProcessingError(
        f"frequencies {ints}: no automatic unwrapping method fits; choose one with --unwrap ({', '.join(REGISTRY)})"
    )
