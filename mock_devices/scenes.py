"""Virtual scenes: height maps in millimetres over the camera's pixel grid.

Every scene is a function ``(height, width, pixel_mm, **params) -> (H, W) float64`` of heights above
the reference plane (0 where the plane shows). Coordinates are in mm from the image centre.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np


def _grid_mm(height: int, width: int, pixel_mm: float) -> tuple[np.ndarray, np.ndarray]:
    if height < 1 or width < 1:
        raise ValueError(f"scene size: expected positive height and width, found {height}x{width}")
    if not pixel_mm > 0:
        raise ValueError(f"pixel_mm: expected > 0, found {pixel_mm}")
    y = (np.arange(height) - (height - 1) / 2.0) * pixel_mm
    x = (np.arange(width) - (width - 1) / 2.0) * pixel_mm
    return np.meshgrid(x, y)


def _cap(x: np.ndarray, y: np.ndarray, cx: float, cy: float, radius: float, depth: float) -> np.ndarray:
    """A spherical cap of sphere radius ``radius`` whose top is ``depth`` above the plane."""
    r2 = (x - cx) ** 2 + (y - cy) ** 2
    return np.maximum(np.sqrt(np.maximum(radius**2 - r2, 0.0)) - (radius - depth), 0.0)


def flat(height: int, width: int, pixel_mm: float, level_mm: float = 0.0) -> np.ndarray:
    """A plane at ``level_mm`` (0: the reference plane itself)."""
    _grid_mm(height, width, pixel_mm)
    return np.full((height, width), float(level_mm))


def sphere_cap(
    height: int, width: int, pixel_mm: float, radius_mm: float = 300.0, max_height_mm: float = 100.0
) -> np.ndarray:
    """A centred spherical cap (thesis Table 4.1: R = 300 mm, 100 mm high)."""
    x, y = _grid_mm(height, width, pixel_mm)
    return _cap(x, y, 0.0, 0.0, radius_mm, max_height_mm)


def hemisphere(height: int, width: int, pixel_mm: float, radius_mm: float | None = None) -> np.ndarray:
    """A centred hemisphere; default radius a third of the shorter image side."""
    x, y = _grid_mm(height, width, pixel_mm)
    r = radius_mm if radius_mm is not None else min(height, width) * pixel_mm / 3.0
    return _cap(x, y, 0.0, 0.0, r, r)


def two_hemispheres(height: int, width: int, pixel_mm: float, radius_mm: float | None = None) -> np.ndarray:
    """Two touching-free hemispheres side by side along x."""
    x, y = _grid_mm(height, width, pixel_mm)
    r = radius_mm if radius_mm is not None else min(height, width / 2.0) * pixel_mm / 3.2
    offset = width * pixel_mm / 4.0
    return np.maximum(_cap(x, y, -offset, 0.0, r, r), _cap(x, y, offset, 0.0, r, r))


def steps(height: int, width: int, pixel_mm: float, step_mm: float = 10.0, count: int = 4) -> np.ndarray:
    """A staircase along x: ``count`` treads of ``step_mm`` each, on the central half of the view."""
    x, y = _grid_mm(height, width, pixel_mm)
    half_w, half_h = width * pixel_mm / 4.0, height * pixel_mm / 4.0
    inside = (np.abs(x) < half_w) & (np.abs(y) < half_h)
    level = np.floor((x + half_w) / (2 * half_w) * count) + 1
    return np.where(inside, level * step_mm, 0.0)


def isolated_objects(height: int, width: int, pixel_mm: float, max_height_mm: float = 40.0) -> np.ndarray:
    """Separate objects on the plane: a block, a cylinder and a cap, with plane between them.

    Isolated objects defeat spatial unwrapping (no path joins them); temporal methods must cope.
    """
    x, y = _grid_mm(height, width, pixel_mm)
    w, h = width * pixel_mm, height * pixel_mm
    block = (np.abs(x + w / 4) < w / 10) & (np.abs(y + h / 5) < h / 8)
    cylinder = (x - w / 5) ** 2 + (y + h / 5) ** 2 < (min(w, h) / 9) ** 2
    out = np.where(block, max_height_mm * 0.75, 0.0)
    out = np.maximum(out, np.where(cylinder, max_height_mm * 0.5, 0.0))
    cap_r = min(w, h) / 6
    return np.maximum(out, _cap(x, y, 0.0, h / 4, cap_r * 1.5, min(max_height_mm, cap_r)))


def gauge_block(height: int, width: int, pixel_mm: float, height_mm: float = 25.0) -> np.ndarray:
    """A gauge block of known height (default 25.000 mm): a centred rectangle a third of the view wide."""
    x, y = _grid_mm(height, width, pixel_mm)
    inside = (np.abs(x) < width * pixel_mm / 6.0) & (np.abs(y) < height * pixel_mm / 6.0)
    return np.where(inside, float(height_mm), 0.0)


SCENES: dict[str, Callable[..., np.ndarray]] = {
    "flat": flat,
    "sphere-cap": sphere_cap,
    "hemisphere": hemisphere,
    "two-hemispheres": two_hemispheres,
    "steps": steps,
    "isolated": isolated_objects,
    "gauge-block": gauge_block,
}


def make_scene(name: str, height: int, width: int, pixel_mm: float, **params: float) -> np.ndarray:
    """Height map of a named scene (see ``SCENES``)."""
    try:
        factory = SCENES[name]
    except KeyError:
        raise ValueError(f"scene: expected one of {', '.join(SCENES)}, found {name!r}") from None
    return factory(height, width, pixel_mm, **params)
