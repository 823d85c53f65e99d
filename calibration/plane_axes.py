"""The fringe axes a reference-plane or polynomial calibration converts, and each axis's sensitivity.

Eq. 1.15 turns the phase difference to the reference plane into height with ``l0``, ``d0`` and
``f0``, where ``d0`` is the share of the camera-projector baseline across the fringes and ``f0``
their frequency on the plane: fringes along x see the baseline's x share, fringes along y its y
share. A calibration fitted on one axis (``fringe_axis``) therefore converts that axis alone. One
fitted on both (the reference plane and the planes captured with fringes on both axes) holds each
axis's own numbers in ``axes``::

    "axes": {"x": {"l0_mm": ..., "d0_mm": ..., "f0_per_mm": ..., "f0_frequency": ...}, "y": {...}}

Near the reference plane a height h moves the phase by ``2 pi f0 d0 h / l0``, so each axis's
sensitivity (rad per mm of height) and height per projector pixel are

    S = 2 pi f0(f) |d0| / l0,   f0(f) = f0_per_mm f / f0_frequency
    dh / du = l0 f0_frequency / (E f0_per_mm |d0|)        (E: the projector extent along the axis)

and the axis with the larger S has the smaller height error for the same phase noise. A
polynomial calibration's per-pixel coefficients belong to the axis it was fitted on: it converts
that one only.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

from calibration.errors import CalibrationError
from calibration.polynomial import POLYNOMIAL
from calibration.store import REFERENCE_PLANE, Calibration

AXES_KEY = "axes"
AXIS_FIELDS = ("l0_mm", "d0_mm", "f0_per_mm", "f0_frequency")


def plane_axes(calibration: Calibration) -> dict[str, dict[str, float]]:
    """Each axis a reference-plane or polynomial calibration converts, with its l0, d0, f0 (CalibrationError
    naming the field when ``axes`` is malformed). Without ``axes``, the ``fringe_axis`` its top-level
    numbers were fitted on; empty for other models and for a calibration that names no axis."""
    if calibration.model not in (REFERENCE_PLANE, POLYNOMIAL):
        return {}
    fields = calibration.to_dict()
    fitted = fields.get("fringe_axis")
    top = {key: getattr(calibration, key) for key in AXIS_FIELDS}
    axes = fields.get(AXES_KEY)
    if axes is None or calibration.model == POLYNOMIAL:
        complete = fitted in ("x", "y") and None not in top.values()
        return {str(fitted): {key: float(value) for key, value in top.items() if value is not None}} if complete else {}
    if not isinstance(axes, dict) or not axes or not set(axes) <= {"x", "y"}:
        raise CalibrationError(
            f"{calibration.where}: {AXES_KEY}: expected an object with keys x and/or y, found {_shown(axes)}"
        )
    out: dict[str, dict[str, float]] = {}
    for name, numbers in axes.items():
        out[name] = {key: _axis_number(calibration, name, numbers, key) for key in AXIS_FIELDS}
    return out


def _axis_number(calibration: Calibration, axis: str, numbers: Any, key: str) -> float:
    value = numbers.get(key) if isinstance(numbers, dict) else None
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (key != "d0_mm" and not value > 0) or value == 0:  # type: ignore[operator]
        rule = "a non-zero number" if key == "d0_mm" else "a positive number"
        raise CalibrationError(f"{calibration.where}: {AXES_KEY}.{axis}.{key}: expected {rule}, found {_shown(value)}")
    return float(value)  # type: ignore[arg-type]


def _shown(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def for_axis(calibration: Calibration, axis: str) -> Calibration:
    """The calibration converting fringes along ``axis``: that axis's l0, d0, f0 at the top level and
    ``fringe_axis`` = ``axis`` (unchanged when it holds no per-axis numbers)."""
    numbers = plane_axes(calibration).get(axis)
    if numbers is None or AXES_KEY not in calibration.extra or calibration.model == POLYNOMIAL:
        return calibration
    return replace(
        calibration,
        l0_mm=numbers["l0_mm"],
        d0_mm=numbers["d0_mm"],
        f0_per_mm=numbers["f0_per_mm"],
        f0_frequency=numbers["f0_frequency"],
        extra={**calibration.extra, "fringe_axis": axis},
    )


def sensitivity_rad_per_mm(numbers: dict[str, float], frequency: float) -> float:
    """Phase change (rad) per mm of height near the reference plane of fringes at ``frequency``: 2 pi f0 |d0| / l0."""
    f0 = numbers["f0_per_mm"] * float(frequency) / numbers["f0_frequency"]
    return 2.0 * math.pi * f0 * abs(numbers["d0_mm"]) / numbers["l0_mm"]


def height_per_projector_pixel_mm(numbers: dict[str, float], extent: float) -> float:
    """Height (mm) one projector pixel of phase is worth near the reference plane: l0 f0_frequency / (E f0_per_mm |d0|)."""
    return numbers["l0_mm"] * numbers["f0_frequency"] / (float(extent) * numbers["f0_per_mm"] * abs(numbers["d0_mm"]))
