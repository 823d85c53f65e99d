"""Virtual scenes: height maps in millimetres over the camera's pixel grid.

Every scene is a function ``(height, width, pixel_mm, **params) -> (H, W) float64`` of heights above
the reference plane (0 where the plane shows). Coordinates are in mm from the image centre.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

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


@dataclass(frozen=True)
class Part:
    """One part of a scene: where it sits (mm from the view's centre), its size, height and albedo."""

    cx: float
    cy: float
    size_x: float  # a dome's sphere radius, a block's half width
    size_y: float  # a block's half depth (unused for a dome)
    height_mm: float
    albedo: float


@dataclass(frozen=True)
class ShinyAndDark:
    """The parts of the "shiny-and-dark" scene: a polished dome, a matte dome and a black block on a matte plane."""

    shiny: Part = Part(-120.0, 10.0, 110.0, 110.0, 35.0, 0.45)
    matte: Part = Part(20.0, -40.0, 90.0, 90.0, 30.0, 0.8)
    dark: Part = Part(120.0, 30.0, 45.0, 60.0, 20.0, 0.02)
    plane_albedo: float = 0.7
    specular_peak: float = 6.0  # the lobe's reflectance where the dome's normal halves L and V
    specular_exponent: float = 60.0  # Blinn-Phong: the lobe halves 8.7 degrees off the half vector

    @classmethod
    def variant(cls, number: int) -> ShinyAndDark:
        """Variant 0 is the nominal scene; others are drawn (seeded by ``number``): parts moved by up to
        20 mm, dark albedo 0.01-0.04, matte 0.6-0.9, specular peak 4-10 with exponent 40-100."""
        if number == 0:
            return cls()
        rng = np.random.default_rng([25, number])
        base = cls()

        def moved(part: Part, albedo: float) -> Part:
            dx, dy = rng.uniform(-20.0, 20.0, size=2)
            return Part(part.cx + dx, part.cy + dy, part.size_x, part.size_y, part.height_mm, albedo)

        return cls(
            shiny=moved(base.shiny, base.shiny.albedo),
            matte=moved(base.matte, float(rng.uniform(0.6, 0.9))),
            dark=moved(base.dark, float(rng.uniform(0.01, 0.04))),
            specular_peak=float(rng.uniform(4.0, 10.0)),
            specular_exponent=float(rng.uniform(40.0, 100.0)),
        )

    def parts(self, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Heights of the shiny dome, the matte dome and the dark block."""
        s, m, b = self.shiny, self.matte, self.dark
        shiny = _cap(x, y, s.cx, s.cy, s.size_x, s.height_mm)
        matte = _cap(x, y, m.cx, m.cy, m.size_x, m.height_mm)
        block = np.where((np.abs(x - b.cx) < b.size_x) & (np.abs(y - b.cy) < b.size_y), b.height_mm, 0.0)
        return shiny, matte, block


def shiny_and_dark(height: int, width: int, pixel_mm: float, variant: int = 0) -> np.ndarray:
    """Parts that need several exposures: a polished dome (a specular highlight), a matte dome and a
    black block (20 mm) on the plane (:class:`ShinyAndDark`; ``variant`` draws another arrangement);
    :func:`shiny_and_dark_reflectance` is how each reflects."""
    x, y = _grid_mm(height, width, pixel_mm)
    shiny, matte, block = ShinyAndDark.variant(variant).parts(x, y)
    return np.maximum(np.maximum(shiny, matte), block)


def shiny_and_dark_reflectance(
    height_mm: np.ndarray, pixel_mm: float, l0_mm: float, d0_mm: float, variant: int = 0
) -> np.ndarray:
    """Reflectance of ``shiny_and_dark`` towards the camera: albedo, plus a specular lobe on the polished dome.

    The camera looks down from ``l0_mm`` above the view's centre, the projector sits ``d0_mm`` beside it;
    the lobe is Blinn-Phong, ``specular_peak (n . h)^specular_exponent`` with h halving the directions
    to the projector and to the camera: it saturates the camera at an exposure that suits the matte parts.
    """
    scene = ShinyAndDark.variant(variant)
    rows, cols = height_mm.shape
    x, y = _grid_mm(rows, cols, pixel_mm)
    shiny, matte, block = scene.parts(x, y)
    albedo = np.full(height_mm.shape, scene.plane_albedo)
    albedo[matte > 0] = scene.matte.albedo
    albedo[block > 0] = scene.dark.albedo
    on_dome = (shiny > 0) & (shiny >= np.maximum(matte, block))
    albedo[on_dome] = scene.shiny.albedo
    dh_dy, dh_dx = np.gradient(height_mm, pixel_mm)
    normal = np.stack([-dh_dx, -dh_dy, np.ones_like(dh_dx)])
    normal /= np.linalg.norm(normal, axis=0)
    up = l0_mm - height_mm
    to_camera = np.stack([-x, -y, up])
    to_projector = np.stack([d0_mm - x, -y, up])
    half = to_camera / np.linalg.norm(to_camera, axis=0) + to_projector / np.linalg.norm(to_projector, axis=0)
    half /= np.linalg.norm(half, axis=0)
    cosine = np.clip(np.einsum("khw,khw->hw", normal, half), 0.0, 1.0)
    return albedo + np.where(on_dome, scene.specular_peak * cosine**scene.specular_exponent, 0.0)


SCENES: dict[str, Callable[..., np.ndarray]] = {
    "flat": flat,
    "sphere-cap": sphere_cap,
    "hemisphere": hemisphere,
    "two-hemispheres": two_hemispheres,
    "steps": steps,
    "isolated": isolated_objects,
    "gauge-block": gauge_block,
    "shiny-and-dark": shiny_and_dark,
}

# Scenes drawn from a family: ``variant`` (an integer, 0 the nominal scene) chooses one
VARIANTS = ("shiny-and-dark",)

# Scenes whose surfaces are not uniformly matte: ``f(height_mm, pixel_mm, l0_mm, d0_mm) -> reflectance``.
REFLECTANCES: dict[str, Callable[..., np.ndarray]] = {"shiny-and-dark": shiny_and_dark_reflectance}


def scene_reflectance(
    name: str, height_mm: np.ndarray, pixel_mm: float, l0_mm: float, d0_mm: float, variant: int = 0
) -> np.ndarray | None:
    """Reflectance map of a named scene (its ``variant``) seen by the rig, or None for a uniformly matte one."""
    factory = REFLECTANCES.get(name)
    if factory is None:
        return None
    return factory(np.asarray(height_mm, dtype=np.float64), pixel_mm, l0_mm, d0_mm, variant=variant)


def make_scene(name: str, height: int, width: int, pixel_mm: float, **params: float) -> np.ndarray:
    """Height map of a named scene (see ``SCENES``)."""
    try:
        factory = SCENES[name]
    except KeyError:
        raise ValueError(f"scene: expected one of {', '.join(SCENES)}, found {name!r}") from None
    return factory(height, width, pixel_mm, **params)
