"""Where the measured fringe orders cannot vouch for the orders a correction keeps: a vote margin per piece.

Temporal unwrapping gives every pixel its own noisy guess of the fringe order; a spatial correction
keeps one order per fringe and overrules the guesses that disagree. Where most guesses agree with
the kept order the evidence is decisive; where the lower frequencies barely tell orders apart (a
close coprime pair such as 29/32, whose ambiguous orders shift the lower frequency's prediction by
0.2 rad) half the guesses or more can be wrong, and the kept order then rests on spatial continuity
alone: a confident-looking surface that can be wrong over whole patches.

The guesses are pooled over pieces of one fringe: the pixels of one kept order inside a
:data:`TILE` x :data:`TILE` square, every :data:`SAMPLE`-th pixel each way voting (a fringe region
of :mod:`processing.correction.region_orders` has one order, so a piece lies on one fringe). In a
piece, ``a`` guesses agree with the kept order and ``b`` name the most frequent other order. If
both orders were equally likely per pixel (the evidence undecided), ``a - b`` would be a sign test's
difference with standard deviation ``sqrt(a + b)``; the piece is decided when

    a - b >= Z_MARGIN sqrt(a + b)

or when no guess in it disagrees (``b = 0``: nothing contradicts the kept order). Every other piece
is unresolved, whether its guesses favour another order or split too evenly to favour any. The
threshold is not fitted to cases: :data:`Z_MARGIN` is the same 3 standard errors as the lower-frequency blob
test (:mod:`processing.correction.temporal_evidence`).

It reports, it never changes an order.
"""

from __future__ import annotations

import numpy as np

from processing.correction.temporal_evidence import TWO_PI, Z_MARGIN

# Side of the square pieces are cut from (pixels) ...
TILE = 32
# ... and the stride of the pixels that vote in it, each way: up to 256 voters a piece, as many as a
# full 16 x 16 tile of pool_region_orders, at a quarter of the cost. A pixel takes the verdict of the
# voter at or above-left of it.
SAMPLE = 2


def undecided_orders(kept: np.ndarray, measured: np.ndarray, wrapped: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) bool: the valid pixels whose piece's measured orders do not decide the kept order.

    Parameters
    ----------
    kept : (H, W) absolute phase after the correction (its order is ``rint((kept - wrapped) / 2 pi)``)
    measured : (H, W) absolute phase as temporally unwrapped
    wrapped : (H, W) wrapped phase both were unwrapped from
    valid : (H, W) bool, where all three are finite

    Examples
    --------
    A fringe 64 pixels wide whose measured orders are right on its left half and split evenly between
    the kept order and the next one (pairs of rows) on its right half:

    >>> import numpy as np
    >>> wrapped = np.zeros((32, 64))
    >>> kept = wrapped + 2 * np.pi * 3
    >>> measured = kept.copy()
    >>> measured[(np.arange(32) // 2) % 2 == 1, 32:] += 2 * np.pi
    >>> undecided = undecided_orders(kept, measured, wrapped, np.ones((32, 64), bool))
    >>> bool(undecided[:, :32].any()), bool(undecided[:, 32:].all())
    (False, True)
    """
    out = np.zeros(valid.shape, dtype=bool)
    grid = (slice(None, None, SAMPLE), slice(None, None, SAMPLE))
    sampled = valid[grid]
    at_kept = kept[grid][sampled]
    offset = np.rint((measured[grid][sampled] - at_kept) / TWO_PI).astype(np.int32)
    others = offset != 0
    if not others.any():
        return out
    order = np.rint((at_kept - wrapped[grid][sampled]) / TWO_PI).astype(np.int64)
    order -= order.min()
    rows, cols = sampled.shape
    side = TILE // SAMPLE
    tile = (np.arange(rows)[:, None] // side) * -(-cols // side) + np.arange(cols)[None, :] // side
    piece, count = _compact(tile[sampled] * (int(order.max()) + 1) + order)
    agree = np.bincount(piece, weights=~others, minlength=count)
    span = int(np.abs(offset[others]).max())
    # the votes for the most frequent other order of each piece: tallied per (piece, offset) pair present
    of_other = piece[others]
    pair, pairs = _compact(of_other * (2 * span + 1) + offset[others] + span)
    piece_of_pair = np.zeros(pairs, dtype=np.int64)
    piece_of_pair[pair] = of_other
    runner_up = np.zeros(count)
    np.maximum.at(runner_up, piece_of_pair, np.bincount(pair, minlength=pairs))
    decided = (runner_up == 0) | (agree - runner_up >= Z_MARGIN * np.sqrt(agree + runner_up))
    undecided = np.zeros(sampled.shape, dtype=bool)
    undecided[sampled] = ~decided[piece]
    out[:] = np.repeat(np.repeat(undecided, SAMPLE, axis=0), SAMPLE, axis=1)[: valid.shape[0], : valid.shape[1]]
    return out & valid


def _compact(key: np.ndarray) -> tuple[np.ndarray, int]:
    """``key`` renumbered 0 .. count - 1 (same order), and count: a lookup table where keys are few."""
    size = int(key.max()) + 1
    if size > 1 << 24:
        unique, inverse = np.unique(key, return_inverse=True)
        return inverse, unique.size
    used = np.zeros(size, dtype=bool)
    used[key] = True
    compact = np.cumsum(used, dtype=np.int64) - 1
    return compact[key], int(compact[-1]) + 1
