"""Temporal phase unwrapping: absolute phase from wrapped phases at several frequencies.

Inputs are wrapped phases of ``phi_i = 2 pi f_i u / W`` (capture-format.md; any 2 pi
representation: [-pi, pi) from :mod:`processing.phase.shifting` or [0, 2 pi)), with ``f_i`` the
integer number of fringes across the projector. Every method returns the absolute phase at its
highest frequency, ``Phi = 2 pi f_max u / W`` in [0, 2 pi f_max), with the fringe orders ``k``
of that frequency (``Phi = phi + 2 pi k``, ``phi`` taken in [0, 2 pi)) and a validity mask.

Methods
-------
- :func:`unwrap_two_frequency`: Ding's number-theoretic method, coprime f1 < f2,
  ``m = round((f2 phi1 - f1 phi2) / 2 pi) = k2 f1 - k1 f2`` through a look-up table; exact
  while the phase errors stay below ``pi / (f1 + f2)``.
- :func:`unwrap_two_frequency_stacks`: phase shifting of both stacks and Ding's method fused
  in one blockwise pass (the fast path of a two-frequency scan).
- :func:`unwrap_three_frequency`: the same on the pairs (f1, f3), (f2, f3) of three frequencies
  without a common divisor, each pair giving f3's order modulo f3 / gcd; combined by the
  Chinese remainder theorem. Tolerance ``min_i t_i pi / (f_i + f3)``, ``t_i = gcd(f_i, f3)``.
- :func:`unwrap_hierarchical`: unit frequency first, each next frequency unwrapped with the
  previous absolute phase scaled by the frequency ratio.
- :func:`unwrap_heterodyne`: beat phases of two or three frequencies down to a unit beat
  (e.g. 64, 58, 53 -> 6, 5 -> 1), then hierarchically back up to the highest frequency.
- :func:`decode_gray` and :func:`unwrap_gray`: Gray-code stripe index (processing.projection.patterns'
  convention) and fringe orders from it, plain or complementary (Zhang, Su, Xiang and Sun,
  Opt. Lasers Eng. 2012); :func:`decode_stripes` for plain binary codes too.
- :func:`unwrap_coded`: a Gray or binary code of any cell width under one or more (not
  necessarily whole) frequencies: the code resolves the period or beat it matches
  (:func:`code_rung`), the higher frequencies follow hierarchically.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from processing import _validate
from processing._blockwise import blockwise
from processing.phase.shifting import block_angle, block_modulation, check_stack, demodulator

TWO_PI = 2.0 * np.pi
# A method on normalised wrapped turns (phi / 2 pi in [0, 1)) of one block, one array per frequency in
# the order its public function takes them -> (absolute phase, orders, valid) of that block.
TurnKernel = Callable[[Sequence[np.ndarray]], tuple[np.ndarray, ...]]


@dataclass
class UnwrapResult:
    """Unwrapped phase at the highest frequency: what every unwrapping method returns.

    Attributes
    ----------
    phase : (H, W) float64
        Absolute phase Phi = 2 pi f u / W of the highest frequency; NaN where an input was NaN.
    orders : (H, W) int64 or None
        Fringe order k of that frequency: phase = (wrapped phase in [0, 2 pi)) + 2 pi k; None
        from spatial unwrapping (:func:`processing.unwrap.spatial.unwrap_spatial`), which has no orders.
    valid : (H, W) bool
        False where the inputs were NaN or the method detected an inconsistency (see each
        method: a look-up value no position inside the projector produces, a residual beyond
        tolerance).
    absolute : bool
        True for temporal methods; False for spatial unwrapping, whose phase is known only up to
        2 pi k per connected region.
    """

    phase: np.ndarray
    orders: np.ndarray | None
    valid: np.ndarray
    absolute: bool = True


# --------------------------------------------------------------------------- shared helpers
#
# Kernels work on flat blocks of pixels (processing._blockwise) and in turns (phase / 2 pi), so
# that normalising, rounding and look-ups are a handful of cheap vectorised operations.


def _fraction(turns: np.ndarray, exact_top: bool = True) -> np.ndarray:
    """``turns`` taken into [0, 1) in place (NaN stays NaN); no np.mod, which is slow.

    -tiny - floor(-tiny) rounds to 1.0; ``exact_top`` moves such values just below 1 (skip it
    where 1.0 is harmless, e.g. the index of a pair look-up, which then reads the same order).
    """
    with np.errstate(invalid="ignore"):  # inf - inf: an infinite input becomes NaN = invalid
        turns -= np.floor(turns)
    if exact_top:
        top = turns >= 1.0
        if top.any():
            one = turns.dtype.type(1.0)
            turns[top] = np.nextafter(one, turns.dtype.type(0.0))
    return turns


def _turns(phi: np.ndarray, exact_top: bool = True) -> np.ndarray:
    """Phase in radians as normalised turns phi / 2 pi in [0, 1) (a new array)."""
    return _fraction(phi * (1.0 / TWO_PI), exact_top)


def _finish(turns: np.ndarray, orders: np.ndarray, valid: np.ndarray, finite: np.ndarray) -> tuple[np.ndarray, ...]:
    """(phase = 2 pi (k + turns), orders, valid) of a block; NaN, order 0 and invalid where not finite."""
    phase = orders + turns
    phase *= TWO_PI
    if not finite.all():
        bad = ~finite
        phase[bad] = np.nan
        orders[bad] = 0
        valid &= finite
    return phase, orders, valid


def _integers(rounded: np.ndarray, finite: np.ndarray) -> np.ndarray:
    """Rounded float orders as int64, 0 where not finite (casting NaN is undefined)."""
    if not finite.all():
        rounded = np.where(finite, rounded, 0.0)
    return rounded.astype(np.int64)


def _run(kernel: Callable[..., tuple[np.ndarray, ...]], maps: Sequence[np.ndarray]) -> UnwrapResult:
    """Apply an elementwise unwrapping kernel block by block over same-shape (H, W) maps."""
    shape = maps[0].shape
    phase, orders, valid = blockwise(kernel, [m.reshape(-1) for m in maps], (np.float64, np.int64, np.bool_))
    return UnwrapResult(phase=phase.reshape(shape), orders=orders.reshape(shape), valid=valid.reshape(shape))


def _run_turns(on_turns: TurnKernel, maps: Sequence[np.ndarray]) -> UnwrapResult:
    """:func:`_run` of a method on normalised turns, every map taken into turns block by block."""

    def kernel(*raw: np.ndarray) -> tuple[np.ndarray, ...]:
        return on_turns([_turns(r) for r in raw])

    return _run(kernel, maps)


# --------------------------------------------------------------------------- number-theoretic (Ding)


@dataclass(frozen=True)
class PairTable:
    """Look-up table of Ding's method for a coprime pair (fa, fb), indexed by m + offset.

    Attributes
    ----------
    offset : int
        fa: m = round(fb ta - fa tb) of normalised turns ta, tb lies in [-fa, fb].
    ka, kb : (fa + fb + 1,) int64
        Orders with fa kb - fb ka = m (mod fa fb), 0 <= ka < fa, 0 <= kb < fb.
    reachable : (fa + fb + 1,) bool
        The fa + fb - 1 values of m that some projector position produces; the other two
        (-fa, fb) only appear when noise crosses the boundaries at u = 0 = W together.
    """

    offset: int
    ka: np.ndarray
    kb: np.ndarray
    reachable: np.ndarray


@lru_cache(maxsize=128)
def pair_table(fa: int, fb: int) -> PairTable:
    """Precomputed look-up table m -> (ka, kb) of coprime frequencies ``fa``, ``fb`` (cached, read-only).

    With normalised wrapped phases (in turns) ta, tb, ``m = round(fb ta - fa tb) = fa kb - fb ka``.
    """
    if math.gcd(fa, fb) != 1:
        raise ValueError(f"frequencies: {fa} and {fb} are not coprime (gcd {math.gcd(fa, fb)})")
    m = np.arange(-fa, fb + 1, dtype=np.int64)
    kb = (m * pow(fa, -1, fb)) % fb if fb > 1 else np.zeros_like(m)
    ka = (-m * pow(fb, -1, fa)) % fa if fa > 1 else np.zeros_like(m)
    # Positions u in [0, 1) between consecutive period boundaries j / fa, j / fb (in integer
    # units of 1 / (2 fa fb)) give the order pairs that really occur.
    bounds = np.union1d(np.arange(fa) * 2 * fb, np.arange(fb) * 2 * fa)
    mids = (bounds + np.append(bounds[1:], 2 * fa * fb)) // 2
    seen = fa * (mids // (2 * fa)) - fb * (mids // (2 * fb))
    reachable = np.zeros(m.shape, dtype=bool)
    reachable[seen + fa] = True
    if reachable[0] or reachable[-1] or not reachable[1:-1].all():  # _pair_lookup relies on this
        raise AssertionError(f"look-up table of ({fa}, {fb}): unexpected reachable set")
    for arr in (ka, kb, reachable):
        arr.flags.writeable = False
    return PairTable(offset=fa, ka=ka, kb=kb, reachable=reachable)


def _pair_lookup(ta: np.ndarray, tb: np.ndarray, table: PairTable, fa: int, fb: int) -> tuple[np.ndarray, ...]:
    """(kb, reachable, finite) for normalised turns ta, tb of the coprime pair (fa, fb).

    kb is the order of fb; pixels where ta or tb is NaN read entry 0 and come back not finite.
    """
    index = ta * float(fb)
    index -= tb * float(fa)
    index += table.offset
    np.rint(index, out=index)
    finite = np.isfinite(index)
    if not finite.all():
        index[~finite] = 0.0
    # Reachable: every entry but the two ends (m = -fa, fb), see PairTable.
    reachable = index > 0.0
    reachable &= index < table.kb.shape[0] - 1
    return table.kb[index.astype(np.intp)], reachable, finite


def unwrap_two_frequency(phi1: np.ndarray, phi2: np.ndarray, f1: int, f2: int) -> UnwrapResult:
    """Ding's number-theoretic two-frequency unwrapping.

    Parameters
    ----------
    phi1, phi2 : (H, W) arrays
        Wrapped phases of frequencies f1 and f2 (any 2 pi representation; NaN or inf = invalid).
    f1, f2 : int
        Coprime fringe counts across the projector, f1 < f2.

    Returns
    -------
    UnwrapResult
        Absolute phase and orders at f2. ``valid`` is False where an input is NaN or m is one of
        the two values (-f1, f2) no position inside the projector produces: noise across both
        period boundaries at the projector's ends (u = 0 = W), whose order is ambiguous.
        Errors beyond the tolerance elsewhere land on other valid pairs and cannot be detected
        (order errors of several fringes).

    Examples
    --------
    Fringe counts 4 and 5 across a projector sampled at five positions u / W:

    >>> import numpy as np
    >>> u = np.array([[0.06, 0.26, 0.46, 0.66, 0.86]])
    >>> wrap = lambda p: np.angle(np.exp(1j * p))
    >>> result = unwrap_two_frequency(wrap(2 * np.pi * 4 * u), wrap(2 * np.pi * 5 * u), 4, 5)
    >>> result.orders
    array([[0, 1, 2, 3, 4]])
    >>> bool(np.allclose(result.phase, 2 * np.pi * 5 * u))
    True

    Notes
    -----
    ``m = round((f2 phi1 - f1 phi2) / 2 pi)`` equals ``k2 f1 - k1 f2``; the look-up table of
    :func:`pair_table` (cached per (f1, f2)) gives (k1, k2). The orders are exact while the
    errors of phi1 and phi2 stay below ``pi / (f1 + f2)``.
    """
    f1, f2 = _coprime_pair(f1, f2)
    p1 = _validate.phase_map(phi1, "phi1", refuse_infinity=False)
    p2 = _validate.phase_map(phi2, "phi2", p1.shape, refuse_infinity=False)
    on_turns = _two_frequency_turns(f1, f2)

    def kernel(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
        return on_turns([_turns(a, exact_top=False), _turns(b)])

    return _run(kernel, [p1, p2])


def _two_frequency_turns(f1: int, f2: int) -> TurnKernel:
    """Ding's look-up on normalised turns [t1, t2] of the coprime pair f1 < f2 (checked)."""
    table = pair_table(f1, f2)

    def on_turns(turns: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
        k2, valid, finite = _pair_lookup(turns[0], turns[1], table, f1, f2)
        return _finish(turns[1], k2, valid, finite)

    return on_turns


def _coprime_pair(f1: object, f2: object) -> tuple[int, int]:
    f1 = _validate.positive_int(f1, "f1")
    f2 = _validate.positive_int(f2, "f2")
    if not f1 < f2:
        raise ValueError(f"f2: expected f1 < f2, found f1 = {f1}, f2 = {f2}")
    if math.gcd(f1, f2) != 1:
        raise ValueError(f"f1, f2: {f1} and {f2} are not coprime (gcd {math.gcd(f1, f2)})")
    return f1, f2


@dataclass
class TwoFrequencyScan:
    """Output of :func:`unwrap_two_frequency_stacks`.

    Attributes
    ----------
    unwrapped : UnwrapResult
        Absolute phase, orders and validity at f2, as :func:`unwrap_two_frequency` gives them.
    background, modulation : (H, W) float64
        A and B of the f2 stack, for :func:`processing.phase.shifting.shadow_mask`.
    """

    unwrapped: UnwrapResult
    background: np.ndarray
    modulation: np.ndarray


def unwrap_two_frequency_stacks(
    stack1: np.ndarray,
    stack2: np.ndarray,
    f1: int,
    f2: int,
    shifts1: np.ndarray | None = None,
    shifts2: np.ndarray | None = None,
) -> TwoFrequencyScan:
    """Phase shifting of two stacks and Ding's two-frequency unwrapping in one pass.

    The same arithmetic as :func:`processing.phase.shifting.phase_shift` on each stack followed
    by :func:`unwrap_two_frequency`, fused block by block: the wrapped phases never leave the
    CPU cache and stay in the stacks' working precision (float32 for integer frames), which
    makes a 1024 x 768 two-frequency scan about a fifth cheaper. The absolute phase then
    carries float32 rounding of the wrapped turn, below 1e-6 rad.

    Parameters
    ----------
    stack1, stack2 : (N1, H, W) and (N2, H, W) arrays
        Phase-shifted frames of frequencies f1 and f2 (pattern ``phase_rad`` 0), N >= 3.
    f1, f2 : int
        Coprime fringe counts across the projector, f1 < f2.
    shifts1, shifts2 : (N,) arrays, optional
        Phase shifts of each stack; default 2 pi k / N.

    Returns
    -------
    TwoFrequencyScan
    """
    f1, f2 = _coprime_pair(f1, f2)
    s1 = check_stack(stack1)
    s2 = check_stack(stack2)
    _validate.same_shape(s2[0], s1.shape[1:], "stack2 frames")
    low = demodulator(s1, shifts1, full=False)
    high = demodulator(s2, shifts2, full=True)
    table = pair_table(f1, f2)

    def kernel(frames1: np.ndarray, frames2: np.ndarray) -> tuple[np.ndarray, ...]:
        coeffs1, coeffs2 = low.coefficients(frames1), high.coefficients(frames2)
        turns1 = _fraction(block_angle(coeffs1) * (1.0 / TWO_PI), exact_top=False)
        turns2 = _fraction(block_angle(coeffs2) * (1.0 / TWO_PI))
        k2, valid, finite = _pair_lookup(turns1, turns2, table, f1, f2)
        return (*_finish(turns2, k2, valid, finite), coeffs2[0], block_modulation(coeffs2))

    shape = s1.shape[1:]
    phase, orders, valid, background, modulation = blockwise(
        kernel,
        [s1.reshape(s1.shape[0], -1), s2.reshape(s2.shape[0], -1)],
        (np.float64, np.int64, np.bool_, np.float64, np.float64),
    )
    unwrapped = UnwrapResult(phase=phase.reshape(shape), orders=orders.reshape(shape), valid=valid.reshape(shape))
    return TwoFrequencyScan(unwrapped, background.reshape(shape), modulation.reshape(shape))


@lru_cache(maxsize=64)
def _crt_table(n1: int, n2: int, modulus: int) -> np.ndarray:
    """k in [0, modulus) from (k mod n1, k mod n2); -1 for residue pairs no k produces."""
    table = np.full((n1, n2), -1, dtype=np.int64)
    k = np.arange(modulus)
    table[k % n1, k % n2] = k
    table.flags.writeable = False
    return table


def unwrap_three_frequency(phis: Sequence[np.ndarray], frequencies: Sequence[int]) -> UnwrapResult:
    """Ding's three-frequency number-theoretic unwrapping.

    Parameters
    ----------
    phis : sequence of three (H, W) arrays
        Wrapped phases at ``frequencies`` (any 2 pi representation; NaN or inf = invalid).
    frequencies : sequence of three ints
        f1, f2, f3 with f3 the largest and no common divisor > 1 of all three (pairs may share
        one: e.g. 6, 10, 15).

    Returns
    -------
    UnwrapResult
        Absolute phase and orders at f3.

    Notes
    -----
    For each pair (f_i, f3), with t = gcd(f_i, f3), ``m = round((f3 phi_i - f_i phi3) / (2 pi t))``
    and the look-up table of the coprime pair (f_i / t, f3 / t) give k3 modulo f3 / t; as
    gcd(t_1, t_2) = 1, the two residues fix k3 in [0, f3) (Chinese remainder theorem). Exact
    while every phase error is below ``min_i t_i pi / (f_i + f3)``. Errors beyond it give other
    valid-looking orders; ``valid`` is False only where an input is NaN.
    """
    on_turns = _three_frequency_turns(frequencies)
    maps = _validate.phase_maps(phis, "phis", 3, refuse_infinity=False)
    return _run_turns(on_turns, maps)


def _three_frequency_turns(frequencies: Sequence[int]) -> TurnKernel:
    """Ding's three-frequency method on normalised turns [t1, t2, t3]; checks ``frequencies``."""
    freqs = _validate.frequency_list(frequencies, "frequencies", count=3)
    if len(set(freqs)) != 3:
        raise ValueError(f"frequencies: expected three distinct values, found {freqs}")
    _check_frequencies_coprime(freqs, "frequencies")
    f1, f2, f3 = freqs
    if f3 != max(freqs):
        raise ValueError(f"frequencies: expected the largest last, found {freqs}")
    pairs = []
    for fi in (f1, f2):
        t = math.gcd(fi, f3)
        # ((f3 / t) phi_i - (fi / t) phi3) / 2 pi = (fi / t) k3 - (f3 / t) k_i: the table of the
        # coprime reduced pair, whose reachable values are the same, gives k3 mod f3 / t.
        pairs.append((pair_table(fi // t, f3 // t), fi // t, f3 // t))
    crt = _crt_table(pairs[0][2], pairs[1][2], f3)

    def on_turns(turns: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
        ta, tb, tc = turns
        # The reduced pairs' boundaries coincide at multiples of 1 / t inside the projector,
        # where noise legitimately produces their edge values of m: reachability says nothing.
        r1, _, finite = _pair_lookup(ta, tc, *pairs[0])
        r2, _, finite_b = _pair_lookup(tb, tc, *pairs[1])
        finite &= finite_b
        valid = np.ones(tc.shape, dtype=bool)
        k3 = crt[r1, r2]
        valid &= k3 >= 0
        np.maximum(k3, 0, out=k3)
        return _finish(tc, k3, valid, finite)

    return on_turns


def _check_frequencies_coprime(frequencies: Sequence[int], name: str) -> None:
    if math.gcd(*frequencies) != 1:
        raise ValueError(
            f"{name}: {list(frequencies)} share the common divisor {math.gcd(*frequencies)}; expected none > 1"
        )


# --------------------------------------------------------------------------- hierarchical / heterodyne


def _hierarchy(
    coarse: np.ndarray, steps: Sequence[tuple[np.ndarray, float]], max_residual: float
) -> tuple[np.ndarray, ...]:
    """Climb from absolute turns at the unit frequency through (normalised turns, frequency) steps.

    Each step: ``k = round(Phi_prev f / f_prev - phi)``, all in turns. Returns the last step's
    (phase, orders, valid) with valid where every residual |estimate - result| stayed within
    ``max_residual`` radians.
    """
    absolute, f_prev = coarse, 1.0
    limit = max_residual / TWO_PI
    valid = np.ones(coarse.shape, dtype=bool)
    for turns, f in steps:
        estimate = absolute * (f / f_prev)
        rounded = estimate - turns
        np.rint(rounded, out=rounded)
        absolute = rounded + turns
        estimate -= absolute
        valid &= np.abs(estimate, out=estimate) <= limit  # NaN compares False
        f_prev = f
    finite = np.isfinite(absolute)  # every input takes part in the chain
    return _finish(turns, _integers(rounded, finite), valid, finite)


def unwrap_hierarchical(
    phis: Sequence[np.ndarray], frequencies: Sequence[int], max_residual: float = np.pi / 2
) -> UnwrapResult:
    """Hierarchical multi-frequency unwrapping from a unit frequency upwards.

    Parameters
    ----------
    phis : sequence of (H, W) arrays
        Wrapped phases at ``frequencies`` (any 2 pi representation; NaN or inf = invalid).
    frequencies : sequence of ints, increasing, the first equal to 1
        The unit frequency covers the projector once, so its wrapped phase is absolute; each
        next one is unwrapped with ``k = round((Phi_prev f / f_prev - phi) / 2 pi)``.
    max_residual : float
        A pixel is valid while every step's |Phi_prev f / f_prev - Phi| <= max_residual
        radians (an order error needs pi; the default flags pixels with half that margin left).

    Returns
    -------
    UnwrapResult
        Absolute phase and orders at the last (highest) frequency. Noise at the two ends of the
        projector can leave the phase a little below 0 or above 2 pi f (orders -1 or f there).
    """
    on_turns, count = _hierarchical_turns(frequencies, max_residual)
    maps = _validate.phase_maps(phis, "phis", count, refuse_infinity=False)
    return _run_turns(on_turns, maps)


def _hierarchical_turns(frequencies: Sequence[int], max_residual: float) -> tuple[TurnKernel, int]:
    """Hierarchical unwrapping on normalised turns, one per frequency, and their count; checks the arguments."""
    freqs = _validate.frequency_list(frequencies, "frequencies", minimum_count=2)
    if freqs[0] != 1:
        raise ValueError(f"frequencies: expected the unit frequency 1 first, found {freqs[0]}")
    if any(b <= a for a, b in zip(freqs, freqs[1:])):
        raise ValueError(f"frequencies: expected increasing values, found {freqs}")
    tolerance = _validate.finite_float(max_residual, "max_residual", minimum=0.0, strict=True)

    def on_turns(turns: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
        return _hierarchy(turns[0], list(zip(turns[1:], freqs[1:])), tolerance)

    return on_turns, len(freqs)


def unwrap_heterodyne(
    phis: Sequence[np.ndarray], frequencies: Sequence[int], max_residual: float = np.pi / 2
) -> UnwrapResult:
    """Heterodyne (multi-wavelength) unwrapping of two or three frequencies.

    Parameters
    ----------
    phis : sequence of two or three (H, W) arrays
        Wrapped phases at ``frequencies`` (any 2 pi representation; NaN or inf = invalid).
    frequencies : sequence of two or three distinct ints
        Two: their difference must be 1 (the beat covers the projector once). Three, sorted
        fa > fb > fc: the beats fa - fb and fb - fc must differ by 1 (64, 58, 53 -> 6, 5 -> 1).
    max_residual : float
        Residual bound of each hierarchical step, as in :func:`unwrap_hierarchical`.

    Returns
    -------
    UnwrapResult
        Absolute phase and orders at the highest frequency.

    Notes
    -----
    The beat of phases at fa > fb, ``(phi_a - phi_b) mod 2 pi``, is the wrapped phase of the
    frequency fa - fb (equivalent wavelength l_a l_b / (l_b - l_a)). The unit beat is absolute;
    then the largest beat and finally fa are unwrapped hierarchically. Beat phases add the
    noise of their terms, so the tolerance is far below that of the individual phases.
    """
    on_turns, count = _heterodyne_turns(frequencies, max_residual)
    maps = _validate.phase_maps(phis, "phis", count, refuse_infinity=False)
    return _run_turns(on_turns, maps)


def _heterodyne_turns(frequencies: Sequence[int], max_residual: float) -> tuple[TurnKernel, int]:
    """Heterodyne unwrapping on normalised turns, one per frequency, and their count; checks the arguments."""
    freqs = _validate.frequency_list(frequencies, "frequencies")
    if len(freqs) not in (2, 3):
        raise ValueError(f"frequencies: expected two or three frequencies, found {len(freqs)}")
    if len(set(freqs)) != len(freqs):
        raise ValueError(f"frequencies: expected distinct values, found {freqs}")
    tolerance = _validate.finite_float(max_residual, "max_residual", minimum=0.0, strict=True)
    order = sorted(range(len(freqs)), key=lambda i: -freqs[i])
    fs = [freqs[i] for i in order]
    if len(fs) == 2 and fs[0] - fs[1] != 1:
        raise ValueError(f"frequencies: the beat {fs[0]} - {fs[1]} must be 1 to cover the projector once")
    if len(fs) == 3 and abs((fs[0] - fs[1]) - (fs[1] - fs[2])) != 1:
        raise ValueError(
            f"frequencies: the beats {fs[0]} - {fs[1]} = {fs[0] - fs[1]} and {fs[1]} - {fs[2]} = {fs[1] - fs[2]} "
            "must differ by 1"
        )

    def on_turns(given: Sequence[np.ndarray]) -> tuple[np.ndarray, ...]:
        turns = [given[i] for i in order]
        if len(fs) == 2:
            return _hierarchy(_fraction(turns[0] - turns[1]), [(turns[0], fs[0])], tolerance)
        beat_ab, beat_bc = fs[0] - fs[1], fs[1] - fs[2]
        turns_ab, turns_bc = _fraction(turns[0] - turns[1]), _fraction(turns[1] - turns[2])
        if beat_ab > beat_bc:
            unit, wide = _fraction(turns_ab - turns_bc), (turns_ab, beat_ab)
        else:
            unit, wide = _fraction(turns_bc - turns_ab), (turns_bc, beat_bc)
        return _hierarchy(unit, [wide, (turns[0], fs[0])], tolerance)

    return on_turns, len(freqs)


TEMPORAL_METHODS = ("two-frequency", "three-frequency", "hierarchical", "heterodyne")


def turn_kernel(
    method: str, frequencies: Sequence[int], max_residual: float = np.pi / 2
) -> tuple[TurnKernel, list[int]]:
    """A temporal method as a kernel on normalised turns, for passes that fuse it with phase shifting.

    Parameters
    ----------
    method : str
        One of :data:`TEMPORAL_METHODS`, with the arithmetic of :func:`unwrap_two_frequency`,
        :func:`unwrap_three_frequency`, :func:`unwrap_hierarchical`, :func:`unwrap_heterodyne`.
    frequencies : sequence of ints
        Every captured frequency, lowest first. As ``rig process`` does, the two- and
        three-frequency methods take the two / three highest, the others all of them.
    max_residual : float
        Residual bound of the hierarchical and heterodyne methods (radians).

    Returns
    -------
    kernel : callable
        ``kernel(turns) -> (phase, orders, valid)`` of one block, ``turns`` a list of arrays of
        wrapped phase / 2 pi in [0, 1), one per used frequency in the order of ``used``.
    used : list of int
        Indices into ``frequencies`` of the frequencies the method reads; the last is the one
        whose absolute phase it returns.
    """
    freqs = _validate.frequency_list(frequencies, "frequencies")
    if method == "two-frequency":
        if len(freqs) < 2:
            raise ValueError(f"frequencies: two-frequency unwrapping needs two, found {freqs}")
        used = [len(freqs) - 2, len(freqs) - 1]
        return _two_frequency_turns(*_coprime_pair(freqs[-2], freqs[-1])), used
    if method == "three-frequency":
        used = list(range(len(freqs) - 3, len(freqs))) if len(freqs) >= 3 else list(range(len(freqs)))
        return _three_frequency_turns([freqs[i] for i in used]), used
    if method == "hierarchical":
        return _hierarchical_turns(freqs, max_residual)[0], list(range(len(freqs)))
    if method == "heterodyne":
        kernel, _ = _heterodyne_turns(freqs, max_residual)
        return kernel, list(range(len(freqs)))
    raise ValueError(f"method: expected one of {', '.join(TEMPORAL_METHODS)}, found {method!r}")


# --------------------------------------------------------------------------- Gray code


def decode_gray(
    images: np.ndarray, inverted: np.ndarray | None = None, threshold: np.ndarray | float | None = None
) -> np.ndarray:
    """Stripe index from captured Gray-code bit planes (processing.projection.patterns' convention).

    Parameters
    ----------
    images : (B, H, W) array
        Captures of bit planes 0 .. B-1, most significant first (pattern ``bit`` = index).
    inverted : (B, H, W) array, optional
        Captures of the inverted planes; a bit is 1 where ``images > inverted`` (robust to
        reflectivity and ambient light). ``threshold`` is then ignored.
    threshold : float or (H, W) array, optional
        A bit is 1 where ``images > threshold``; e.g. (white + black) / 2 from two flat frames.
        Default: per pixel (max + min) / 2 over the B planes; pixels whose planes barely differ
        (range below a quarter of the image's median range: all bits equal, stripe 0 or the
        stripe whose code is all ones) use the image's median of that mid-level instead.

    Returns
    -------
    stripes : (H, W) int64 array in [0, 2**B)
        Stripe index s (projector stripe s covers u in [s W / 2**B, (s + 1) W / 2**B), or
        [s P, (s + 1) P) for cells P pixels wide).
    """
    return decode_stripes(images, inverted, threshold, binary=False)


def decode_stripes(
    images: np.ndarray,
    inverted: np.ndarray | None = None,
    threshold: np.ndarray | float | None = None,
    binary: bool = False,
) -> np.ndarray:
    """Stripe index from captured code bit planes: Gray code, or plain binary with ``binary``.

    The planes are thresholded as in :func:`decode_gray` (the inverted planes, else
    ``threshold``, else the planes' own per-pixel mid-level); a binary code's bits are the stripe
    index itself, a Gray code's are converted first.
    """
    planes = _validate.real_array(images, "images", ndim=3)
    if inverted is not None:
        levels = _validate.real_array(inverted, "inverted", ndim=3)
        _validate.same_shape(levels, planes.shape, "inverted")
    else:
        levels = np.broadcast_to(_bit_threshold(planes, threshold), planes.shape)  # a view, no copy
    # One plane at a time (most significant first): stripes = 2 stripes + bit. A Gray code's binary
    # bit is the XOR of its Gray bits so far (b_i = g_0 ^ ... ^ g_i).
    stripes = np.zeros(planes.shape[1:], dtype=np.int64)
    running = np.zeros(planes.shape[1:], dtype=bool)  # a Gray code's binary bit so far
    bit = np.empty(planes.shape[1:], dtype=bool)
    for index in range(planes.shape[0]):
        np.greater(planes[index], levels[index], out=bit)
        if not binary:
            running ^= bit
        stripes <<= 1
        stripes |= running if not binary else bit
    return stripes


def border_side(
    images: np.ndarray,
    stripes: np.ndarray,
    inverted: np.ndarray | None = None,
    threshold: np.ndarray | float | None = None,
    binary: bool = False,
) -> np.ndarray:
    """Which border of its decoded cell each pixel sits on, as the code's own bits tell it.

    A pixel within the blur of a cell border reads the bits that change there (one for a Gray
    code) at a fraction of their full contrast |plane - level|. Returns an int8 map: +1 where the
    bits changing between cells s and s + 1 read below half the pixel's strongest bit and those
    changing between s - 1 and s at least half, -1 for the converse, 0 where the bits do not
    single out one border. :func:`unwrap_coded` uses it where cells and periods share their borders.
    """
    planes = _validate.real_array(images, "images", ndim=3)
    if inverted is not None:
        levels = _validate.real_array(inverted, "inverted", ndim=3)
        _validate.same_shape(levels, planes.shape, "inverted")
    else:
        levels = np.broadcast_to(_bit_threshold(planes, threshold), planes.shape)
    s = np.asarray(stripes).astype(np.int32)  # code words of up to MAX_CODE_BITS (24) bits
    _validate.same_shape(s, planes.shape[1:], "stripes")
    word = s if binary else s ^ (s >> 1)
    below, above = np.maximum(s - 1, 0), s + 1
    left = np.where(s > 0, word ^ (below if binary else below ^ (below >> 1)), 0)  # bits changing at s - 1 | s
    right = word ^ (above if binary else above ^ (above >> 1))  # bits changing at s | s + 1
    weak_left = np.full(s.shape, np.inf, dtype=np.float32)
    weak_right = np.full(s.shape, np.inf, dtype=np.float32)
    strongest = np.zeros(s.shape, dtype=np.float32)
    contrast = np.empty(s.shape, dtype=np.float32)
    count = planes.shape[0]
    for index in range(count):
        np.subtract(planes[index], levels[index], out=contrast, dtype=np.float32)  # not in uint8: no wrap-around
        np.abs(contrast, out=contrast)
        np.maximum(strongest, contrast, out=strongest)
        bit = np.int32(1 << (count - 1 - index))  # plane 0 is the most significant bit
        np.minimum(weak_left, contrast, out=weak_left, where=(left & bit) != 0)
        np.minimum(weak_right, contrast, out=weak_right, where=(right & bit) != 0)
    half = 0.5 * strongest
    side = np.zeros(s.shape, dtype=np.int8)
    side[(weak_right < half) & (weak_left >= half)] = 1
    side[(weak_left < half) & (weak_right >= half)] = -1
    return side


def _bit_threshold(planes: np.ndarray, threshold: np.ndarray | float | None) -> np.ndarray:
    """The level a plane's pixel is compared with: ``threshold`` (checked), else the planes' own mid-level."""
    if threshold is None:
        return _default_gray_threshold(planes)
    level = np.asarray(threshold, dtype=np.float64)
    if level.ndim not in (0, 2) or (level.ndim == 2 and level.shape != planes.shape[1:]):
        raise ValueError(
            f"threshold: expected a number or an array of shape {planes.shape[1:]}, found shape {level.shape}"
        )
    return level


def _default_gray_threshold(planes: np.ndarray) -> np.ndarray:
    high = planes.max(axis=0).astype(np.float64)
    low = planes.min(axis=0).astype(np.float64)
    mid = (high + low) / 2.0
    spread = high - low
    flat = spread < 0.25 * np.median(spread)
    if flat.any():
        mid[flat] = np.median(mid[~flat]) if (~flat).any() else np.median(mid)
    return mid


def unwrap_gray(
    phi: np.ndarray, stripes: np.ndarray, bits: int, frequency: int, complementary: bool = False
) -> UnwrapResult:
    """Absolute phase from a wrapped phase and a decoded Gray-code stripe index.

    Parameters
    ----------
    phi : (H, W) array
        Wrapped phase of the sinusoid with ``frequency`` fringes (any 2 pi representation,
        periods starting at phase 0 as in capture-format.md; NaN or inf = invalid).
    stripes : (H, W) int array
        Stripe index from :func:`decode_gray` with ``bits`` planes.
    bits : int
        Number of Gray-code planes.
    frequency : int
        Fringes across the projector.
    complementary : bool
        False (plain): order ``k = floor(stripes * frequency / 2**bits)`` (2**bits == frequency
        gives one code word per period). Its boundaries fall exactly on the phase wraps, so
        blur or a small misregistration makes off-by-one errors along every period edge.
        True (complementary Gray code, Zhang et al. 2012): ``2**bits == 2 * frequency``, the
        extra finest plane splitting each period in halves. ``K1 = stripes // 2`` (from the
        first bits - 1 planes) changes at period edges, ``K2 = (stripes + 1) // 2`` in the
        middle of periods; each pixel takes the one whose boundaries are far from its phase:
        K2 for phase < pi / 2, K1 for pi / 2 <= phase < 3 pi / 2, K2 - 1 above.

    Returns
    -------
    UnwrapResult
        ``valid`` is False where a stripe index is outside [0, 2**bits) or phi is NaN.
    """
    bits = _validate.positive_int(bits, "bits")
    frequency = _validate.positive_int(frequency, "frequency")
    p = _validate.phase_map(phi, "phi", refuse_infinity=False)
    s = np.asarray(stripes)
    if not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"stripes: expected an integer array, found dtype {s.dtype}")
    _validate.same_shape(s, p.shape, "stripes")
    count = 1 << bits
    if complementary and count != 2 * frequency:
        raise ValueError(
            f"bits: complementary Gray code needs 2**bits == 2 * frequency, found bits = {bits}, frequency = {frequency}"
        )

    def kernel(raw: np.ndarray, stripe: np.ndarray) -> tuple[np.ndarray, ...]:
        stripe = stripe.astype(np.int64)
        valid = (stripe >= 0) & (stripe < count)
        turns = _turns(raw)
        if complementary:
            k1 = stripe >> 1
            k2 = (stripe + 1) >> 1
            orders = np.where(turns < 0.25, k2, np.where(turns < 0.75, k1, k2 - 1))
        else:
            orders = (stripe * frequency) // count
        return _finish(turns, orders, valid, np.isfinite(turns))

    return _run(kernel, [p, s])


# --------------------------------------------------------------------------- a code under several frequencies
#
# A Gray or binary code cuts the projector axis into cells ``cell`` wide (a fraction of the axis,
# W / 2**bits or a given width). It resolves a fringe period directly when the period holds at
# least one cell: with r = period / cell cells per period, the cell's centre predicts the absolute
# phase to within half a cell, and k = round((s + 1/2) / r - t) is right while that half cell
# plus the phase noise stays under half a period (r > 1; r = 2 is the complementary Gray code of
# Zhang et al.). With r = 1 the cells and periods share their borders and k = s. Periods shorter
# than a cell follow hierarchically from a resolved one; the beat of two frequencies (their
# difference, e.g. kamino410's 100 px and 200/3 px fringes beat at 200 px = 2 cells of 100 px)
# is a period the code may resolve with a wider margin than either frequency.

# Cells per period from which the rounding rule's margin (1/2 - 1/(2r) turns) is a quarter period.
ROBUST_CELLS_PER_PERIOD = 2.0
_RATIO_TOLERANCE = 1e-6


@dataclass(frozen=True)
class CodeRung:
    """The period a code resolves: a captured frequency (``pair`` of one index) or the beat of two.

    ``frequency``: fringes across the axis (the beat's: the difference of the pair's);
    ``pair``: indices into the captured frequencies, (i,) or (higher, lower) for a beat;
    ``cells_per_period``: r = 1 / (frequency * cell).
    """

    frequency: float
    pair: tuple[int, ...]
    cells_per_period: float

    @property
    def aligned(self) -> bool:
        """One cell per period: cells and periods share their borders (k is the cell index)."""
        return abs(self.cells_per_period - 1.0) < _RATIO_TOLERANCE


def code_rung(frequencies: Sequence[float], cell: float) -> CodeRung:
    """The period a code of cells ``cell`` wide (fraction of the axis) resolves among ``frequencies``.

    Candidates are the captured frequencies and the beats of every pair, those with at least one
    cell per period. The highest-frequency candidate with :data:`ROBUST_CELLS_PER_PERIOD` cells per
    period or more is chosen (a quarter period of margin), else the highest with at least one.
    ``ValueError`` (one line) when every period and beat is shorter than a cell.
    """
    freqs = [float(f) for f in frequencies]
    if not freqs or not all(f > 0 and math.isfinite(f) for f in freqs):
        raise ValueError(f"frequencies: expected positive fringe counts, found {freqs}")
    if not (cell > 0 and math.isfinite(cell)):
        raise ValueError(f"cell: expected a positive fraction of the axis, found {cell}")
    rungs = [CodeRung(f, (i,), 1.0 / (f * cell)) for i, f in enumerate(freqs)]
    for i, fa in enumerate(freqs):
        for j, fb in enumerate(freqs):
            if fa > fb:
                rungs.append(CodeRung(fa - fb, (i, j), 1.0 / ((fa - fb) * cell)))
    resolvable = [r for r in rungs if r.cells_per_period >= 1.0 - _RATIO_TOLERANCE]
    robust = [r for r in resolvable if r.cells_per_period >= ROBUST_CELLS_PER_PERIOD - _RATIO_TOLERANCE]
    pool = robust or resolvable
    if not pool:
        periods = ", ".join(f"{1.0 / (f * cell):.3g}" for f in sorted(freqs))
        raise ValueError(
            f"the code's cells are wider than every fringe period and every beat of two frequencies "
            f"(periods {periods} cells); expected a period or beat of at least one cell"
        )
    # highest frequency first; of equals, a captured frequency before a beat (less noise)
    return max(pool, key=lambda r: (r.frequency, -len(r.pair)))


def unwrap_coded(
    phis: Sequence[np.ndarray],
    frequencies: Sequence[float],
    stripes: np.ndarray,
    cell: float,
    max_residual: float = np.pi / 2,
    side: np.ndarray | None = None,
) -> UnwrapResult:
    """Absolute phase from a decoded code (Gray or binary) and wrapped phases at one or more frequencies.

    Parameters
    ----------
    phis : sequence of (H, W) arrays
        Wrapped phases at ``frequencies`` (any 2 pi representation, periods starting at phase 0).
    frequencies : sequence of positive numbers, increasing
        Fringes across the axis; need not be whole (1920 px / 100 px = 19.2).
    stripes : (H, W) int array
        Cell index from :func:`decode_stripes`; cells past ``1 / cell`` are invalid.
    cell : float
        Width of one code cell as a fraction of the axis (``1 / 2**bits``, or cell px / W).
    max_residual : float
        Bound, in radians, of each hierarchical step's residual (as :func:`unwrap_hierarchical`).
    side : (H, W) int8 array, optional
        :func:`border_side` of the code. Used where the rung has one cell per period (its cells'
        borders are its phase wraps): a pixel in the first quarter of its period whose bits say
        it sits on the border with the next cell belongs to that cell (k = s + 1), one in the
        last quarter on the border with the previous cell to that one (k = s - 1).

    Returns
    -------
    UnwrapResult
        Absolute phase and orders at the highest frequency. The code resolves the rung of
        :func:`code_rung`; the captured frequencies above it follow hierarchically, a pixel
        staying valid while every step's residual is within ``max_residual``.
    """
    freqs = [float(f) for f in frequencies]
    if any(b <= a for a, b in zip(freqs, freqs[1:])):
        raise ValueError(f"frequencies: expected increasing values, found {freqs}")
    rung = code_rung(freqs, cell)
    maps = _validate.phase_maps(phis, "phis", len(freqs), refuse_infinity=False)
    s = np.asarray(stripes)
    if not np.issubdtype(s.dtype, np.integer):
        raise ValueError(f"stripes: expected an integer array, found dtype {s.dtype}")
    _validate.same_shape(s, maps[0].shape, "stripes")
    tolerance = _validate.finite_float(max_residual, "max_residual", minimum=0.0, strict=True)
    cells = math.ceil(1.0 / cell - _RATIO_TOLERANCE)
    climb = [i for i, f in enumerate(freqs) if f > rung.frequency]
    ratio = rung.cells_per_period

    sides = np.zeros(s.shape, dtype=np.int8) if side is None else np.asarray(side, dtype=np.int8)
    _validate.same_shape(sides, s.shape, "side")

    def kernel(stripe: np.ndarray, border: np.ndarray, *raw: np.ndarray) -> tuple[np.ndarray, ...]:
        turns = [_turns(r) for r in raw]
        anchor = turns[rung.pair[0]] if len(rung.pair) == 1 else _fraction(turns[rung.pair[0]] - turns[rung.pair[1]])
        stripe = stripe.astype(np.int64)
        valid = (stripe >= 0) & (stripe < cells)
        if rung.aligned:
            orders = stripe.astype(np.float64)
            orders += (anchor < 0.25) & (border == 1)  # read in the previous cell, but past its border
            orders -= (anchor >= 0.75) & (border == -1)  # read in the next cell, short of its border
        else:
            orders = (stripe + 0.5) * (1.0 / ratio) - anchor
            np.rint(orders, out=orders)
        if not climb:
            finite = np.isfinite(anchor)
            return _finish(anchor, _integers(orders, finite), valid, finite)
        coarse = (orders + anchor) * (1.0 / rung.frequency)  # absolute turns at the unit frequency
        phase, k, climbed = _hierarchy(coarse, [(turns[i], freqs[i]) for i in climb], tolerance)
        return phase, k, climbed & valid

    return _run(kernel, [s, sides, *maps])
