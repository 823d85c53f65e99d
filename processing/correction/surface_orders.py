"""Where the kept fringe orders and the low-rank surface's disagree, the evidence both can be scored on decides.

``auto`` keeps an order per pixel from the pooled and re-derived candidates and the evidence steps
that judge them against the measured orders; its low-rank surface L (thesis ch. 4) is then used only
to denoise, and where L lies a fringe or more from the kept orders the kept orders stay. Both are
estimates: the evidence steps judge a blob of changed pixels as a whole, so a blob that mixes right
and wrong changes can go back to measured orders that are wrong (a pair of pixels seven orders off
beside a ramp's edge at 18/25, which one order's shift of the lower frequency cannot see), or keep a
proposal off at an object's edge; L, fitted to the whole map, has none of these there.

The pixels where L's re-derived orders ``rint((L - phi) / 2 pi)`` differ from the kept ones form
8-connected blobs, each scored both ways on what needs no truth:

- continuity: the order breaks (4-neighbour steps beyond pi) on the edges touching the blob, as
  :func:`~processing.correction.order_evidence.breaks_per_blob` counts them for step 5;
- the lower frequencies' wrapped phases, when given: ``D``, the noise-weighted misfit with L's orders
  minus that with the kept ones summed over the blob, against ``S``, what ``D`` is if the kept orders
  are right (:mod:`processing.correction.temporal_evidence`).

A blob takes L's orders where they leave at most half the breaks the kept ones leave and the lower
frequencies do not contradict them (``D`` above ``S / 2`` by
:data:`~processing.correction.temporal_evidence.Z_MARGIN` standard errors, ``2 sqrt(S)``: the same test,
in the same noise units, step 5 reverts a blob by), or where they leave no more breaks and the lower
frequencies clearly favour them (``D`` below ``S / 2`` by the same margin, on a blob whose ``S`` clears
:data:`~processing.correction.temporal_evidence.SEPARATION` squared noise variances a pixel). Why half:
where L is right on a blob of wrong kept orders it removes the breaks around it; where L is blurred
across an object's edge it moves the edge's breaks into the blur, about as many, and a blob that mixes
a few wrong kept orders with L's blur then shows a few breaks fewer with L (1.1x - 1.2x, seen at 320 px
on isolated objects: taking L there doubled NMSE_h). A change must earn its place: every other blob keeps
the kept orders, and one where L leaves no more breaks and the lower frequencies decide nothing either
way is reported unresolved.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from processing.correction.order_evidence import blob_edges, breaks_per_blob, changed_orders, label_blobs
from processing.correction.temporal_evidence import SEPARATION, Z_MARGIN, PixelEvidence

TWO_PI = 2.0 * np.pi


def arbitrate_low_rank_orders(
    kept: np.ndarray,
    low_rank: np.ndarray,
    valid: np.ndarray,
    frequency: float | None = None,
    lower: Sequence[tuple[float, np.ndarray]] = (),
    weights: Sequence[float] | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """``kept`` with L's orders on the blobs where the evidence favours them; the unresolved pixels; pixels moved.

    Parameters
    ----------
    kept : (H, W) absolute phase with the kept orders (the measured wrapped phase plus whole fringes)
    low_rank : (H, W) low-rank estimate L of the absolute phase
    valid : (H, W) bool, where all three are finite
    frequency, lower, weights : the phases' frequency, ((f_l, wrapped phase at f_l), ...) and each lower
        frequency's 1 / noise variance (:func:`~processing.correction.temporal_evidence.noise_weights`);
        without them the breaks decide alone

    Examples
    --------
    A ramp whose kept orders are one fringe off on a 2 x 2 patch; L is the ramp:

    >>> import numpy as np
    >>> truth = np.tile(np.linspace(0.0, 40.0, 50), (30, 1))
    >>> kept = truth.copy()
    >>> kept[10:12, 20:22] += 2 * np.pi
    >>> out, unresolved, moved = arbitrate_low_rank_orders(kept, truth, np.ones((30, 50), bool))
    >>> bool(np.allclose(out, truth)), moved, int(unresolved.sum())
    (True, 4, 0)
    """
    # kept and L's orders share the wrapped phase: they differ where |L - kept| > pi, and L's phase there is kept
    # plus the whole fringes nearest L (only those pixels are computed: a full map costs more than the step)
    differ = changed_orders(low_rank, kept, valid)
    none = np.zeros(valid.shape, dtype=bool)
    if not differ.any():
        return kept, none, 0
    alternative = kept.copy()
    at = np.flatnonzero(differ)
    at_kept = np.ravel(kept)[at]
    alternative.reshape(-1)[at] = at_kept + TWO_PI * np.rint((np.ravel(low_rank)[at] - at_kept) / TWO_PI)
    count, labels = label_blobs(differ)
    edges = blob_edges(valid, differ)
    with_surface = breaks_per_blob(alternative, valid, labels, count, edges)
    with_kept = breaks_per_blob(kept, valid, labels, count, edges)
    blob = np.ravel(labels)[at]
    contradicted = favoured = np.zeros(count, dtype=bool)
    if lower and frequency is not None:
        contradicted, favoured = _lower_frequency_verdict(alternative, kept, blob, count, at, frequency, lower, weights)
    no_more = with_surface <= with_kept
    # at most half the breaks: L removes them rather than moving them (a surface blurred across an edge
    # moves the edge's breaks into the blur, about as many)
    clearly_fewer = (2 * with_surface <= with_kept) & (with_surface < with_kept)
    take = (clearly_fewer & ~contradicted) | (no_more & favoured)
    tie = no_more & ~take & ~contradicted
    take[0] = tie[0] = False
    out = kept
    moved = int(np.count_nonzero(take[blob]))
    if moved:
        out = kept.copy()
        chosen = at[take[blob]]
        out.reshape(-1)[chosen] = np.ravel(alternative)[chosen]
    unresolved = none
    if tie.any():
        unresolved = none.copy()
        unresolved.reshape(-1)[at[tie[blob]]] = True
    return out, unresolved, moved


def _lower_frequency_verdict(
    alternative: np.ndarray,
    kept: np.ndarray,
    blob: np.ndarray,
    count: int,
    at: np.ndarray,
    frequency: float,
    lower: Sequence[tuple[float, np.ndarray]],
    weights: Sequence[float] | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Per blob: whether the lower frequencies contradict L's orders, and whether they clearly favour them (only
    where the blob's shift clears :data:`~processing.correction.temporal_evidence.SEPARATION` noise deviations a
    pixel: a verdict for a change needs the frequencies to tell the orders apart, one against it does not).
    L's orders play the proposed ones of step 5's evidence, the kept orders the measured ones."""
    unit = [1.0] * len(lower) if weights is None else weights  # without weights, every frequency counts alike
    ev = PixelEvidence.at(at, alternative, kept, frequency, lower, unit)
    d = np.bincount(blob, weights=ev.with_proposed - ev.with_measured, minlength=count)
    s = np.bincount(blob, weights=ev.shift, minlength=count)
    pixels = np.bincount(blob, minlength=count)
    margin = Z_MARGIN * 2.0 * np.sqrt(s)
    favoured = (s > SEPARATION**2 * pixels * len(lower)) & (d < s / 2.0 - margin)
    return d > s / 2.0 + margin, favoured
