"""Captures taken at several exposures: how capture.json records them, and reading that back.

A multi-exposure (HDR) capture is a version 1 capture whose pattern list is one base sequence
repeated once per exposure, each exposure's full sequence in turn, every entry carrying the
exposure its frame was planned at (``"exposure_us"``, an extra key of the pattern)::

    patterns[k * N + i] = base pattern i at exposures_us[k]      (k = 0 .. E-1, i = 0 .. N-1)

Each pattern still has exactly one frame; the frame's own ``exposure_us`` is what the camera
reported. A capture without ``exposure_us`` on its patterns is a single-exposure capture, read as
before. :func:`exposure_sets` checks the structure and gives the base sequence and the frame
index of every (exposure, base pattern).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from processing.projection.patterns import Pattern, as_pattern, parse_pattern, same_projection
from rig.errors import CaptureError

EXPOSURE_KEY = "exposure_us"


@dataclass(frozen=True)
class ExposureSets:
    """The exposures of a capture and where each (exposure, base pattern) frame sits."""

    exposures_us: tuple[float, ...]  # in capture order; one entry for a single-exposure capture
    base: list[Pattern]  # the sequence projected at each exposure (without the exposure key)
    indices: tuple[tuple[int, ...], ...]  # indices[k][i]: pattern index of base pattern i at exposure k

    @property
    def multiple(self) -> bool:
        """True when the capture holds more than one exposure."""
        return len(self.exposures_us) > 1


def with_exposures(patterns: Sequence[Mapping[str, Any]], exposures_us: Sequence[float]) -> list[dict[str, Any]]:
    """The pattern entries of a scan at several exposures: each exposure's full sequence in turn.

    One exposure (or none) gives the patterns unchanged, a single-exposure capture.
    """
    if len(exposures_us) <= 1:
        return [dict(p) for p in patterns]
    return [{**dict(p), EXPOSURE_KEY: _plain(e)} for e in exposures_us for p in patterns]


def _plain(value: float) -> int | float:
    return int(value) if float(value).is_integer() else float(value)


def planned_exposure(pattern: Pattern | Mapping[str, Any]) -> Any:
    """The exposure a pattern entry was planned at (None when it names none)."""
    extra = as_pattern(pattern).extra
    return extra.get(EXPOSURE_KEY)


def exposure_sets(patterns: Sequence[Pattern | Mapping[str, Any]], where: str = "capture.json") -> ExposureSets:
    """Split a capture's patterns into exposures of one base sequence; CaptureError if they do not form one.

    Without ``exposure_us`` on any pattern: one exposure (``nan``: the capture does not say which)
    holding every pattern.
    """
    models = [as_pattern(p) for p in patterns]
    planned = [m.extra.get(EXPOSURE_KEY) for m in models]
    if all(value is None for value in planned):
        return ExposureSets((float("nan"),), models, (tuple(range(len(models))),))
    order: list[float] = []
    for i, value in enumerate(planned):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0 or value == float("inf"):
            raise CaptureError(
                f"{where}: patterns[{i}].{EXPOSURE_KEY}: expected a positive exposure in microseconds on every "
                f"pattern (or on none), found {value!r}"
            )
        if not order or order[-1] != float(value):
            if float(value) in order:
                raise CaptureError(
                    f"{where}: patterns[{i}].{EXPOSURE_KEY}: expected each exposure's patterns together "
                    f"(one full sequence per exposure), found {value:g} again after other exposures"
                )
            order.append(float(value))
    count = len(models) // len(order)
    if count * len(order) != len(models):
        raise CaptureError(
            f"{where}: patterns: expected the same sequence at each of {len(order)} exposures, "
            f"found {len(models)} patterns"
        )
    base = models[:count]
    for k in range(1, len(order)):
        for i in range(count):
            index = k * count + i
            if planned[index] != order[k] or not same_projection(models[index], base[i]):
                raise CaptureError(
                    f"{where}: patterns[{index}]: expected base pattern {i} at exposure {order[k]:g} us "
                    "(each exposure's full sequence in the same order)"
                )
    indices = tuple(tuple(range(k * count, (k + 1) * count)) for k in range(len(order)))
    plain = [parse_pattern({key: v for key, v in m.to_dict().items() if key != EXPOSURE_KEY}) for m in base]
    return ExposureSets(tuple(order), plain, indices)


def describe_exposures(patterns: Sequence[Pattern | Mapping[str, Any]], where: str = "capture.json") -> str | None:
    """One line naming a multi-exposure capture's exposures (None for a single exposure)."""
    sets = exposure_sets(patterns, where)
    if not sets.multiple:
        return None
    listed = ", ".join(f"{e:g}" for e in sets.exposures_us)
    return f"{len(sets.exposures_us)} exposures ({listed} us) of {len(sets.base)} patterns each"
