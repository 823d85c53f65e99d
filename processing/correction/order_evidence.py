"""Whether the neighbours support a change of fringe orders, blob by blob, and where nothing decides.

A spatial correction proposes new orders for some pixels; temporal unwrapping measured others.
Both are evidence, neither is the truth. Where the proposal differs from the measurement, the
pixels that changed form blobs (8-connected). Each blob is judged on its own by the order breaks
(4-neighbour steps beyond pi) on the edges that touch it, counted once with the proposed and
once with the measured orders:

- fewer breaks with the proposal: the change makes the blob agree with its surroundings (a wrong
  temporal order, the case corrections are for) and is kept;
- fewer with the measurement: the proposal broke a surface the measurement had right (a region
  pooled across a real height step, a low-rank estimate off at an edge) and the measured orders
  stay;
- as many either way: the neighbours cannot tell the two apart (an object whose border steps by a
  whole number of fringes, a region too small to carry evidence). The measured orders stay and
  the blob is reported as unresolved rather than guessed.

A change must earn its place, so a wrong proposal can never win by a tie.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi
# The largest unresolved blobs listed in a report, by size.
LISTED_REGIONS = 20
FOUR_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1))  # (dy, dx) of a pixel's 4-neighbours


def neighbours_at(
    phase: np.ndarray, valid: np.ndarray, rows: np.ndarray, cols: np.ndarray, reach: int = 1
) -> np.ndarray:
    """(4, n): ``phase`` at the 4-neighbours of the given pixels, in :data:`FOUR_NEIGHBOURS` order, ``reach``
    pixels away (2: the neighbours' neighbours straight on); NaN where one lies off the map or outside ``valid``."""
    height, width = valid.shape
    out = np.empty((len(FOUR_NEIGHBOURS), np.size(rows)))
    for side, (dy, dx) in enumerate(FOUR_NEIGHBOURS):
        y, x = rows + reach * dy, cols + reach * dx
        seen = (y >= 0) & (y < height) & (x >= 0) & (x < width)
        y, x = np.clip(y, 0, height - 1), np.clip(x, 0, width - 1)
        seen &= valid[y, x]
        out[side] = np.where(seen, phase[y, x], np.nan)
    return out


def label_blobs(mask: np.ndarray) -> tuple[int, np.ndarray]:
    """8-connected blobs of ``mask``: (count including the background label 0, int32 labels)."""
    import cv2  # lazily: only auto needs it

    count, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=8, ltype=cv2.CV_32S)
    return int(count), labels


def beyond_pi(second: np.ndarray, first: np.ndarray) -> np.ndarray:
    """``|second - first| > pi`` (NaN: False) with one float temporary written in one pass
    (:func:`~processing.elementwise.abs_difference`; the expression as written allocates two)."""
    difference = abs_difference(second, first)
    with np.errstate(invalid="ignore"):
        return np.greater(difference, np.pi)


def changed_orders(proposed: np.ndarray, measured: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The valid pixels whose orders differ, ``valid & (|proposed - measured| > pi)``."""
    changed = beyond_pi(proposed, measured)
    changed &= valid
    return changed


def blob_edges(valid: np.ndarray, inside: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """The 4-neighbour edges between valid pixels that touch a blob pixel (``inside``), along the rows and then
    down the columns: (first pixels, second pixels) as flat indices, the second to the right of or below the first.

    Edges away from every blob decide nothing, so the blob steps count the breaks on these only.
    """
    width = valid.shape[1]
    flat_valid, flat_inside = np.ravel(valid), np.ravel(inside)
    edges = []
    for step in (1, width):  # along the rows on the flat map: no edge from a row's last pixel to the next row
        pair = flat_inside[:-step] | flat_inside[step:]
        pair &= flat_valid[:-step]
        pair &= flat_valid[step:]
        if step == 1:
            pair[width - 1 :: width] = False
        first = np.flatnonzero(pair)
        edges.append((first, first + step))
    return edges


def breaks_per_blob(
    phase: np.ndarray,
    valid: np.ndarray,
    labels: np.ndarray,
    count: int,
    edges: list[tuple[np.ndarray, np.ndarray]] | None = None,
) -> np.ndarray:
    """Order breaks (|step| > pi between valid 4-neighbours) on the edges touching each blob of ``labels``.

    An edge between two blobs counts for both; an edge inside a blob once. Label 0 (no blob) counts
    the breaks on its edges to blobs and is meaningless. ``edges``: :func:`blob_edges` of ``valid``
    and the blobs, taken once where several phases are counted on the same blobs.
    """
    if edges is None:
        edges = blob_edges(valid, labels != 0)
    flat_labels = np.ravel(labels)
    out = np.zeros(count, dtype=np.int64)
    for first, second in edges:
        broken = _broken_at(phase, first, second)
        head, tail = flat_labels[first[broken]], flat_labels[second[broken]]
        out += np.bincount(head, minlength=count)
        out += np.bincount(tail[tail != head], minlength=count)
    return out


# Below one pair per this many pixels, :func:`_broken_at` gathers the pairs' pixels instead of stepping the whole map.
_GATHER_BELOW = 8


def _broken_at(phase: np.ndarray, first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """``|phase[second] - phase[first]| > pi`` (NaN: False) for flat pixel pairs one step apart along the rows
    (second = first + 1) or down the columns (second = first + width), as :func:`blob_edges` gives them.

    The breaks of the whole map (:func:`beyond_pi` of its steps), read at the pairs: two gathers of float pixels
    and the arithmetic on them cost several times more where edges are many.
    """
    if first.size * _GATHER_BELOW < phase.size:  # few pairs: gathering them costs less than a pass over the map
        flat = np.ravel(phase)
        return beyond_pi(flat[second], flat[first])
    width = phase.shape[1]
    if int(second[0] - first[0]) == 1:
        return beyond_pi(phase[:, 1:], phase[:, :-1]).reshape(-1)[first - first // width]  # (H, W - 1) positions
    return beyond_pi(phase[1:], phase[:-1]).reshape(-1)[first]


def keep_supported_changes(
    proposed: np.ndarray, measured: np.ndarray, valid: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``proposed`` where its neighbours support it better than ``measured``; the unresolved pixels.

    Parameters
    ----------
    proposed, measured : (H, W) absolute phases with the same wrapped phase (orders differ)
    valid : (H, W) bool

    Returns
    -------
    phase : (H, W) ``proposed``, with each changed blob that does not have fewer order breaks
        than with the measured orders set back to ``measured``
    unresolved : (H, W) bool, the pixels of blobs with as many breaks either way
    """
    changed = changed_orders(proposed, measured, valid)
    if not changed.any():
        return proposed, changed
    count, labels = label_blobs(changed)
    edges = blob_edges(valid, changed)
    with_proposal = breaks_per_blob(proposed, valid, labels, count, edges)
    with_measured = breaks_per_blob(measured, valid, labels, count, edges)
    back = with_measured <= with_proposal
    tie = with_measured == with_proposal
    back[0] = tie[0] = False
    if not back.any():
        return proposed, np.zeros(valid.shape, dtype=bool)
    at = np.flatnonzero(changed)  # only the changed pixels carry a blob label
    blob = np.ravel(labels)[at]
    return revert_changed(proposed, measured, at, back[blob], tie[blob])


def revert_changed(
    proposed: np.ndarray, measured: np.ndarray, at: np.ndarray, back: np.ndarray, unresolved: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A copy of ``proposed`` with ``measured`` at the changed pixels ``at`` (flat indices) where ``back``, and
    the mask of those where ``unresolved``: the evidence steps write only where orders changed, never the whole map."""
    out = proposed.copy()
    out.reshape(-1)[at[back]] = np.ravel(measured)[at[back]]
    return out, mask_at(proposed.shape, at[unresolved])


def mask_at(shape: tuple[int, ...], at: np.ndarray) -> np.ndarray:
    """A bool map of ``shape``, True at the flat indices ``at``."""
    mask = np.zeros(shape, dtype=bool)
    mask.reshape(-1)[at] = True
    return mask


def unresolved_summary(unresolved: np.ndarray, valid: np.ndarray) -> dict[str, Any]:
    """Report entry of an unresolved mask: pixels, fraction of the valid pixels, and where.

    ``regions`` lists the :data:`LISTED_REGIONS` largest blobs, largest first, as
    ``[top, left, bottom, right, pixels]`` (rows and columns inclusive).
    """
    pixels = int(np.count_nonzero(unresolved))
    total = max(int(np.count_nonzero(valid)), 1)
    regions: list[list[int]] = []
    if pixels:
        count, labels = label_blobs(unresolved)  # OpenCV's statistics cost 10x the labelling: taken here instead
        at = np.flatnonzero(unresolved)  # the labelled pixels
        label = np.ravel(labels)[at]
        area = np.bincount(label, minlength=count)
        order = np.argsort(-area[1:], kind="stable")[:LISTED_REGIONS] + 1
        listed = np.zeros(count, dtype=bool)
        listed[order] = True
        rows, cols = np.divmod(at[listed[label]], unresolved.shape[1])
        label = label[listed[label]]
        box = np.zeros((4, count), dtype=np.int64)  # top, left, bottom, right
        box[:2] = np.iinfo(np.int64).max
        np.minimum.at(box[0], label, rows)
        np.minimum.at(box[1], label, cols)
        np.maximum.at(box[2], label, rows)
        np.maximum.at(box[3], label, cols)
        regions = [[*(int(v) for v in box[:, index]), int(area[index])] for index in order]
    return {"pixels": pixels, "fraction": round(pixels / total, 6), "regions": regions}


def mend_spikes(
    phase: np.ndarray, valid: np.ndarray, misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None
) -> tuple[np.ndarray, int]:
    """``phase`` with every order spike moved onto the order its neighbours support; how many moved.

    A spike is a valid pixel whose four neighbours are all valid and all more than pi away: no
    surface a camera resolves puts one pixel a fringe or more off everything around it, but a wrong
    order does (left by every step before when its blob was a tie, e.g. at a corner of a step where
    two neighbours sit on each side). Each spike takes the order that makes it continuous with the
    most neighbours; between equally supported orders (a corner), the one with the lowest
    ``misfit(values, spikes)`` (the misfit of candidate phases at the spike pixels with the lower
    frequencies, when given), else the one nearest the neighbours' median.
    """
    ys, xs = _spike_pixels(phase, valid)
    if not ys.size:
        return phase, 0
    at = phase[ys, xs]
    # the four neighbours, up, down, left, right (all valid at a spike)
    around = np.stack([phase[ys - 1, xs], phase[ys + 1, xs], phase[ys, xs - 1], phase[ys, xs + 1]])  # (4, n)
    candidates = at + TWO_PI * np.rint((around - at) / TWO_PI)  # the order of each neighbour's side
    support = (np.abs(candidates[:, None, :] - around[None, :, :]) <= np.pi).sum(axis=1)  # (4, n)
    if misfit is not None:
        spike = np.zeros(valid.shape, dtype=bool)
        spike[ys, xs] = True
        tie_break = np.stack([misfit(c, spike) for c in candidates])
    else:
        tie_break = np.abs(candidates - np.median(around, axis=0))
    score = np.where(support == support.max(axis=0), tie_break, np.inf)
    choice = np.argmin(score, axis=0)
    out = phase.copy()
    out[ys, xs] = candidates[choice, np.arange(at.size)]
    return out, int(at.size)


def _spike_pixels(phase: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Rows and columns (row-major) of the valid pixels whose four neighbours are all valid and all more than
    pi away: the steps along the rows are taken once over the map, and the steps up and down only at the few
    pixels that break with both their left and right neighbours."""
    with np.errstate(invalid="ignore"):
        step = np.diff(phase, axis=1)
        across = np.abs(step, out=step) > np.pi
        across &= valid[:, 1:]
        across &= valid[:, :-1]  # (H, W - 1)
        sides = across[1:-1, 1:] & across[1:-1, :-1]  # pixels off the border
        ys, xs = np.divmod(np.flatnonzero(sides), sides.shape[1])
        ys += 1
        xs += 1
        here = phase[ys, xs]
        keep = valid[ys - 1, xs] & valid[ys + 1, xs]
        keep &= np.abs(phase[ys - 1, xs] - here) > np.pi
        keep &= np.abs(phase[ys + 1, xs] - here) > np.pi
    return ys[keep], xs[keep]
