"""Absolute phase error correction by RPCA (thesis ch. 4), and order re-derivation from it.

The measured absolute phase is Phi_hat = Phi + S + J: the phase of the scene (low rank for
smooth surfaces), sparse errors of multiples of 2 pi from wrong fringe orders, and dense noise.
The inexact ALM with tau = 1 / sqrt(max(M, N)) separates them; heights come from the low-rank
parts of the object's and the reference's phase (thesis ch. 4.2.2).

By default the solver runs as stable PCP: it stops once ||Phi_hat - L - S||_F reaches the
noise level sqrt(M N) sigma (sigma estimated robustly from the map) instead of exact equality.
On the thesis' Table 4.1 protocol this is both far more accurate (the low-rank part then carries
no noise: NMSE_h ~4e-4 against ~2e-3 for exact equality) and ~50x faster (rank 1-3 instead of
hundreds).

Beyond the thesis, :func:`reorder_from_low_rank` keeps the measured phase and only re-derives
each pixel's fringe order from the low-rank estimate, k = round((L - phi) / 2 pi): exact orders
wherever L is within pi of the truth, and every measured detail kept. :func:`restore_detail`
combines both: the low-rank phase, except where the re-derived phase departs from it by more
than the noise explains (structure the low-rank model missed). :func:`low_rank_misfit`,
:func:`settle_orders` and :func:`order_breaks` guard, tidy and rank re-derived order maps without
the truth (see :func:`processing.correction.registry.correct_auto`).
"""

from __future__ import annotations

import cv2
import numpy as np

from processing import _validate
from processing.angles import wrap_to_pi
from processing.correction.region_orders import neighbour_steps_at
from processing.correction.shadow_fill import fill_shadows, valid_mask
from processing.denoise.rpca import (
    RPCAResult,
    masked_second_differences,
    noise_sigma_from_second_differences,
    robust_noise_sigma,
    rpca_ialm,
)
from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi


def correct_phase_rpca(
    absolute_phase: np.ndarray,
    mask: np.ndarray | None = None,
    tau: float | None = None,
    stable: bool = True,
    svd: str = "auto",
    tol: float = 1e-7,
    max_iter: int = 500,
    noise_sigma: float | None = None,
    dtype: np.dtype | type | None = None,
) -> tuple[np.ndarray, RPCAResult]:
    """Low-rank part of an absolute phase map by inexact ALM RPCA (thesis ch. 4).

    Parameters
    ----------
    absolute_phase : (H, W) array
        Unwrapped phase (NaN where invalid).
    mask : (H, W) bool array, optional
        True where valid; default the finite pixels. Shadows are filled by row-wise linear
        interpolation before RPCA and are NaN in the result.
    tau : float, optional
        Weight of ||S||_1; default 1 / sqrt(max(H, W)).
    stable : bool
        Stop at the noise level (stable PCP, the default: measured more accurate) rather than
        at ||D - L - S||_F / ||D||_F < tol (the thesis' rule).
    svd : {"auto", "partial", "full"}
    tol, max_iter : solver controls, see :func:`processing.denoise.rpca.rpca_ialm`.
    noise_sigma : float, optional
        Phase noise in radians for ``stable``; default :func:`phase_noise_sigma` of the valid pixels.
    dtype : float32 or float64, optional
        Working precision; default float32 for ``stable`` (it stops at the noise level, far above
        float32 rounding: same NMSE_h to 1e-5 relative on Table 4.1, 2.5x faster), else float64.

    Returns
    -------
    low_rank_phase : (H, W) float64, NaN outside the mask
    result : RPCAResult
    """
    phase = _validate.phase_map(absolute_phase, "absolute_phase")
    valid = valid_mask(phase, mask, "absolute_phase")
    filled = fill_shadows(phase, valid)
    if stable and noise_sigma is None:
        noise_sigma = phase_noise_sigma(filled, valid)
    if dtype is None:
        dtype = np.float32 if stable else np.float64
    result = rpca_ialm(
        filled, tau=tau, tol=tol, max_iter=max_iter, svd=svd, stable=stable, noise_sigma=noise_sigma, dtype=dtype
    )
    return np.where(valid, result.low_rank.astype(np.float64), np.nan), result


def phase_noise_sigma(phase: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Standard deviation of the noise on a phase map, blind to its 2 pi order errors.

    As :func:`processing.denoise.rpca.robust_noise_sigma` (median absolute deviation of the second
    differences along rows and along columns, the smaller kept), with the differences wrapped into
    [-pi, pi): a wrong fringe order adds a multiple of 2 pi to them, which the wrapping removes,
    so the estimate holds however many orders are wrong. Unwrapped, with 14 % of the orders wrong
    (10 dB) it came out 1.7x the noise and with 25 % wrong (isolated objects, f = 25) 300x, and
    stable RPCA stopped far too early (NMSE_h 1.6 instead of 0.06).
    """
    return robust_noise_sigma(phase, mask, wrap=True)


def phase_noise_and_breaks(phase: np.ndarray, valid: np.ndarray) -> tuple[float, int]:
    """:func:`phase_noise_sigma` and :func:`order_breaks` of one map, from one set of its second differences."""
    seconds = masked_second_differences(phase, valid)
    sigma = noise_sigma_from_second_differences((s[np.isfinite(s)] for s in seconds), wrap=True)
    return sigma, _count_breaks(seconds)


def reorder_from_low_rank(
    low_rank_phase: np.ndarray, wrapped_phase: np.ndarray, mask: np.ndarray | None = None
) -> np.ndarray:
    """Measured wrapped phase with fringe orders re-derived from a low-rank estimate.

    k = round((L - phi) / 2 pi), Phi = phi + 2 pi k: the integer order nearest the estimate, so
    the result is exact wherever |L - Phi_true| < pi, and keeps the measured detail.

    Parameters
    ----------
    low_rank_phase : (H, W) array
        Estimate L of the absolute phase (NaN where invalid).
    wrapped_phase : (H, W) array
        Measured wrapped phase phi (any 2 pi representation).
    mask : (H, W) bool array, optional
        True where valid; default the finite pixels of ``low_rank_phase``.

    Returns
    -------
    (H, W) float64, NaN outside the mask
    """
    estimate, wrapped, valid = phase_pair(low_rank_phase, wrapped_phase, mask, ("low_rank_phase", "wrapped_phase"))
    out = np.subtract(estimate, wrapped)  # the expression in one buffer: the same values, one map instead of five
    out /= TWO_PI
    with np.errstate(invalid="ignore"):
        np.rint(out, out=out)
        out *= TWO_PI
        out += wrapped
    np.copyto(out, np.nan, where=~valid)
    return out


def phase_pair(
    phase: np.ndarray, other: np.ndarray, mask: np.ndarray | None, names: tuple[str, str]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Validate a phase map, a second map of its shape and the mask: ``(phase, other, valid)``.

    ``valid`` is :func:`processing.correction.shadow_fill.valid_mask` of ``phase``; ``other`` must be finite
    wherever ``phase`` is valid. ``names`` name the two maps in the ``ValueError`` messages.
    """
    first = _validate.phase_map(phase, names[0])
    second = _validate.phase_map(other, names[1], first.shape)
    valid = valid_mask(first, mask, names[0])
    if np.any(valid & ~np.isfinite(second)):
        raise ValueError(f"{names[1]}: NaN at pixels where {names[0]} is valid")
    return first, second, valid


def neighbour_prediction(phase: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """Each pixel's phase predicted from its neighbours, robust to one wrong neighbour.

    The mean of each opposite pair (left-right, up-down and both diagonals) is exact on a plane,
    whatever its slope; the prediction is the median of the complete pairs. Where fewer than two
    pairs are complete (image borders, corners of shadows), one wrong neighbour could sway it: the
    median of the valid single neighbours is used instead; NaN if there is none.

    The median of the (at most four) pairs is closed-form, in float32 (the prediction only ever
    picks a fringe order or compares two candidates; float32 is exact to 2e-5 rad at 160 rad):
    with n complete pairs, sum S, largest and smallest, it is (S - max - min) / (n - 2) for
    n = 3, 4 and (max + min) / 2 for n = 2; no sort of a (4, H, W) stack.
    """
    padded = np.pad(np.where(valid, phase, np.nan).astype(np.float32), 1, constant_values=np.nan)
    rows, cols = phase.shape

    def shifted(dy: int, dx: int) -> np.ndarray:
        return padded[1 + dy : 1 + dy + rows, 1 + dx : 1 + dx + cols]

    offsets = ((0, 1), (1, 0), (1, 1), (1, -1))
    total = np.zeros((rows, cols), dtype=np.float32)
    count = np.zeros((rows, cols), dtype=np.float32)
    largest = np.full((rows, cols), -np.inf, dtype=np.float32)
    smallest = np.full((rows, cols), np.inf, dtype=np.float32)
    pair = np.empty((rows, cols), dtype=np.float32)
    for dy, dx in offsets:
        np.add(shifted(-dy, -dx), shifted(dy, dx), out=pair)
        pair *= 0.5
        complete = np.isfinite(pair)
        count += complete
        total += np.where(complete, pair, 0.0)
        np.fmax(largest, pair, out=largest)
        np.fmin(smallest, pair, out=smallest)
    usable = count >= 2
    with np.errstate(invalid="ignore", divide="ignore"):
        median = np.where(count >= 3, (total - largest - smallest) / (count - 2), (largest + smallest) * 0.5)
    out = np.where(usable, median, np.nan).astype(np.float64)
    lonely = valid & ~usable
    if lonely.any():
        singles = np.stack([shifted(sy * dy, sy * dx)[lonely] for dy, dx in offsets for sy in (-1, 1)])
        out[lonely] = _nan_median_first_axis(singles.astype(np.float64))
    return out


def _nan_median_first_axis(stack: np.ndarray) -> np.ndarray:
    """Median over axis 0 ignoring NaN (NaN where all are NaN); a sort, far faster than np.nanmedian."""
    ordered = np.sort(stack, axis=0)  # NaN sort last
    count = np.isfinite(stack).sum(axis=0)
    low = np.take_along_axis(ordered, np.maximum((count - 1) // 2, 0)[None], axis=0)[0]
    high = np.take_along_axis(ordered, (count // 2)[None].clip(max=len(stack) - 1), axis=0)[0]
    return np.where(count > 0, (low + high) / 2.0, np.nan)


def accept_if_consistent(candidate: np.ndarray, original: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """``candidate`` where it fits the neighbours of ``original`` better than ``original`` does.

    Guards order changes proposed by a low-rank estimate: a pixel whose measured phase already
    agrees with its neighbours keeps it, even where the estimate is off by more than pi (steep
    edges, fringes too dense for the low-rank model).
    """
    prediction = neighbour_prediction(original, valid)
    better = np.abs(candidate - prediction) < np.abs(original - prediction)
    return np.where(valid & better, candidate, original)


def low_rank_misfit(
    low_rank_phase: np.ndarray, wrapped_phase: np.ndarray, valid: np.ndarray, limit: float = np.pi / 2
) -> np.ndarray:
    """Pixels near which the low-rank estimate does not fit the measured wrapped phase.

    Where L is within the noise of the truth, phi - L is a multiple of 2 pi plus noise; where the
    low-rank model missed structure (a steep edge, fringes too dense for it), the wrapped
    difference |wrap(phi - L)| grows past ``limit``. True at such pixels and their 8 neighbours
    (a misfit band sweeps through multiples of 2 pi, where single pixels look fine).
    """
    residual = wrap_to_pi(wrapped_phase - low_rank_phase)
    bad = ~(np.abs(residual, out=residual) < limit)  # NaN (no estimate) misfits too
    bad &= valid
    return valid & _dilate_3x3(bad)


def _dilate_3x3(mask: np.ndarray) -> np.ndarray:
    """Binary dilation by a 3 x 3 square (separable: rows, then columns), without scipy.ndimage."""
    across = mask.copy()
    across[:, 1:] |= mask[:, :-1]
    across[:, :-1] |= mask[:, 1:]
    out = across.copy()
    out[1:, :] |= across[:-1, :]
    out[:-1, :] |= across[1:, :]
    return out


def settle_orders(phase: np.ndarray, wrapped_phase: np.ndarray, valid: np.ndarray, passes: int = 2) -> np.ndarray:
    """Re-derive each pixel's order from its neighbours' phase, ``passes`` times.

    k = round((P - phi) / 2 pi) with P the :func:`neighbour_prediction` of the current map: a
    pixel whose order disagrees with its neighbours (an error the low-rank estimate carried, a
    blob of them too small to span a neighbourhood) takes theirs; detail is kept, only orders move.
    """
    out = phase
    for _ in range(passes):
        prediction = neighbour_prediction(out, valid)
        out = reorder_from_low_rank(np.where(np.isfinite(prediction), prediction, out), wrapped_phase, valid)
    return out


def order_breaks(phase: np.ndarray, valid: np.ndarray) -> int:
    """Second differences beyond pi along rows and columns: the order errors a map still shows.

    Truth-free: a wrong order puts a +-2 pi spike into the second differences, which a smooth or
    steep but continuous phase keeps well below pi (real steps also count, equally for all
    candidates of one map).
    """
    return _count_breaks(masked_second_differences(phase, valid))


# Share of the map that may differ from the previous map for :func:`order_breaks_since` to recount only near it.
RECOUNT_WHOLE_FROM = 1.0 / 16.0


def order_breaks_since(phase: np.ndarray, previous: np.ndarray, previous_breaks: int, valid: np.ndarray) -> int:
    """:func:`order_breaks` of ``phase``, given ``previous_breaks`` = :func:`order_breaks` of ``previous``.

    A second difference reads three neighbours, so only those that read a valid pixel where the two maps
    differ can change: they are recounted on both maps, in the arithmetic of the whole-map count (the same
    integer), at a cost that follows the differences (a candidate order map differs from the pooled one at
    a few hundred pixels).
    """
    differ = np.flatnonzero((phase != previous) & valid)
    if differ.size >= RECOUNT_WHOLE_FROM * valid.size:
        return order_breaks(phase, valid)
    height, width = valid.shape
    rows, cols = np.divmod(differ, width)
    back = np.arange(3)[None, :]  # a pixel is read by the second differences starting 0, 1 and 2 before it
    breaks = int(previous_breaks)
    for step, length in ((1, width), (width, height)):  # along the rows, then down the columns
        if length < 3:
            continue
        if step == 1:
            first = rows[:, None] * width + np.clip(cols[:, None] - back, 0, width - 3)
        else:
            first = np.clip(rows[:, None] - back, 0, height - 3) * width + cols[:, None]
        first = np.unique(first)  # clipped starts read no differing pixel: they count alike on both maps
        breaks += _count_breaks_at(np.ravel(phase), np.ravel(valid), first, step)
        breaks -= _count_breaks_at(np.ravel(previous), np.ravel(valid), first, step)
    return breaks


def _count_breaks_at(flat: np.ndarray, flat_valid: np.ndarray, first: np.ndarray, step: int) -> int:
    """Second differences beyond pi of the flat map at ``first``, ``first + step``, ``first + 2 step`` (NaN
    unless all three are valid), as :func:`processing.denoise.rpca.masked_second_differences` computes them."""
    before, middle, after = (
        np.where(flat_valid[at], flat[at], np.nan) for at in (first, first + step, first + 2 * step)
    )
    second = np.multiply(middle, 2.0)
    np.subtract(after, second, out=second)
    second += before
    with np.errstate(invalid="ignore"):
        return int(np.count_nonzero(np.abs(second) > np.pi))


def _count_breaks(seconds: tuple[np.ndarray, np.ndarray]) -> int:
    """Second differences beyond pi (NaN, an invalid pixel of the three, never counts)."""
    breaks = 0
    for second in seconds:
        breaks += int(np.count_nonzero(np.abs(second) > np.pi))
    return breaks


def restore_detail(
    low_rank_phase: np.ndarray,
    measured_phase: np.ndarray,
    mask: np.ndarray | None = None,
    k_sigma: float = 4.0,
    noise_sigma: float | None = None,
    unwrapped_phase: np.ndarray | None = None,
) -> np.ndarray:
    """Low-rank phase, except where the measured phase departs from it coherently beyond the noise.

    Where the residual r = measured - L averaged over the 3 x 3 neighbourhood exceeds
    ``k_sigma`` standard deviations of such a mean (k_sigma sigma / 3; sigma: ``noise_sigma``,
    default :func:`phase_noise_sigma` of ``measured``) and at least 3 of the 9 pixels depart by
    more than 2 sigma, the low-rank model missed structure (an edge, a small feature, a bias of
    the low-rank fit) and the measured value is kept. Requiring a coherent departure keeps L at
    noise outliers and at a lone wrong order that ``measured_phase`` may still carry: measured
    on rig study's sphere cap (15 dB) and isolated objects (18 dB, 15 dB), it beats the per-pixel
    rule |r| > 4 sigma by 6 % to 37 % in NMSE_h and the plain L everywhere but at 10 dB (2 %).
    A lone pixel departing beyond 2 k_sigma sigma is kept too (:func:`_lone_departures_kept`).
    ``measured_phase`` should be free of order errors, e.g. from :func:`reorder_from_low_rank`;
    ``unwrapped_phase``: the phase as temporal unwrapping measured it, the independent evidence of
    ``measured_phase``'s orders that the lone pixels at a real height step are kept on.

    Returns
    -------
    (H, W) float64, NaN outside the mask
    """
    estimate, measured, valid = phase_pair(low_rank_phase, measured_phase, mask, ("low_rank_phase", "measured_phase"))
    k_sigma = float(k_sigma)
    if not k_sigma > 0:
        raise ValueError(f"k_sigma: expected > 0, found {k_sigma}")
    sigma = phase_noise_sigma(measured, valid) if noise_sigma is None else float(noise_sigma)
    unwrapped = None
    if unwrapped_phase is not None:
        unwrapped = np.asarray(unwrapped_phase, dtype=np.float64)
        if unwrapped.shape != valid.shape:
            raise ValueError(f"unwrapped_phase: expected shape {valid.shape}, found {unwrapped.shape}")
    return keep_coherent_detail(estimate, measured, valid, k_sigma, sigma, unwrapped)


def keep_coherent_detail(
    estimate: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    k_sigma: float,
    sigma: float,
    unwrapped: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`restore_detail` on maps already validated (finite wherever ``valid``), ``k_sigma`` > 0."""
    invalid = ~valid
    residual = np.subtract(measured, estimate, out=np.empty(valid.shape, dtype=np.float32), casting="same_kind")
    np.copyto(residual, np.float32(0.0), where=invalid)
    size = np.abs(residual)
    mean = _box_sum_3x3(residual) / 9.0
    departing = _box_count_3x3(size > 2.0 * sigma)
    coherent, lone = _departures(size, mean, departing, k_sigma, sigma)
    rows, cols = np.divmod(np.flatnonzero(lone), lone.shape[1])  # rare: the neighbour tests run at these only
    lone[rows, cols] = _lone_departures_kept(measured, valid, rows, cols, unwrapped)
    out = np.where(valid & (coherent | lone), measured, estimate)
    np.copyto(out, np.nan, where=invalid)
    return out


def _lone_departures_kept(
    measured: np.ndarray, valid: np.ndarray, rows: np.ndarray, cols: np.ndarray, unwrapped: np.ndarray | None
) -> np.ndarray:
    """Which lone departures (one pixel beyond 2 k_sigma sigma: far beyond any noise) keep the measured value.

    Structure (a one-pixel feature, fringes too dense for L) unless the pixel breaks with a neighbour, which
    may be a wrong order left in it; then L stays. Except on the edge of a real height step of more than
    pi: there the pixel breaks with the far side, and the 3 x 3 mean of the residual cancels (L blurs both
    sides alike, r changes sign across the edge), so L's in-between value, up to half the step off, would
    stay. Such a pixel continues more of its valid neighbours than it breaks with, and its order is the one
    temporal unwrapping measured (``unwrapped``): two independent estimates agree on it, so it is kept. A
    pixel whose order the correction changed is not: a line pooled with the far side of a step looks the
    same to its neighbours, and there L's in-between value is the smaller error.
    """
    breaks, continues = neighbour_steps_at(measured, valid, rows, cols)
    kept = breaks == 0
    if unwrapped is not None:
        measured_order = np.abs(measured[rows, cols] - unwrapped[rows, cols]) < np.pi
        kept |= (breaks < continues) & measured_order
    return kept


# Share of the map near changed orders from which :func:`update_coherent_detail` recomputes the whole map
# instead (gathering 9 neighbours per pixel costs more than one streaming pass there).
UPDATE_WHOLE_FROM = 1.0 / 16.0


def update_coherent_detail(
    previous_out: np.ndarray,
    previous_measured: np.ndarray,
    estimate: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    k_sigma: float,
    sigma: float,
    unwrapped: np.ndarray | None = None,
) -> np.ndarray:
    """:func:`keep_coherent_detail` of ``measured``, given ``previous_out`` = the same of ``previous_measured``
    (both with the same ``unwrapped``).

    A pixel's result reads the maps within its 3 x 3 neighbourhood only, so it is recomputed at the pixels
    within one of a change only, from their 9 neighbours gathered and summed in the order of the whole-map
    pass (rows, then columns, in float32): bit-identical to it, at a cost that follows the changes.
    """
    height, width = valid.shape
    rows, cols = np.divmod(np.flatnonzero(valid & (measured != previous_measured)), width)
    if not rows.size:
        return previous_out
    offsets = np.arange(-1, 2)
    near_rows = np.clip(rows[:, None, None] + offsets[None, :, None], 0, height - 1)
    near_cols = np.clip(cols[:, None, None] + offsets[None, None, :], 0, width - 1)
    near = np.unique((near_rows * width + near_cols).ravel())
    if near.size >= UPDATE_WHOLE_FROM * valid.size:
        return keep_coherent_detail(estimate, measured, valid, k_sigma, sigma, unwrapped)
    ys, xs = np.divmod(near, width)

    def residual_at(dy: int, dx: int) -> np.ndarray:
        """measured - estimate in float32 at the pixels' neighbour (dy, dx), 0 off the map or the mask."""
        y, x = ys + dy, xs + dx
        inside = (y >= 0) & (y < height) & (x >= 0) & (x < width)
        y, x = np.clip(y, 0, height - 1), np.clip(x, 0, width - 1)
        residual = np.subtract(measured[y, x], estimate[y, x], out=np.empty(y.size, np.float32), casting="same_kind")
        np.copyto(residual, np.float32(0.0), where=~(inside & valid[y, x]))
        return residual

    box = [[residual_at(dy, dx) for dx in (-1, 0, 1)] for dy in (-1, 0, 1)]
    across = [row[0] + row[1] + row[2] for row in box]
    departing = [[(np.abs(value) > 2.0 * sigma).view(np.uint8) for value in row] for row in box]
    count = sum(value for row in departing for value in row)
    coherent, lone = _departures(np.abs(box[1][1]), (across[0] + across[1] + across[2]) / 9.0, count, k_sigma, sigma)
    lone[lone] = _lone_departures_kept(measured, valid, ys[lone], xs[lone], unwrapped)
    here_valid = valid[ys, xs]
    values = np.where(here_valid & (coherent | lone), measured[ys, xs], estimate[ys, xs])
    values[~here_valid] = np.nan
    out = previous_out.copy()
    out[ys, xs] = values
    return out


def _departures(
    size: np.ndarray, mean: np.ndarray, departing: np.ndarray, k_sigma: float, sigma: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`restore_detail`'s rules: the coherent departures, and the lone ones (before their order-break test)."""
    return (np.abs(mean) > k_sigma * sigma / 3.0) & (departing >= 3), size > 2.0 * k_sigma * sigma


def _box_sum_3x3(values: np.ndarray) -> np.ndarray:
    """Sum over each pixel's 3 x 3 neighbourhood (zero beyond the borders), separable."""
    padded = np.pad(values, 1)
    across = padded[:, :-2] + padded[:, 1:-1] + padded[:, 2:]
    return across[:-2, :] + across[1:-1, :] + across[2:, :]


def _box_count_3x3(mask: np.ndarray) -> np.ndarray:
    """True pixels in each pixel's 3 x 3 neighbourhood (uint8: at most 9), as :func:`_box_sum_3x3`: whole numbers,
    exact in any order of summation, so OpenCV's box filter counts them."""
    return cv2.boxFilter(mask.view(np.uint8), -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)


def block_means(values: np.ndarray, valid: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the valid pixels of each ``factor`` x ``factor`` block (float32) and the blocks with any.

    The map is padded with invalid pixels to a multiple of ``factor``; a block without a valid
    pixel is 0 and False.
    """
    rows, cols = values.shape
    down, across = -(-rows // factor), -(-cols // factor)
    data = np.zeros((down * factor, across * factor), dtype=np.float32)
    count = np.zeros(data.shape, dtype=np.uint8)
    with np.errstate(over="ignore", invalid="ignore"):  # what lies outside ``valid`` is overwritten by 0
        np.copyto(data[:rows, :cols], values, casting="same_kind")
    np.copyto(data[:rows, :cols], np.float32(0.0), where=~valid)
    count[:rows, :cols] = valid
    sums = _block_sums(data, factor, np.float32)
    counts = _block_sums(count, factor, np.uint16).astype(np.float32)  # whole numbers: exact either way
    with np.errstate(invalid="ignore", divide="ignore"):
        means = np.where(counts > 0, sums / counts, 0.0).astype(np.float32)
    return means, counts > 0


def _block_sums(data: np.ndarray, factor: int, dtype: type) -> np.ndarray:
    """Sums of the ``factor`` x ``factor`` blocks of ``data`` (sides multiples of ``factor``) in ``dtype``.

    Bit-identical to ``data.reshape(down, factor, across, factor).sum(axis=(1, 3))`` in float32: numpy adds
    each block row's values left to right and then the rows, top to bottom, onto 0 (one tiny inner loop per
    block row there; a few strided passes over the map here).
    """
    rows, cols = data.shape
    by_row = data.reshape(rows, cols // factor, factor)
    row_sums: np.ndarray = by_row[:, :, 0].astype(dtype)
    for k in range(1, factor):
        row_sums += by_row[:, :, k]
    blocks = row_sums.reshape(rows // factor, factor, cols // factor)
    out = np.zeros((rows // factor, cols // factor), dtype=dtype)
    for k in range(factor):
        out += blocks[:, k, :]
    return out


def upsample_blocks(blocks: np.ndarray, factor: int, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear interpolation of block means back to pixels, linear beyond the outer block centres.

    Each block's value sits at its centre; the blocks are first extended by one linearly
    extrapolated block on every side, so the pixels outside the outermost centres follow the
    slope rather than a constant. Returns (``shape``) float32.
    """

    grid = np.asarray(blocks, dtype=np.float32)
    if grid.shape[0] > 1:
        grid = np.concatenate([2 * grid[:1] - grid[1:2], grid, 2 * grid[-1:] - grid[-2:-1]], axis=0)
    else:
        grid = np.concatenate([grid, grid, grid], axis=0)
    if grid.shape[1] > 1:
        grid = np.concatenate([2 * grid[:, :1] - grid[:, 1:2], grid, 2 * grid[:, -1:] - grid[:, -2:-1]], axis=1)
    else:
        grid = np.concatenate([grid, grid, grid], axis=1)
    up = cv2.resize(grid, (grid.shape[1] * factor, grid.shape[0] * factor), interpolation=cv2.INTER_LINEAR)
    return up[factor : factor + shape[0], factor : factor + shape[1]]


def decimated_low_rank(
    phase: np.ndarray,
    valid: np.ndarray,
    factor: int,
    noise_sigma: float,
    tau: float | None = None,
    svd: str = "auto",
    bend: float = 1.0,
) -> tuple[np.ndarray, RPCAResult, np.ndarray]:
    """Low-rank part of a phase map solved on its ``factor`` x ``factor`` block means, interpolated back.

    The low-rank part of a smooth phase is smooth: stable RPCA (thesis ch. 4) on the block means,
    whose noise is ``noise_sigma / factor``, costs ``factor ** 2`` times less per iteration and
    stops on a cleaner surface (measured: see :data:`processing.correction.registry.DECIMATION`). Bilinear
    interpolation blurs the surface's sharp edges, so the pixels near blocks where it bends by
    more than ``bend`` radians (second difference between blocks) are returned as ``rough``:
    the interpolated value there may be off by more than pi and must not set fringe orders.

    Returns
    -------
    low_rank : (H, W) float64, NaN outside ``valid``
    result : RPCAResult of the block solve
    rough : (H, W) bool
    """
    means, inside = block_means(phase, valid, factor)
    filled = fill_shadows(means, inside)
    result = rpca_ialm(filled, tau=tau, svd=svd, stable=True, noise_sigma=noise_sigma / factor, dtype=np.float32)
    low_rank = upsample_blocks(result.low_rank, factor, phase.shape).astype(np.float64)
    np.copyto(low_rank, np.nan, where=~valid)
    return low_rank, result, _bent_pixels(result.low_rank, factor, phase.shape, bend)


# Largest block-solve rank :func:`refit_full_resolution` refits: its four products cost 8 x rank flops per
# pixel, and a surface of higher rank is no longer the smooth scene whose edges the blocks blurred.
REFIT_MAX_RANK = 24


# How many standard deviations of a 3 x 3 noise sum the refit's residual must gain over the block surface's.
# Without a margin, noise alone picked the (noisier) refit on about half of a smooth part's pixels (NMSE_h of
# the study's sphere cap at 10 dB 24 % worse than before the refit); one standard deviation keeps the refit's
# gain on the develop family's staircases and ramps (two lost part of it on develop-15, -53 and -61).
REFIT_MARGIN = 1.0


def refit_full_resolution(
    low_rank: np.ndarray,
    blocks: np.ndarray,
    factor: int,
    measured: np.ndarray,
    valid: np.ndarray,
    rank: int,
    outlier: float,
    noise: float = 0.0,
) -> np.ndarray:
    """The block solve's low-rank surface, refitted at full resolution where that fits ``measured`` clearly better.

    Block means blur what changes within a block (a step's edge, a ramp's kink), which ch. 4 at full
    resolution keeps. Here the ``rank`` factors of the solved ``blocks`` are interpolated to pixels and
    refitted to ``measured`` by alternating least squares (columns, then rows; pixels outside ``valid`` take
    the interpolated surface), twice, the second time with the pixels more than ``outlier`` radians off the
    first refit replaced by it: products of the map with ``rank`` vectors, not a full-resolution solve. A valid pixel
    then takes the refit where the refit lies within ``outlier`` of ``measured`` and its 3 x 3 sum of absolute
    residuals is smaller than the block surface's by more than :data:`REFIT_MARGIN` standard deviations of a
    3 x 3 noise sum (3 ``noise``). So structure the refit spreads along rows or columns (an object the low
    rank cannot hold) stays out, a refit oscillating about ``measured`` does not win on a signed sum near 0,
    and on smooth parts, where both surfaces fit within the noise, the block surface (a mean of 16 pixels,
    less noisy than a full-resolution fit) stays. ``low_rank`` unchanged where ``rank`` is 0 or above
    :data:`REFIT_MAX_RANK`.
    """
    rank = min(int(rank), *blocks.shape)
    if not 0 < rank <= REFIT_MAX_RANK:
        return low_rank
    grid = np.asarray(blocks, dtype=np.float64)
    # any rank-``rank`` factors of the blocks will do (ALS refits both): an orthonormal basis of their
    # columns, from their product with fixed random vectors (exact for a matrix of that rank), is cheaper
    # than their SVD
    basis, _ = np.linalg.qr(grid @ np.random.default_rng(0).standard_normal((grid.shape[1], rank)))
    rows = _interpolate_factors(basis, factor, measured.shape[0])
    cols = _interpolate_factors(grid.T @ basis, factor, measured.shape[1])
    measured_32 = measured.astype(np.float32)
    target = np.where(valid, measured_32, rows @ cols.T)
    for round_ in range(2):
        cols = _least_squares_factor(rows, target.T @ rows)
        rows = _least_squares_factor(cols, target @ cols)
        refit = rows @ cols.T
        if round_ == 0:
            # what departs from the refit far beyond the noise (an object the low rank cannot hold) is left
            # out of the second round, so the refit does not spread it along its rows and columns
            np.copyto(target, refit, where=abs_difference(target, refit) > outlier)
    # residuals of both surfaces (0 outside ``valid``), float32, compared as 3 x 3 sums of absolute values
    # (each map cast to float32 before it is chosen from: the same values, half the memory traffic)
    inside = np.where(valid, measured_32, refit)
    block = np.where(valid, low_rank.astype(np.float32), refit)
    margin = REFIT_MARGIN * 3.0 * float(noise)
    # where neither surface holds the scene (beyond ``outlier``), the block surface stays for the detail
    # restore to judge, as without the refit (develop-33's tall objects: 0.087 -> 0.025 x the oracle)
    misfit = abs_difference(inside, refit)
    better = valid & (misfit <= outlier) & (_box_sum(misfit) + margin < _box_sum(abs_difference(inside, block)))
    return np.where(better, refit, low_rank)


def _box_sum(values: np.ndarray) -> np.ndarray:
    """:func:`_box_sum_3x3` of a float32 map by OpenCV's box filter (several times faster)."""
    return cv2.boxFilter(values, -1, (3, 3), normalize=False, borderType=cv2.BORDER_CONSTANT)


def _interpolate_factors(factors: np.ndarray, factor: int, length: int) -> np.ndarray:
    """(blocks, r) factors of a block solution linearly interpolated to ``length`` pixels (float32)."""
    centres = (np.arange(factors.shape[0]) + 0.5) * factor - 0.5
    pixels = np.arange(length, dtype=np.float64)
    return np.stack([np.interp(pixels, centres, column) for column in factors.T], axis=1).astype(np.float32)


def _least_squares_factor(fixed: np.ndarray, products: np.ndarray) -> np.ndarray:
    """The other factor of ``target ~ fixed @ other.T`` given ``products = target.T @ fixed`` (ridge-regularised)."""
    gram = (fixed.T @ fixed).astype(np.float64)
    gram += np.eye(len(gram)) * (1e-9 * np.trace(gram) + 1e-30)
    return np.linalg.solve(gram, products.T.astype(np.float64)).T.astype(np.float32)


def _bent_pixels(blocks: np.ndarray, factor: int, shape: tuple[int, int], bend: float) -> np.ndarray:
    """Pixels of the blocks (and their 8 neighbours) where the block surface bends by more than ``bend``."""
    bent = np.zeros(blocks.shape, dtype=bool)
    if blocks.shape[1] > 2:
        bent[:, 1:-1] |= np.abs(np.diff(blocks, n=2, axis=1)) > bend
    if blocks.shape[0] > 2:
        bent[1:-1, :] |= np.abs(np.diff(blocks, n=2, axis=0)) > bend
    bent = _dilate_3x3(bent)
    return np.repeat(np.repeat(bent, factor, axis=0), factor, axis=1)[: shape[0], : shape[1]]
