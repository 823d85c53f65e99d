"""Triangles of an organised point grid: one camera pixel, one vertex; neighbours joined, jumps cut."""

from __future__ import annotations

import numpy as np

# An edge is cut when its depth step exceeds this many times the grid's typical in-plane spacing:
# surfaces up to atan(8) = 83 degrees from facing the camera stay whole, occlusion edges are cut.
DEFAULT_MAX_SLOPE = 8.0


def grid_triangles(points: np.ndarray, mask: np.ndarray, max_slope: float = DEFAULT_MAX_SLOPE) -> np.ndarray:
    """Triangles joining valid neighbours of an organised grid, cut where the depth jumps.

    Parameters
    ----------
    points : (H, W, 3) float array
        The point of each pixel (x, y, z); only pixels in ``mask`` are used.
    mask : (H, W) bool array
        Valid pixels. Vertex ``k`` is the ``k``-th valid pixel in C order (``points[mask][k]``).
    max_slope : float
        An edge between two neighbours is kept when ``|dz| <= max_slope * s``, with ``s`` the
        median in-plane (x, y) distance of horizontally adjacent valid pixels.

    Returns
    -------
    faces : (M, 3) int32 array
        Vertex indices; each 2 x 2 cell gives up to two triangles, (top-left, top-right,
        bottom-left) and (top-right, bottom-right, bottom-left), kept only when all three corners
        are valid and all three edges are kept. Same winding for every triangle.

    Examples
    --------
    >>> yy, xx = np.mgrid[0:2, 0:3].astype(float)
    >>> grid = np.dstack([xx, yy, np.zeros_like(xx)])
    >>> grid_triangles(grid, np.ones((2, 3), bool)).tolist()
    [[0, 1, 3], [1, 4, 3], [1, 2, 4], [2, 5, 4]]
    """
    points = np.asarray(points)
    mask = np.asarray(mask, dtype=bool)
    if points.ndim != 3 or points.shape[2] != 3 or points.shape[:2] != mask.shape:
        raise ValueError(f"points: expected (H, W, 3) matching mask {mask.shape}, found {points.shape}")
    if not max_slope > 0:
        raise ValueError(f"max_slope: expected > 0, found {max_slope}")
    if mask.shape[0] < 2 or mask.shape[1] < 2:
        return np.empty((0, 3), dtype=np.int32)
    valid = mask & np.isfinite(points).all(axis=2)
    index = np.full(mask.shape, -1, dtype=np.int64)
    index[mask] = np.arange(int(np.count_nonzero(mask)))
    limit = max_slope * _spacing(points, valid)
    z = points[..., 2]

    def joined(first: tuple[slice, slice], second: tuple[slice, slice]) -> np.ndarray:
        with np.errstate(invalid="ignore"):
            return valid[first] & valid[second] & (np.abs(z[first] - z[second]) <= limit)

    top, bottom, left, right = slice(None, -1), slice(1, None), slice(None, -1), slice(1, None)
    across = joined((slice(None), left), (slice(None), right))  # (H, W-1)
    down = joined((top, slice(None)), (bottom, slice(None)))  # (H-1, W)
    diagonal = joined((top, right), (bottom, left))  # top-right to bottom-left, (H-1, W-1)
    keep_upper = across[:-1] & down[:, :-1] & diagonal
    keep_lower = down[:, 1:] & across[1:] & diagonal
    tl, tr, bl, br = index[top, left], index[top, right], index[bottom, left], index[bottom, right]
    triangles = np.stack([np.stack([tl, tr, bl], axis=-1), np.stack([tr, br, bl], axis=-1)], axis=2)
    keep = np.stack([keep_upper, keep_lower], axis=2)
    return triangles[keep].astype(np.int32)


def _spacing(points: np.ndarray, valid: np.ndarray) -> float:
    """Median in-plane distance of horizontally adjacent valid pixels (1.0 when there are none)."""
    both = valid[:, :-1] & valid[:, 1:]
    if not both.any():
        return 1.0
    step = points[:, 1:, :2][both] - points[:, :-1, :2][both]
    spacing = float(np.median(np.hypot(step[:, 0], step[:, 1])))
    return spacing if spacing > 0 and np.isfinite(spacing) else 1.0
