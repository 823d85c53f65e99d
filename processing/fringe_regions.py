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

import numpy as np

from processing.angles import wrap_to_pi

TWO_PI = 2.0 * np.pi
# The 8 neighbours, as (row, column) offsets.
NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))
_NO_VOTE = np.iinfo(np.int32).min
_CHUNK = 1 << 15  # re-voted pixels per gathered block: (chunk, window) int32 stays ~10 MiB


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
        chosen = step[pair]
        if chosen.size:
            sample = np.abs(wrap_to_pi(chosen[:: max(1, chosen.size // 100_000)]))
            typical = max(typical, float(np.median(sample)))
    return float(np.clip(2.0 * typical, np.pi / 2, np.pi))


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
    """:func:`fringe_regions` from the :func:`_steps` of the masked wrapped phase."""
    import cv2  # lazily: only the commands that correct orders pay for it

    down, across = steps
    step = np.zeros(valid.shape, dtype=bool)
    step[:, :-1] = np.abs(across) > cut
    step[:-1, :] |= np.abs(down) > cut
    # A kink: the wrapped slope changes by more than ``bend`` (second difference, wrapped).
    step[:, 1:-1] |= np.abs(wrap_to_pi(np.diff(across, axis=1))) > bend
    step[1:-1, :] |= np.abs(wrap_to_pi(np.diff(down, axis=0))) > bend
    core = valid & ~step
    count, labels = cv2.connectedComponents(core.view(np.uint8), connectivity=4, ltype=cv2.CV_32S)
    return core, labels, int(count)


def _drop_small_regions(
    labels: np.ndarray, core: np.ndarray, count: int, min_size: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """Regions of fewer than ``min_size`` pixels removed from ``core`` (label 0), the rest relabelled 1 .. n.

    Such a region can hold no square with ``min_size`` votes, so it never votes; noisy maps have
    thousands of them (kinks cut by noise), which would otherwise size every per-region table.
    """
    areas = np.bincount(labels.ravel(), minlength=count)
    big = areas >= min_size
    big[0] = False
    relabel = (np.cumsum(big) * big).astype(np.int32)
    kept = relabel[labels]
    return kept, core & (kept > 0), int(relabel.max()) + 1


def _tile_pieces(labels: np.ndarray, core: np.ndarray, count: int, tile: int) -> tuple[np.ndarray, int]:
    """Each region cut into ``tile`` x ``tile`` squares: compact piece labels (0 outside ``core``)."""
    rows, cols = labels.shape
    across, down = -(-cols // tile), -(-rows // tile)
    tiles = (np.arange(rows, dtype=np.int32)[:, None] // tile) * across + (
        np.arange(cols, dtype=np.int32)[None, :] // tile
    )
    key = (
        labels[core].astype(np.int64 if count * down * across >= 1 << 31 else np.int32) * (down * across) + tiles[core]
    )
    pieces = np.zeros(labels.shape, dtype=np.int32)
    if count * down * across <= 1 << 24:
        used = np.zeros(count * down * across, dtype=bool)
        used[key] = True
        compact = np.cumsum(used, dtype=np.int32)
        pieces[core] = compact[key]
        return pieces, int(compact[-1]) + 1
    unique, inverse = np.unique(key, return_inverse=True)
    pieces[core] = inverse + 1
    return pieces, unique.size + 1


def _tally(pieces: np.ndarray, orders: np.ndarray, count: int) -> tuple[np.ndarray, np.ndarray]:
    """Most frequent order of each piece (ties: the smaller) and the piece sizes."""
    low = int(orders.min())
    span = int(orders.max()) - low + 1
    if count * span <= 1 << 25:
        tally = np.bincount(pieces * span + (orders - low), minlength=count * span).reshape(count, span)
        return np.argmax(tally, axis=1) + low, tally.sum(axis=1)
    key = pieces.astype(np.int64) * span + (orders - low)
    unique, votes = np.unique(key, return_counts=True)
    piece_of = unique // span
    order = np.lexsort((-votes, piece_of))
    first = np.r_[True, piece_of[order][1:] != piece_of[order][:-1]]
    winners = np.zeros(count, dtype=np.int64)
    winners[piece_of[order][first]] = unique[order][first] % span + low
    return winners, np.bincount(pieces, minlength=count)


def _window_majority(
    orders: np.ndarray, labels: np.ndarray, rows: np.ndarray, cols: np.ndarray, radius: int
) -> tuple[np.ndarray, np.ndarray]:
    """Most frequent order in the window around each (row, col), among pixels of its own region.

    Returns the winners and their vote counts (0 where the window holds no vote).
    """
    side = 2 * radius + 1
    k = np.pad(orders.astype(np.int32), radius)
    lab = np.pad(labels, radius)
    winners = np.zeros(rows.size, dtype=np.int64)
    support = np.zeros(rows.size, dtype=np.int64)
    stride = lab.shape[1]
    offsets = (np.arange(-radius, radius + 1)[:, None] * stride + np.arange(-radius, radius + 1)[None, :]).ravel()
    flat_k, flat_lab = k.reshape(-1), lab.reshape(-1)
    small = np.int16 if side * side < 1 << 15 else np.int32  # run lengths: the narrowest type that holds them
    for start in range(0, rows.size, _CHUNK):
        r = rows[start : start + _CHUNK] + radius
        c = cols[start : start + _CHUNK] + radius
        at = r * stride + c
        near = at[:, None] + offsets[None, :]  # the window's flat indices, row by row
        window = np.where(flat_lab[near] == flat_lab[at][:, None], flat_k[near], _NO_VOTE).astype(np.int32)
        window.sort(axis=1)
        # Length of the run each sorted entry ends; the longest run is the majority.
        index = np.broadcast_to(np.arange(side * side, dtype=small), window.shape)
        new = np.ones(window.shape, dtype=bool)
        new[:, 1:] = window[:, 1:] != window[:, :-1]
        run = index - np.maximum.accumulate(np.where(new, index, small(0)), axis=1) + small(1)
        run[window == _NO_VOTE] = 0
        best = np.argmax(run, axis=1)
        picked = np.arange(r.size)
        winners[start : start + r.size] = window[picked, best]
        support[start : start + r.size] = run[picked, best]
    return winners, support


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


def fill_from_neighbours(
    phase: np.ndarray, wrapped_phase: np.ndarray, todo: np.ndarray, passes: int = 16
) -> np.ndarray:
    """Give the NaN pixels of ``todo`` an order from the neighbour nearest in wrapped phase.

    Each pass, a pixel with a finite 8-neighbour takes phi + 2 pi round((Phi_q - phi) / 2 pi)
    from the neighbour q whose wrapped phase is closest to its own (most likely the same
    surface); pixels reached by no pass stay NaN. ``phase`` is filled in place and returned.
    """
    padded = np.pad(phase, 1, constant_values=np.nan)
    padded_phi = np.pad(wrapped_phase, 1)
    flat, flat_phi = padded.reshape(-1), padded_phi.reshape(-1)
    stride = padded.shape[1]
    ys, xs = np.nonzero(todo & np.isnan(phase))
    at = (ys + 1) * stride + (xs + 1)  # flat indices into the padded maps
    for _ in range(passes):
        if not at.size:
            break
        phi = flat_phi[at]
        best = np.full(at.size, np.nan)
        distance = np.full(at.size, np.inf)
        for dy, dx in NEIGHBOURS:
            near = at + (dy * stride + dx)
            value = flat[near]
            gap = np.abs(wrap_to_pi(flat_phi[near] - phi))
            closer = (gap < distance) & np.isfinite(value)
            best[closer] = value[closer]
            distance[closer] = gap[closer]
        found = np.isfinite(best)
        if not found.any():
            break
        # Every pixel of a pass reads its neighbours before any of them is written (one sweep).
        flat[at[found]] = phi[found] + TWO_PI * np.rint((best[found] - phi[found]) / TWO_PI)
        at = at[~found]
    phase[...] = padded[1:-1, 1:-1]
    return phase


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
    with np.errstate(invalid="ignore"):
        orders = np.where(valid, np.rint((phase - phi) / TWO_PI), 0.0).astype(np.int32)
    steps = _steps(phi)
    core, labels, count = _fringe_regions(steps, valid, _region_cut(steps, valid) if cut is None else cut, bend)
    out = np.full(phase.shape, np.nan)
    labels, core, count = _drop_small_regions(labels, core, count, min_votes)
    if count > 1:
        pieces, piece_count = _tile_pieces(labels, core, count, tile)
        winners, sizes = _tally(pieces[core], orders[core], piece_count)
        voted = core & (sizes >= min_votes)[pieces]
        out = np.where(voted, phi + TWO_PI * winners[pieces], np.nan)
        # Squares that disagree with a neighbour may straddle a hidden edge: vote them pixel by pixel.
        suspect_piece = np.zeros(piece_count, dtype=bool)
        suspect_piece[pieces[order_break_pixels(out) & voted]] = True
        ys, xs = np.nonzero(voted & suspect_piece[pieces])
        if ys.size:
            local, support = _window_majority(orders, labels, ys, xs, radius)
            enough = support >= min_votes
            out[ys[enough], xs[enough]] = phi[ys[enough], xs[enough]] + TWO_PI * local[enough]
    out = fill_from_neighbours(out, phi, valid)
    unsettled = valid & np.isnan(out)
    out[unsettled] = phase[unsettled]
    return out
