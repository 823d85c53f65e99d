"""Islands of the kept orders that one order shift the lower frequencies cannot see joins to the surface around.

With a close frequency pair, orders some way apart predict the lower frequencies' phase almost alike: 11 orders
of 32 move the 29-fringe prediction by 0.2 rad, 7 of 25 the 18-fringe one by 0.25 rad. Where noise splits the
measured orders among such shifts over a whole fringe region, the region's vote can settle on a wrong one, and no
temporal evidence tells it apart. The surface can: such an island breaks (steps by more than pi) with its
neighbours all round, and one whole shift mends those breaks at once.

A continuity component is a set of valid pixels joined by 4-neighbour pairs within pi of each other. A component
takes the shift ``s`` that brings its neighbours in a larger component within :data:`CLOSE_RAD` across most of its
border (:data:`MIN_SHARE` of its broken pairs), where

- ``s`` is :data:`MIN_ORDERS` orders or more and confusable for the lower frequencies (the ``confusable`` test:
  below the bounds a blob is judged by), so no temporal evidence speaks against it, and
- most of the component's pixels are undecided (:func:`~processing.correction.order_margin.undecided_orders`): their
  measured orders do not vouch for the kept one; a component of fewer than :data:`TOO_FEW_TO_VOTE` pixels always
  is (too few votes for any margin), and
- the shift does not raise the component's root-mean-square misfit with the lower frequencies by more than
  :data:`MAX_RISE_RAD` (components of :data:`TOO_FEW_TO_VOTE` pixels or more): a shift the per-pixel bounds call
  confusable (9 orders of 32 move the 29-fringe prediction by 0.98 rad, just under them) can still be seen over a
  whole object, and an object that fits where it is stays there.

A real height step lies within :data:`CLOSE_RAD` of some whole shift half the time, so the breaks alone cannot tell
an island from an object; the measured orders can, where they are not split. Passes repeat while islands join (at
most :data:`PASSES`: an island inside an island comes down in two).
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from processing.concurrency import side_by_side
from processing.correction.temporal_evidence import Z_MARGIN
from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi
# Across the border after the shift, a pair must lie within this of each other: half the way to a break, the
# fringe regions' own cut (processing.correction.region_orders.region_cut's least value).
CLOSE_RAD = np.pi / 2.0
# The shift must mend at least this share of the island's broken pairs (most of its border).
MIN_SHARE = 0.5
# Shifts of at least this many orders: a step of a fringe or two beside an edge is real as often as not, and is
# what the steps that weigh single pixels against their neighbours judge (processing.correction.surface_continuation
# judges one and two); the close pairs' ambiguous orders lie further apart (7 of 25, 11 of 32).
MIN_ORDERS = 3
# Passes: islands joined in one pass can bring a neighbouring island within reach of a larger surface.
PASSES = 4
# Islands of fewer pixels than this are undecided whatever their measured orders say: a sign test of n votes cannot
# reach Z_MARGIN standard errors below n = Z_MARGIN ** 2 (9), so no vote can vouch for them.
TOO_FEW_TO_VOTE = int(np.ceil(Z_MARGIN**2))
# A shift that raises a component's RMS lower-frequency misfit by more than this (radians) is refused: the right
# shifts of components of TOO_FEW_TO_VOTE pixels or more on develop cases 0-447 raised it by 0.29 rad at most
# (1578 of them), the one wrong shift that pooled an object into its surround by 0.83 rad; half the least shift a
# blob is judged by (temporal_evidence.MIN_SHIFT_RAD). Smaller components are not judged: single right pixels rose
# by up to 0.57 rad.
MAX_RISE_RAD = 0.5


def broken_pairs(phase: np.ndarray, valid: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The 4-neighbour links of valid pixels within pi of each other (across: (H, W - 1), down: (H - 1, W), bool) and
    the flat indices of both pixels of every broken valid pair (first, second)."""
    cols = phase.shape[1]
    with np.errstate(invalid="ignore"):
        across_step = abs_difference(phase[:, 1:], phase[:, :-1])
        down_step = abs_difference(phase[1:], phase[:-1])
    across_pair, down_pair = valid[:, :-1] & valid[:, 1:], valid[:-1] & valid[1:]
    across, down = across_pair & (across_step <= np.pi), down_pair & (down_step <= np.pi)
    first_across = np.flatnonzero(across_pair ^ across)  # (H, W - 1) positions, to pixels below
    first_across += first_across // (cols - 1)
    first_down = np.flatnonzero(down_pair ^ down)
    first = np.concatenate([first_across, first_down])
    second = np.concatenate([first_across + 1, first_down + cols])
    return across, down, first, second


def continuity_components(valid: np.ndarray, across: np.ndarray, down: np.ndarray) -> tuple[np.ndarray, int]:
    """Labels of the components of valid pixels joined by the links ``across`` and ``down`` (0 outside ``valid``) and
    the number of labels including 0.

    A link is a cell of a grid of twice the resolution (pixels at even rows and columns, links between), so
    OpenCV's 4-connected labelling of that grid follows the links, not the pixels.
    """
    rows, cols = valid.shape
    grid = np.zeros((2 * rows - 1, 2 * cols - 1), dtype=np.uint8)
    grid[::2, ::2] = valid
    grid[::2, 1::2] = across
    grid[1::2, ::2] = down
    count, labels = cv2.connectedComponentsWithAlgorithm(grid, 4, cv2.CV_32S, cv2.CCL_BOLELLI)
    return np.ascontiguousarray(labels[::2, ::2]), int(count)


def _joining_shifts(step: np.ndarray, confusable: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The whole-order shift that brings each broken pair's ``step`` (second minus first) within :data:`CLOSE_RAD`,
    0 where it is none, under :data:`MIN_ORDERS` or not ``confusable``."""
    orders = np.rint(step / TWO_PI)
    usable = (np.abs(step - TWO_PI * orders) <= CLOSE_RAD) & (np.abs(orders) >= MIN_ORDERS)
    values, index = np.unique(orders[usable], return_inverse=True)  # few distinct shifts: each judged once
    orders[usable] = np.where(confusable(values)[index], orders[usable], 0.0)
    orders[~usable] = 0.0
    return orders.astype(np.int64)


def island_shifts(sizes: np.ndarray, first: np.ndarray, second: np.ndarray, joining: np.ndarray) -> np.ndarray:
    """The whole-order shift each component takes (int64 per component, 0: none): the joining shift towards a
    larger component that :data:`MIN_SHARE` of its broken pairs share. ``first``, ``second``: the components of
    each broken pair's pixels; ``joining``: its shift (:func:`_joining_shifts`); ``sizes``: each component's pixels."""
    component = np.concatenate([first, second])  # each pair seen from both of its components
    other = np.concatenate([second, first])
    shift = np.concatenate([joining, -joining])
    broken = np.bincount(component, minlength=sizes.size)
    joins = (shift != 0) & (sizes[other] > sizes[component])
    component, shift = component[joins], shift[joins]
    out = np.zeros(sizes.size, dtype=np.int64)
    if not component.size:
        return out
    low = int(shift.min())
    span = int(shift.max()) - low + 1
    keys, votes = np.unique(component * span + (shift - low), return_counts=True)
    owner, value = keys // span, keys % span + low
    order = np.lexsort((-votes, owner))  # per component, the shift most pairs share first
    first_of = np.r_[True, owner[order][1:] != owner[order][:-1]]
    owner, value, votes = owner[order][first_of], value[order][first_of], votes[order][first_of]
    taken = votes >= MIN_SHARE * broken[owner]
    out[owner[taken]] = value[taken]
    return out


def level_islands(
    phase: np.ndarray,
    valid: np.ndarray,
    confusable: Callable[[np.ndarray], np.ndarray],
    undecided: Callable[[np.ndarray], np.ndarray],
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> tuple[np.ndarray, int]:
    """``phase`` with each island shifted onto the larger surface it continues (see the module), and how many
    pixels moved.

    ``confusable(shifts)``: whether the lower frequencies cannot tell orders ``shifts`` apart; ``undecided(phase)``:
    the (H, W) pixels whose measured orders do not decide the order ``phase`` keeps (asked only where some island
    could move: it reads the whole map). An island moves only if most of its pixels are undecided: where the
    measured orders vouch for the kept ones, a break all round is a real edge. An island of fewer than
    :data:`TOO_FEW_TO_VOTE` pixels counts as undecided whatever ``undecided`` says. ``misfit(values, at)``: the
    squared misfit (rad^2) with the lower frequencies of phase ``values`` at flat pixel indices ``at``; when given,
    a shift raising a larger island's RMS misfit by more than :data:`MAX_RISE_RAD` is refused.

    The map is labelled once, and only where some broken pair has a joining shift; the passes then work on the
    components and their broken pairs alone: components whose pairs a shift brought within pi join into one.
    """
    across, down, first, second = broken_pairs(phase, valid)
    flat = phase.reshape(-1)
    step = flat[second] - flat[first]
    joining = _joining_shifts(step, confusable)
    if not joining.any():
        return phase, 0
    # the labelling and the undecided pixels read the map alone: side by side
    (labels, count), undecided_map = side_by_side(
        lambda: continuity_components(valid, across, down), lambda: undecided(phase)
    )
    flat_labels = labels.reshape(-1)
    sizes = np.bincount(flat_labels, minlength=count)
    doubtful = np.bincount(flat_labels, weights=undecided_map.reshape(-1), minlength=count)
    doubtful = np.where(sizes < TOO_FEW_TO_VOTE, sizes, doubtful)  # their whole size: undecided
    one, two = flat_labels[first], flat_labels[second]  # the components of each broken pair's pixels
    total = np.zeros(count, dtype=np.int64)  # each component's shift so far
    # before any shift every component is its own group and every pair is apart, with the joining shifts above
    groups, group, apart = count, np.arange(count), np.ones(step.size, dtype=bool)
    for _ in range(PASSES):
        group_sizes = np.bincount(group, weights=sizes, minlength=groups)
        shifts = island_shifts(group_sizes, group[one[apart]], group[two[apart]], joining)
        shifts[np.bincount(group, weights=doubtful, minlength=groups) < MIN_SHARE * group_sizes] = 0
        if misfit is not None:
            shifts[_misfit_rises(flat, flat_labels, group, total, shifts, group_sizes, misfit)] = 0
        if not shifts.any():
            break
        total += shifts[group]
        now = step + TWO_PI * (total[two] - total[one])
        joined = np.abs(now) <= np.pi  # components a shift brought within pi of each other join
        groups, group = connected_components(
            coo_matrix((np.ones(np.count_nonzero(joined)), (one[joined], two[joined])), shape=(count, count)),
            directed=False,
        )
        apart = ~joined
        joining = _joining_shifts(now[apart], confusable)
    at = np.flatnonzero(total[flat_labels])  # label 0 (outside valid) never shifts: it has no broken pair
    if not at.size:
        return phase, 0
    out = phase.copy()
    out.reshape(-1)[at] += TWO_PI * total[flat_labels[at]]
    return out, int(at.size)


def _misfit_rises(
    flat: np.ndarray,
    flat_labels: np.ndarray,
    group: np.ndarray,
    total: np.ndarray,
    shifts: np.ndarray,
    group_sizes: np.ndarray,
    misfit: Callable[[np.ndarray, np.ndarray], np.ndarray],
) -> np.ndarray:
    """Per group, whether its shift raises its RMS lower-frequency misfit by more than :data:`MAX_RISE_RAD` (groups
    of :data:`TOO_FEW_TO_VOTE` pixels or more; ``total``: each component's shift so far, per component)."""
    judged = (shifts != 0) & (group_sizes >= TOO_FEW_TO_VOTE)
    if not judged.any():
        return judged
    at = np.flatnonzero(judged[group[flat_labels]])
    owner = group[flat_labels[at]]
    now = flat[at] + TWO_PI * total[flat_labels[at]]
    before = np.bincount(owner, weights=misfit(now, at), minlength=shifts.size)
    after = np.bincount(owner, weights=misfit(now + TWO_PI * shifts[owner], at), minlength=shifts.size)
    size = np.maximum(group_sizes, 1.0)
    return judged & (np.sqrt(after / size) - np.sqrt(before / size) > MAX_RISE_RAD)
