"""Test artefacts seen by the simulated camera: spheres, a ball bar's bar, flat plates, ray-cast.

The reference-plane rig's camera has its pupil at ``l0`` above the centre of its view; the pixel
at plane coordinates (x, y) looks along the ray from the pupil through (x, y, 0). A scene is the
height of the first surface each ray meets (0: the reference plane behind). Heights made this way
turn back into exactly these surfaces through the pipeline's point formula
X = x (l0 - h) / l0, so a sphere stays a sphere in the measured cloud: what VDI/VDE 2634-2
artefacts need. The surfaces are matte (the camera's reflectivity applies unchanged).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Sphere:
    centre: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Cylinder:
    """A bar from ``start`` to ``end`` (mm) of ``radius``, without end caps (spheres cover them)."""

    start: tuple[float, float, float]
    end: tuple[float, float, float]
    radius: float


@dataclass(frozen=True)
class Plate:
    """A flat rectangle: centre, unit axis along its length, unit axis along its width, sizes (mm)."""

    centre: tuple[float, float, float]
    along: tuple[float, float, float]
    across: tuple[float, float, float]
    length: float
    width: float


Shape = Sphere | Cylinder | Plate


def _rays(height: int, width: int, pixel_mm: float, l0_mm: float) -> tuple[np.ndarray, np.ndarray]:
    """Pupil (3,) and ray directions (H*W, 3) through each pixel's point on the reference plane."""
    if height < 1 or width < 1 or not pixel_mm > 0 or not l0_mm > 0:
        raise ValueError(
            f"camera: expected positive size, pixel_mm and l0_mm, found {width}x{height}, {pixel_mm}, {l0_mm}"
        )
    x = (np.arange(width) - (width - 1) / 2.0) * pixel_mm
    y = (np.arange(height) - (height - 1) / 2.0) * pixel_mm
    gx, gy = np.meshgrid(x, y)
    pupil = np.array([0.0, 0.0, l0_mm])
    directions = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, -l0_mm)], axis=1)
    return pupil, directions


def _sphere_t(pupil: np.ndarray, d: np.ndarray, shape: Sphere) -> np.ndarray:
    w = pupil - np.asarray(shape.centre, dtype=np.float64)
    a = np.sum(d * d, axis=1)
    b = 2.0 * (d @ w)
    c = w @ w - shape.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    return np.where(disc >= 0, t, np.inf)


def _cylinder_t(pupil: np.ndarray, d: np.ndarray, shape: Cylinder) -> np.ndarray:
    start, end = np.asarray(shape.start, dtype=np.float64), np.asarray(shape.end, dtype=np.float64)
    length = float(np.linalg.norm(end - start))
    axis = (end - start) / length
    w = pupil - start
    d_perp = d - np.outer(d @ axis, axis)
    w_perp = w - (w @ axis) * axis
    a = np.sum(d_perp * d_perp, axis=1)
    b = 2.0 * (d_perp @ w_perp)
    c = w_perp @ w_perp - shape.radius**2
    disc = b * b - 4 * a * c
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (-b - np.sqrt(disc)) / (2 * a)
    s = w @ axis + t * (d @ axis)
    return np.where((disc >= 0) & (a > 0) & (s >= 0) & (s <= length), t, np.inf)


def _plate_t(pupil: np.ndarray, d: np.ndarray, shape: Plate) -> np.ndarray:
    centre = np.asarray(shape.centre, dtype=np.float64)
    along, across = np.asarray(shape.along, dtype=np.float64), np.asarray(shape.across, dtype=np.float64)
    normal = np.cross(along, across)
    denominator = d @ normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((centre - pupil) @ normal) / denominator
    hit = pupil + t[:, None] * d - centre
    inside = (np.abs(hit @ along) <= shape.length / 2) & (np.abs(hit @ across) <= shape.width / 2)
    return np.where(inside & np.isfinite(t), t, np.inf)


def ray_cast_heights(height: int, width: int, pixel_mm: float, l0_mm: float, shapes: Sequence[Shape]) -> np.ndarray:
    """(H, W) heights (mm) of the first surface of ``shapes`` each camera ray meets; 0 where none.

    Shapes must lie below the pupil (z < l0); what lies below the reference plane is not seen.
    """
    pupil, d = _rays(height, width, pixel_mm, l0_mm)
    nearest = np.full(len(d), np.inf)
    for shape in shapes:
        if isinstance(shape, Sphere):
            t = _sphere_t(pupil, d, shape)
        elif isinstance(shape, Cylinder):
            t = _cylinder_t(pupil, d, shape)
        elif isinstance(shape, Plate):
            t = _plate_t(pupil, d, shape)
        else:
            raise ValueError(f"shapes: expected Sphere, Cylinder or Plate, found {type(shape).__name__}")
        nearest = np.minimum(nearest, np.where(t > 0, t, np.inf))
    z = np.where(np.isfinite(nearest), l0_mm * (1.0 - nearest), 0.0)
    return np.maximum(z, 0.0).reshape(height, width)
