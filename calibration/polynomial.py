"""Per-pixel phase-to-height polynomial ("model": "polynomial") for rigs where eq. 1.15 does not hold.

Eq. 1.15 assumes camera and projector pupils at the same height with parallel axes; a real rig
with a tilted camera or a projector off that line sees, on a flat plane, a phase difference that
changes across the view. Along one camera pixel's ray, though, height is still a smooth monotonic
function of the phase difference, so each pixel gets its own polynomial

    h(x, y) = sum_{k=1..n} c_k(x, y) dPhi(x, y)^k        (h = 0 at dPhi = 0: the reference plane)

fitted by least squares to the plane at several known heights (at least n, better n + 1 or more
for a residual). Coefficients are stored beside calibration.json in ``polynomial.npy`` (n, H, W).

calibration.json keys: ``"model": "polynomial"``, ``"polynomial": {"file", "degree",
"phase_frequency", "residual_rms_mm"}``, ``reference`` as for the reference-plane model, and
optionally ``l0_mm`` / ``pixel_mm`` for lateral point coordinates.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from calibration.errors import CalibrationError

POLYNOMIAL = "polynomial"
COEFFICIENTS_FILE = "polynomial.npy"


@dataclass(frozen=True)
class PolynomialModel:
    """Per-pixel polynomial h = sum_i c_i dPhi^i (no constant term) in the phase difference to the reference."""

    coefficients: np.ndarray  # (degree, H, W): c_1 .. c_n, NaN where unfitted
    phase_frequency: float  # the fringe frequency the phase differences are at
    residual_rms_mm: float = float("nan")
    residuals_mm: tuple[float, ...] = ()

    @property
    def degree(self) -> int:
        return int(self.coefficients.shape[0])

    def height(self, delta_phase: np.ndarray, frequency: float | None = None) -> np.ndarray:
        """Heights (H, W) in mm of phase differences at ``frequency`` (default: the fitted one)."""
        dphi = np.asarray(delta_phase, dtype=np.float64)
        if dphi.shape != self.coefficients.shape[1:]:
            raise CalibrationError(
                f"phase difference: shape {dphi.shape} does not match the polynomial calibration {self.coefficients.shape[1:]}"
            )
        if frequency is not None and frequency != self.phase_frequency:
            dphi = dphi * (self.phase_frequency / float(frequency))
        # Horner: ((c_n x + c_{n-1}) x + ... + c_1) x
        total = np.zeros_like(dphi)
        for coefficient in self.coefficients[::-1]:
            total = (total + coefficient) * dphi
        return total

    def fields(self, file: str = COEFFICIENTS_FILE) -> dict[str, Any]:
        """The calibration.json keys of this model, its coefficients stored in ``file`` beside it."""
        return {
            "model": POLYNOMIAL,
            "polynomial": {
                "file": file,
                "degree": self.degree,
                "phase_frequency": self.phase_frequency,
                "residual_rms_mm": self.residual_rms_mm,
                "residuals_mm": list(self.residuals_mm),
            },
        }

    def save(self, directory: str | Path, file: str = COEFFICIENTS_FILE) -> dict[str, Any]:
        """Write the coefficients into ``directory`` and return the calibration.json keys."""
        path = Path(directory)
        path.mkdir(parents=True, exist_ok=True)
        np.save(path / file, self.coefficients)
        return self.fields(file)


def load_polynomial(
    fields: Mapping[str, Any], directory: str | Path | None, where: str = "calibration.json"
) -> PolynomialModel:
    """The model described by calibration.json's ``polynomial`` entry, coefficients read beside it."""
    entry = fields.get("polynomial")
    if not isinstance(entry, Mapping):
        raise CalibrationError(f"{where}: polynomial: expected an object with file, degree, phase_frequency")
    file = entry.get("file")
    if not isinstance(file, str) or not file or Path(file).is_absolute() or ".." in Path(file).parts:
        raise CalibrationError(f"{where}: polynomial.file: expected a relative file name, found {file!r}")
    frequency = entry.get("phase_frequency")
    if not isinstance(frequency, (int, float)) or not frequency > 0:
        raise CalibrationError(f"{where}: polynomial.phase_frequency: expected > 0, found {frequency!r}")
    path = Path(directory or ".") / file
    try:
        coefficients = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise CalibrationError(f"{path}: missing (the polynomial coefficients of {where})") from None
    except (OSError, ValueError) as exc:
        raise CalibrationError(f"{path}: not a .npy array: {exc}") from None
    if coefficients.ndim != 3 or coefficients.shape[0] < 1:
        raise CalibrationError(f"{path}: expected coefficients of shape (degree, H, W), found {coefficients.shape}")
    degree = entry.get("degree", coefficients.shape[0])
    if degree != coefficients.shape[0]:
        raise CalibrationError(
            f"{where}: polynomial.degree = {degree} but {path} holds {coefficients.shape[0]} coefficients"
        )
    return PolynomialModel(
        coefficients.astype(np.float64), float(frequency), float(entry.get("residual_rms_mm", np.nan))
    )


def fit_polynomial(
    heights_mm: Sequence[float],
    delta_phases: Sequence[np.ndarray],
    phase_frequency: float,
    degree: int = 3,
    masks: Sequence[np.ndarray | None] | None = None,
) -> PolynomialModel:
    """Per-pixel least squares of h = sum_k c_k dPhi^k over planes at known heights.

    Parameters
    ----------
    heights_mm : sequence of float
        Known plane heights (non-zero, at least ``degree`` distinct values).
    delta_phases : sequence of (H, W) arrays
        Phi_plane - Phi_reference per height, at ``phase_frequency``.
    degree : int
        Polynomial degree n (1 .. 5).
    masks : optional sequence of (H, W) bool arrays
        Valid pixels per plane; a pixel missing in any plane gets NaN coefficients.
    """
    heights = np.asarray(heights_mm, dtype=np.float64).ravel()
    if not 1 <= degree <= 5:
        raise CalibrationError(f"polynomial degree: expected 1 .. 5, found {degree}")
    if len(delta_phases) != heights.size:
        raise CalibrationError(f"plane heights: {heights.size} heights but {len(delta_phases)} phase maps")
    if np.unique(heights).size < degree or heights.size < degree:
        raise CalibrationError(
            f"plane heights: a degree-{degree} polynomial needs at least {degree} distinct heights "
            f"({degree + 1} for a residual), found {np.unique(heights).size}"
        )
    if np.any(heights == 0):
        raise CalibrationError("plane heights: 0 mm is the reference plane itself; use heights away from it")
    stack = np.stack([np.asarray(d, dtype=np.float64) for d in delta_phases])
    if stack.ndim != 3:
        raise CalibrationError(f"phase maps: expected (H, W) maps, found shape {stack.shape[1:]}")
    valid = np.all(np.isfinite(stack), axis=0)
    if masks is not None:
        for mask in masks:
            if mask is not None:
                valid &= np.asarray(mask, dtype=bool)
    if not valid.any():
        raise CalibrationError("phase maps: no pixel is valid in every plane")
    dphi = stack[:, valid].T  # (N, P)
    scale = np.max(np.abs(dphi), axis=1, keepdims=True)
    if np.any(scale == 0):
        raise CalibrationError(
            "phase maps: some pixels show no phase change across the planes (the plane did not move)"
        )
    x = dphi / scale
    powers = np.arange(1, degree + 1)
    design = x[:, :, None] ** powers[None, None, :]  # (N, P, n)
    normal = np.einsum("npk,npj->nkj", design, design)
    rhs = np.einsum("npk,p->nk", design, heights)
    conditions = np.linalg.cond(normal)
    if np.nanmax(conditions) > 1e12 or not np.all(np.isfinite(conditions)):
        raise CalibrationError(
            f"polynomial fit: singular for some pixels (heights too few or too close for degree {degree})"
        )
    scaled = np.linalg.solve(normal, rhs[..., None])[..., 0]  # (N, n)
    coefficients = scaled / scale ** powers[None, :]
    fitted = np.einsum("npk,nk->np", design, scaled)
    residual_per_height = np.sqrt(np.mean((fitted - heights[None, :]) ** 2, axis=0))
    out = np.full((degree, *valid.shape), np.nan)
    out[:, valid] = coefficients.T
    return PolynomialModel(
        coefficients=out,
        phase_frequency=float(phase_frequency),
        residual_rms_mm=float(np.sqrt(np.mean((fitted - heights[None, :]) ** 2))),
        residuals_mm=tuple(float(r) for r in residual_per_height),
    )
