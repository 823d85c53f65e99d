"""Whether the other frequencies' wrapped phases support a change of fringe orders, blob by blob.

Temporal unwrapping measured each pixel's fringe order from the lower frequencies of the capture;
a spatial correction proposes other orders for some pixels. Any choice of orders predicts every
lower frequency's wrapped phase: the absolute phase ``Phi = phi + 2 pi k`` at frequency ``f`` is
``Phi f_l / f`` at ``f_l``. The squared misfit of that prediction, wrapped and summed over the
lower frequencies, is (up to the noise variance) minus twice the log-likelihood of the orders.

Over a blob of changed pixels, ``D`` (the misfit with the proposed orders minus that with the
measured ones, summed over the blob) is compared with ``S``, what ``D`` is expected to be if the
measured orders were right (each pixel's squared shift of the prediction, ``wrap(2 pi dk f_l / f)``
squared). If the measured orders were wrong (noise pushed them past the decision boundary, the
case corrections are for), the proposed orders fit about as well as the measured ones and ``D``
lies near 0. Misfits are counted in units of each frequency's noise variance (the median misfit of
the measured orders over the map, :func:`noise_weights`, or the blob's own where larger). The
midpoint ``S / 2`` decides, with a margin of :data:`Z_MARGIN` standard errors (``2 sqrt(S)``):

- ``D`` well above ``S / 2``: the other frequencies contradict the change (a spatial correction that
  pooled across a real step or blurred an edge); the measured orders come back on the blob's pixels
  whose own misfit says so (a blob can also hold pixels whose measured orders were wrong);
- ``D`` well below: the change stands;
- in between, where the blob's evidence cannot tell the two apart: the proposal (which the neighbours
  supported) stays and the blob is reported unresolved;
- ``S`` within the margin of 0 (changes by a whole cycle of every lower frequency, e.g. 64 orders of
  1/8/64), below :data:`SEPARATION` noise deviations or below :data:`MIN_SHIFT_RAD`: the frequencies
  cannot judge, and the change keeps what the neighbour evidence
  (:mod:`processing.correction.order_evidence`) decided.

A blob the frequencies did not contradict as a whole but whose pixels changed by several order shifts is
judged again piece by piece, a piece being its pixels of one shift (:func:`judge_shift_pieces`): right
changes of many wrongly measured pixels can outweigh a wrong change of a few (a line of edge pixels pooled
onto a step's far side). A contradicted piece goes back as a contradicted blob does, unless an order within
two of the proposed one, or one that continues a neighbour, would be as undecidable against the measured
orders as a blob of that shift (a close pair, where orders many fringes apart predict the lower phase
alike): then the measured orders may be as wrong as the proposal, and the piece is reported unresolved,
or a pixel takes the neighbour's order where that is the only such order the most neighbours continue and
it fits the lower frequencies within the noise.

Before judging, :func:`snap_to_lower_frequencies` moves changed pixels one or two orders where the lower
frequencies clearly fit that order better.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from processing.angles import wrap_to_pi
from processing.correction.order_evidence import changed_orders, label_blobs, mask_at, neighbours_at, revert_changed
from processing.denoise.rpca import finite_median

TWO_PI = 2.0 * np.pi
# Standard errors between a blob's evidence and the decision threshold for a confident decision.
Z_MARGIN = 3.0
# A blob's lower frequencies judge it only where changing its orders shifts their predictions by more
# than this many noise standard deviations (per pixel, root mean square): below it, the measured orders
# are themselves likely wrong (the noise that misled the temporal unwrapping), and the evidence is
# left to the neighbours.
SEPARATION = 4.0
# ... and only where that shift is more than this (radians, root mean square over the blob's pixels):
# systematic phase errors that differ between frequencies (harmonics with few phase steps, mixed
# pixels at edges) mislead the temporal unwrapping into smaller shifts, up to 0.8 rad on the develop
# cases, where the measured orders then fit better than the right ones.
MIN_SHIFT_RAD = 1.0
# Order steps :func:`snap_to_lower_frequencies` tries, each only where its shift clears both bounds above, two
# orders only where one order does not: where one order shifts the lower frequencies' predictions too little
# (29/32: 0.59 rad, 1/8/64: 0.79 rad), two orders may not (1.18 rad, 1.57 rad), and pooling beside an edge
# of 29/32 leaves pixels two orders off.
SNAP_STEPS = (-1.0, 1.0, -2.0, 2.0)


def lower_frequency_misfit(
    phase: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float] | None = None,
) -> np.ndarray:
    """Sum over ``lower`` = ((f_l, wrapped phase at f_l), ...) of wrap(phase f_l / frequency - phi_l)^2
    (each term times its ``weights`` entry, default 1)."""
    out = np.zeros(phase.shape, dtype=np.float64)
    for index, term in enumerate(_misfit_terms(phase, frequency, lower)):
        out += term if weights is None else weights[index] * term
    return out


def order_shift(
    delta_orders: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float] | None = None,
) -> np.ndarray:
    """Squared shift of every lower frequency's prediction when the orders change by ``delta_orders``
    (weighted as :func:`lower_frequency_misfit`): the misfit's expected increase for that change."""
    out = np.zeros(delta_orders.shape, dtype=np.float64)
    for index, term in enumerate(_shift_terms(delta_orders, frequency, lower)):
        out += term if weights is None else weights[index] * term
    return out


def _plain_and_weighted(terms: Sequence[np.ndarray], weights: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    """The sums :func:`lower_frequency_misfit` and :func:`order_shift` form of per-frequency ``terms``, without and
    with ``weights``, in their order (the same values as two calls, each term computed once)."""
    plain = np.zeros(terms[0].shape, dtype=np.float64)
    weighted = np.zeros(terms[0].shape, dtype=np.float64)
    for index, term in enumerate(terms):
        plain += term
        weighted += weights[index] * term
    return plain, weighted


def _misfit_terms(phase: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]]) -> list[np.ndarray]:
    """The terms of :func:`lower_frequency_misfit`, one per lower frequency."""
    return [wrap_to_pi(phase * (float(f_low) / float(frequency)) - wrapped_low) ** 2 for f_low, wrapped_low in lower]


def _shift_terms(
    delta_orders: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]]
) -> list[np.ndarray]:
    """The terms of :func:`order_shift`, one per lower frequency."""
    return [wrap_to_pi(TWO_PI * delta_orders * (float(f_low) / float(frequency))) ** 2 for f_low, _wrapped in lower]


def noise_weights(
    measured: np.ndarray, valid: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]]
) -> list[float]:
    """1 / noise variance of each lower frequency's misfit with the measured orders (median over the valid
    pixels / 0.455, the median of chi-square with one degree of freedom: robust to wrong orders)."""
    at = measured[valid]
    weights = []
    for f_low, wrapped_low in lower:
        term = wrap_to_pi(at * (float(f_low) / float(frequency)) - wrapped_low[valid]) ** 2
        variance = finite_median(term) / 0.455 if term.size else 0.0
        weights.append(1.0 / max(variance, 1e-12))
    return weights


def snap_to_lower_frequencies(
    proposed: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float] | None = None,
) -> tuple[np.ndarray, int]:
    """``proposed`` with each changed pixel moved one or two orders where the lower frequencies clearly say so.

    A spatial correction knows the order only to within its neighbours': beside a height step close to
    a whole fringe it can be one order off on a whole side of the step. The lower frequencies tell
    neighbouring orders apart well wherever one order shifts their prediction by :data:`MIN_SHIFT_RAD`
    or more (all drawn frequency sets but 29/32 and 1/8/64): a pixel changed by the correction takes
    the order next to the proposed one if that fits them better by more than half that shift squared
    (the likelihood midpoint, plus a quarter of the shift of margin). Where one order shifts them too little
    (29/32, 1/8/64), two orders may not (:data:`SNAP_STEPS`), tried the same way; a two-order step also only
    where every lower frequency fits the new order and it leaves no change :func:`keep_temporally_supported`
    could judge unjudgeable (:func:`_two_order_step_allowed`). Returns the phase and how many pixels moved.
    """
    changed = changed_orders(proposed, measured, valid)
    if not changed.any() or not lower:
        return proposed, 0
    # flat indices, not the mask: gathering by a scattered boolean mask costs several times more
    where = np.flatnonzero(changed)
    lower_at = gather_lower(lower, where)
    at = np.ravel(proposed)[where]
    best = lower_frequency_misfit(at, frequency, lower_at)
    one_order_judged = False
    measured_at: np.ndarray | None = None  # gathered once, by the two-order guard alone
    step = np.zeros(at.shape)
    if weights is None:
        weights = noise_weights(measured, valid, frequency, lower)
    for delta in SNAP_STEPS:
        shift = float(order_shift(np.full(1, delta), frequency, lower)[0])
        separation = float(order_shift(np.full(1, delta), frequency, lower, weights)[0])
        if shift < MIN_SHIFT_RAD**2 or separation < SEPARATION**2 or (abs(delta) > 1 and one_order_judged):
            continue
        one_order_judged |= abs(delta) == 1
        fits, weighted = _plain_and_weighted(_misfit_terms(at + TWO_PI * delta, frequency, lower_at), weights)
        # and the new order must fit them within the noise (3 sigma a frequency): beside edges and
        # where the lower phases are corrupted too, a better fit is not yet a good one
        within = weighted <= 9.0 * len(lower)
        if abs(delta) > 1:
            measured_at = np.ravel(measured)[where] if measured_at is None else measured_at
            within &= _two_order_step_allowed(at, measured_at, delta, frequency, lower_at, weights)
        better = within & (fits < best - shift / 2.0)
        step[better] = delta
        best = np.where(better, fits, best)
    moved = int(np.count_nonzero(step))
    if not moved:
        return proposed, 0
    out = proposed.copy()
    out.reshape(-1)[where] = at + TWO_PI * step
    return out, moved


def _two_order_step_allowed(
    proposed: np.ndarray,
    measured: np.ndarray,
    delta: float,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float],
) -> np.ndarray:
    """Where a step of ``delta`` (two orders) neither misfits one lower frequency nor hides a change from
    :func:`keep_temporally_supported`: two orders can land a whole cycle of a middle frequency off (1/8/64 six
    orders off moved to eight), which the other frequencies' sum forgives and the judgement of the change
    then cannot see, where it would have sent the proposed order back to the measured one."""
    target = proposed + TWO_PI * delta
    allowed = _fits_each_frequency(target, frequency, lower, weights)
    before = np.rint((proposed - measured) / TWO_PI)
    after = before + delta
    judged_before = order_shift(before, frequency, lower) >= MIN_SHIFT_RAD**2
    judged_after = order_shift(after, frequency, lower) >= MIN_SHIFT_RAD**2
    return allowed & ~(judged_before & ~judged_after & (after != 0))


def _fits_each_frequency(
    phase: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]], weights: Sequence[float]
) -> np.ndarray:
    """Whether ``phase`` fits every lower frequency within 3 noise deviations (a sum over them can hide
    one that contradicts it: 1/8/64 six orders off moved to eight fits the 8 phase and misfits the 1 phase)."""
    out = np.ones(phase.shape, dtype=bool)
    for index, entry in enumerate(lower):
        out &= lower_frequency_misfit(phase, frequency, [entry], [weights[index]]) <= 9.0
    return out


def gather_lower(lower: Sequence[tuple[float, np.ndarray]], where: np.ndarray) -> list[tuple[float, np.ndarray]]:
    """((f_l, wrapped phase at f_l), ...) at the flat indices ``where`` of the (H, W) maps (by index, not by a
    scattered boolean mask: that gather costs several times more)."""
    return [(f_low, np.ravel(wrapped_low)[where]) for f_low, wrapped_low in lower]


@dataclass(frozen=True)
class PixelEvidence:
    """Per changed pixel: noise-weighted misfits of both orders, the shift between them weighted and in rad^2, and
    the orders changed (proposed minus measured)."""

    with_measured: np.ndarray
    with_proposed: np.ndarray
    shift: np.ndarray
    shift_rad: np.ndarray
    delta: np.ndarray

    @classmethod
    def at(
        cls,
        where: np.ndarray,
        proposed: np.ndarray,
        measured: np.ndarray,
        frequency: float,
        lower: Sequence[tuple[float, np.ndarray]],
        weights: Sequence[float],
    ) -> PixelEvidence:
        """:meth:`of` the pixels at the flat indices ``where`` of (H, W) maps."""
        lower_at = gather_lower(lower, where)
        return cls.of(np.ravel(proposed)[where], np.ravel(measured)[where], frequency, lower_at, weights)

    @classmethod
    def of(
        cls,
        proposed: np.ndarray,
        measured: np.ndarray,
        frequency: float,
        lower: Sequence[tuple[float, np.ndarray]],
        weights: Sequence[float],
    ) -> PixelEvidence:
        delta = np.rint((proposed - measured) / TWO_PI)
        shift_rad, shift = _plain_and_weighted(_shift_terms(delta, frequency, lower), weights)
        return cls(
            lower_frequency_misfit(measured, frequency, lower, weights),
            lower_frequency_misfit(proposed, frequency, lower, weights),
            shift,
            shift_rad,
            delta,
        )

    def take(self, index: np.ndarray) -> PixelEvidence:
        """The evidence of the pixels ``index`` (a boolean mask or indices into these arrays)."""
        return PixelEvidence(
            self.with_measured[index],
            self.with_proposed[index],
            self.shift[index],
            self.shift_rad[index],
            self.delta[index],
        )


def keep_temporally_supported(
    proposed: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, int]]:
    """``proposed`` where the lower frequencies do not contradict it; the unresolved pixels; blob counts.

    Parameters
    ----------
    proposed, measured : (H, W) absolute phases at ``frequency`` with the same wrapped phase
    valid : (H, W) bool
    frequency : the frequency of both phases
    lower : ((f_l, wrapped phase at f_l), ...), each (H, W), any 2 pi representation, finite where valid

    Returns
    -------
    phase : (H, W) ``proposed`` with the contradicted pixels of contradicted blobs and pieces set back to ``measured``
        (a piece's pixel to its neighbours' order where the lower frequencies cannot tell that from the measured one)
    unresolved : (H, W) bool, the ambiguous blobs' and pieces' pixels (their proposed orders, which the neighbours
        supported, stay)
    counts : blobs ``kept``, ``reverted``, ``unresolved`` and ``undecidable`` (left to the neighbours), and
        the pixels of pieces of one order shift in the kept blobs sent back to the measured orders or a
        neighbour's (``piece_pixels_reverted``) and reported (``piece_pixels_unresolved``)
        (:func:`judge_shift_pieces`)

    Examples
    --------
    A ramp at 17 fringes whose 13-fringe phase confirms the measured orders; a proposal three
    orders off on a patch goes back:

    >>> import numpy as np
    >>> from processing.angles import wrap_to_pi
    >>> truth = np.tile(np.linspace(0.0, 60.0, 80), (60, 1))
    >>> lower = [(13.0, wrap_to_pi(truth * 13.0 / 17.0))]
    >>> proposed = truth.copy()
    >>> proposed[20:24, 30:34] -= 3 * 2 * np.pi
    >>> kept, unresolved, counts = keep_temporally_supported(proposed, truth, np.ones((60, 80), bool), 17.0, lower)
    >>> bool(np.allclose(kept, truth)), counts["reverted"], int(unresolved.sum())
    (True, 1, 0)
    """
    counts = {"kept": 0, "reverted": 0, "unresolved": 0, "undecidable": 0}
    counts |= {"piece_pixels_reverted": 0, "piece_pixels_unresolved": 0}
    changed = changed_orders(proposed, measured, valid)
    if not changed.any() or not lower:
        return proposed, np.zeros(valid.shape, dtype=bool), counts
    count, labels = label_blobs(changed)
    # flat indices, not the mask: gathering by a scattered boolean mask costs several times more
    where = np.flatnonzero(changed)
    at = np.ravel(labels)[where]
    if weights is None:  # misfits in units of each frequency's noise
        weights = noise_weights(measured, valid, frequency, lower)
    ev = PixelEvidence.at(where, proposed, measured, frequency, lower, weights)
    undecidable, contradicted, ambiguous = _verdicts(ev, at, count, len(lower))
    contradicted[0] = ambiguous[0] = undecidable[0] = False
    counts["reverted"] = int(np.count_nonzero(contradicted[1:]))
    counts["unresolved"] = int(np.count_nonzero(ambiguous[1:]))
    counts["undecidable"] = int(np.count_nonzero(undecidable[1:]))
    counts["kept"] = count - 1 - counts["reverted"] - counts["unresolved"] - counts["undecidable"]
    # inside a contradicted blob or piece, only the pixels whose own evidence contradicts the change go back
    # (a blob can mix them with pixels whose measured orders were wrong)
    own = (ev.shift_rad >= MIN_SHIFT_RAD**2) & (ev.with_proposed - ev.with_measured > ev.shift / 2.0)
    own &= np.maximum(ev.with_measured, len(lower)) * SEPARATION**2 <= ev.shift
    # a blob they did not contradict as a whole may still mix right changes with a wrong one: its pieces of one
    # order shift are judged on their own
    piece_back, piece_unresolved = judge_shift_pieces(ev, at, count, ~contradicted, own, frequency, lower, weights)
    piece_back, piece_unresolved, taken, values = _neighbour_verdicts(
        piece_back & own, piece_unresolved, where, proposed, measured, valid, frequency, lower, weights
    )
    counts["piece_pixels_reverted"] = int(np.count_nonzero(piece_back)) + int(taken.size)
    counts["piece_pixels_unresolved"] = int(np.count_nonzero(piece_unresolved & ~ambiguous[at]))
    back_at = (contradicted[at] & own) | piece_back
    unresolved_at = ambiguous[at] | piece_unresolved
    if not back_at.any() and not taken.size:
        return proposed, mask_at(valid.shape, where[unresolved_at]), counts
    out, unresolved = revert_changed(proposed, measured, where, back_at, unresolved_at)
    out.reshape(-1)[taken] = values
    return out, unresolved, counts


def _verdicts(
    ev: PixelEvidence, group: np.ndarray, count: int, n_lower: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per group of changed pixels (``group``: each pixel's label, ``count`` labels): whether the lower frequencies
    cannot judge it, contradict its change, or leave it ambiguous (the rules of :func:`keep_temporally_supported`)."""
    difference = np.bincount(group, weights=ev.with_proposed - ev.with_measured, minlength=count)
    expected = np.bincount(group, weights=ev.shift, minlength=count)
    # the group's own noise: the misfit of the better-fitting orders (dark or mixed pixels carry more)
    noise = np.minimum(
        np.bincount(group, weights=ev.with_measured, minlength=count),
        np.bincount(group, weights=ev.with_proposed, minlength=count),
    )
    pixels = np.bincount(group, minlength=count)
    undecidable = (expected <= SEPARATION**2 * np.maximum(noise, pixels * n_lower)) | (
        np.bincount(group, weights=ev.shift_rad, minlength=count) < MIN_SHIFT_RAD**2 * pixels
    )
    margin = Z_MARGIN * 2.0 * np.sqrt(np.maximum(noise / np.maximum(pixels * n_lower, 1), 1.0) * expected)
    contradicted = ~undecidable & (difference > expected / 2.0 + margin)
    ambiguous = ~undecidable & ~contradicted & (difference >= expected / 2.0 - margin)
    return undecidable, contradicted, ambiguous


def judge_shift_pieces(
    ev: PixelEvidence,
    blob: np.ndarray,
    count: int,
    eligible: np.ndarray,
    own: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float],
) -> tuple[np.ndarray, np.ndarray]:
    """Per changed pixel, whether its piece is contradicted and whether it is ambiguous.

    A piece is the pixels of one order shift (``ev.delta``) in a blob (``blob``: each changed pixel's label,
    ``count`` labels) that mixes several shifts and is ``eligible`` (the lower frequencies did not contradict it as
    a whole). Pooling beside a height step of several fringes gives a line of edge pixels the far side's order; the
    line's blob of changed pixels also holds pixels whose measured orders were wrong and are rightly changed, by
    another shift, and their evidence for the blob outweighs the line's against it. Each piece is judged with
    the same test and margin as a blob (:func:`_verdicts`). A contradicted piece goes back to its measured orders
    only where the lower frequencies tell them apart from every order within :data:`SNAP_STEPS` of the proposed
    one: where one of those orders is as undecidable against the measured orders as a blob of that shift would be
    (a close pair such as 29/32, where orders 11 apart predict the 29 phase within 0.2 rad; 18/25 at 7 apart),
    the measured orders may be that far from the truth as easily as the proposal is one or two orders from it,
    and the piece is reported unresolved instead (the proposal, which the neighbours supported, stays). The same
    holds pixel by pixel for the orders that continue each neighbour (:func:`keep_temporally_supported` checks
    those on the few pixels that would go back, :func:`_neighbour_verdicts`): there the lower
    frequencies have rejected the proposal but fit that order as well as the measured one, so the pixel takes
    it where it is the one such order continuing the most neighbours and fits every lower frequency within the
    noise, and is reported otherwise (heterodyne 32/29/27 at 3 steps and 13.7 dB, where 31 orders shift the lower
    phases by 1.1 rad: without this, pixels three orders off went back to measured orders 31 off). Only the
    blobs with a pixel whose ``own`` evidence contradicts its change are split (no piece of another could send
    a pixel back), and pieces are grouped by shift within a blob, not labelled again.
    """
    none = np.zeros(blob.shape, dtype=bool)
    split = np.bincount(blob, weights=own, minlength=count) > 0
    split &= eligible
    split[0] = False
    inside = np.flatnonzero(split[blob])
    if not inside.size:
        return none, none
    sub = ev.take(inside)
    shifts, slot = np.unique(sub.delta, return_inverse=True)  # the few shifts present
    keys, piece = np.unique(blob[inside].astype(np.int64) * shifts.size + slot, return_inverse=True)
    of_blob = keys // shifts.size
    mixed = np.bincount(of_blob)[of_blob] > 1  # a blob of one shift is its own piece, judged already
    _undecidable, contradicted, ambiguous = _verdicts(sub, piece, keys.size, len(lower))
    contradicted &= mixed
    ambiguous &= mixed
    confusable = _confusable_near_proposal(shifts, frequency, lower, weights)[keys % shifts.size]
    ambiguous |= contradicted & confusable
    contradicted &= ~confusable
    back, unresolved = none.copy(), none.copy()
    back[inside] = contradicted[piece]
    unresolved[inside] = ambiguous[piece]
    return back, unresolved


def _confusable_near_proposal(
    delta: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]], weights: Sequence[float]
) -> np.ndarray:
    """Per order shift ``delta`` (proposed minus measured): whether an order within :data:`SNAP_STEPS` of the
    proposed one shifts the lower frequencies' predictions from the measured one's too little to judge (below
    :data:`MIN_SHIFT_RAD` or :data:`SEPARATION` noise deviations a pixel, the bounds of a blob's judgement)."""
    out = np.zeros(delta.shape, dtype=bool)
    for step in SNAP_STEPS:
        near = delta + step
        out |= (near != 0) & confusable_shift(near, frequency, lower, weights)
    return out


def _neighbour_verdicts(
    back: np.ndarray,
    unresolved: np.ndarray,
    where: np.ndarray,
    proposed: np.ndarray,
    measured: np.ndarray,
    valid: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float],
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``back`` and ``unresolved`` (per changed pixel at the flat indices ``where``) where the lower frequencies also
    tell each pixel going back from its neighbours' orders, and the pixels (flat indices) that take a neighbour's
    order instead, with their phases.

    A pixel stays out of ``back`` where an order that continues one of its valid 4-neighbours (in ``proposed``)
    differs from its measured order by a shift too small to judge (:func:`confusable_shift`). It takes that order
    where it is the one such order continuing the most neighbours (no other continues as many) and fits every lower
    frequency within 3 noise deviations, and is added to ``unresolved`` otherwise.
    """
    taken, values = np.zeros(0, dtype=np.int64), np.zeros(0)
    if not back.any():
        return back, unresolved, taken, values
    back, unresolved = back.copy(), unresolved.copy()
    index = np.flatnonzero(back)
    at = where[index]
    rows, cols = np.divmod(at, valid.shape[1])
    here = np.ravel(measured)[at]
    around = neighbours_at(proposed, valid, rows, cols)
    seen = np.isfinite(around)
    shifts = np.where(seen, np.rint((around - here) / TWO_PI), 0.0)  # an unseen side's shift is never read
    like = seen & (shifts != 0) & confusable_shift(shifts, frequency, lower, weights)
    doubtful = like.any(axis=0)
    support = ((shifts[:, None, :] == shifts[None, :, :]) & seen[None, :, :]).sum(axis=1)  # neighbours continued
    support = np.where(like, support, 0)
    best = np.argmax(support, axis=0)
    columns = np.arange(at.size)
    best_shift, top = shifts[best, columns], support[best, columns]
    chosen = doubtful & ~((support == top) & (shifts != best_shift)).any(axis=0)  # no rival as well supported
    if chosen.any():
        lower_at = gather_lower(lower, at[chosen])
        chosen[chosen] = _fits_each_frequency(here[chosen] + TWO_PI * best_shift[chosen], frequency, lower_at, weights)
    back[index[doubtful]] = False
    unresolved[index[doubtful & ~chosen]] = True
    taken = at[chosen]
    return back, unresolved, taken, here[chosen] + TWO_PI * best_shift[chosen]


def separable_shift(
    shift: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]], sigma: float
) -> np.ndarray:
    """Whether orders ``shift`` apart predict the lower frequencies more than :data:`SEPARATION` standard deviations
    of a pixel's misfit apart, the misfit's noise taken from the phase noise ``sigma`` (rad, each frequency's
    phase alike: ``wrap(Phi f_l / f - phi_l)`` has variance ``sigma^2 (1 + (f_l / f)^2)``).

    Not from the measured orders' misfit (:func:`noise_weights`): temporal unwrapping chose those orders to fit,
    so where the close pairs' shifts lie within the noise their misfit is small by selection (29/32 at 14 dB: 0.07
    rad against 0.22). For evidence that agrees with another (a pixel's surface continuation): a blob's judgement
    needs :func:`confusable_shift`'s bounds."""
    plain = order_shift(np.asarray(shift, dtype=np.float64), frequency, lower)
    variance = sum(float(sigma) ** 2 * (1.0 + (float(f_low) / float(frequency)) ** 2) for f_low, _ in lower)
    return plain > SEPARATION**2 * variance


def confusable_shift(
    shift: np.ndarray, frequency: float, lower: Sequence[tuple[float, np.ndarray]], weights: Sequence[float]
) -> np.ndarray:
    """Whether orders ``shift`` apart predict the lower frequencies too alike to judge (below :data:`MIN_SHIFT_RAD` or
    :data:`SEPARATION` noise deviations a pixel, the bounds of a blob's judgement)."""
    shift_rad, weighted = _plain_and_weighted(_shift_terms(shift, frequency, lower), weights)
    return (shift_rad < MIN_SHIFT_RAD**2) | (weighted <= SEPARATION**2 * len(lower))
