"""Fringe synthesiser: what a camera sees of a height-map scene under projected patterns.

The rig follows the thesis' reference-plane geometry (ch. 1): camera and projector pupils at
``l0`` above the plane, signed baseline ``d0`` along x (or turned by ``baseline_angle_deg``
towards y), fringes of ``f0`` cycles/mm on the plane for the ``f0_frequency`` pattern. The camera looks straight down with ``pixel_mm`` per pixel on
the plane; the projector covers a wider footprint than the camera's view (``margin``) so that
temporal unwrapping stays unique, unless a test asks for the edge case.

Two steps, so simulated hardware can reuse the first one:
1. :func:`projector_coordinates` maps every camera pixel to the projector pixel lighting it
   (eq. 1.15 inverted) and marks projector shadows;
2. :func:`render_frame` / :func:`render_stack` turn a pattern (analytic, or a projector image
   sampled at those coordinates) into camera intensities with reflectivity, ambient light,
   projector gamma, noise at a given SNR and quantisation.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import cv2
import numpy as np

from processing.geometry.height import height_to_phase
from processing.projection.patterns import pattern_intensity


@dataclass(frozen=True)
class RigGeometry:
    """Reference-plane rig geometry and resolutions (lengths in mm, sizes in pixels)."""

    l0_mm: float = 1000.0
    d0_mm: float = 250.0
    f0_per_mm: float = 0.015625  # 8 fringes over 512 mm: the projector footprint is 1.25x the view
    f0_frequency: float = 8.0
    pixel_mm: float = 0.4
    camera_width: int = 1024
    camera_height: int = 768
    projector_width: int = 912
    projector_height: int = 1140
    view_offset_px: float | None = None  # projector u of the camera's left edge on the plane
    # direction of the baseline from the x axis: a height moves the projector coordinate by its
    # d0 cos(angle) share along x and its d0 sin(angle) share along y (0: along x alone)
    baseline_angle_deg: float = 0.0

    def __post_init__(self) -> None:
        for name in ("l0_mm", "f0_per_mm", "f0_frequency", "pixel_mm"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: expected > 0, found {getattr(self, name)}")
        if self.d0_mm == 0:
            raise ValueError("d0_mm: expected a non-zero baseline")

    @property
    def projector_px_per_mm(self) -> float:
        """Projector pixels per mm along x on the reference plane."""
        return self.projector_width * self.f0_per_mm / self.f0_frequency

    @property
    def camera_shape(self) -> tuple[int, int]:
        return (self.camera_height, self.camera_width)

    @property
    def projector_size(self) -> tuple[int, int]:
        return (self.projector_width, self.projector_height)

    def per_mm(self, frequency: float) -> float:
        """Fringe frequency on the plane (cycles/mm) of a sinusoid with ``frequency`` fringes."""
        return self.f0_per_mm * float(frequency) / self.f0_frequency

    def baseline_share(self, axis: str) -> float:
        """The baseline's signed component (mm) along ``axis``: the d0 the fringes along it see."""
        angle = np.deg2rad(self.baseline_angle_deg)
        return float(self.d0_mm * (np.cos(angle) if axis == "x" else np.sin(angle)))

    def per_mm_along(self, axis: str, frequency: float) -> float:
        """Fringe frequency on the plane (cycles/mm) of a sinusoid along ``axis`` with ``frequency`` fringes."""
        extent = self.projector_width if axis == "x" else self.projector_height
        return self.projector_px_per_mm * float(frequency) / extent

    def with_camera(self, width: int, height: int) -> RigGeometry:
        return replace(self, camera_width=width, camera_height=height)


@dataclass(frozen=True)
class Sensor:
    """A camera sensor's noise and saturation, so that exposure matters as it does on a real one.

    The full well (electrons) maps onto the top digital number of the bit depth; each pixel's
    signal S (in DN, before clipping) gets shot noise of variance S / (electrons per DN) and read
    noise of ``read_noise_e`` electrons; then quantisation and clipping at the top DN (saturation).
    """

    full_well_e: float = 10_000.0
    read_noise_e: float = 8.0

    def __post_init__(self) -> None:
        if not self.full_well_e > 0:
            raise ValueError(f"full_well_e: expected > 0 electrons, found {self.full_well_e}")
        if not self.read_noise_e >= 0:
            raise ValueError(f"read_noise_e: expected >= 0 electrons, found {self.read_noise_e}")

    def electrons_per_dn(self, bit_depth: int | None) -> float:
        """Conversion gain: the full well over the top digital number (8 bit when the output stays float)."""
        return self.full_well_e / float((1 << (bit_depth or 8)) - 1)

    def add_noise(self, signal: np.ndarray, bit_depth: int | None, rng: np.random.Generator) -> np.ndarray:
        """``signal`` (DN) with shot and read noise (Gaussian approximation of Poisson), in place when float."""
        per_dn = self.electrons_per_dn(bit_depth)
        work = signal.dtype.type
        variance = np.maximum(signal, 0.0) / work(per_dn)
        variance += work((self.read_noise_e / per_dn) ** 2)
        noise = rng.standard_normal(signal.shape, dtype=work)
        noise *= np.sqrt(variance, out=variance)
        signal += noise
        return signal


@dataclass(frozen=True)
class Appearance:
    """Photometric model of the scene and the camera (intensities in camera digital numbers).

    ``sensor`` (a :class:`Sensor`) replaces the ``snr_db`` noise by shot and read noise.
    """

    reflectivity: float | np.ndarray = 1.0
    ambient: float = 0.0  # light not from the projector, in projector-intensity units
    gamma: float = 1.0  # projector response: out = in ** gamma
    gain: float = 200.0  # DN for projector intensity 1 on reflectivity 1
    snr_db: float | None = None  # additive white Gaussian noise, signal power = mean(I^2)
    bit_depth: int | None = 8  # None: keep float
    shadow_level: float = 0.0  # intensity seen in projector shadow (besides ambient)
    sensor: Sensor | None = None  # shot + read noise and full well instead of snr_db


@dataclass
class ProjectorMap:
    """Where each camera pixel looks in projector coordinates."""

    u: np.ndarray  # (H, W) projector column (continuous, pixel centres at k + 0.5)
    v: np.ndarray  # (H, W) projector row
    lit: np.ndarray  # (H, W) bool: the projector reaches the pixel
    height_mm: np.ndarray | None = field(repr=False, default=None)  # the scene


def projector_coordinates(height_mm: np.ndarray, geometry: RigGeometry, clip_to_projector: bool = True) -> ProjectorMap:
    """Projector pixel lighting each camera pixel of a scene, and the projector shadows.

    Parameters
    ----------
    height_mm : (H, W) array
        Scene heights above the reference plane; (H, W) must match the geometry's camera.
    geometry : RigGeometry
    clip_to_projector : bool
        Mark pixels whose projector coordinate falls outside 0 .. width as unlit (a real
        projector has no light there). False keeps the periodic extension (the edge case).
    """
    h = np.asarray(height_mm, dtype=np.float64)
    if h.shape != geometry.camera_shape:
        raise ValueError(f"height_mm: shape {h.shape} does not match the camera {geometry.camera_shape}")
    if not np.all(np.isfinite(h)):
        raise ValueError("height_mm: contains NaN or infinity")
    g = geometry
    px_per_mm = g.projector_px_per_mm
    view_mm = g.camera_width * g.pixel_mm
    offset = g.view_offset_px
    if offset is None:  # centre the camera's view in the projector's footprint
        offset = (g.projector_width - view_mm * px_per_mm) / 2.0
    x_mm = (np.arange(g.camera_width) + 0.5) * g.pixel_mm
    u_reference = offset + x_mm * px_per_mm
    delta_phase = height_to_phase(h, g.l0_mm, g.d0_mm, g.f0_per_mm)
    angle = np.deg2rad(g.baseline_angle_deg)
    shift_px = delta_phase * g.projector_width / (2.0 * np.pi * g.f0_frequency)  # along the baseline
    u = u_reference[None, :] + shift_px * np.cos(angle)
    view_h_mm = g.camera_height * g.pixel_mm
    y_mm = (np.arange(g.camera_height) + 0.5) * g.pixel_mm
    v_row = (g.projector_height - view_h_mm * px_per_mm) / 2.0 + y_mm * px_per_mm
    v = v_row[:, None] + shift_px * np.sin(angle)
    lit = ~projector_shadow(u, g.baseline_share("x"))
    if g.baseline_angle_deg:  # shadows cast along the columns too
        lit &= ~projector_shadow(v.T, g.baseline_share("y")).T
    if clip_to_projector:
        lit &= (u >= 0) & (u < g.projector_width) & (v >= 0) & (v < g.projector_height)
    return ProjectorMap(u=u, v=v, lit=lit, height_mm=h)


def projector_shadow(u: np.ndarray, d0_mm: float) -> np.ndarray:
    """Pixels the projector cannot reach, from the projector coordinates along each row.

    Rays from the projector hit the surface nearest to it first: walking a row away from the
    projector (towards -x when d0 > 0), a visible pixel must have a smaller coordinate than every
    pixel before it. A pixel that does not is behind a ridge.
    """
    if d0_mm > 0:
        ahead = np.minimum.accumulate(u[:, ::-1], axis=1)[:, ::-1]
        nearer = np.concatenate([ahead[:, 1:], np.full((u.shape[0], 1), np.inf)], axis=1)
        return u > nearer
    ahead = np.maximum.accumulate(u, axis=1)
    nearer = np.concatenate([np.full((u.shape[0], 1), -np.inf), ahead[:, :-1]], axis=1)
    return u < nearer


def awgn(image: np.ndarray, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Add white Gaussian noise at ``snr_db`` with signal power mean(I^2) (MATLAB awgn 'measured').

    Works in float32 for a float32 ``image`` (a simulated camera's per-frame precision: the noise
    is drawn as float32, half the work), in float64 otherwise; returns a new array.
    """
    image = np.asarray(image)
    work = np.float32 if image.dtype == np.float32 else np.float64
    image = image.astype(work, copy=False)
    power = float(np.mean(image * image))
    sigma = np.sqrt(power / (10.0 ** (snr_db / 10.0)))
    noisy = rng.standard_normal(image.shape, dtype=work)  # float64: the stream of rng.normal(0, sigma)
    noisy *= sigma
    noisy += image
    return noisy


def _remap_maps(mapping: ProjectorMap) -> tuple[np.ndarray, np.ndarray]:
    """float32 sampling maps (projector pixel centres at integers) for ``cv2.remap``, cached on ``mapping``.

    A simulated camera samples every frame at the same coordinates, so the maps are built once.
    The cache assumes ``mapping.u`` / ``mapping.v`` are not modified in place after the first sample.
    """
    cached = mapping.__dict__.get("_remap_maps")
    if cached is None:
        cached = ((mapping.u - 0.5).astype(np.float32), (mapping.v - 0.5).astype(np.float32))
        mapping.__dict__["_remap_maps"] = cached
    return cached


def sample_projector_image(image: np.ndarray, mapping: ProjectorMap) -> np.ndarray:
    """Bilinear sample of a rendered projector frame (rows x cols) at the mapped coordinates, float32.

    Coordinates outside the frame take the nearest edge pixel (``mapping.lit`` marks them unlit
    anyway). OpenCV >= 5 interpolates with float weights (coordinates as float32: within 1e-4 px
    of the float64 ones); OpenCV 4 rounds positions to 1/32 px, a fixed phase error of at most
    2 pi / (64 P) rad for fringes of period P projector pixels (7e-3 rad at 64 fringes on 912 px).
    """
    img = np.asarray(image)
    if img.ndim != 2:
        raise ValueError(f"image: expected a (rows, cols) projector frame, found shape {img.shape}")
    img = np.ascontiguousarray(img, dtype=np.float32)
    map_x, map_y = _remap_maps(mapping)
    return cv2.remap(img, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)


def expose(
    projected: np.ndarray, mapping: ProjectorMap, appearance: Appearance, rng: np.random.Generator
) -> np.ndarray:
    """Camera image from the projector intensity reaching each pixel (before gamma).

    I = gain * reflectivity * (ambient + gamma(projected) on lit pixels, shadow_level elsewhere),
    then noise (the ``sensor``'s shot and read noise, else white noise at ``snr_db``) and
    quantisation to ``bit_depth``, clipping at its top value (saturation). A float32 ``projected`` (what
    :func:`sample_projector_image` returns) is exposed in float32, anything else in float64.
    """
    projected = np.asarray(projected)
    work = np.float32 if projected.dtype == np.float32 else np.float64
    light = np.clip(projected.astype(work, copy=False), 0.0, 1.0)  # a new array: updated in place below
    if appearance.gamma != 1.0:
        np.power(light, appearance.gamma, out=light)
    np.copyto(light, work(appearance.shadow_level), where=~np.asarray(mapping.lit))
    light += work(appearance.ambient)
    scale = appearance.gain * np.asarray(appearance.reflectivity)
    if scale.ndim:
        light *= scale.astype(work, copy=False)
    else:
        light *= work(scale)
    if appearance.sensor is not None:
        image = appearance.sensor.add_noise(light, appearance.bit_depth, rng)
    else:
        image = light if appearance.snr_db is None else awgn(light, appearance.snr_db, rng)
    if appearance.bit_depth is None:
        return image.astype(np.float32, copy=False)
    top = (1 << appearance.bit_depth) - 1
    dtype = np.uint8 if appearance.bit_depth <= 8 else np.uint16
    np.rint(image, out=image)
    np.clip(image, 0, top, out=image)
    return image.astype(dtype)


def render_frame(
    pattern: Mapping[str, Any],
    mapping: ProjectorMap,
    geometry: RigGeometry,
    appearance: Appearance = Appearance(),
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Camera image of one analytic pattern (capture-format pattern dict) on the scene."""
    rng = np.random.default_rng() if rng is None else rng
    projected = pattern_intensity(pattern, mapping.u, mapping.v, geometry.projector_size)
    return expose(projected, mapping, appearance, rng)


def render_stack(
    patterns: Sequence[Mapping[str, Any]],
    mapping: ProjectorMap,
    geometry: RigGeometry,
    appearance: Appearance = Appearance(),
    rng: np.random.Generator | None = None,
) -> np.ndarray:
    """Camera images (N, H, W) of a pattern sequence on the scene; noise drawn from ``rng``."""
    rng = np.random.default_rng() if rng is None else rng
    return np.stack([render_frame(p, mapping, geometry, appearance, rng) for p in patterns])


def sinusoid_patterns(frequencies: Sequence[float], steps: int, axis: str = "x") -> list[dict[str, Any]]:
    """Pattern entries for ``steps``-step phase shifting at each frequency, in capture order."""
    if steps < 3:
        raise ValueError(f"steps: expected >= 3, found {steps}")
    return [
        {"kind": "sinusoid", "axis": axis, "frequency": f, "steps": steps, "step": j}
        for f in frequencies
        for j in range(steps)
    ]


def true_absolute_phase(mapping: ProjectorMap, geometry: RigGeometry, frequency: float) -> np.ndarray:
    """Ground truth absolute phase 2 pi f u / W of a sinusoid of ``frequency`` (NaN where unlit)."""
    phase = 2.0 * np.pi * frequency * mapping.u / geometry.projector_width
    return np.where(mapping.lit, phase, np.nan)
