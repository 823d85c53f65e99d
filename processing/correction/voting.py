"""Row-wise voting correction of fringe orders (Ding et al. [119], thesis ch. 2.3.3).

Along a row, the wrapped phase rises continuously within one fringe and jumps by 2 pi at the
fringe boundaries, so every segment between two jumps has a single fringe order. Temporal
unwrapping recovers each pixel's order independently; a wrong order is an isolated outlier in its
segment. The method: (1) row by row, cut the order map into segments at the wrapped-phase jumps;
(2) in each segment, replace every order by the most frequent one.

It fails where most pixels of a segment share the same wrong order (the thesis notes this). Noise
at the wrap point cuts one- or two-pixel segments that carry no majority; here their pixels take
the order that makes them continuous with the nearest pixel of a proper segment on the same row
(an addition to [119]; ``min_segment=1`` switches it off).
"""

from __future__ import annotations

import numpy as np

from processing import _validate
from processing.correction.shadow_fill import valid_mask

TWO_PI = 2.0 * np.pi


def segment_labels(wrapped_phase: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Label (0 .. n-1, -1 for invalid pixels) of each run between wrapped-phase jumps along rows.

    A new segment starts at a row's first column, after any jump ``|phi(x+1) - phi(x)| > pi``,
    and after an invalid pixel.
    """
    rows, cols = wrapped_phase.shape
    jump = np.abs(np.diff(wrapped_phase, axis=1)) > np.pi
    starts = np.ones((rows, cols), dtype=bool)
    starts[:, 1:] = jump | ~valid[:, :-1]
    starts &= valid
    labels = np.cumsum(starts.ravel()).reshape(rows, cols) - 1
    return np.where(valid, labels, -1)


def majority_per_label(labels: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Most frequent integer of ``values`` within each label 0 .. labels.max() (ties: the larger value).

    ``labels`` and ``values`` are 1-D of equal length, labels >= 0. Returns an array indexed by label.
    """
    count = int(labels.max()) + 1
    low = int(values.min())
    span = int(values.max()) - low + 1
    key = labels.astype(np.int64) * span + (values - low)
    if count * span <= 1 << 24:
        tally = np.bincount(key, minlength=count * span).reshape(count, span)
        from_top = np.argmax(tally[:, ::-1], axis=1)  # first maximum from the top: ties go to the larger value
        return (span - 1 - from_top) + low
    unique, tally = np.unique(key, return_counts=True)
    label_of, value_of = unique // span, unique % span
    order = np.lexsort((value_of, tally, label_of))  # last of each label: most frequent, then largest
    last = np.r_[label_of[order][1:] != label_of[order][:-1], True]
    winners = np.zeros(count, dtype=np.int64)
    winners[label_of[order][last]] = value_of[order][last]
    return winners + low


def vote_row_orders(
    absolute_phase: np.ndarray, wrapped_phase: np.ndarray, mask: np.ndarray | None = None, min_segment: int = 4
) -> np.ndarray:
    """Absolute phase with each row segment's fringe order set to its majority vote.

    Parameters
    ----------
    absolute_phase : (H, W) array
        Unwrapped phase Phi = phi + 2 pi k (NaN where invalid); fringes vary along rows.
    wrapped_phase : (H, W) array
        The wrapped phase phi it was unwrapped from (any 2 pi representation).
    mask : (H, W) bool array, optional
        True where valid; default the finite pixels of ``absolute_phase``.
    min_segment : int
        Segments shorter than this take their order from the nearest longer segment of the row
        (continuity of the phase) instead of their own vote.

    Returns
    -------
    (H, W) float64 array: Phi + 2 pi (k_vote - k) at valid pixels, NaN elsewhere.
    """
    phase = _validate.phase_map(absolute_phase, "absolute_phase")
    wrapped = _validate.phase_map(wrapped_phase, "wrapped_phase", phase.shape)
    valid = valid_mask(phase, mask, "absolute_phase")
    if np.any(valid & ~np.isfinite(wrapped)):
        raise ValueError("wrapped_phase: NaN at pixels where absolute_phase is valid")
    orders = np.zeros(phase.shape, dtype=np.int64)
    orders[valid] = np.rint((phase[valid] - wrapped[valid]) / TWO_PI).astype(np.int64)
    labels = segment_labels(np.where(valid, wrapped, 0.0), valid)
    min_segment = _validate.positive_int(min_segment, "min_segment")
    winners = majority_per_label(labels[valid], orders[valid])
    voted = np.full(phase.shape, np.nan)
    voted[valid] = phase[valid] + TWO_PI * (winners[labels[valid]] - orders[valid])
    if min_segment > 1:
        sizes = np.bincount(labels[valid])
        short = valid & (sizes[np.maximum(labels, 0)] < min_segment)
        anchor = nearest_along_rows(voted, valid & ~short)
        fix = short & np.isfinite(anchor)
        voted[fix] = wrapped[fix] + TWO_PI * np.rint((anchor[fix] - wrapped[fix]) / TWO_PI)
    return voted


def nearest_along_rows(values: np.ndarray, source: np.ndarray) -> np.ndarray:
    """At each pixel, ``values`` at the nearest ``source`` pixel of its row (NaN if the row has none)."""
    rows, cols = values.shape
    col = np.broadcast_to(np.arange(cols), values.shape)
    left = np.maximum.accumulate(np.where(source, col, -1), axis=1)
    right = np.minimum.accumulate(np.where(source, col, cols)[:, ::-1], axis=1)[:, ::-1]
    use_left = (left >= 0) & ((right >= cols) | (col - left <= right - col))
    pick = np.where(use_left, left, right)
    found = (pick >= 0) & (pick < cols)
    picked = values[np.arange(rows)[:, None], np.clip(pick, 0, cols - 1)]
    return np.where(found, picked, np.nan)
