"""First-order error model: how a calibration error moves PS and SD (docs/verification.md derives it).

A wrong calibration parameter moves every measured point by a small displacement dp. A
least-squares sphere (free centre c, radius R) of points p_i with unit normals n_i = (p_i - c)/R
answers, to first order, with the (dc, dR) that minimise sum_i (n_i . dp_i - n_i . dc - dR)^2:
a linear regression of n_i . dp_i on [n_i, 1]. Then dPS = 2 dR and, for a ball bar with centres
c1, c2 at distance L along u = (c2 - c1)/L, dSD = u . (dc2 - dc1).

Displacements of the reference-plane model (h = l0 dPhi / (dPhi - 2 pi f0 d0), X = x p (l0 - h)/l0):

- l0 off by a factor (1 + e): h scales by (1 + e) exactly and X, Y do not move: dp = (0, 0, e z).
  On a ball bar this gives dSD = e dz^2 / L (dz: the bar's rise), whatever the caps look like.
- f0 (the projector's fringe pitch on the plane) off by (1 + e): dh = -e h (l0 - h) / l0 and
  dX = X e h / l0 (the same for Y).
"""

from __future__ import annotations

import numpy as np

from rig.verify.fits import FormFit


def l0_displacement(points: np.ndarray, error: float) -> np.ndarray:
    """(N, 3) displacement of ``points`` when the calibration's l0 is (1 + error) times the true one."""
    p = np.asarray(points, dtype=np.float64)
    out = np.zeros_like(p)
    out[:, 2] = error * p[:, 2]
    return out


def f0_displacement(points: np.ndarray, l0_mm: float, error: float) -> np.ndarray:
    """(N, 3) displacement of ``points`` when the calibration's f0 is (1 + error) times the true one."""
    p = np.asarray(points, dtype=np.float64)
    h = p[:, 2]
    return np.column_stack([p[:, 0] * error * h / l0_mm, p[:, 1] * error * h / l0_mm, -error * h * (l0_mm - h) / l0_mm])


def sphere_response(fit: FormFit, displacement: np.ndarray) -> tuple[np.ndarray, float]:
    """First-order (d centre (3,), d radius) of a least-squares sphere whose points move by ``displacement``."""
    if fit.kind != "sphere":
        raise ValueError(f"fit: expected a sphere, found a {fit.kind}")
    n = (fit.points - fit.centre) / np.linalg.norm(fit.points - fit.centre, axis=1, keepdims=True)
    y = np.sum(n * np.asarray(displacement, dtype=np.float64), axis=1)
    design = np.hstack([n, np.ones((len(n), 1))])
    solution = np.linalg.lstsq(design, y, rcond=None)[0]
    return solution[:3], float(solution[3])


def predicted_ps_change(fit: FormFit, displacement: np.ndarray) -> float:
    """First-order change of PS (mm)."""
    return 2.0 * sphere_response(fit, displacement)[1]


def predicted_sd_change(first: FormFit, second: FormFit, moves: tuple[np.ndarray, np.ndarray]) -> float:
    """First-order change of SD (mm) of a ball bar whose two spheres' points move by ``moves``."""
    u = (second.centre - first.centre) / np.linalg.norm(second.centre - first.centre)
    d1 = sphere_response(first, moves[0])[0]
    d2 = sphere_response(second, moves[1])[0]
    return float(u @ (d2 - d1))
