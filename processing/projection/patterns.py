"""The pattern model of capture-format.md: typed patterns, their validation, JSON form and maths.

A pattern is what the projector shows for one frame. Every layer uses these classes: the
projector driver validates what it is asked to show with them, the capture store checks
``capture.json`` entries with them, the importer and the rig config build them, the pipeline
groups them. Validation lives in one place, the classes' ``__post_init__``; a wrong value raises
:class:`PatternError` (a ``ValueError``) naming the key, what was expected and what was found,
which each layer prefixes with its own context (file and field, or the device).

JSON form (format v1): :func:`parse_pattern` reads one ``patterns`` entry, :meth:`Pattern.to_dict`
writes it back. The round trip is exact: keys the entry carried stay, in their order, with their
values as written (``5`` stays ``5``, not ``5.0``); keys it left out stay out; unknown keys are
kept in ``extra`` (capture-format.md: tools that rewrite a file preserve them). A pattern built
in code writes its kind's main keys and every optional key that differs from its default.

This module is also the single definition of the projected intensities: the moderngl shaders,
the synthesiser and the simulated camera are all checked against it. Intensities are in [0, 1],
before the projector's gamma. The projector pixel coordinate ``u`` runs along the pattern's
``axis`` over ``0 .. W`` (``W`` the projector width for ``"x"``, its height for ``"y"``).
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from processing.projection.speckle import DEFAULT_DOT_PX, DEFAULT_SEED, DEFAULT_SPECKLE_GAIN, cached_speckle_field

AXES = ("x", "y")
MAX_CODE_BITS = 24  # code words of Gray/binary planes: 16 M cells, far beyond any projector
_MISSING = object()


class PatternError(ValueError):
    """A pattern entry or value that capture-format.md does not allow.

    ``key`` is the entry's key at fault (``""`` for the entry itself); ``missing`` is True when the
    key is required and absent, otherwise ``expected`` and ``found`` say what is wrong.
    """

    def __init__(self, key: str, expected: str = "", found: Any = _MISSING) -> None:
        self.key = key
        self.expected = expected
        self.missing = found is _MISSING
        self.found = None if self.missing else found
        self.detail = "missing" if self.missing else f"expected {expected}, found {found!r}"
        super().__init__(f"{key}: {self.detail}" if key else self.detail)


# --------------------------------------------------------------------------- value checks


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _check_number(key: str, value: Any, positive: bool = False) -> None:
    if not _is_number(value):
        raise PatternError(key, "a finite number", value)
    if positive and value <= 0:
        raise PatternError(key, "a positive number", value)


def _check_int(key: str, value: Any, minimum: int) -> None:
    if not _is_int(value) or value < minimum:
        raise PatternError(key, f"an integer >= {minimum}", value)


def _check_axis(value: Any) -> None:
    if value not in AXES:
        raise PatternError("axis", "'x' or 'y'", value)


# --------------------------------------------------------------------------- the kinds


@functools.cache
def _compared_fields(kind: type) -> tuple[str, ...]:
    """Fields a pattern of ``kind`` compares by (extra keys aside); looked up once per kind."""
    return tuple(f.name for f in dataclasses.fields(kind) if f.compare and f.name != "extra")


@functools.cache
def _field_defaults(kind: type) -> dict[str, Any]:
    """Default value of each field of ``kind`` that has one (callers only read it)."""
    return {f.name: f.default for f in dataclasses.fields(kind) if f.default is not dataclasses.MISSING}


@dataclass(frozen=True, kw_only=True, eq=False)
class Pattern(Mapping[str, Any]):
    """Base of the pattern kinds: the JSON round trip and the unknown keys.

    ``extra`` holds the entry's keys that are not the kind's own (provenance, a tool's notes);
    ``source_keys`` the order of the keys of the entry it was parsed from (empty when built in
    code), so that :meth:`to_dict` writes the entry back as it was. A pattern also reads as a
    read-only mapping of its capture.json entry (``pattern["kind"]``, ``dict(pattern)``) for
    code that handles entries generically; code that needs values uses the typed attributes.
    """

    kind: ClassVar[str] = ""
    # JSON keys of the kind (besides "kind"), in the order an entry built in code writes them,
    # and those written even when they hold their default.
    KEYS: ClassVar[tuple[str, ...]] = ()
    MAIN_KEYS: ClassVar[tuple[str, ...]] = ()

    extra: dict[str, Any] = field(default_factory=dict, hash=False)
    source_keys: tuple[str, ...] = field(default=(), compare=False, repr=False)

    def __post_init__(self) -> None:
        if not isinstance(self.extra, Mapping):
            raise PatternError("extra", "a mapping of extra keys", self.extra)
        clash = sorted(set(self.extra) & ({"kind"} | set(self.KEYS)))
        if clash:
            raise PatternError(clash[0], f"a key of {self.kind!r} given as a field, not in extra", self.extra[clash[0]])
        self.validate()

    def validate(self) -> None:
        """Raise :class:`PatternError` on the first value the format does not allow."""

    def _defaults(self) -> dict[str, Any]:
        return _field_defaults(type(self))

    def to_dict(self) -> dict[str, Any]:
        """The capture.json entry (format v1); the exact entry it was parsed from, if unchanged."""
        values = {"kind": self.kind, **{key: getattr(self, key) for key in self.KEYS}, **self.extra}
        defaults = self._defaults()
        parsed = bool(self.source_keys)

        def written(key: str) -> bool:
            if key == "kind" or key in self.extra or key in self.source_keys:
                return True
            if not parsed and key in self.MAIN_KEYS:
                return True
            return values[key] != defaults.get(key, _MISSING)

        order = [k for k in self.source_keys if k in values] + [k for k in values if k not in self.source_keys]
        return {key: values[key] for key in order if written(key)}

    def _values(self) -> tuple[Any, ...]:
        return tuple(getattr(self, name) for name in _compared_fields(type(self)))

    def __eq__(self, other: object) -> bool:
        """Same kind and values (key order aside); equal to a mapping holding its capture.json entry."""
        if isinstance(other, Pattern):
            return type(self) is type(other) and self._values() == other._values() and self.extra == other.extra
        if isinstance(other, Mapping):
            return self.to_dict() == dict(other)
        return NotImplemented

    def __hash__(self) -> int:
        return hash((self.kind, self._values()))

    def __getitem__(self, key: str) -> Any:
        return self.to_dict()[key]

    def __iter__(self) -> Iterator[str]:
        return iter(self.to_dict())

    def __len__(self) -> int:
        return len(self.to_dict())

    def replace(self, **changes: Any) -> Pattern:
        """A copy with ``changes`` (validated); keeps the key order and extra keys."""
        return dataclasses.replace(self, **changes)


@dataclass(frozen=True, kw_only=True, eq=False)
class Sinusoid(Pattern):
    """``offset + amplitude cos(2 pi frequency u / W + phase_rad + shift)``.

    ``shift`` is ``shift_rad`` if given, else 2 pi ``step`` / ``steps``. The absolute phase the
    product reports is 2 pi f u / W, whatever ``offset``, ``phase_rad`` and ``shift``.
    """

    kind: ClassVar[str] = "sinusoid"
    KEYS: ClassVar[tuple[str, ...]] = (
        "axis",
        "frequency",
        "steps",
        "step",
        "offset",
        "amplitude",
        "phase_rad",
        "shift_rad",
    )
    MAIN_KEYS: ClassVar[tuple[str, ...]] = ("axis", "frequency", "steps", "step")

    axis: str = "x"
    frequency: float
    steps: int
    step: int
    offset: float = 0.5
    amplitude: float = 0.5
    phase_rad: float = 0.0
    shift_rad: float | None = None

    def validate(self) -> None:
        _check_axis(self.axis)
        _check_number("frequency", self.frequency, positive=True)
        _check_int("steps", self.steps, 1)
        _check_int("step", self.step, 0)
        if self.step >= self.steps:
            raise PatternError("step", f"0 .. {self.steps - 1} (steps = {self.steps})", self.step)
        for key in ("offset", "amplitude", "phase_rad"):
            _check_number(key, getattr(self, key))
        if self.shift_rad is not None:
            _check_number("shift_rad", self.shift_rad)

    @property
    def shift(self) -> float:
        """This frame's phase shift in radians: ``shift_rad`` if given, else 2 pi j / J."""
        if self.shift_rad is not None:
            return float(self.shift_rad)
        return 2.0 * np.pi * int(self.step) / int(self.steps)

    @property
    def phase_delay(self) -> float:
        """``phase_rad + shift``: what phase shifting subtracts to get 2 pi f u / W."""
        return self.shift + float(self.phase_rad)


@dataclass(frozen=True, kw_only=True, eq=False)
class SpeckleSinusoid(Sinusoid):
    """The thesis' single-shot pattern: a :class:`Sinusoid` scaled by (1 - g) plus g times a speckle field.

    ``seed`` and ``dot_px`` choose the field (:func:`processing.projection.speckle.speckle_field`),
    ``speckle_gain`` is g in [0, 1].
    """

    kind: ClassVar[str] = "speckle-sinusoid"
    KEYS: ClassVar[tuple[str, ...]] = Sinusoid.KEYS + ("seed", "dot_px", "speckle_gain")
    MAIN_KEYS: ClassVar[tuple[str, ...]] = Sinusoid.MAIN_KEYS + ("seed", "dot_px", "speckle_gain")

    seed: int = DEFAULT_SEED
    dot_px: int = DEFAULT_DOT_PX
    speckle_gain: float = DEFAULT_SPECKLE_GAIN

    def validate(self) -> None:
        super().validate()
        _check_int("seed", self.seed, 0)
        _check_int("dot_px", self.dot_px, 1)
        _check_number("speckle_gain", self.speckle_gain)
        if not 0.0 <= self.speckle_gain <= 1.0:
            raise PatternError("speckle_gain", "a value in [0, 1]", self.speckle_gain)


@dataclass(frozen=True, kw_only=True, eq=False)
class Gray(Pattern):
    """Gray-code bit plane ``bit`` (0 the most significant) of ``bits``; ``inverted`` its negative.

    The axis is cut into cells: ``period_px`` projector pixels wide when given (a code of cells
    that do not tile the axis in ``2**bits``, e.g. OpenCV's GrayCodePattern upscaled to 100-px
    cells), else ``W / 2**bits``. Cell ``s`` carries the code word of ``s`` (see
    :func:`stripe_code`); cells past the last code word repeat it.
    """

    kind: ClassVar[str] = "gray"
    KEYS: ClassVar[tuple[str, ...]] = ("axis", "bit", "bits", "inverted", "period_px")
    MAIN_KEYS: ClassVar[tuple[str, ...]] = ("axis", "bit", "bits", "inverted")

    axis: str = "x"
    bit: int
    bits: int
    inverted: bool = False
    period_px: float | None = None

    def validate(self) -> None:
        _check_axis(self.axis)
        _check_int("bits", self.bits, 1)
        if self.bits > MAX_CODE_BITS:
            raise PatternError("bits", f"an integer in 1 .. {MAX_CODE_BITS}", self.bits)
        _check_int("bit", self.bit, 0)
        if self.bit >= self.bits:
            raise PatternError("bit", f"0 .. {self.bits - 1} (bits = {self.bits})", self.bit)
        if not isinstance(self.inverted, bool):
            raise PatternError("inverted", "true or false", self.inverted)
        if self.period_px is not None:
            _check_number("period_px", self.period_px, positive=True)

    def cell_px(self, extent: float) -> float:
        """Width of one code cell in projector pixels along an axis ``extent`` pixels long."""
        return float(self.period_px) if self.period_px is not None else float(extent) / (1 << self.bits)


@dataclass(frozen=True, kw_only=True, eq=False)
class Binary(Gray):
    """Plain binary-code bit plane: as :class:`Gray`, but cell ``s`` carries ``s`` itself."""

    kind: ClassVar[str] = "binary"


@dataclass(frozen=True, kw_only=True, eq=False)
class Flat(Pattern):
    """Constant intensity ``level`` (white 1, black 0, mid 0.5)."""

    kind: ClassVar[str] = "flat"
    KEYS: ClassVar[tuple[str, ...]] = ("level",)
    MAIN_KEYS: ClassVar[tuple[str, ...]] = KEYS

    level: float

    def validate(self) -> None:
        _check_number("level", self.level)


@dataclass(frozen=True, kw_only=True, eq=False)
class Grid(Pattern):
    """Alignment grid with a centre crosshair: projector-only, not a capture-format v1 kind.

    Lines ``line_px`` wide every ``pitch_px`` pixels along both axes, and two lines
    ``crosshair_px`` wide, all through the projector's centre pixel (``width // 2``,
    ``height // 2``); lines at ``level``, the rest at ``background``. In integer pixels a
    column ``i`` is on a grid line when ``(i - width // 2 + line_px // 2) mod pitch_px < line_px``
    (rows alike), so the shader draws exactly the same pixels. Captures refuse it (the capture
    store names it); the projector and the console show it to align the rig.
    """

    kind: ClassVar[str] = "grid"
    KEYS: ClassVar[tuple[str, ...]] = ("pitch_px", "line_px", "crosshair_px", "level", "background")
    MAIN_KEYS: ClassVar[tuple[str, ...]] = ("pitch_px",)

    pitch_px: int
    line_px: int = 2
    crosshair_px: int = 6
    level: float = 1.0
    background: float = 0.0

    def validate(self) -> None:
        _check_int("pitch_px", self.pitch_px, 2)
        _check_int("line_px", self.line_px, 1)
        if self.line_px >= self.pitch_px:
            raise PatternError("line_px", f"1 .. {self.pitch_px - 1} (pitch_px = {self.pitch_px})", self.line_px)
        _check_int("crosshair_px", self.crosshair_px, 0)
        _check_number("level", self.level)
        _check_number("background", self.background)


PATTERN_TYPES: dict[str, type[Pattern]] = {
    cls.kind: cls for cls in (Sinusoid, SpeckleSinusoid, Gray, Binary, Flat, Grid)
}
PATTERN_KINDS = tuple(PATTERN_TYPES)
# Kinds a projector shows but a capture never holds (capture-format v1 does not define them).
PROJECTOR_ONLY_KINDS = (Grid.kind,)
CAPTURE_KINDS = tuple(kind for kind in PATTERN_KINDS if kind not in PROJECTOR_ONLY_KINDS)

# Keys of a pattern entry that change what is projected: two captures are comparable only if
# these agree pattern by pattern (provenance and other extra keys may differ).
PROJECTION_KEYS = ("kind",) + tuple(dict.fromkeys(key for cls in PATTERN_TYPES.values() for key in cls.KEYS))


def parse_pattern(entry: Any) -> Pattern:
    """The typed pattern of one capture.json ``patterns`` entry; :class:`PatternError` if invalid."""
    if isinstance(entry, Pattern):
        return entry
    if not isinstance(entry, Mapping):
        raise PatternError("", "a mapping (a capture.json pattern entry)", type(entry).__name__)
    kind = entry.get("kind", _MISSING)
    if kind is _MISSING:
        raise PatternError("kind")
    cls = PATTERN_TYPES.get(kind) if isinstance(kind, str) else None
    if cls is None:
        raise PatternError("kind", f"one of {', '.join(PATTERN_KINDS)}", kind)
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    for key in required:
        if key not in entry:
            raise PatternError(key)
    own = {key: entry[key] for key in cls.KEYS if key in entry}
    extra = {key: value for key, value in entry.items() if key != "kind" and key not in cls.KEYS}
    return cls(**own, extra=extra, source_keys=tuple(entry))


def as_pattern(pattern: Pattern | Mapping[str, Any]) -> Pattern:
    """``pattern`` itself if typed, else :func:`parse_pattern` of the entry."""
    return parse_pattern(pattern)


def same_projection(a: Pattern | Mapping[str, Any], b: Pattern | Mapping[str, Any]) -> bool:
    """True when two patterns project the same image (extra keys and key order aside)."""
    pa, pb = as_pattern(a), as_pattern(b)
    return type(pa) is type(pb) and pa._values() == pb._values()


# --------------------------------------------------------------------------- intensities


def sinusoid_shift(pattern: Sinusoid | Mapping[str, Any]) -> float:
    """Phase shift of one sinusoid frame in radians: ``shift_rad`` if given, else 2 pi j / J."""
    sinusoid = as_pattern(pattern)
    if not isinstance(sinusoid, Sinusoid):
        raise PatternError("kind", "'sinusoid' or 'speckle-sinusoid'", sinusoid.kind)
    return sinusoid.shift


def sinusoid_intensity(pattern: Sinusoid | Mapping[str, Any], u: np.ndarray, extent: float) -> np.ndarray:
    """Intensity of a ``sinusoid`` (or the fringe of a ``speckle-sinusoid``) at coordinate ``u``.

    Parameters
    ----------
    pattern : Sinusoid or mapping
        A sinusoid pattern (its capture.json entry is accepted too).
    u : array
        Projector coordinate in pixels along the pattern's axis.
    extent : float
        Projector size ``W`` along the axis, in pixels.

    Returns
    -------
    array like ``u``: offset + amplitude cos(2 pi f u / W + phase_rad + shift).
    """
    sinusoid = as_pattern(pattern)
    if not isinstance(sinusoid, Sinusoid):
        raise PatternError("kind", "'sinusoid' or 'speckle-sinusoid'", sinusoid.kind)
    phase = 2.0 * np.pi * float(sinusoid.frequency) * np.asarray(u, dtype=np.float64) / extent
    phase += float(sinusoid.phase_rad) + sinusoid.shift
    return float(sinusoid.offset) + float(sinusoid.amplitude) * np.cos(phase)


def gray_stripe_index(u: np.ndarray, extent: float, bits: int, cell_px: float | None = None) -> np.ndarray:
    """Index of the code cell (0 .. 2**bits - 1) that projector coordinate ``u`` lies in.

    Cells are ``cell_px`` wide (default ``extent / 2**bits``); coordinates past the last cell
    read the last one.
    """
    stripes = 1 << bits
    coord = np.asarray(u, dtype=np.float64)
    cells = coord * stripes / extent if cell_px is None else coord / float(cell_px)
    return np.clip(np.floor(cells), 0, stripes - 1).astype(np.int64)


def stripe_code(stripe: np.ndarray, binary: bool = False) -> np.ndarray:
    """The code word a cell carries: Gray ``s ^ (s >> 1)``, or ``s`` itself for a plain binary code."""
    return stripe if binary else stripe ^ (stripe >> 1)


def gray_intensity(pattern: Gray | Mapping[str, Any], u: np.ndarray, extent: float) -> np.ndarray:
    """Intensity (0 or 1) of one Gray- or binary-code bit plane; ``bit`` 0 is the most significant.

    The axis is cut into cells (:meth:`Gray.cell_px`); cell ``s`` carries code word
    :func:`stripe_code` of ``s``, and plane ``bit`` shows its bit ``bits - 1 - bit``.
    ``inverted`` gives the complementary (negative) image.
    """
    code_pattern = as_pattern(pattern)
    if not isinstance(code_pattern, Gray):
        raise PatternError("kind", "'gray' or 'binary'", code_pattern.kind)
    stripe = gray_stripe_index(u, extent, code_pattern.bits, code_pattern.cell_px(extent))
    code = stripe_code(stripe, isinstance(code_pattern, Binary))
    value = ((code >> (code_pattern.bits - 1 - code_pattern.bit)) & 1).astype(np.float64)
    return 1.0 - value if code_pattern.inverted else value


def grid_intensity(
    pattern: Grid | Mapping[str, Any], u: np.ndarray, v: np.ndarray, projector_size: tuple[int, int]
) -> np.ndarray:
    """Intensity of the alignment :class:`Grid` at projector coordinates (u, v); see the class for the rule."""
    grid = as_pattern(pattern)
    if not isinstance(grid, Grid):
        raise PatternError("kind", "'grid'", grid.kind)
    width, height = (int(projector_size[0]), int(projector_size[1]))
    cols = np.clip(np.floor(np.asarray(u, dtype=np.float64)), 0, width - 1).astype(np.int64) - width // 2
    rows = np.clip(np.floor(np.asarray(v, dtype=np.float64)), 0, height - 1).astype(np.int64) - height // 2
    pitch, line, cross = int(grid.pitch_px), int(grid.line_px), int(grid.crosshair_px)
    on_grid = ((cols + line // 2) % pitch < line) | ((rows + line // 2) % pitch < line)
    on_cross = ((cols + cross // 2) >= 0) & ((cols + cross // 2) < cross)
    on_cross |= ((rows + cross // 2) >= 0) & ((rows + cross // 2) < cross)
    return np.where(on_grid | on_cross, float(grid.level), float(grid.background))


def speckle_sinusoid_intensity(
    pattern: SpeckleSinusoid | Mapping[str, Any], u: np.ndarray, v: np.ndarray, projector_size: tuple[int, int]
) -> np.ndarray:
    """Intensity in [0, 1] of a ``speckle-sinusoid`` pattern at projector coordinates (u, v).

    I = (1 - g) * (offset + amplitude cos(2 pi f u / W + phase)) + g * Z(floor v, floor u), with
    ``g`` = ``speckle_gain`` and ``Z`` = :func:`processing.projection.speckle.speckle_field` of the whole
    projector frame with the pattern's ``seed`` and ``dot_px``. Scaling the sinusoid by (1 - g)
    keeps the sum inside [0, 1] whenever the sinusoid is; in the thesis' notation
    A = (1 - g) offset, B = (1 - g) amplitude, C = g. The speckle field is fixed to the
    projector's pixels: it does not move with ``step`` or ``axis``.
    """
    speckle = as_pattern(pattern)
    if not isinstance(speckle, SpeckleSinusoid):
        raise PatternError("kind", "'speckle-sinusoid'", speckle.kind)
    width, height = (int(projector_size[0]), int(projector_size[1]))
    gain = float(speckle.speckle_gain)
    coord, extent = (u, width) if speckle.axis == "x" else (v, height)
    fringe = sinusoid_intensity(speckle, coord, extent)
    field_z = cached_speckle_field(width, height, int(speckle.seed), int(speckle.dot_px))
    cols = np.clip(np.floor(np.asarray(u, dtype=np.float64)), 0, width - 1).astype(np.intp)
    rows = np.clip(np.floor(np.asarray(v, dtype=np.float64)), 0, height - 1).astype(np.intp)
    return (1.0 - gain) * fringe + gain * field_z[rows, cols]


def pattern_intensity(
    pattern: Pattern | Mapping[str, Any], u: np.ndarray, v: np.ndarray, projector_size: tuple[int, int]
) -> np.ndarray:
    """Projected intensity in [0, 1] of any pattern kind at projector pixel coordinates (u, v).

    Parameters
    ----------
    pattern : Pattern or mapping
        A pattern (or its capture.json entry).
    u, v : arrays of equal shape
        Projector column and row coordinates in pixels (pixel centres at k + 0.5).
    projector_size : (width, height)
        Projector resolution in pixels.
    """
    model = as_pattern(pattern)
    width, height = projector_size
    if isinstance(model, SpeckleSinusoid):
        return speckle_sinusoid_intensity(model, u, v, projector_size)
    if isinstance(model, Flat):
        return np.full(np.shape(u), float(model.level))
    if isinstance(model, Grid):
        return grid_intensity(model, u, v, projector_size)
    assert isinstance(model, (Sinusoid, Gray))
    coord, extent = (u, width) if model.axis == "x" else (v, height)
    if isinstance(model, Sinusoid):
        return sinusoid_intensity(model, coord, extent)
    return gray_intensity(model, coord, extent)


def pattern_image(pattern: Pattern | Mapping[str, Any], projector_size: tuple[int, int]) -> np.ndarray:
    """The full projector frame of a pattern, (height, width) float32 in [0, 1], sampled at pixel centres."""
    width, height = projector_size
    u = np.arange(width, dtype=np.float64) + 0.5
    v = np.arange(height, dtype=np.float64) + 0.5
    uu, vv = np.meshgrid(u, v)
    return pattern_intensity(pattern, uu, vv, projector_size).astype(np.float32)
