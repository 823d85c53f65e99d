"""Fringe orders pooled over 2-D fringe regions: Ding's row vote, in two dimensions.

A fringe region is a 4-connected set of valid pixels that no wrapped-phase jump crosses. Inside
it the wrapped phase is continuous and spans less than one period, so every pixel has the same
fringe order; temporal unwrapping gives each pixel its own noisy guess of that order, and the
region's majority is far more reliable than any single guess (with 40 % of the guesses wrong,
spread over several wrong orders, the right one still leads by a wide margin).

Two refinements make the vote safe on real scenes:

- a region can leak across a hidden edge: an object's outline where the phase steps by a
  multiple of 2 pi plus less than the cut, so no jump separates the two sides. Pooling is
  therefore done per tile (``tile`` x ``tile`` pixels of one region), and a tile whose pooled
  orders disagree with a neighbour's (an order break: 4-neighbours more than pi apart) is voted
  again pixel by pixel, over a ``(2 radius + 1)``-square window restricted to the pixel's
  region. A window centred on a pixel always holds at least half its own side of a straight
  edge, so the local majority keeps the edge where it is;
- pixels at a jump, in regions too small to vote or at image borders, take the order that makes
  them continuous with the neighbour closest to them in wrapped phase (the same surface).

Everything is vectorised: connected components (OpenCV), ``np.bincount`` tallies and gathered
windows for the few re-voted pixels.
"""

from __future__ import annotations

import cv2
import numpy as np
from numpy.lib.stride_tricks import sliding_window_view

from processing.angles import wrap_to_pi
from processing.correction.order_evidence import neighbours_at
from processing.denoise.rpca import finite_median
from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi
# The 8 neighbours, as (row, column) offsets.
NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_NO_VOTE = np.iinfo(np.int32).min
_CHUNK = 1 << 15  # re-voted pixels per gathered block: (chunk, window) int32 stays ~10 MiB
# Largest (chunk, orders) count table :func:`_window_majority` tallies by counting (64 MiB of int64), beyond
# which (spans over 255 orders) it sorts each window instead.
_COUNT_CELLS = 1 << 23


def region_cut(wrapped_phase: np.ndarray, valid: np.ndarray) -> float:
    """The wrapped-phase step that separates fringe regions: pi / 2, more where fringes are dense.

    A hidden edge whose wrapped step exceeds the cut splits a region, so it is kept low; but
    neighbours on a steep fringe differ by the slope itself, so the cut is at least twice the
    median step along the axis the fringes vary on (and at most pi, Ding's jump).
    """
    return _region_cut(_steps(wrapped_phase), valid)


def _steps(phi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Differences of neighbours down the columns and along the rows (shared by the cut and the regions)."""
    return np.diff(phi, axis=0), np.diff(phi, axis=1)


def _region_cut(steps: tuple[np.ndarray, np.ndarray], valid: np.ndarray) -> float:
    typical = 0.0
    for axis, step in enumerate(steps):
        pair = valid[1:, :] & valid[:-1, :] if axis == 0 else valid[:, 1:] & valid[:, :-1]
        sample = _spaced_selection(step, pair, 100_000)
        if sample.size:
            typical = max(typical, finite_median(np.abs(wrap_to_pi(sample))))
    return float(np.clip(2.0 * typical, np.pi / 2, np.pi))


def _spaced_selection(values: np.ndarray, selected: np.ndarray, target: int) -> np.ndarray:
    """``values[selected][:: max(1, n // target)]`` (n selected entries), gathering only the entries kept.

    The r-th selected entry lies at position r + (the unselected entries before it), counted from the few
    unselected ones: most pixels are valid, so this reads far less than selecting them all.
    """
    skipped = np.flatnonzero(~selected)
    count = selected.size - skipped.size
    if not count:
        return np.empty(0, dtype=values.dtype)
    stride = max(1, count // target)
    ranks = np.arange(0, count, stride)
    # selected entries before each unselected one; those at or below a rank lie before its entry
    before = skipped - np.arange(skipped.size)
    first_rank_after = -(-before // stride)  # the first rank index at or above each
    passed = np.cumsum(np.bincount(first_rank_after, minlength=ranks.size + 1)[: ranks.size])
    return values.reshape(-1)[ranks + passed]


def fringe_regions(
    wrapped_phase: np.ndarray, valid: np.ndarray, cut: float, bend: float = 1.2
) -> tuple[np.ndarray, np.ndarray, int]:
    """4-connected regions of valid pixels that no wrapped step beyond ``cut`` crosses.

    A pixel with such a step to its right or lower neighbour is left out (so 4-connectivity
    cannot cross the step), and so is a pixel where the wrapped slope changes by more than
    ``bend`` (its wrapped second difference along a row or column): a hidden edge steps by any
    amount, and the kink also cuts the steps smaller than ``cut``, while a smooth phase, however
    steep, bends little (1.2 rad is 4 standard deviations of the second difference of 6-step
    phase at 15 dB). Returns ``(core, labels, count)``: the pixels in a region, their
    labels 1 .. count - 1 (0 elsewhere, int32) and the number of labels including 0.
    """
    return _fringe_regions(_steps(np.where(valid, wrapped_phase, 0.0)), valid, cut, bend)


def _fringe_regions(
    steps: tuple[np.ndarray, np.ndarray], valid: np.ndarray, cut: float, bend: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`fringe_regions` from the :func:`_steps` of the masked wrapped phase (two float scratch maps for
    every test: a fresh map per test costs as much as its arithmetic)."""
    down, across = steps
    rows, cols = valid.shape
    scratch = (np.empty(rows * cols), np.empty(rows * cols))

    def buffer(shape: tuple[int, int], second: bool = False) -> np.ndarray:
        return scratch[int(second)][: shape[0] * shape[1]].reshape(shape)

    step = np.zeros(valid.shape, dtype=bool)
    np.greater(np.abs(across, out=buffer(across.shape)), cut, out=step[:, :-1])
    step[:-1, :] |= np.abs(down, out=buffer(down.shape)) > cut
    # A kink: the wrapped slope changes by more than ``bend`` (second difference, wrapped).
    kink = np.subtract(across[:, 1:], across[:, :-1], out=buffer((rows, cols - 2)))
    step[:, 1:-1] |= _beyond_wrapped(kink, bend, buffer(kink.shape, second=True))
    kink = np.subtract(down[1:, :], down[:-1, :], out=buffer((rows - 2, cols)))
    step[1:-1, :] |= _beyond_wrapped(kink, bend, buffer(kink.shape, second=True))
    core = valid & ~step
    # Spaghetti4C (CCL_BOLELLI): the same labels as the default for 4-connectivity (a decision tree per
    # pixel pair) in 60 % of its time on 1024 x 768 maps
    count, labels = cv2.connectedComponentsWithAlgorithm(core.view(np.uint8), 4, cv2.CV_32S, cv2.CCL_BOLELLI)
    return core, labels, int(count)


def _beyond_wrapped(values: np.ndarray, bound: float, scratch: np.ndarray | None = None) -> np.ndarray:
    """``|wrap_to_pi(values)| > bound`` for ``bound`` < pi, wrapping only the values beyond it.

    Below pi in magnitude the wrap is the identity, so a value within the bound stays within;
    only the others (a few per cent: the fringe jumps) are wrapped and tested again. ``scratch``: a
    map of ``values``' shape for the magnitudes.
    """
    beyond = np.abs(values, out=scratch) > bound
    at = np.flatnonzero(beyond)
    beyond.reshape(-1)[at] = np.abs(wrap_to_pi(values.reshape(-1)[at])) > bound
    return beyond


def _drop_small_regions(labels: np.ndarray, count: int, min_size: int) -> tuple[np.ndarray, int]:
    """Regions of fewer than ``min_size`` pixels removed (label 0), the rest relabelled 1 .. n.

    Such a region can hold no square with ``min_size`` votes, so it never votes; noisy maps have
    thousands of them (kinks cut by noise), which would otherwise size every per-region table.
    """
    areas = np.bincount(labels.ravel(), minlength=count)
    big = areas >= min_size
    big[0] = False
    relabel = (np.cumsum(big) * big).astype(np.int32)
    return relabel[labels], int(relabel.max()) + 1


def _tile_pieces(labels: np.ndarray, count: int, tile: int) -> tuple[np.ndarray, int]:
    """Each region cut into ``tile`` x ``tile`` squares: compact piece labels (0 where ``labels`` is 0: outside
    every region). Keys and pieces are taken over the whole map, no pixel gathered or scattered by a mask."""
    rows, cols = labels.shape
    across, down = -(-cols // tile), -(-rows // tile)
    per_label = down * across
    key = labels.astype(np.int64) if count * per_label >= 1 << 31 else labels.copy()
    key *= per_label
    key += (np.arange(rows, dtype=key.dtype) // tile * across)[:, None]
    key += (np.arange(cols, dtype=key.dtype) // tile)[None, :]
    if count * per_label <= 1 << 24:
        used = np.zeros(count * per_label, dtype=bool)
        used[key] = True
        used[:per_label] = False  # label 0's squares: outside every region, piece 0
        compact = np.cumsum(used, dtype=np.int32)
        return compact[key], int(compact[-1]) + 1
    core = labels > 0
    pieces = np.zeros(labels.shape, dtype=np.int32)
    unique, inverse = np.unique(key[core], return_inverse=True)
    pieces[core] = inverse + 1
    return pieces, unique.size + 1


def _tally(pieces: np.ndarray, orders: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Most frequent order of each piece (ties: the smaller) and the piece sizes."""
    low = int(orders.min())
    span = int(orders.max()) - low + 1
    if count * span <= 1 << 25:
        cells = pieces * span  # below 2 ** 25
        cells += orders
        cells -= low
        tally = np.bincount(cells.ravel(), minlength=count * span).reshape(count, span)
        return np.argmax(tally, axis=1) + low, tally.sum(axis=1)
    key = pieces.astype(np.int64) * span + (orders - low)
    unique, votes = np.unique(key, return_counts=True)
    piece_of = unique // span
    order = np.lexsort((-votes, piece_of))
    first = np.r_[True, piece_of[order][1:] != piece_of[order][:-1]]
    winners = np.zeros(count, dtype=np.int64)
    winners[piece_of[order][first]] = unique[order][first] % span + low
    return winners, np.bincount(pieces.ravel(), minlength=count)


def _window_majority(
    orders: np.ndarray, labels: np.ndarray, rows: np.ndarray, cols: np.ndarray, radius: int
) -> tuple[np.ndarray, np.ndarray]:
    """Most frequent order in the window around each (row, col), among pixels of its own region.

    Returns the winners (ties: the smaller order) and their vote counts (0, and winner
    ``_NO_VOTE``, where the window holds no vote). A window pixel's region and order are
    packed into one code (label x span + order offset), so each window is one strided copy;
    its votes are counted per order in one bincount (:func:`_count_majority`), or, for spans too
    wide to count, the sorted windows are scanned with the window position as the leading axis,
    where numpy's running maximum and maximum are vectorised across pixels.
    """

    side = 2 * radius + 1
    size = side * side
    low = int(orders.min())
    span = int(orders.max()) - low + 1
    code_type = np.int64 if (int(labels.max()) + 1) * span >= 1 << 31 else np.int32
    code = np.zeros((labels.shape[0] + 2 * radius, labels.shape[1] + 2 * radius), dtype=code_type)
    inner = code[radius : radius + labels.shape[0], radius : radius + labels.shape[1]]
    np.multiply(labels, span, out=inner, casting="unsafe")
    inner += orders
    inner -= low
    windows = sliding_window_view(code, (side, side))  # windows[y, x]: the window centred on pixel (y, x)
    # Runs and the packed (run, order) key below must fit: int16 for the usual small spans.
    small = np.int16 if size * (span + 1) + span < 1 << 15 else np.int64
    unsigned = np.uint64 if code_type == np.int64 else np.uint32
    position = np.arange(size, dtype=small)[:, None]
    counting = (span + 1) * _CHUNK <= _COUNT_CELLS
    winners = np.full(rows.size, _NO_VOTE, dtype=np.int64)
    support = np.zeros(rows.size, dtype=np.int64)
    for start in range(0, rows.size, _CHUNK):
        r, c = rows[start : start + _CHUNK], cols[start : start + _CHUNK]
        window = windows[r, c].reshape(r.size, size)
        window -= (labels[r, c].astype(code_type) * span)[:, None]  # the order offset, in [0, span) in the region
        # Any other region's pixel (negative, or beyond span as unsigned) becomes span, sorted last.
        value = np.empty(window.shape, dtype=small)
        np.minimum(window.view(unsigned), unsigned(span), out=value, casting="unsafe")
        if counting:  # few orders: count each pixel's votes per order, the first largest count wins
            votes, best = _count_majority(value, span)
            support[start : start + r.size] = votes
            winners[start : start + r.size] = np.where(votes > 0, best + low, _NO_VOTE)
            continue
        value.sort(axis=1)
        value = np.ascontiguousarray(value.T)  # (size, pixels)
        # Length of the run each sorted entry ends (the longest run is the majority) ...
        new = np.ones(value.shape, dtype=bool)
        np.not_equal(value[1:], value[:-1], out=new[1:])
        run = np.where(new, position, small(0))
        for i in range(1, size):  # running maximum down the window positions, all pixels at once
            np.maximum(run[i], run[i - 1], out=run[i])
        np.subtract(position + small(1), run, out=run)
        run[value == span] = 0
        # ... packed with the order so that one maximum finds the longest run, ties the smaller order.
        run *= small(span + 1)
        run += small(span)
        run -= value
        key = run.max(axis=0).astype(np.int64)
        votes = key // (span + 1)
        support[start : start + r.size] = votes
        winners[start : start + r.size] = np.where(votes > 0, span - key % (span + 1) + low, _NO_VOTE)
    return winners, support


def _count_majority(value: np.ndarray, span: int) -> tuple[np.ndarray, np.ndarray]:
    """Per row of ``value`` (order offsets in [0, span], span = another region's pixel): the largest count
    of one offset below ``span`` and that offset (ties: the smaller), from one bincount over all rows."""
    pixels = value.shape[0]
    cells = value.astype(np.intp)
    cells += (np.arange(pixels, dtype=np.intp) * (span + 1))[:, None]
    counts = np.bincount(cells.ravel(), minlength=pixels * (span + 1)).reshape(pixels, span + 1)
    counts[:, span] = 0
    best = counts.argmax(axis=1)
    return counts[np.arange(pixels), best], best


def order_break_pixels(phase: np.ndarray) -> np.ndarray:
    """Pixels with a 4-neighbour more than pi away (NaN neighbours never count)."""
    out = np.zeros(phase.shape, dtype=bool)
    with np.errstate(invalid="ignore"):
        across = np.abs(np.diff(phase, axis=1)) > np.pi
        down = np.abs(np.diff(phase, axis=0)) > np.pi
    out[:, :-1] |= across
    out[:, 1:] |= across
    out[:-1, :] |= down
    out[1:, :] |= down
    return out


def neighbour_steps_at(
    phase: np.ndarray, valid: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """At the given pixels of ``phase`` masked to ``valid``: how many valid 4-neighbours lie more than pi away
    (order breaks) and how many within pi (continuations), as int8 counts; both 0 at an invalid pixel.

    ``breaks > 0`` is :func:`order_break_pixels` of the masked phase at those pixels.
    """
    here = np.where(valid[rows, cols], phase[rows, cols], np.nan)
    with np.errstate(invalid="ignore"):
        step = np.abs(neighbours_at(phase, valid, rows, cols) - here)
    # NaN (an invalid neighbour or pixel): neither
    return (step > np.pi).sum(axis=0, dtype=np.int8), (step <= np.pi).sum(axis=0, dtype=np.int8)


def fill_from_neighbours(
    phase: np.ndarray, wrapped_phase: np.ndarray, todo: np.ndarray, passes: int = 16
) -> np.ndarray:
    """Give the NaN pixels of ``todo`` an order from the neighbour nearest in wrapped phase.

    Each pass, a pixel with a finite 8-neighbour takes phi + 2 pi round((Phi_q - phi) / 2 pi)
    from the neighbour q whose wrapped phase is closest to its own (most likely the same
    surface); pixels reached by no pass stay NaN. ``phase`` is filled in place and returned.
    Neighbours are read at flat offsets (clipped to the map); only the few pixels on the map's
    border test which of their neighbours lie beyond it.
    """
    height, width = phase.shape
    work = phase if phase.flags.c_contiguous else np.ascontiguousarray(phase)  # flat writes reach it
    flat, flat_phi = work.reshape(-1), np.ravel(wrapped_phase)
    at = np.flatnonzero(todo & np.isnan(work))
    for _ in range(passes):
        if not at.size:
            break
        ys, xs = np.divmod(at, width)
        rim = np.flatnonzero((ys == 0) | (ys == height - 1) | (xs == 0) | (xs == width - 1))
        phi = flat_phi[at]
        best = np.full(at.size, np.nan)
        distance = np.full(at.size, np.inf)
        for dy, dx in NEIGHBOURS:
            near = at + (dy * width + dx)
            value = flat.take(near, mode="clip")
            if rim.size:  # beyond the border: no value
                y, x = ys[rim] + dy, xs[rim] + dx
                value[rim[(y < 0) | (y >= height) | (x < 0) | (x >= width)]] = np.nan
            gap = np.abs(wrap_to_pi(flat_phi.take(near, mode="clip") - phi))  # meaningless where value is NaN
            closer = (gap < distance) & np.isfinite(value)
            np.copyto(best, value, where=closer)
            np.copyto(distance, gap, where=closer)
        found = np.isfinite(best)
        if not found.any():
            break
        # Every pixel of a pass reads its neighbours before any of them is written (one sweep).
        flat[at[found]] = phi[found] + TWO_PI * np.rint((best[found] - phi[found]) / TWO_PI)
        at = at[~found]
    if work is not phase:
        phase[...] = work
    return phase


def _measured_orders(phase: np.ndarray, phi: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """The measured fringe orders ``rint((phase - phi) / 2 pi)`` (int32, 0 outside ``valid``), in one buffer."""
    orders = np.subtract(phase, phi)
    orders /= TWO_PI
    with np.errstate(invalid="ignore"):
        np.rint(orders, out=orders)
    np.copyto(orders, 0.0, where=~valid)
    return orders.astype(np.int32)


def _break_ends(phase: np.ndarray) -> np.ndarray:
    """Flat indices of both pixels of every 4-neighbour pair more than pi apart (NaN pairs never count)."""
    width = phase.shape[1]
    ends = []
    with np.errstate(invalid="ignore"):
        for axis, step in ((1, 1), (0, width)):
            after, before = (phase[:, 1:], phase[:, :-1]) if axis == 1 else (phase[1:], phase[:-1])
            first = np.flatnonzero(abs_difference(after, before) > np.pi)
            if axis == 1:  # (H, W - 1) positions to pixels
                first += first // (width - 1)
            ends += [first, first + step]
    return np.concatenate(ends)


def pool_region_orders(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    valid: np.ndarray,
    tile: int = 16,
    radius: int = 4,
    min_votes: int = 16,
    cut: float | None = None,
    bend: float = 1.2,
) -> np.ndarray:
    """The measured wrapped phase with each fringe region's pooled fringe order.

    Parameters
    ----------
    absolute_phase : (H, W) float array
        Phi = phi + 2 pi k from temporal unwrapping (finite at the valid pixels).
    wrapped_phase : (H, W) float array
        The wrapped phase phi it came from (any 2 pi representation; finite where valid).
    valid : (H, W) bool array
    tile : int
        Side of the squares a region is pooled over (smaller: less leakage across hidden edges,
        fewer votes per square).
    radius : int
        Half-side of the window a tile with order breaks is re-voted over, pixel by pixel.
    min_votes : int
        A square or window with fewer pixels of its region keeps no vote of its own; its pixels
        take their order from their neighbours.
    cut : float, optional
        Wrapped step that separates regions; default :func:`region_cut`.
    bend : float
        Wrapped second difference that separates regions (see :func:`fringe_regions`).

    Returns
    -------
    (H, W) float64: phi + 2 pi k_pooled at the valid pixels (the measured phase where no
    neighbour settles a pixel), NaN elsewhere.
    """
    phase = np.asarray(absolute_phase, dtype=np.float64)
    phi = np.where(valid, np.asarray(wrapped_phase, dtype=np.float64), 0.0)
    steps = _steps(phi)
    _, labels, count = _fringe_regions(steps, valid, _region_cut(steps, valid) if cut is None else cut, bend)
    labels, count = _drop_small_regions(labels, count, min_votes)  # 0 outside every region
    orders = _measured_orders(phase, phi, valid)
    if count > 1:
        pieces, piece_count = _tile_pieces(labels, count, tile)
        winners, sizes = _tally(pieces, orders, piece_count)  # piece 0 (outside every region) is never used
        voted_piece = sizes >= min_votes
        voted_piece[0] = False
        # each piece's order step, NaN where it keeps no vote: phi + the step is the pooled phase
        step = np.where(voted_piece, TWO_PI * winners, np.nan)
        out = phi + step[pieces]
        # Squares that disagree with a neighbour may straddle a hidden edge: vote them pixel by pixel.
        suspect_piece = np.zeros(piece_count, dtype=bool)
        suspect_piece[np.ravel(pieces)[_break_ends(out)]] = True  # both ends of a break are voted
        if suspect_piece.any():  # then a voted pixel of it at least
            ys, xs = np.divmod(np.flatnonzero(suspect_piece[pieces]), phase.shape[1])  # np.nonzero's order
            local, support = _window_majority(orders, labels, ys, xs, radius)
            enough = support >= min_votes
            out[ys[enough], xs[enough]] = phi[ys[enough], xs[enough]] + TWO_PI * local[enough]
    else:
        out = np.full(phase.shape, np.nan)
    out = fill_from_neighbours(out, phi, valid)
    unsettled = valid & np.isnan(out)
    out[unsettled] = phase[unsettled]
    return out
