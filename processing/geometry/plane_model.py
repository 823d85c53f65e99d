"""Heights of the reference-plane model, their predicted sigma and the valid mask in one blocked pass.

The reference-plane model (thesis eq. 1.15) gives the height of a phase difference
``D = Phi_object - Phi_reference`` and, in closed form, its slope::

    h = l0 D / (D - c),    dh / dD = -l0 c / (D - c)^2,    c = 2 pi f0 d0,

so a pixel's predicted height sigma is ``|l0 c| sigma_phi / (D - c)^2`` with ``sigma_phi`` the
object's and the reference's phase sigma in quadrature. ``D - c`` is the heights' own denominator:
the sigma costs two products where a difference of the model (the other models' way,
:func:`processing.geometry.uncertainty.height_sigma`) costs a second evaluation of it.

Each block of pixels goes from the two phases to its heights, sigma and mask while it is in the CPU
cache, on as many threads as asked; the heights are computed operation for operation as
:func:`processing.geometry.height.phase_to_height` computes them (the same values bit for bit,
tested), in float32 for float32 phases and in float64 otherwise, and stored as float32.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from processing import concurrency
from processing._aligned import aligned_empty
from processing.geometry.height import check_geometry

BLOCK = 65536  # pixels per block: its few temporaries (256 KiB each in float32) stay in cache


@dataclass
class PlaneHeights:
    """Output of :func:`plane_heights`: (H, W) maps, the float32 ones NaN outside ``mask``."""

    height: np.ndarray  # mm, float32
    sigma: np.ndarray | None  # predicted height standard deviation (mm, float32); None without a phase sigma
    mask: np.ndarray  # valid in the object and the reference, with a finite height


def plane_heights(
    phase: np.ndarray,
    reference: np.ndarray,
    valid: np.ndarray,
    reference_valid: np.ndarray,
    geometry: tuple[float, float, float],
    phase_sigma: np.ndarray | None = None,
    reference_sigma: np.ndarray | None = None,
    threads: int = 1,
) -> PlaneHeights:
    """Eq. 1.15's heights of two absolute phases, their predicted sigma and the valid mask.

    Parameters
    ----------
    phase, reference : (H, W) float arrays of one dtype
        Absolute phases of the object and of the reference plane at one frequency (NaN: unknown).
    valid, reference_valid : (H, W) bool
        Where each phase is valid.
    geometry : (l0_mm, d0_mm, f0_per_mm)
        The reference-plane model (:func:`processing.geometry.height.phase_to_height`).
    phase_sigma, reference_sigma : (H, W) float32, optional
        Predicted phase sigma (rad) of each phase; they add in quadrature. Without ``phase_sigma`` no
        height sigma; without ``reference_sigma`` the object's alone.
    threads : int
        Threads sharing the blocks.

    Examples
    --------
    A point 10 mm above the plane (pupil 500 mm up, 200 mm baseline, 0.1 fringe / mm), its phase
    known to 0.01 rad on the object and exactly on the reference:

    >>> import numpy as np
    >>> from processing.geometry.height import height_to_phase
    >>> delta = np.float32(height_to_phase(np.array([10.0]), 500.0, 200.0, 0.1)[0])
    >>> phase, reference = np.full((1, 2), delta + np.float32(3.0)), np.full((1, 2), np.float32(3.0))
    >>> valid = np.array([[True, False]])
    >>> out = plane_heights(phase, reference, valid, np.ones((1, 2), bool), (500.0, 200.0, 0.1), np.full((1, 2), np.float32(0.01)))
    >>> np.round(out.height, 3), np.round(out.sigma, 4), out.mask
    (array([[10., nan]], dtype=float32), array([[0.0382,    nan]], dtype=float32), array([[ True, False]]))
    """
    check_geometry(*geometry)
    shape = np.shape(phase)
    dtype = np.result_type(phase, reference)
    if dtype not in (np.float32, np.float64):
        raise ValueError(f"phase, reference: expected float32 or float64, found {dtype}")
    named: dict[str, np.ndarray | None] = {"reference": reference, "valid": valid, "reference_valid": reference_valid}
    named.update({"phase_sigma": phase_sigma, "reference_sigma": reference_sigma})
    for name, values in named.items():
        if values is not None and np.shape(values) != shape:
            raise ValueError(f"{name}: expected the shape {shape} of phase, found {np.shape(values)}")

    def flat(values: np.ndarray, kind: Any) -> np.ndarray:
        return np.ascontiguousarray(values, dtype=kind).reshape(-1)

    pixels = int(np.prod(shape))
    out = PlaneHeights(
        aligned_empty(pixels), None if phase_sigma is None else aligned_empty(pixels), np.empty(pixels, bool)
    )
    kernel = _Kernel(
        (flat(phase, dtype), flat(reference, dtype)),
        (flat(valid, bool), flat(reference_valid, bool)),
        tuple(None if s is None else flat(s, np.float32) for s in (phase_sigma, reference_sigma)),
        geometry,
        out,
    )
    concurrency.on_blocks(lambda take: kernel.run(take, pixels), pixels, BLOCK, threads)
    sigma = None if out.sigma is None else out.sigma.reshape(shape)
    return PlaneHeights(out.height.reshape(shape), sigma, out.mask.reshape(shape))


class _Kernel:
    """The per-block arithmetic; each thread brings its own scratch."""

    def __init__(
        self,
        phases: tuple[np.ndarray, np.ndarray],
        masks: tuple[np.ndarray, np.ndarray],
        sigmas: tuple[np.ndarray | None, ...],
        geometry: tuple[float, float, float],
        out: PlaneHeights,
    ) -> None:
        l0_mm, d0_mm, f0_per_mm = geometry
        self.phase, self.reference = phases
        self.valid, self.reference_valid = masks
        self.phase_sigma, self.reference_sigma = sigmas
        self.dtype = self.phase.dtype.type
        # phase_to_height's constants and order of operations: (D / (D - c)) * l0
        self.offset = self.dtype(2.0 * np.pi * f0_per_mm * d0_mm)
        self.scale = self.dtype(l0_mm)
        self.slope = np.float32(abs(l0_mm * 2.0 * np.pi * f0_per_mm * d0_mm))  # |l0 c|
        self.out = out
        self.cv2: Any = None
        if self.reference_sigma is not None:
            import cv2  # a hard dependency, imported on first use like the fused pass's kernels

            self.cv2 = cv2

    def run(self, take: Callable[[], int | None], pixels: int) -> None:
        size = min(BLOCK, pixels)
        scratch = (
            aligned_empty(size, self.dtype),
            aligned_empty(size, self.dtype),
            aligned_empty(size),
            np.empty(size, bool),
        )
        while (begin := take()) is not None:
            self._block(slice(begin, min(begin + BLOCK, pixels)), scratch)

    def _block(self, window: slice, scratch: tuple[np.ndarray, ...]) -> None:
        size = window.stop - window.start
        delta, below, phase_sigma, outside = (buffer[:size] for buffer in scratch)
        height, mask = self.out.height[window], self.out.mask[window]
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            np.subtract(self.phase[window], self.reference[window], out=delta)
            np.subtract(delta, self.offset, out=below)
            np.divide(delta, below, out=delta)
            np.multiply(delta, self.scale, out=height, casting="unsafe")  # float64 phases: stored as float32
            np.logical_and(self.valid[window], self.reference_valid[window], out=mask)
            mask &= np.isfinite(height, out=outside)
            np.logical_not(mask, out=outside)
            np.copyto(height, np.float32(np.nan), where=outside)
            if self.out.sigma is None or self.phase_sigma is None:
                return
            sigma = self.out.sigma[window]
            sigma_phi = self.phase_sigma[window]
            if self.reference_sigma is not None:
                # in quadrature: OpenCV's magnitude, one vectorised pass (combined_phase_sigma's)
                sigma_phi = self.cv2.magnitude(sigma_phi, self.reference_sigma[window], phase_sigma)
            np.multiply(below, below, out=below)  # (D - c)^2
            np.divide(sigma_phi, below, out=sigma, casting="unsafe")
            sigma *= self.slope
            np.copyto(sigma, np.float32(np.nan), where=outside)
