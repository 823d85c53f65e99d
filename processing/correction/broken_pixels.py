"""Pixels whose kept order breaks with three or four of their neighbours take the order more of them support.

:func:`~processing.correction.order_evidence.mend_spikes` moves a pixel a fringe or more off all four
neighbours. Beside an object's edge a spatial correction also leaves pixels one to eight orders off in
pairs or short runs along the edge (pooled with the other side of the edge): each breaks with three of
its four neighbours, its partner in the run being the fourth, so none is a spike. No surface a camera
resolves puts a pixel a fringe or more off three of its four neighbours where another order is
continuous with more of them.

Beside a shadow or the map's border a pixel has three valid neighbours; breaking with all three is the same
evidence (three neighbours a fringe or more away), and such pixels are judged alike: temporal unwrapping
fails most often there, where the fringes lose contrast, and neither this step nor the spikes' saw them.

Each such pixel (three or four valid neighbours, three or four of them more than pi away) is offered the order of
each neighbour's side, ``phi + 2 pi round((neighbour - phi) / 2 pi)``, and takes the one continuous with
the most neighbours (between equals, the one the lower frequencies fit best) only where that is more
neighbours than its own order is continuous with, and, with the lower frequencies, only where they fit
the new order no worse than the kept one: the move needs the neighbours' evidence for it and none
against it. Pixels next to a moved one are judged again (a run mends from its ends), up to
:data:`PASSES` times.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from processing.correction.order_evidence import FOUR_NEIGHBOURS, beyond_pi, neighbours_at
from processing.correction.region_orders import neighbour_steps_at

TWO_PI = 2.0 * np.pi
# Passes over the pixels next to those that moved: runs of up to about twice this many pixels mend.
PASSES = 3
# Relative rounding of the lower frequencies' misfit: orders a whole cycle of every lower frequency apart (36 orders
# of 1/6/36) fit them equally, yet their misfits differ in the last digits, and a strict "no worse" kept a wrong order
# by 1e-13 of a misfit.
ROUNDING = 1e-9


def mend_broken_pixels(
    phase: np.ndarray,
    valid: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
    next_to: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """``phase`` with the pixels that break with three or four neighbours moved where more support another order.

    Parameters
    ----------
    phase : (H, W) absolute phase (orders differ by whole fringes only)
    valid : (H, W) bool
    misfit : optional ``misfit(values, where)``, the lower frequencies' misfit of candidate phases at the
        pixels of the (H, W) mask ``where`` (row-major order along the last axis of ``values``, which may
        stack several candidates); without it the neighbours decide alone
    next_to : optional (H, W) bool, pixels another step moved: only the pixels next to them are judged (a run
        of wrong pixels along an edge breaks with too few neighbours to be judged until part of it moves)

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
    if next_to is None:
        ys, xs = _broken_pixels(phase, valid)
    else:
        moved_ys, moved_xs = np.nonzero(next_to)
        ys, xs = _next_to(moved_ys, moved_xs, valid)
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
    them more than pi away, and of those beside a shadow or the border with three valid neighbours, all three more
    than pi away.

    On the flat map, where every shift is a contiguous slice (a 2-D slice off the first column is strided and costs
    twice as much): pixel ``p`` steps ``across[p - 1]`` to its left, ``across[p]`` to its right, ``down[p - W]``
    up and ``down[p]`` down. Only pixels whose four neighbours are valid count, so no step needs its own validity
    test; the first and last columns, where the flat map wraps a row, are dropped at the end. The pixels with three
    valid neighbours lie on the mask's outline and are tested there only.
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
    column = at % cols
    keep = (column > 0) & (column < cols - 1)
    rim = _beside_the_mask_edge(valid)
    # three of three valid neighbours away: the left or the right one among them (the cheap test, on the row steps)
    x = rim % cols
    rim = rim[(across[np.maximum(rim - 1, 0)] & (x > 0)) | (across[np.minimum(rim, across.size - 1)] & (x < cols - 1))]
    ys, xs = np.divmod(rim, cols)
    breaks, continues = neighbour_steps_at(phase, valid, ys, xs)
    at = np.union1d(at[keep], rim[(breaks == 3) & (continues == 0)])  # row-major, each once
    return np.divmod(at, cols)


def _beside_the_mask_edge(valid: np.ndarray) -> np.ndarray:
    """Flat indices (row-major) of the valid pixels with a 4-neighbour invalid or off the map: where a pixel may
    have three valid neighbours (few: the outline of the mask)."""
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    inner = cv2.erode(valid.view(np.uint8), cross, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    return np.flatnonzero(valid & ~inner.view(bool))


def _next_to(ys: np.ndarray, xs: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The valid pixels 4-adjacent to the given ones with three or four valid neighbours (row-major, once)."""
    rows, cols = valid.shape
    ny = np.concatenate([ys + dy for dy, _ in FOUR_NEIGHBOURS])
    nx = np.concatenate([xs + dx for _, dx in FOUR_NEIGHBOURS])
    inside = (ny >= 0) & (ny < rows) & (nx >= 0) & (nx < cols)
    flat = np.unique(ny[inside] * cols + nx[inside])
    ny, nx = flat // cols, flat % cols
    keep = valid[ny, nx]
    ny, nx = ny[keep], nx[keep]
    count = np.isfinite(neighbours_at(valid, valid, ny, nx)).sum(axis=0)  # valid neighbours: the ones found
    return ny[count >= 3], nx[count >= 3]


def _mend_at(
    phase: np.ndarray,
    valid: np.ndarray,
    ys: np.ndarray,
    xs: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """One pass at the given pixels (all with three or four valid neighbours): the phase and which of them moved.

    A pixel moves where three or more of its valid neighbours lie more than pi away and another neighbour's order
    is continuous with more of them than its own (an invalid neighbour is NaN: it supports nothing)."""
    at = phase[ys, xs]
    around = neighbours_at(phase, valid, ys, xs)  # (4, n)
    with np.errstate(invalid="ignore"):
        own = (np.abs(around - at) <= np.pi).sum(axis=0)
        breaks = (np.abs(around - at) > np.pi).sum(axis=0)
        candidates = at + TWO_PI * np.rint((around - at) / TWO_PI)  # the order of each neighbour's side
        support = (np.abs(candidates[:, None, :] - around[None, :, :]) <= np.pi).sum(axis=1)  # (4, n)
    best = support.max(axis=0)
    moved = (breaks >= 3) & (best > own)
    if not moved.any():
        return phase, moved
    index = np.arange(at.size)
    if misfit is None:
        choice = np.argmax(support, axis=0)
    else:
        where = np.zeros(valid.shape, dtype=bool)
        where[ys, xs] = True  # ys, xs are row-major: the mask's order
        with np.errstate(invalid="ignore"):  # a missing neighbour's candidate is NaN, never chosen
            fits = misfit(np.vstack([candidates, at[None, :]]), where)  # the lower phases gathered once for all five
        choice = np.argmin(np.where(support == best, fits[:4], np.inf), axis=0)
        moved &= fits[choice, index] <= fits[4] * (1.0 + ROUNDING) + ROUNDING  # no worse, up to rounding
    out = phase.copy()
    out[ys[moved], xs[moved]] = candidates[choice, index][moved]
    return out, moved
