"""Pixels whose kept order breaks with three or four of their neighbours take the order more of them support.

:func:`~processing.correction.order_evidence.mend_spikes` moves a pixel a fringe or more off all four
neighbours. Beside an object's edge a spatial correction also leaves pixels one to eight orders off in
pairs or short runs along the edge (pooled with the other side of the edge): each breaks with three of
its four neighbours, its partner in the run being the fourth, so none is a spike. No surface a camera
resolves puts a pixel a fringe or more off three of its four neighbours where another order is
continuous with more of them.

Each such pixel (four valid neighbours, three or four of them more than pi away) is offered the order of
each neighbour's side, ``phi + 2 pi round((neighbour - phi) / 2 pi)``, and takes the one continuous with
the most neighbours (between equals, the one the lower frequencies fit best) only where that is more
neighbours than its own order is continuous with, and, with the lower frequencies, only where they fit
the new order no worse than the kept one: the move needs the neighbours' evidence for it and none
against it. Pixels next to a moved one are judged again (a run mends from its ends), up to
:data:`PASSES` times.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from processing.correction.order_evidence import FOUR_NEIGHBOURS, beyond_pi

TWO_PI = 2.0 * np.pi
# Passes over the pixels next to those that moved: runs of up to about twice this many pixels mend.
PASSES = 3


def mend_broken_pixels(
    phase: np.ndarray, valid: np.ndarray, misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
) -> tuple[np.ndarray, int]:
    """``phase`` with the pixels that break with three or four neighbours moved where more support another order.

    Parameters
    ----------
    phase : (H, W) absolute phase (orders differ by whole fringes only)
    valid : (H, W) bool
    misfit : optional ``misfit(values, where)``, the lower frequencies' misfit of candidate phases at the
        pixels of the (H, W) mask ``where`` (row-major order along the last axis of ``values``, which may
        stack several candidates); without it the neighbours decide alone

    Returns the phase and how many pixel moves were made.

    Examples
    --------
    A ramp with a vertical pair of pixels two orders off (each breaks with three neighbours):

    >>> import numpy as np
    >>> truth = np.tile(np.linspace(0.0, 12.0, 12), (10, 1))
    >>> kept = truth.copy()
    >>> kept[4:6, 6] += 2 * 2 * np.pi
    >>> out, moved = mend_broken_pixels(kept, np.ones((10, 12), bool))
    >>> bool(np.allclose(out, truth)), moved
    (True, 2)
    """
    ys, xs = _broken_pixels(phase, valid)
    out, total = phase, 0
    for _ in range(PASSES):
        if not ys.size:
            break
        out, moved = _mend_at(out, valid, ys, xs, misfit)
        if not moved.any():
            break
        total += int(np.count_nonzero(moved))
        ys, xs = _next_to(ys[moved], xs[moved], valid)
    return out, total


def _broken_pixels(phase: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (row-major) of the valid pixels off the border with four valid neighbours, three or four of
    them more than pi away.

    On the flat map, where every shift is a contiguous slice (a 2-D slice off the first column is strided and costs
    twice as much): pixel ``p`` steps ``across[p - 1]`` to its left, ``across[p]`` to its right, ``down[p - W]``
    up and ``down[p]`` down. Only pixels whose four neighbours are valid count, so no step needs its own validity
    test; the first and last columns, where the flat map wraps a row, are dropped at the end.
    """
    rows, cols = phase.shape
    flat, flat_valid = np.ravel(phase), np.ravel(valid)
    across = beyond_pi(flat[1:], flat[:-1])
    down = beyond_pi(flat[cols:], flat[:-cols])
    inner = rows * cols - 2 * cols  # the pixels of rows 1 .. H - 2, from flat index W on
    left, right = across[cols - 1 : cols - 1 + inner], across[cols : cols + inner]
    up, below = down[:inner], down[cols : cols + inner]
    # three or four of four: both of one pair and at least one of the other
    broken = (left & right & (up | below)) | (up & below & (left | right))
    for start in (cols, cols - 1, cols + 1, 0, 2 * cols):  # the pixel, left, right, up, down
        broken &= flat_valid[start : start + inner]
    at = np.flatnonzero(broken) + cols
    ys, xs = at // cols, at % cols
    keep = (xs > 0) & (xs < cols - 1)
    return ys[keep], xs[keep]


def _next_to(ys: np.ndarray, xs: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The pixels 4-adjacent to the given ones, off the border and with four valid neighbours (row-major, once)."""
    rows, cols = valid.shape
    ny = np.concatenate([ys + dy for dy, _ in FOUR_NEIGHBOURS])
    nx = np.concatenate([xs + dx for _, dx in FOUR_NEIGHBOURS])
    inside = (ny >= 1) & (ny < rows - 1) & (nx >= 1) & (nx < cols - 1)
    flat = np.unique(ny[inside] * cols + nx[inside])
    ny, nx = flat // cols, flat % cols
    keep = valid[ny, nx]
    for dy, dx in FOUR_NEIGHBOURS:
        keep &= valid[ny + dy, nx + dx]
    return ny[keep], nx[keep]


def _mend_at(
    phase: np.ndarray,
    valid: np.ndarray,
    ys: np.ndarray,
    xs: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One pass at the given pixels (all with four valid neighbours): the phase and which of them moved."""
    at = phase[ys, xs]
    around = np.stack([phase[ys + dy, xs + dx] for dy, dx in FOUR_NEIGHBOURS])  # (4, n)
    own = (np.abs(around - at) <= np.pi).sum(axis=0)
    candidates = at + TWO_PI * np.rint((around - at) / TWO_PI)  # the order of each neighbour's side
    support = (np.abs(candidates[:, None, :] - around[None, :, :]) <= np.pi).sum(axis=1)  # (4, n)
    best = support.max(axis=0)
    moved = (own <= 1) & (best > own)
    if not moved.any():
        return phase, moved
    index = np.arange(at.size)
    if misfit is None:
        choice = np.argmax(support, axis=0)
    else:
        where = np.zeros(valid.shape, dtype=bool)
        where[ys, xs] = True  # ys, xs are row-major: the mask's order
        fits = misfit(np.vstack([candidates, at[None, :]]), where)  # the lower phases gathered once for all five
        choice = np.argmin(np.where(support == best, fits[:4], np.inf), axis=0)
        moved &= fits[choice, index] <= fits[4]
    out = phase.copy()
    out[ys[moved], xs[moved]] = candidates[choice, index][moved]
    return out, moved
