"""Which fringe axis (or both) a capture is processed along, why, and how well each is conditioned.

A capture may hold sinusoids along x (vertical fringes, coding projector columns) and along y
(horizontal fringes, coding rows). What each carries depends on the rig: on a rig with a mostly
vertical baseline the column fringes carry metres of depth per projector pixel and the row fringes
fractions of a millimetre. The rule (:func:`choose_axes`):

- ``--axis x`` or ``y``: that axis; the report gives each axis's depth (height) per projector
  pixel, and a note warns when the chosen one's is :data:`ILL_CONDITIONED_RATIO` times the other
  axis's or more;
- ``--axis both``: every pixel from both axes, a camera-projector (stereo) model triangulating it
  from both projector coordinates, a reference-plane model fitted on both axes taking the
  inverse-variance mean of the two heights; refused in one line with any other calibration;
- default: the only axis the capture has; with both captured and a stereo model, both
  (:mod:`processing.geometry.axis_fusion`); with a reference-plane model fitted on both axes, the
  axis with the larger sensitivity ``2 pi f0 |d0| / l0`` at its highest captured frequency
  (:mod:`calibration.plane_axes`); with a reference-plane or polynomial model fitted on one axis,
  that axis (``fringe_axis``), the one whose phase it converts to height; otherwise the first axis
  in the capture, as before.

The choice and its reason go to report.json (``methods.fringe_axis``, ``methods.axis_choice``)
and to the summary line.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from calibration.plane_axes import height_per_projector_pixel_mm, plane_axes, sensitivity_rad_per_mm
from calibration.stereo import STEREO
from calibration.store import Calibration
from processing.geometry.axis_fusion import depth_per_projector_pixel
from rig.errors import ProcessingError
from rig.pipeline.plan import PatternGroups

AXES = ("x", "y", "both")
ONLY_AXIS = "the only axis with fringes in the capture"
# a chosen axis whose depth per projector pixel is this many times the other's gets a warning
ILL_CONDITIONED_RATIO = 3.0


@dataclass(frozen=True)
class AxisChoice:
    """The axes to process (one, or ``("x", "y")``) and the reason, for the report."""

    axes: tuple[str, ...]
    why: str
    requested: str | None

    @property
    def name(self) -> str:
        """``x``, ``y`` or ``both`` (report.json's ``methods.fringe_axis``)."""
        return "both" if len(self.axes) == 2 else self.axes[0]


def captured_axes(groups: PatternGroups) -> list[str]:
    """The axes with sinusoid (or single-shot) patterns, in capture order."""
    seen: list[str] = []
    for group in [*groups.sinusoids, *groups.single_shot]:
        if group.axis not in seen:
            seen.append(group.axis)
    return seen


def choose_axes(
    groups: PatternGroups, calibration: Calibration | None, requested: str | None, where: str
) -> AxisChoice:
    """The axes to process and why (ProcessingError when the request cannot be met)."""
    captured = captured_axes(groups)
    if not captured:
        raise ProcessingError(f"{where}: no sinusoid pattern: nothing to compute a phase from")
    stereo = calibration is not None and calibration.model == STEREO
    planes = plane_axes(calibration) if calibration is not None else {}
    if requested == "both":
        _check_both(calibration, planes, stereo)
        missing = [a for a in ("x", "y") if a not in captured]
        if missing:
            raise ProcessingError(f"--axis both: {where} has no sinusoid patterns along {missing[0]}")
        return AxisChoice(("x", "y"), "asked for (--axis both)", requested)
    if requested in ("x", "y"):
        return AxisChoice((requested,), f"asked for (--axis {requested})", requested)
    if len(captured) == 1:
        return AxisChoice((captured[0],), ONLY_AXIS, requested)
    if stereo and {"x", "y"} <= set(captured) and _phase_shifted_both(groups):
        return AxisChoice(
            ("x", "y"),
            "fringes on both axes and a camera-projector calibration: each pixel from both projector "
            "coordinates, weighted by their predicted noise",
            requested,
        )
    if calibration is not None and len(planes) == 2 and {"x", "y"} <= set(captured):
        sensitivity = plane_sensitivities(calibration, groups)
        best = max(sensitivity, key=lambda axis: sensitivity[axis])
        other = "y" if best == "x" else "x"
        return AxisChoice(
            (best,),
            f"the larger sensitivity of the reference-plane calibration's two axes (2 pi f0 |d0| / l0 at the "
            f"highest captured frequency): {sensitivity[best]:.3g} rad/mm along {best} against "
            f"{sensitivity[other]:.3g} along {other}",
            requested,
        )
    if calibration is not None and len(planes) == 1 and next(iter(planes)) in captured:
        fitted = next(iter(planes))
        why = f"the axis the {calibration.model!r} calibration was fitted on"
        if set(captured) == {"x", "y"}:
            why += f", the only one it converts (it holds no fit along {'y' if fitted == 'x' else 'x'})"
        return AxisChoice((fitted,), why, requested)
    why = "no calibration to choose by" if calibration is None else "the calibration names none"
    return AxisChoice((captured[0],), f"the first axis in the capture ({why})", requested)


def _check_both(calibration: Calibration | None, planes: dict[str, dict[str, float]], stereo: bool) -> None:
    """``--axis both`` needs a stereo model or a reference-plane model fitted on both axes (ProcessingError)."""
    if stereo or len(planes) == 2:
        return
    if calibration is None:
        model = "no calibration converts a phase to height"
    elif planes:
        model = (
            f"{calibration.where} converts fringes along {next(iter(planes))} only (the {calibration.model!r} model "
            "needs its own fit of each axis: calibrate with fringes on both axes)"
        )
    else:
        model = f"the {calibration.model!r} calibration names no fitted axis"
    raise ProcessingError(
        f"--axis both: needs a camera-projector (stereo) calibration or a reference-plane calibration fitted on "
        f"both axes; {model}; choose --axis x or y"
    )


def plane_sensitivities(calibration: Calibration, groups: PatternGroups) -> dict[str, float]:
    """Each captured axis's sensitivity (rad per mm of height) at its highest frequency (reference-plane model)."""
    planes = plane_axes(calibration)
    out = {}
    for axis, numbers in planes.items():
        frequencies = [g.frequency for g in [*groups.sinusoids, *groups.single_shot] if g.axis == axis]
        if frequencies:
            out[axis] = sensitivity_rad_per_mm(numbers, max(frequencies))
    return out


def plane_conditioning(calibration: Calibration, projector_size: tuple[int, int]) -> dict[str, float]:
    """Height (mm) per projector pixel near the reference plane along each axis the calibration converts."""
    extents = {"x": projector_size[0], "y": projector_size[1]}
    return {
        axis: round(height_per_projector_pixel_mm(numbers, extents[axis]), 4)
        for axis, numbers in plane_axes(calibration).items()
    }


def _phase_shifted_both(groups: PatternGroups) -> bool:
    """Both axes have phase-shifted sinusoids (whose noise the fusion's weights need)."""
    return all(any(g.steps >= 3 for g in groups.along(axis)) for axis in ("x", "y"))


def stereo_conditioning(calibration: Calibration, points: np.ndarray) -> dict[str, float]:
    """Median depth per projector pixel (mm) along x and y at the measured points (stereo model)."""
    from calibration.models import stereo_model

    model = stereo_model(calibration)
    per_x, per_y = depth_per_projector_pixel(points, model.rotation, model.translation_mm, model.projector_matrix)
    return {"x": round(per_x, 4), "y": round(per_y, 4)}


def conditioning_note(choice: AxisChoice, per_pixel: dict[str, float]) -> str | None:
    """A warning when an explicitly chosen axis carries much more depth per projector pixel than the other."""
    if choice.requested not in ("x", "y"):
        return None
    chosen = choice.requested
    other = "y" if chosen == "x" else "x"
    mine, theirs = per_pixel.get(chosen, float("nan")), per_pixel.get(other, float("nan"))
    if not (np.isfinite(mine) and np.isfinite(theirs)) or mine < ILL_CONDITIONED_RATIO * theirs:
        return None
    return (
        f"--axis {chosen}: ill-conditioned on this rig: {mine:.3g} mm of depth per projector pixel along {chosen}, "
        f"against {theirs:.3g} mm along {other} (a phase error of 1/100 pixel is {mine / 100:.3g} mm of depth); "
        f"use --axis {other} or both if the capture has those fringes"
    )
