"""Re-admit well-modulated pixels that a temporal unwrapping rejected, where neighbours vouch for them.

Temporal methods (heterodyne, hierarchical, multi-frequency) mark a pixel invalid when one of its
residuals exceeds a tolerance chosen for the worst case. On real rigs whole 1-2 px slivers fail
that test although their fringe order is right (a beat phase crosses its wrap a pixel later than
the finer phase, defocus blurs a wrap), so the product kept fewer pixels than a plain modulation
threshold. A rejected pixel is taken back when

1. its modulation passed (it is a ``candidate``),
2. at least ``min_support`` valid pixels in the (2 radius + 1)^2 window around it lie on a plane
   (least-squares fit, RMS misfit below ``max_fit_rms`` rad; a depth step does not),
3. its absolute phase, with the order the unwrapping gave it, is within ``tolerance`` rad of that
   plane at the pixel. The order itself is never changed: a pixel whose order disagrees with its
   neighbours stays out.

Passes repeat (rescued pixels support their neighbours) until none is added or ``passes`` run out.
Only the candidates are visited, so the cost follows the number of rejected pixels.
"""

from __future__ import annotations

import numpy as np


def plane_estimate(
    phase: np.ndarray, valid: np.ndarray, rows: np.ndarray, cols: np.ndarray, radius: int = 3
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Value at (rows, cols) of the plane fitted to the valid ``phase`` in each window.

    Returns (estimate, support count, RMS misfit of the fit); estimate NaN where fewer than three
    supporting pixels. Degenerate windows (one line of support) fall back towards the mean through
    a small ridge on the slopes.
    """
    h, w = phase.shape
    offsets = np.arange(-radius, radius + 1)
    grid_y, grid_x = np.meshgrid(offsets, offsets, indexing="ij")
    dy, dx = grid_y.ravel().astype(np.float64), grid_x.ravel().astype(np.float64)
    yy = rows[:, None] + dy.astype(np.int64)[None, :]
    xx = cols[:, None] + dx.astype(np.int64)[None, :]
    inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
    yy, xx = np.clip(yy, 0, h - 1), np.clip(xx, 0, w - 1)
    values = phase[yy, xx]
    weight = (inside & valid[yy, xx] & np.isfinite(values)).astype(np.float64)
    values = np.where(weight > 0, values, 0.0)
    n = weight.sum(axis=1)
    # normal equations of [1, dx, dy] per candidate
    sx, sy = weight @ dx, weight @ dy
    sxx, syy, sxy = weight @ (dx * dx), weight @ (dy * dy), weight @ (dx * dy)
    wv = weight * values
    sv, sxv, syv = wv.sum(axis=1), wv @ dx, wv @ dy
    ridge = 1e-6 * np.maximum(n, 1.0)
    a = np.stack(
        [np.stack([n, sx, sy], -1), np.stack([sx, sxx + ridge, sxy], -1), np.stack([sy, sxy, syy + ridge], -1)], -2
    )
    b = np.stack([sv, sxv, syv], -1)
    enough = n >= 3
    coef = np.full((rows.size, 3), np.nan)
    if enough.any():
        coef[enough] = np.linalg.solve(a[enough], b[enough][..., None])[..., 0]
    fitted = coef[:, :1] + coef[:, 1:2] * dx[None, :] + coef[:, 2:3] * dy[None, :]
    misfit = np.where(weight > 0, values - fitted, 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rms = np.sqrt((misfit * misfit).sum(axis=1) / n)
    return coef[:, 0], n, rms


def rescue(
    phase: np.ndarray,
    valid: np.ndarray,
    candidates: np.ndarray,
    tolerance: float = np.pi / 4,
    radius: int = 3,
    min_support: int = 8,
    max_fit_rms: float = 0.3,
    passes: int = 3,
) -> np.ndarray:
    """The valid mask with rejected ``candidates`` re-admitted where their neighbours vouch for them.

    Parameters
    ----------
    phase : (H, W) float array
        Absolute phase with the orders the unwrapping chose, finite also where it was rejected.
    valid : (H, W) bool array
        What the unwrapping accepted.
    candidates : (H, W) bool array
        Pixels that may be re-admitted (lit and well modulated).
    tolerance, radius, min_support, max_fit_rms, passes :
        See the module docstring.

    Returns
    -------
    (H, W) bool array: ``valid`` or a re-admitted candidate.
    """
    phase = np.asarray(phase, dtype=np.float64)
    out = np.asarray(valid, dtype=bool).copy()
    pending = np.asarray(candidates, dtype=bool) & ~out & np.isfinite(phase)
    for _ in range(passes):
        rows, cols = np.nonzero(pending)
        if rows.size == 0:
            break
        estimate, support, rms = plane_estimate(phase, out, rows, cols, radius)
        with np.errstate(invalid="ignore"):
            ok = (support >= min_support) & (rms <= max_fit_rms) & (np.abs(phase[rows, cols] - estimate) <= tolerance)
        if not ok.any():
            break
        out[rows[ok], cols[ok]] = True
        pending[rows[ok], cols[ok]] = False
    return out
