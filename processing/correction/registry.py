"""Registry of absolute-phase correction methods, one calling convention for all.

Every entry is ``f(absolute_phase, wrapped_phase, orders=None, mask=None, frequency=None,
**params) -> (corrected_phase, info)``:

- ``absolute_phase``: (H, W) unwrapped phase, NaN where invalid;
- ``wrapped_phase``: (H, W) the wrapped phase it came from (any 2 pi representation);
- ``orders``: optional fringe orders (ignored: re-derived from the two phases, which cannot
  disagree with them);
- ``mask``: optional valid pixels (default: finite ``absolute_phase``);
- ``frequency``: fringes across the projector, recorded in ``info`` (and reserved for methods
  that bound the orders).

``info`` holds ``method``, ``parameters``, ``iterations``, ``rank`` and ``seconds`` (plus what
the method adds), for reports. The corrected phase is NaN outside the mask.

Methods: ``none``; ``vote`` (Ding's row voting, thesis [119]); ``rpca-orders`` (thesis ch. 3);
``rpca-phase`` (thesis ch. 4, stable inexact ALM); ``auto``, the most accurate combination
measured on the thesis' Table 4.1 protocol (see :func:`correct_auto`).
"""

from __future__ import annotations

import functools
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from processing.concurrency import side_by_side
from processing.correction.broken_pixels import mend_broken_pixels
from processing.correction.method import CorrectionMethod, Result
from processing.correction.order_evidence import (
    changed_orders,
    keep_supported_changes,
    mend_spikes,
    unresolved_summary,
)
from processing.correction.order_islands import level_islands
from processing.correction.order_margin import undecided_orders
from processing.correction.orders import correct_orders_rpca
from processing.correction.phase_range import keep_range_folds
from processing.correction.phase_rpca import (
    accept_if_consistent,
    correct_phase_rpca,
    decimated_low_rank,
    keep_coherent_detail,
    low_rank_misfit,
    order_breaks,
    order_breaks_since,
    phase_noise_and_breaks,
    phase_pair,
    refit_full_resolution,
    reorder_from_low_rank,
    settle_orders,
    update_coherent_detail,
)
from processing.correction.region_orders import pool_region_orders
from processing.correction.surface_continuation import continuation_margin, restore_continued_orders
from processing.correction.surface_orders import arbitrate_low_rank_orders
from processing.correction.temporal_evidence import (
    confusable_shift,
    keep_temporally_supported,
    lower_frequency_misfit,
    noise_weights,
    order_shift,
    separable_shift,
    snap_to_lower_frequencies,
)
from processing.correction.voting import vote_row_orders
from processing.denoise.rpca import RPCAResult, default_tau
from processing.elementwise import abs_difference

TWO_PI = 2.0 * np.pi


def _inputs(
    absolute_phase: np.ndarray, wrapped_phase: np.ndarray, mask: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return phase_pair(absolute_phase, wrapped_phase, mask, ("absolute_phase", "wrapped_phase"))


def _info(
    method: str, parameters: dict[str, Any], start: float, frequency: float | None, **extra: Any
) -> dict[str, Any]:
    info: dict[str, Any] = {
        "method": method,
        "parameters": parameters,
        "iterations": extra.pop("iterations", 0),
        "rank": extra.pop("rank", None),
        "seconds": round(time.perf_counter() - start, 4),
    }
    if frequency is not None:
        info["frequency"] = float(frequency)
    info.update(extra)
    return info


def _solver_info(
    method: str, parameters: dict[str, Any], start: float, frequency: float | None, result: RPCAResult, **extra: Any
) -> dict[str, Any]:
    """:func:`_info` with the RPCA solver's iterations, rank and convergence."""
    iterations, rank, converged = result.iterations, result.rank, result.converged
    return _info(method, parameters, start, frequency, iterations=iterations, rank=rank, converged=converged, **extra)


def correct_none(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    **params: Any,
) -> Result:
    """No correction: the phase as unwrapped (NaN outside the mask)."""
    start = time.perf_counter()
    phase, _, valid = _inputs(absolute_phase, wrapped_phase, mask)
    return np.where(valid, phase, np.nan), _info("none", {}, start, frequency)


def correct_vote(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    min_segment: int = 4,
) -> Result:
    """Ding's row-wise voting between wrapped-phase jumps ([119])."""
    start = time.perf_counter()
    phase, wrapped, valid = _inputs(absolute_phase, wrapped_phase, mask)
    out = vote_row_orders(phase, wrapped, valid, min_segment=min_segment)
    return out, _info("vote", {"min_segment": min_segment}, start, frequency)


def correct_rpca_orders(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    t: float = 0.034,
    beta: float | None = None,
    postprocess: bool = True,
    solver: str = "ialm",
    svd: str = "auto",
) -> Result:
    """RPCA on the fringe-order map, then the monotonicity pass (thesis ch. 3)."""
    start = time.perf_counter()
    phase, wrapped, valid = _inputs(absolute_phase, wrapped_phase, mask)
    k = np.where(valid, np.rint((phase - np.mod(wrapped, TWO_PI)) / TWO_PI), 0.0)
    out, _, result = correct_orders_rpca(
        k, wrapped, valid, t=t, beta=beta, postprocess=postprocess, solver=solver, svd=svd
    )
    parameters = {"t": t, "beta": beta, "postprocess": postprocess, "solver": solver, "svd": svd}
    return out, _solver_info("rpca-orders", parameters, start, frequency, result)


def correct_rpca_phase(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    tau: float | None = None,
    stable: bool = True,
    svd: str = "auto",
) -> Result:
    """Low-rank part of the absolute phase by inexact ALM RPCA (thesis ch. 4)."""
    start = time.perf_counter()
    phase, _, valid = _inputs(absolute_phase, wrapped_phase, mask)
    out, result = correct_phase_rpca(phase, valid, tau=tau, stable=stable, svd=svd)
    parameters = {"tau": tau if tau is not None else default_tau(phase.shape), "stable": stable, "svd": svd}
    return out, _solver_info("rpca-phase", parameters, start, frequency, result)


# Block side of auto's decimated RPCA solve, and the smallest image side it is used from. Measured
# on rig study's sphere cap (10 dB) and isolated objects (18 dB), NMSE_h of 4 x 4 blocks against the
# full-resolution solve: 0.52x and 1.13x at 480 px, 0.60x and 0.99x at 640 px, 0.50x and 0.86x
# at 768 px, 0.38x and 0.60 - 0.92x at 1000 px (3 seeds); 2 x 2 blocks lose on isolated objects.
DECIMATION = 4
DECIMATE_FROM = 600


def default_decimation(shape: tuple[int, ...]) -> int:
    """Block side of auto's low-rank solve for a map of ``shape``: :data:`DECIMATION` on large maps, else 1."""
    return DECIMATION if min(shape) >= DECIMATE_FROM else 1


@dataclass(frozen=True)
class _AutoMaps:
    """What every step of :func:`correct_auto` reads: the validated maps and the solver settings."""

    phase: np.ndarray  # measured absolute phase, finite wherever valid
    wrapped: np.ndarray
    valid: np.ndarray
    sigma: float  # phase noise, blind to order errors
    decimate: int
    tau: float | None
    svd: str
    k_sigma: float

    def low_rank_of(self, base: np.ndarray) -> tuple[np.ndarray, RPCAResult, np.ndarray]:
        """Ch. 4 low-rank part of ``base`` stopped at the noise level (on block means when decimating) and
        the pixels where a block solve blurred an edge (none at full resolution)."""
        if self.decimate > 1:
            return decimated_low_rank(base, self.valid, self.decimate, self.sigma, tau=self.tau, svd=self.svd)
        low_rank, result = correct_phase_rpca(
            base, self.valid, tau=self.tau, stable=True, svd=self.svd, noise_sigma=self.sigma
        )
        return low_rank, result, np.zeros(self.valid.shape, dtype=bool)


@dataclass
class _Candidates:
    """Order maps ``auto`` ranks by their order breaks, and what ranking them needs."""

    maps: dict[str, np.ndarray]
    breaks: dict[str, int]
    low_rank: np.ndarray
    result: RPCAResult
    rpca_input: str
    rough: np.ndarray  # pixels where a block solve blurred an edge
    misfit: np.ndarray
    pooled_detail: np.ndarray | None = None  # step 5 on the pooled orders, computed alongside


def _solve_low_rank(maps: _AutoMaps, pooled: np.ndarray, measured_breaks: int) -> _Candidates:
    """Step 2: L of the pooled phase (far sparser errors), or of the measured phase where pooling left more
    order breaks than it (ties keep the pooled phase, so pooled orders without a break always win).

    L of the pooled phase is solved while its breaks are counted, and solved again on the measured
    phase in that rare case.
    """
    solved, regions_breaks = side_by_side(lambda: maps.low_rank_of(pooled), lambda: order_breaks(pooled, maps.valid))
    rpca_input = "regions" if regions_breaks <= measured_breaks else "measured"
    low_rank, result, rough = solved if rpca_input == "regions" else maps.low_rank_of(maps.phase)
    none = np.zeros(maps.valid.shape, dtype=bool)
    return _Candidates({"regions": pooled}, {"regions": regions_breaks}, low_rank, result, rpca_input, rough, none)


def _add_low_rank_orders(maps: _AutoMaps, found: _Candidates) -> np.ndarray:
    """Step 3a: the pooled orders where L misfits the wrapped phase, L's re-derived orders elsewhere.

    Returns L's re-derived orders everywhere (the guarded candidates of step 3b start from them).
    Runs only where the pooled orders still break somewhere: without a break they cannot lose.
    """
    pooled, valid = found.maps["regions"], maps.valid
    proposed, misfit = side_by_side(
        lambda: reorder_from_low_rank(found.low_rank, maps.wrapped, valid),
        lambda: low_rank_misfit(found.low_rank, maps.wrapped, valid) | (found.rough & valid),
    )
    found.misfit = misfit
    candidate = found.maps["regions+low-rank"] = np.where(misfit, pooled, proposed)
    found.pooled_detail, found.breaks["regions+low-rank"] = side_by_side(
        lambda: (  # after a block solve step 6 restores detail around the refitted L instead
            None
            if maps.decimate > 1
            else keep_coherent_detail(found.low_rank, pooled, valid, maps.k_sigma, maps.sigma, maps.phase)
        ),
        lambda: order_breaks_since(candidate, pooled, found.breaks["regions"], valid),
    )
    return proposed


def _add_guarded_orders(maps: _AutoMaps, found: _Candidates, proposed: np.ndarray) -> None:
    """Step 3b, where fringes are too dense to pool: L's orders, where L misfits changed only if the change
    fits the neighbours of the measured phase (or of Ding's row vote), then settled from their neighbours."""
    phase, wrapped, valid = maps.phase, maps.wrapped, maps.valid
    for guard_name, guard in (("measured", phase), ("vote", vote_row_orders(phase, wrapped, valid))):
        guarded = np.where(found.misfit, accept_if_consistent(proposed, guard, valid), proposed)
        found.maps[guard_name] = settle_orders(guarded, wrapped, valid)
        found.breaks[guard_name] = order_breaks(found.maps[guard_name], valid)


def _candidate_orders(maps: _AutoMaps, pooled: np.ndarray, measured_breaks: int) -> _Candidates:
    """Steps 2 - 3: L and the candidate order maps with their order breaks."""
    found = _solve_low_rank(maps, pooled, measured_breaks)
    proposed = None
    if found.breaks["regions"] > 0:
        proposed = _add_low_rank_orders(maps, found)
    if proposed is not None and min(found.breaks.values()) > measured_breaks:
        _add_guarded_orders(maps, found, proposed)
    return found


def _supported_orders(
    maps: _AutoMaps, proposed: np.ndarray, temporal: _Temporal | None
) -> tuple[np.ndarray, np.ndarray, dict[str, int], list[float] | None]:
    """Step 5: the proposed orders where their neighbours (:func:`~processing.correction.order_evidence.
    keep_supported_changes`) and then the lower frequencies (:func:`~processing.correction.temporal_evidence.
    keep_temporally_supported`) support them, order spikes mended (:func:`~processing.correction.order_evidence.
    mend_spikes`); the unresolved pixels of both; what each step did; the lower frequencies' noise weights."""
    (reordered, unresolved), weights = side_by_side(  # the noise weights read the measured phase only
        lambda: keep_supported_changes(proposed, maps.phase, maps.valid),
        lambda: None if temporal is None else noise_weights(maps.phase, maps.valid, temporal.frequency, temporal.lower),
    )
    counts: dict[str, int] = {}
    misfit = None
    if temporal is not None:
        assert weights is not None
        snapped, moved = snap_to_lower_frequencies(
            reordered, maps.phase, maps.valid, temporal.frequency, temporal.lower, weights
        )
        reordered, ambiguous, counts = keep_temporally_supported(
            snapped, maps.phase, maps.valid, temporal.frequency, temporal.lower, weights
        )
        unresolved = unresolved | ambiguous
        counts["moved_one_order"] = moved
        misfit = _lower_misfit(temporal, weights)
    reordered, counts["spikes_mended"] = mend_spikes(reordered, maps.valid, misfit)
    return reordered, unresolved, counts, weights


def _lower_misfit(
    temporal: _Temporal, weights: list[float] | None = None
) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """Misfit of candidate phases with the lower frequencies at the pixels ``where`` (an (H, W) mask, row-major, or
    flat pixel indices): noise-weighted with ``weights``, in rad^2 without."""

    def misfit(values: np.ndarray, where: np.ndarray) -> np.ndarray:
        at = where.reshape(-1)
        lower = [(f_low, wrapped_low.reshape(-1)[at]) for f_low, wrapped_low in temporal.lower]
        return lower_frequency_misfit(values, temporal.frequency, lower, weights)

    return misfit


def _restore_detail(
    maps: _AutoMaps, found: _Candidates, chosen: str, temporal: _Temporal | None, given: np.ndarray
) -> tuple[np.ndarray, np.ndarray, int, dict[str, int]]:
    """Steps 5 - 6: the chosen orders where the evidence supports them (:func:`_supported_orders`), L except
    where they depart from it coherently, never off their orders.

    Returns the phase, the unresolved pixels, how many orders differ from the ``given`` phase (before step 0)
    and the lower frequencies' blob counts.
    """
    reordered, unresolved, counts, weights = _supported_orders(maps, found.maps[chosen], temporal)
    low_rank = found.low_rank
    if maps.decimate > 1:  # what the block means blurred, refitted at full resolution where it fits better
        low_rank = refit_full_resolution(
            low_rank,
            found.result.low_rank,
            maps.decimate,
            reordered,
            maps.valid,
            found.result.rank,
            outlier=2.0 * maps.k_sigma * maps.sigma,
            noise=maps.sigma,
        )
    reordered, unresolved = _arbitrate_with_low_rank(maps, reordered, unresolved, low_rank, temporal, weights, counts)
    mended = reordered = _mend_broken_pixels(maps, reordered, temporal, weights, counts)
    reordered = _restore_continued_orders(maps, reordered, temporal, weights, counts)
    reordered = _level_islands(maps, reordered, temporal, weights, counts)
    if reordered is not mended:  # what steps 6c and 6d moved can leave a neighbour broken all round
        reordered = _mend_broken_pixels(
            maps, reordered, temporal, weights, counts, next_to=(reordered != mended) & maps.valid
        )
    pooled_detail = found.pooled_detail if low_rank is found.low_rank else None
    out, changed = side_by_side(
        lambda: (  # step 6 ran alongside step 3 on the pooled orders: redone only where the orders differ
            keep_coherent_detail(low_rank, reordered, maps.valid, maps.k_sigma, maps.sigma, maps.phase)
            if pooled_detail is None
            else update_coherent_detail(
                pooled_detail,
                found.maps["regions"],
                low_rank,
                reordered,
                maps.valid,
                maps.k_sigma,
                maps.sigma,
                maps.phase,
            )
        ),
        lambda: int(np.count_nonzero(changed_orders(reordered, given, maps.valid))),
    )
    assert out is not None
    # L only denoises: where it lies a fringe or more from the kept orders, the measured phase stays
    off = abs_difference(out, reordered) > np.pi  # one pass: a fresh full map costs as much as the arithmetic
    if off.any():
        out = np.where(off, reordered, out)
    return out, unresolved, changed, counts


def _arbitrate_with_low_rank(
    maps: _AutoMaps,
    reordered: np.ndarray,
    unresolved: np.ndarray,
    low_rank: np.ndarray,
    temporal: _Temporal | None,
    weights: list[float] | None,
    counts: dict[str, int],
) -> tuple[np.ndarray, np.ndarray]:
    """Step 6a: L's orders on the blobs where they clearly leave fewer order breaks than the kept ones and the lower
    frequencies do not contradict them (:func:`~processing.correction.surface_orders.arbitrate_low_rank_orders`);
    the blobs nothing decides are added to the unresolved pixels."""
    frequency, lower = (temporal.frequency, temporal.lower) if temporal is not None else (None, [])
    reordered, tied, counts["low_rank_orders_taken"] = arbitrate_low_rank_orders(
        reordered, low_rank, maps.valid, frequency, lower, weights
    )
    return reordered, unresolved | tied


def _mend_broken_pixels(
    maps: _AutoMaps,
    reordered: np.ndarray,
    temporal: _Temporal | None,
    weights: list[float] | None,
    counts: dict[str, int],
    next_to: np.ndarray | None = None,
) -> np.ndarray:
    """Step 6b: pixels whose order breaks with three or four neighbours take the order more of them support, where
    the lower frequencies fit it no worse (:func:`~processing.correction.broken_pixels.mend_broken_pixels`); with
    ``next_to``, only the pixels next to those (the ones steps 6c and 6d moved), its moves added to the count."""
    misfit = None if temporal is None or weights is None else _lower_misfit(temporal, weights)
    reordered, mended = mend_broken_pixels(reordered, maps.valid, misfit, next_to)
    counts["broken_pixels_mended"] = counts.get("broken_pixels_mended", 0) + mended
    return reordered


def _restore_continued_orders(
    maps: _AutoMaps,
    reordered: np.ndarray,
    temporal: _Temporal | None,
    weights: list[float] | None,
    counts: dict[str, int],
) -> np.ndarray:
    """Step 6c: pixels kept one or two orders off the measured ones (further off where the lower frequencies tell the
    orders apart by a blob's bounds, or by the phase noise alone) go back where the measured order continues the
    settled surface on a side (better than the kept order continues one, or as well where the phase noise alone
    tells the two orders apart) and the lower frequencies favour it
    (:func:`~processing.correction.surface_continuation.restore_continued_orders`)."""
    misfit = shift = telling = separable = None
    if temporal is not None and weights is not None:
        misfit = _lower_misfit(temporal, weights)
        shift = functools.partial(order_shift, frequency=temporal.frequency, lower=temporal.lower, weights=weights)
        confusable = _confusable(temporal, weights)
        separable = functools.partial(
            separable_shift, frequency=temporal.frequency, lower=temporal.lower, sigma=maps.sigma
        )
        telling = lambda orders: separable(orders) | ~confusable(orders)  # noqa: E731 - either bound suffices
    reordered, counts["continued_orders_restored"] = restore_continued_orders(
        reordered, maps.phase, maps.valid, misfit, shift, telling, continuation_margin(maps.sigma), separable
    )
    return reordered


def _level_islands(
    maps: _AutoMaps,
    reordered: np.ndarray,
    temporal: _Temporal | None,
    weights: list[float] | None,
    counts: dict[str, int],
) -> np.ndarray:
    """Step 6d: islands cut off from a larger surface by breaks that one order shift the lower frequencies cannot
    see would mend take that shift, where the measured orders do not decide their kept ones
    (:func:`~processing.correction.order_islands.level_islands`)."""
    counts["islands_levelled"] = 0
    if temporal is None or weights is None:
        return reordered
    reordered, counts["islands_levelled"] = level_islands(
        reordered,
        maps.valid,
        _confusable(temporal, weights),
        lambda kept: undecided_orders(kept, maps.phase, maps.wrapped, maps.valid),
        _lower_misfit(temporal),
    )
    return reordered


def _confusable(temporal: _Temporal, weights: list[float]) -> Callable[[np.ndarray], np.ndarray]:
    """Whether the lower frequencies cannot tell orders a given number of orders apart (per entry; steps 6c, 6d)."""
    return functools.partial(confusable_shift, frequency=temporal.frequency, lower=temporal.lower, weights=weights)


@dataclass(frozen=True)
class _Temporal:
    """The capture's lower frequencies, the evidence step 5 weighs order changes against."""

    frequency: float
    lower: list[tuple[float, np.ndarray]]


def _temporal_inputs(
    frequency: float | None, lower_wrapped: Sequence[tuple[float, np.ndarray]] | None, valid: np.ndarray
) -> _Temporal | None:
    """Validated ``lower_wrapped`` (None without it); ValueError naming what does not fit."""
    if not lower_wrapped:
        return None
    if frequency is None or not float(frequency) > 0:
        raise ValueError(f"frequency: expected > 0 with lower_wrapped, found {frequency}")
    lower: list[tuple[float, np.ndarray]] = []
    for f_low, wrapped_low in lower_wrapped:
        wrapped_low = np.asarray(wrapped_low)
        if not 0 < float(f_low) < float(frequency):
            raise ValueError(f"lower_wrapped: expected frequencies in (0, {frequency:g}), found {f_low:g}")
        if wrapped_low.shape != valid.shape:
            raise ValueError(f"lower_wrapped at {f_low:g}: expected shape {valid.shape}, found {wrapped_low.shape}")
        if (valid & ~np.isfinite(wrapped_low)).any():  # whole-map tests: gathering the valid pixels costs more
            return None  # a lower map with holes inside the mask (pixels the pass did not keep): no evidence
        lower.append((float(f_low), np.where(valid, wrapped_low, 0.0)))
    return _Temporal(float(frequency), lower)


def _in_pattern_range(phase: np.ndarray, valid: np.ndarray, temporal: _Temporal | None) -> tuple[np.ndarray, int]:
    """Step 0: the measured phase with the pixels outside the pattern's range moved back by whole invisible periods
    where the neighbours support it (:func:`~processing.correction.phase_range.keep_range_folds`); how many moved.
    Only with the lower frequencies: the period is theirs."""
    if temporal is None:
        return phase, 0
    return keep_range_folds(phase, valid, temporal.frequency, [f for f, _ in temporal.lower])


def correct_auto(
    absolute_phase: np.ndarray,
    wrapped_phase: np.ndarray,
    orders: np.ndarray | None = None,
    mask: np.ndarray | None = None,
    frequency: float | None = None,
    tau: float | None = None,
    k_sigma: float = 4.0,
    svd: str = "auto",
    decimate: int | None = None,
    lower_wrapped: Sequence[tuple[float, np.ndarray]] | None = None,
) -> Result:
    """The most accurate method measured: region-pooled orders, ch. 4 RPCA, measured detail restored.

    0. with ``lower_wrapped``: measured phase outside the pattern, [0, 2 pi ``frequency``), moved back by periods no
       lower frequency sees, where the neighbours agree (:mod:`~processing.correction.phase_range`; ``range_folded``);
    1. pool the fringe orders over 2-D fringe regions (:func:`~processing.correction.region_orders.pool_region_orders`:
       one order per region no wrapped-phase jump or kink crosses, voted per 16 x 16 square, re-voted pixel by pixel);
    2. L = low-rank part of that phase (stable inexact ALM, thesis ch. 4, stopped at the noise level of
       :func:`~processing.correction.phase_rpca.phase_noise_sigma`, blind to order errors), solved on 4 x 4 block means
       from :data:`DECIMATE_FROM` pixels on (``decimate``), interpolated back; the measured phase if pooling broke more;
    3. candidate order maps (only if the pooled orders still break somewhere): the pooled orders; the pooled orders
       where L misfits the wrapped phase (|wrap(phi - L)| > pi / 2 nearby, or an edge the block solve blurred) and
       L's re-derived orders elsewhere; only if both leave more order breaks than the measured phase (fringes too
       dense to pool), also L's orders guarded where L misfits by the measured phase or by Ding's row vote, then
       settled from their neighbours (the earlier ``auto``);
    4. keep the candidate with fewest order breaks (second differences beyond pi, truth-free);
    5. judge its changes blob by blob against the measured orders
       (:func:`~processing.correction.order_evidence.keep_supported_changes`): a blob keeps the new orders
       only if they leave fewer order breaks on its edges than the measured ones; where both
       leave as many, the measured orders stay and the blob is reported unresolved
       (``info["unresolved"]``: pixels, fraction, the largest blobs' boxes; ``info["unresolved_mask"]``,
       the (H, W) bool mask, an array that ``rig process`` writes to unresolved.npy, not to the report).
       With ``lower_wrapped`` ((frequency, wrapped phase) of the capture's lower frequencies, and
       ``frequency``), the kept changes are then weighed against them (:mod:`~processing.correction.temporal_evidence`):
       a pixel one or two orders off moves to the order they clearly fit, a blob they clearly contradict goes back to
       the measured orders, one they cannot tell is reported unresolved (``info["evidence"]`` counts the blobs), a
       kept blob of several order shifts is judged again per shift (``judge_shift_pieces`` there). Last, lone order
       spikes take their neighbours' order (:func:`~processing.correction.order_evidence.mend_spikes`);
    6. after a block solve, refit L at full resolution (:func:`~processing.correction.phase_rpca.refit_full_resolution`:
       its factors refitted to the kept orders' phase by least squares, used where they fit it better by more than the
       noise; the blocks blur a step's or a ramp's edge, ch. 4 at full resolution does not); weigh L's orders against
       the kept ones blob by blob (:mod:`~processing.correction.surface_orders`; ``info["evidence"]
       ["low_rank_orders_taken"]``), move pixels breaking with three or four neighbours
       (:mod:`~processing.correction.broken_pixels`), send changed pixels back where the measured order continues the
       settled surface and the lower frequencies favour it (:mod:`~processing.correction.surface_continuation`),
       shift islands breaking with a larger surface all round onto it by a shift the lower frequencies cannot see
       per pixel, nor over the island (:mod:`~processing.correction.order_islands`), and judge the broken pixels
       again next to what those two moved; keep L (denoised) except where the result departs from it
       coherently beyond the noise (:func:`~processing.correction.phase_rpca.restore_detail`, ``k_sigma`` standard
       deviations of the 3 x 3 mean residual) or one pixel departs far beyond it where nothing suggests a wrong order
       (on a height step's edge: its order is the measured one), and never where L lies a fringe or more from the
       kept orders.
    7. report as unresolved too the pieces of a fringe whose measured orders' vote does not decide the
       kept order (:func:`~processing.correction.order_margin.undecided_orders`; ``info["evidence"]
       ["vote_undecided_pixels"]``): where the lower frequencies barely tell orders apart, most measured
       orders can be wrong and the kept ones rest on continuity alone. The phase does not change.

    Measured: docs/study/README.md (``rig study``, the thesis' experiments) and docs/study/family.md (drawn cases,
    ``benchmarks/bench_auto_family.py``: held-out median 0.02x the oracle, never worse than no correction).
    """
    start = time.perf_counter()
    if not float(k_sigma) > 0:
        raise ValueError(f"k_sigma: expected > 0, found {k_sigma}")
    measured, wrapped, valid = _inputs(absolute_phase, wrapped_phase, mask)
    temporal = _temporal_inputs(frequency, lower_wrapped, valid)
    phase, folded = _in_pattern_range(measured, valid, temporal)
    pooled, (sigma, measured_breaks) = side_by_side(
        lambda: pool_region_orders(phase, wrapped, valid), lambda: phase_noise_and_breaks(phase, valid)
    )
    decimate = default_decimation(phase.shape) if decimate is None else int(decimate)
    maps = _AutoMaps(phase, wrapped, valid, sigma, decimate, tau, svd, float(k_sigma))
    found = _candidate_orders(maps, pooled, measured_breaks)
    chosen = min(found.breaks, key=found.breaks.__getitem__)  # ties: the first
    out, unresolved, changed, evidence = _restore_detail(maps, found, chosen, temporal, measured)
    undecided = undecided_orders(out, phase, wrapped, valid)  # reported only: the orders stay
    evidence["vote_undecided_pixels"], evidence["range_folded"] = int(np.count_nonzero(undecided)), folded
    unresolved = unresolved | undecided
    extra = {"unresolved": unresolved, "changed": changed, "evidence": evidence, "temporal": temporal is not None}
    return out, _auto_info(maps, found, chosen, start, frequency, extra)


def _auto_info(
    maps: _AutoMaps, found: _Candidates, chosen: str, start: float, frequency: float | None, extra: dict[str, Any]
) -> dict[str, Any]:
    """``auto``'s report entry: solver, steps, candidates and what the evidence steps decided (``extra``)."""
    parameters = {
        "tau": maps.tau if maps.tau is not None else default_tau(maps.phase.shape),
        "stable": True,
        "k_sigma": maps.k_sigma,
        "svd": maps.svd,
    }
    steps = (["fold-into-pattern-range"] if extra["temporal"] else []) + ["pool-region-orders", "rpca-phase"]
    steps += ["reorder-if-consistent"]
    steps += ["settle-orders"] if len(found.maps) > 2 else []
    steps += ["keep-supported-changes"] + (["lower-frequency-evidence"] if extra["temporal"] else [])
    steps += ["mend-spikes"] + (["refit-full-resolution"] if maps.decimate > 1 else [])
    steps += ["arbitrate-low-rank-orders", "mend-broken-pixels", "restore-continued-orders"]
    steps += (["level-islands"] if extra["temporal"] else []) + ["restore-detail"]
    return _solver_info(
        "auto",
        parameters,
        start,
        frequency,
        found.result,
        steps=steps,
        orders_changed=int(extra["changed"]),
        misfit_pixels=int(np.count_nonzero(found.misfit)),
        guard=chosen,
        order_breaks=found.breaks,
        rpca_input=found.rpca_input,
        unresolved=unresolved_summary(extra["unresolved"], maps.valid),
        unresolved_mask=extra["unresolved"],
        evidence=extra["evidence"],
    )


CORRECTIONS: dict[str, CorrectionMethod] = {
    method.name: method
    for method in (
        CorrectionMethod("none", correct_none, "no correction: the phase as unwrapped"),
        CorrectionMethod("vote", correct_vote, "Ding's row-wise voting of fringe orders between wrapped-phase jumps"),
        CorrectionMethod(
            "rpca-orders", correct_rpca_orders, "RPCA on the fringe-order map, then monotonic rows (thesis ch. 3)"
        ),
        CorrectionMethod(
            "rpca-phase", correct_rpca_phase, "low-rank part of the absolute phase by stable RPCA (thesis ch. 4)"
        ),
        CorrectionMethod(
            "auto", correct_auto, "ch. 4 RPCA with guarded re-derived fringe orders (most accurate measured)"
        ),
    )
}


def correct(name: str, absolute_phase: np.ndarray, wrapped_phase: np.ndarray, **kwargs: Any) -> Result:
    """Run the correction ``name`` of :data:`CORRECTIONS`."""
    try:
        method = CORRECTIONS[name]
    except KeyError:
        raise ValueError(f"correction: expected one of {', '.join(CORRECTIONS)}, found {name!r}") from None
    return method(absolute_phase, wrapped_phase, **kwargs)
