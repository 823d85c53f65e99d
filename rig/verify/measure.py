"""The VDI/VDE 2634-2 quantities of one scanned artefact position: PF and PS, SD, or F.

Input is a processed scan: the (H, W, 3) point grid in mm and its validity mask. The artefact is
found in the cloud (:mod:`rig.verify.fits`), fitted as the guideline's least-squares element, and
compared with its calibrated value:

- sphere: PF = range of the radial residuals, PS = fitted diameter - calibrated diameter;
- ball bar: SD = distance of the fitted centres - calibrated distance (spheres with free radius);
- plane: F = range of the signed distances to the fitted plane.

Points at the reference plane (below half of :data:`rig.verify.guideline.CLEARANCE_MM`) are the
background of the scan and never the artefact; nor is the rim of an artefact's image
(:data:`RIM_PX`), whose pixels see part artefact, part background.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from rig.verify.artefacts import Artefacts
from rig.verify.fits import FormFit, find_plane, find_sphere, fit_form
from rig.verify.guideline import CLEARANCE_MM, Placement

# Pixels this close (in pixels) to the edge of an artefact's image straddle it: not its surface.
RIM_PX = 2


class ArtefactNotFound(ValueError):
    """The scan holds no artefact of the expected kind and size."""


@dataclass
class PositionResult:
    """What one position gave: its quantities (mm), fits, residual maps (cropped, NaN off the artefact)."""

    placement: Placement
    values: dict[str, float]
    fits: list[FormFit]
    maps: list[np.ndarray] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def as_dict(self) -> dict[str, object]:
        return {
            "name": self.placement.name,
            "where": self.placement.where,
            "values_mm": dict(self.values),
            "fits": [
                {
                    "kind": f.kind,
                    "centre_mm": [round(float(v), 5) for v in f.centre],
                    "radius_mm": None if f.kind == "plane" else round(f.radius_mm, 5),
                    "points_used": f.used,
                    "points_trimmed": f.trimmed,
                    "points_excluded": f.excluded,
                    "residual_rms_mm": round(float(np.sqrt(np.mean(f.residuals**2))), 5),
                }
                for f in self.fits
            ],
            "notes": list(self.notes),
        }


def _tolerance(diameter_mm: float) -> float:
    """How far from a candidate a point may lie and still vote for it: 1 mm, or 2 % of the diameter."""
    return max(1.0, 0.02 * diameter_mm)


def _residual_map(grid: np.ndarray, chosen: np.ndarray, fit: FormFit) -> np.ndarray:
    """Signed residuals (mm) of the chosen pixels against the fit, cropped to their bounding box."""
    rows, cols = np.nonzero(chosen)
    if not len(rows):
        return np.full((1, 1), np.nan)
    box = grid[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    keep = chosen[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    if fit.kind == "sphere":
        res = np.linalg.norm(box - fit.centre, axis=-1) - fit.radius_mm
    else:
        res = (box - fit.centre) @ fit.normal
    limit = np.max(np.abs(fit.residuals)) if fit.residuals.size else 0.0
    return np.where(keep & (np.abs(res) <= limit), res, np.nan)


def _candidates(points: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Pixels that may hold the artefact: valid, finite, clear of the reference plane behind it."""
    finite = mask & np.isfinite(points).all(axis=-1)
    return finite & (np.where(finite, points[..., 2], 0.0) > CLEARANCE_MM / 2)


def _sphere_pixels(grid: np.ndarray, free: np.ndarray, diameter_mm: float) -> np.ndarray:
    """Pixels of the best-supported sphere of ``diameter_mm`` among the ``free`` pixels."""
    pts = grid[free]
    if len(pts) < 50:
        raise ArtefactNotFound(f"{len(pts)} valid points above the reference plane: no sphere to measure")
    try:
        on = find_sphere(pts, diameter_mm / 2, _tolerance(diameter_mm))
    except ValueError as exc:
        raise ArtefactNotFound(str(exc)) from None
    chosen = np.zeros_like(free)
    chosen[free] = on
    return _inner(chosen)


def _inner(chosen: np.ndarray) -> np.ndarray:
    """``chosen`` without its rim of :data:`RIM_PX` pixels (mixed pixels at the artefact's edge)."""
    return ndimage.binary_erosion(chosen, iterations=RIM_PX)


def measure_sphere(grid: np.ndarray, mask: np.ndarray, placement: Placement, artefacts: Artefacts) -> PositionResult:
    """PF and PS of the sphere in one scan."""
    chosen = _sphere_pixels(grid, _candidates(grid, mask), artefacts.sphere_diameter_mm)
    fit = fit_form("sphere", grid[chosen])
    values = {"PF": fit.form_range_mm, "PS": 2 * fit.radius_mm - artefacts.sphere_diameter_mm}
    return PositionResult(placement, values, [fit], [_residual_map(grid, chosen, fit)], _fit_notes([fit]))


def measure_ball_bar(grid: np.ndarray, mask: np.ndarray, placement: Placement, artefacts: Artefacts) -> PositionResult:
    """SD of the ball bar in one scan: both spheres found, fitted with free radius, centres compared."""
    free = _candidates(grid, mask)
    diameter = artefacts.ball_bar_sphere_diameter_mm
    fits, maps = [], []
    for _ in range(2):
        chosen = _sphere_pixels(grid, free, diameter)
        fit = fit_form("sphere", grid[chosen])
        fits.append(fit)
        maps.append(_residual_map(grid, chosen, fit))
        # the found ball and its part of the bar are out of the running for the second sphere
        near = np.linalg.norm(np.where(free[..., None], grid, np.inf) - fit.centre, axis=-1) < 1.5 * fit.radius_mm
        free = free & ~near
    distance = float(np.linalg.norm(fits[0].centre - fits[1].centre))
    notes = _fit_notes(fits)
    if abs(distance - artefacts.ball_bar_length_mm) > 0.25 * artefacts.ball_bar_length_mm:
        raise ArtefactNotFound(
            f"the two spheres found are {distance:.1f} mm apart, expected about {artefacts.ball_bar_length_mm:g} mm"
        )
    return PositionResult(placement, {"SD": distance - artefacts.ball_bar_length_mm}, fits, maps, notes)


def measure_plane(grid: np.ndarray, mask: np.ndarray, placement: Placement, artefacts: Artefacts) -> PositionResult:
    """F of the plane in one scan."""
    free = _candidates(grid, mask)
    pts = grid[free]
    if len(pts) < 50:
        raise ArtefactNotFound(f"{len(pts)} valid points above the reference plane: no plane to measure")
    chosen = np.zeros_like(free)
    chosen[free] = find_plane(pts, _tolerance(0.0))
    chosen = _inner(chosen)
    fit = fit_form("plane", grid[chosen])
    notes = _fit_notes([fit])
    if artefacts.plane_flatness_mm > 0:
        notes.append(f"the plane's calibrated flatness {artefacts.plane_flatness_mm:g} mm is part of F")
    return PositionResult(placement, {"F": fit.form_range_mm}, [fit], [_residual_map(grid, chosen, fit)], notes)


MEASURES = {"sphere": measure_sphere, "ball-bar": measure_ball_bar, "plane": measure_plane}


def measure(grid: np.ndarray, mask: np.ndarray, placement: Placement, artefacts: Artefacts) -> PositionResult:
    """The quantities of ``placement``'s artefact in a processed scan (points (H, W, 3) mm, mask (H, W))."""
    grid = np.asarray(grid, dtype=np.float64)
    if grid.ndim != 3 or grid.shape[-1] != 3 or grid.shape[:2] != np.shape(mask):
        raise ValueError(f"points: expected (H, W, 3) matching the mask {np.shape(mask)}, found {grid.shape}")
    return MEASURES[placement.kind](grid, np.asarray(mask, dtype=bool), placement, artefacts)


def _fit_notes(fits: list[FormFit]) -> list[str]:
    notes = []
    for fit in fits:
        total = fit.used + fit.trimmed + fit.excluded
        notes.append(
            f"{fit.kind}: {fit.used} points used of {total}; {fit.trimmed} trimmed as not the artefact, "
            f"{fit.excluded} ({100 * fit.excluded / max(total, 1):.2f} %) left out as largest residuals"
        )
    return notes
