"""Least-squares form elements of VDI/VDE 2634-2: sphere (free radius) and plane, found robustly in a cloud.

The guideline evaluates Gaussian (least-squares) elements: a sphere whose centre and radius are
free, a plane fitted orthogonally. Finding the artefact in a scan is a separate step: a
random-sample consensus (RANSAC) proposes candidates in one vectorised batch, a trimmed refit
(median absolute deviation) drops what is not the artefact (its stand, the bar, mixed pixels at
its rim), and only then does the guideline's own allowance apply: up to 0.3 % of the points with
the largest residuals may be left out (:data:`EXCLUDED_FRACTION`) before the final fit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize

# VDI/VDE 2634-2: at most this share of a fit's points, those of largest residual, may be left out.
EXCLUDED_FRACTION = 0.003
# Robust scale of the trimmed refit: points beyond this many MAD-sigmas are not the artefact.
TRIM_SIGMAS = 5.0
RANSAC_SAMPLES = 400
RANSAC_SUBSET = 4000


@dataclass(frozen=True)
class FormFit:
    """A fitted sphere or plane with what the fit used and left out.

    ``residuals`` are signed distances (mm) of the points used: radial distance minus radius for
    a sphere, distance along the normal for a plane. ``points`` are those used (for the residual
    map); ``trimmed`` counts points taken as not the artefact, ``excluded`` the 0.3 % left out.
    """

    kind: str  # "sphere" or "plane"
    centre: np.ndarray  # (3,) sphere centre, or the plane's centroid
    radius_mm: float  # sphere radius; NaN for a plane
    normal: np.ndarray  # (3,) plane normal (towards +z); zeros for a sphere
    residuals: np.ndarray
    points: np.ndarray
    trimmed: int
    excluded: int

    @property
    def form_range_mm(self) -> float:
        """Range of the signed residuals: PF of a sphere, F of a plane."""
        return float(np.ptp(self.residuals)) if self.residuals.size else float("nan")

    @property
    def used(self) -> int:
        return int(self.residuals.size)


def _check_points(points: np.ndarray, minimum: int, what: str) -> np.ndarray:
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f"points: expected an (N, 3) array, found shape {p.shape}")
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) < minimum:
        raise ValueError(f"points: a {what} fit needs at least {minimum} finite points, found {len(p)}")
    return p


def sphere_lsq(points: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares sphere with free radius: (centre (3,), radius), geometric residuals |p - c| - r.

    Starts from the algebraic (linear) fit and minimises the orthogonal distances with
    :func:`scipy.optimize.least_squares` (Gaussian fit, no robust loss: the guideline's element).
    """
    p = _check_points(points, 4, "sphere")
    centre0, radius0 = _sphere_algebraic(p)
    shift = p.mean(axis=0)
    q = p - shift

    def residual(x: np.ndarray) -> np.ndarray:
        return np.linalg.norm(q - x[:3], axis=1) - x[3]

    def jacobian(x: np.ndarray) -> np.ndarray:
        d = q - x[:3]
        norm = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-12)
        return np.hstack([-d / norm, -np.ones((len(q), 1))])

    start = np.append(centre0 - shift, radius0)
    fit = optimize.least_squares(residual, start, jac=jacobian, method="lm", xtol=1e-12, ftol=1e-12)
    return fit.x[:3] + shift, float(abs(fit.x[3]))


def _sphere_algebraic(p: np.ndarray) -> tuple[np.ndarray, float]:
    """Linear fit |p|^2 = 2 c.p + (r^2 - |c|^2); good start, biased under noise."""
    shift = p.mean(axis=0)
    q = p - shift
    a = np.hstack([2.0 * q, np.ones((len(q), 1))])
    b = np.sum(q * q, axis=1)
    sol = np.linalg.lstsq(a, b, rcond=None)[0]
    centre = sol[:3]
    radius = float(np.sqrt(max(sol[3] + centre @ centre, 0.0)))
    return centre + shift, radius


def plane_lsq(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthogonal least-squares plane: (centroid (3,), unit normal (3,) with non-negative z)."""
    p = _check_points(points, 3, "plane")
    centroid = p.mean(axis=0)
    normal = np.linalg.svd(p - centroid, full_matrices=False)[2][-1]
    return centroid, (normal if normal[2] >= 0 else -normal)


def _ransac_spheres(p: np.ndarray, radius: float, rng: np.random.Generator) -> np.ndarray:
    """Centres (K, 3) of candidate spheres through 4-point samples, radius within 15 % of ``radius``."""
    idx = rng.integers(0, len(p), size=(RANSAC_SAMPLES, 4))
    quad = p[idx]  # (S, 4, 3)
    a = np.concatenate([2.0 * quad, np.ones((RANSAC_SAMPLES, 4, 1))], axis=2)
    b = np.sum(quad * quad, axis=2)
    ok = np.abs(np.linalg.det(a)) > 1e-9
    sol = np.linalg.solve(a[ok], b[ok][..., None])[..., 0]
    centres = sol[:, :3]
    radii = np.sqrt(np.maximum(sol[:, 3] + np.sum(centres * centres, axis=1), 0.0))
    return centres[np.abs(radii - radius) < 0.15 * radius]


def find_sphere(
    points: np.ndarray, radius_mm: float, tolerance_mm: float, rng: np.random.Generator | None = None
) -> np.ndarray:
    """Boolean mask of the points on the sphere of about ``radius_mm`` with the most support.

    ``tolerance_mm``: how far from the candidate sphere a point may lie and still vote for it.
    Raises ValueError when no candidate of that size is found.
    """
    p = _check_points(points, 4, "sphere")
    rng = np.random.default_rng(0) if rng is None else rng
    subset = p[rng.choice(len(p), size=min(RANSAC_SUBSET, len(p)), replace=False)]
    centres = _ransac_spheres(subset, radius_mm, rng)
    if not len(centres):
        raise ValueError(f"no sphere of diameter near {2 * radius_mm:g} mm found among {len(p)} points")
    # distances of the subset to each candidate's nominal sphere, in one (K, M) array
    dist = np.abs(np.linalg.norm(subset[None, :, :] - centres[:, None, :], axis=2) - radius_mm)
    best = centres[int(np.argmax(np.sum(dist < tolerance_mm, axis=1)))]
    return np.abs(np.linalg.norm(points - best, axis=1) - radius_mm) < 2.0 * tolerance_mm


def find_plane(points: np.ndarray, tolerance_mm: float, rng: np.random.Generator | None = None) -> np.ndarray:
    """Boolean mask of the points on the plane with the most support (RANSAC over 3-point samples)."""
    p = _check_points(points, 3, "plane")
    rng = np.random.default_rng(0) if rng is None else rng
    subset = p[rng.choice(len(p), size=min(RANSAC_SUBSET, len(p)), replace=False)]
    tri = subset[rng.integers(0, len(subset), size=(RANSAC_SAMPLES, 3))]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normals, axis=1)
    keep = length > 1e-9
    normals = normals[keep] / length[keep, None]
    offsets = np.sum(normals * tri[keep, 0], axis=1)
    support = np.sum(np.abs(subset @ normals.T - offsets) < tolerance_mm, axis=0)
    best = int(np.argmax(support))
    return np.abs(points @ normals[best] - offsets[best]) < 2.0 * tolerance_mm


def _residuals(kind: str, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    if kind == "sphere":
        centre, radius = sphere_lsq(p)
        return np.linalg.norm(p - centre, axis=1) - radius, centre, radius, np.zeros(3)
    centroid, normal = plane_lsq(p)
    return (p - centroid) @ normal, centroid, float("nan"), normal


def fit_form(kind: str, points: np.ndarray, excluded_fraction: float = EXCLUDED_FRACTION) -> FormFit:
    """Trimmed least-squares ``kind`` ("sphere", "plane") of the points of one artefact.

    Points further than :data:`TRIM_SIGMAS` robust sigmas from the fit are trimmed (repeated until
    none is), then the ``excluded_fraction`` of largest |residual| is left out and the element
    refitted: its residuals give PF or F.
    """
    if kind not in ("sphere", "plane"):
        raise ValueError(f"kind: expected 'sphere' or 'plane', found {kind!r}")
    p = _check_points(points, 4 if kind == "sphere" else 3, kind)
    total = len(p)
    for _ in range(10):
        res = _residuals(kind, p)[0]
        scale = 1.4826 * np.median(np.abs(res - np.median(res)))
        keep = np.abs(res - np.median(res)) <= TRIM_SIGMAS * max(scale, 1e-9)
        if keep.all() or keep.sum() < 8:
            break
        p = p[keep]
    trimmed = total - len(p)
    res = _residuals(kind, p)[0]
    drop = int(np.floor(excluded_fraction * len(p)))
    if drop:
        p = p[np.argsort(np.abs(res))[: len(p) - drop]]
    res, centre, radius, normal = _residuals(kind, p)
    return FormFit(kind, centre, radius, normal, res, p, trimmed, drop)
