"""One point per pixel from several estimates of it along the same camera ray, weighted by their noise.

A camera-projector (stereo) model triangulates a pixel's camera ray with the projector plane its
absolute phase names. With fringes on both axes the pixel has two such planes, hence two points on
the same ray, ``P_x`` and ``P_y``, with predicted standard deviations ``s_x`` and ``s_y`` along
it (:func:`processing.geometry.uncertainty.height_sigma`). To first order their least-squares
intersection with both planes, weighted by the projector coordinates' noise, is the
inverse-variance mean

    P = (P_x / s_x^2 + P_y / s_y^2) / (1 / s_x^2 + 1 / s_y^2),   s = (1 / s_x^2 + 1 / s_y^2)^(-1/2)

so the axis whose plane cuts the ray at a shallow angle (much depth per projector pixel, large
``s``) carries little weight. Where only one estimate exists it is used alone. Where the two
disagree by more than :data:`AGREEMENT_SIGMAS` standard deviations of their difference (a fringe
order wrong on one axis, e.g. at the edge of the projector's image) nothing tells which is right:
the pixel gets no point and is counted.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

AGREEMENT_SIGMAS = 6.0  # as processing.phase.frequency_fusion: no honest pixel of a megapixel rejected by chance


@dataclass
class FusedPoints:
    """Output of :func:`fuse_points`: (H, W, 3) points and (H, W) sigma (NaN where no estimate or
    where they disagree), the pixels each estimate alone served (``alone[i]``), those both served
    (``combined``), and those where they disagreed (``disagreeing``, left without a point)."""

    points: np.ndarray
    sigma: np.ndarray
    combined: int
    alone: list[int]
    disagreeing: int


def fuse_points(points: Sequence[np.ndarray], sigmas: Sequence[np.ndarray]) -> FusedPoints:
    """The inverse-variance mean of two point estimates per pixel (NaN points or sigmas: no estimate).

    Parameters
    ----------
    points : two (H, W, 3) arrays
        Estimates of each pixel's point, NaN where that estimate does not exist.
    sigmas : two (H, W) arrays
        Their predicted standard deviations (mm, > 0).
    """
    if len(points) != 2 or len(sigmas) != 2:
        raise ValueError(f"points, sigmas: expected two estimates each, found {len(points)} and {len(sigmas)}")
    first, second = (np.asarray(p, dtype=np.float64) for p in points)
    s1, s2 = (np.asarray(s, dtype=np.float64) for s in sigmas)
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        has1 = np.isfinite(first).all(axis=-1) & np.isfinite(s1) & (s1 > 0)
        has2 = np.isfinite(second).all(axis=-1) & np.isfinite(s2) & (s2 > 0)
        w1, w2 = np.where(has1, 1.0 / np.square(s1), 0.0), np.where(has2, 1.0 / np.square(s2), 0.0)
        both = has1 & has2
        gap = np.linalg.norm(np.where(both[..., None], first - second, 0.0), axis=-1)
        disagree = both & (np.square(gap) > AGREEMENT_SIGMAS**2 * (np.square(s1) + np.square(s2)))
        total = w1 + w2
        fused = (np.where(w1[..., None] > 0, first, 0.0) * w1[..., None]) + (
            np.where(w2[..., None] > 0, second, 0.0) * w2[..., None]
        )
        fused /= total[..., None]
        sigma = 1.0 / np.sqrt(total)
    undecided = ~(has1 | has2) | disagree
    fused[undecided] = np.nan
    sigma[undecided] = np.nan
    return FusedPoints(
        points=fused,
        sigma=sigma.astype(np.float32),
        combined=int(np.count_nonzero(both & ~disagree)),
        alone=[int(np.count_nonzero(has1 & ~has2)), int(np.count_nonzero(has2 & ~has1))],
        disagreeing=int(np.count_nonzero(disagree)),
    )


def depth_per_projector_pixel(
    points: np.ndarray, rotation: np.ndarray, translation: np.ndarray, projector_matrix: np.ndarray
) -> tuple[float, float]:
    """Median distance (mm) a point moves along its camera ray per projector pixel, along x and along y.

    A point ``P = t d`` on a camera ray (camera at the origin) projects to the projector pixel
    ``(u, v)``; ``|dP/dt| / |du/dt|`` is the depth one projector column is worth, and likewise
    for rows. A projector axis nearly parallel to the epipolar lines' normal (a baseline along
    the other axis) gives a large value: its fringes carry little depth. Pinhole projection (the
    lens distortion changes this by a few per cent at most); NaN points are ignored.
    """
    flat = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    flat = flat[np.isfinite(flat).all(axis=1)]
    if not flat.size:
        return float("nan"), float("nan")
    stride = max(1, flat.shape[0] // 20000)  # a sample is enough for a median
    sample = flat[::stride]
    q = sample @ np.asarray(rotation, dtype=np.float64).T + np.asarray(translation, dtype=np.float64)
    dq = sample @ np.asarray(rotation, dtype=np.float64).T  # d(R t d + T)/dt at t = 1, scaled by |P| below
    fx, fy = float(projector_matrix[0, 0]), float(projector_matrix[1, 1])
    with np.errstate(invalid="ignore", divide="ignore"):
        # d(q_x / q_z)/dt for P = t d with d = P (t = 1): (dq_x q_z - q_x dq_z) / q_z^2
        du = fx * (dq[:, 0] * q[:, 2] - q[:, 0] * dq[:, 2]) / np.square(q[:, 2])
        dv = fy * (dq[:, 1] * q[:, 2] - q[:, 1] * dq[:, 2]) / np.square(q[:, 2])
        length = np.linalg.norm(sample, axis=1)
        per_u, per_v = length / np.abs(du), length / np.abs(dv)
    return float(np.nanmedian(per_u)), float(np.nanmedian(per_v))
