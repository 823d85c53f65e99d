"""One pass over a phase-shifted capture: wrapped phases, modulation, shadow mask and temporal
unwrapping, fused block by block in float32.

Done stage by stage (:func:`processing.phase.shifting.phase_shift` per frequency, then
:func:`processing.phase.shifting.shadow_mask` and :mod:`processing.unwrap.temporal`), a two-frequency
six-step 1024 x 768 capture writes float64 phase, background and modulation maps of every
frequency to memory and reads them back several times. Here each block of pixels (64k, a few MiB
of float32 temporaries reused from block to block) goes from the raw frames to its absolute phase in
one visit::

    frames (N_i, P) --weights (3, N_i)--> A, B cos phi, B sin phi      one small product per frequency
    -> wrapped phase phi in [0, 2 pi), modulation B, the modulation mask of each frequency
    -> fringe orders and absolute phase of the highest frequency       (processing.unwrap.temporal's methods)
    -> every frequency's phase in the absolute phase, noise-weighted    (processing.phase.frequency_fusion)

Angles and magnitudes come from OpenCV (``cv2.phase``, ``cv2.magnitude``, imported on first use)
when it is installed: numpy's arctan2 costs about 20 ms per megapixel on CPUs without AVX-512,
``cv2.phase`` well under 1 ms, with at most 1.7e-4 rad error (bounded by
:data:`ANGLE_TOLERANCE`, tested). Where numpy's float32 arctan2 runs a vectorised loop (its AVX-512
build, :func:`exact_angles_are_fast`) the angles are numpy's instead, correctly rounded to float32
for about 15 % more time per angle: OpenCV's error, 6.8e-5 rad RMS, is far below an 8-bit capture's
phase noise but not a high-SNR one's (at 50 dB it made the fused phase's RMS error 0.026 % larger).
Ding's two-frequency look-up then runs as OpenCV look-up tables on the rounded index. Without OpenCV
(or with ``opencv=False``) numpy's exact arctan2 and the numpy look-up are used.

The automatic thresholds of the shadow mask (a fraction of the 99th percentile of the modulation,
as :func:`processing.phase.shifting.shadow_mask` derives them) come from the same regular subsample
of about 16k pixels, demodulated before the pass, so the mask is known inside it.
"""

from __future__ import annotations

import itertools
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any

import numpy as np

from processing import _validate, concurrency
from processing._aligned import aligned_empty
from processing.phase.frequency_fusion import fuse_frequencies
from processing.phase.shifting import robust_high, sample_stride, shift_weights
from processing.unwrap.temporal import TEMPORAL_METHODS, TurnKernel, pair_table, turn_kernel

TWO_PI = 2.0 * np.pi
# Pixels per block. Each block is tens of numpy and OpenCV calls: at 16k pixels their per-call overhead
# and the GIL hand-overs between two threads took a third of the pass; 32k and 128k were slower than
# 64k too (the in-memory pipeline of benchmarks/bench_pipeline.py on the 2-core development machine).
BLOCK = 65536
ANGLE_TOLERANCE = 2.0e-4  # rad: bound on |angle - exact angle| of the OpenCV path (measured max 1.7e-4)
_TOP = np.nextafter(np.float32(TWO_PI), np.float32(0.0))  # largest float32 below 2 pi: angles in [0, 2 pi)
_BELOW_ONE = np.nextafter(np.float32(1.0), np.float32(0.0))
_PI = np.array(np.pi, dtype=np.float32)  # a 0-d array: numpy's ufuncs take it faster than a NumPy scalar
_LUT_SIZE = 256  # OpenCV look-up tables index 8-bit images


@lru_cache(maxsize=1)
def _opencv() -> Any | None:
    """The cv2 module, or None when OpenCV is not installed (imported once, on first use)."""
    try:
        import cv2
    except ImportError:
        return None
    return cv2


def _backend(opencv: bool) -> Any | None:
    return _opencv() if opencv else None


@lru_cache(maxsize=1)
def exact_angles_are_fast() -> bool:
    """Whether numpy's float32 arctan2 runs a vectorised loop here (a dispatched target above numpy's baseline,
    as ``numpy.lib.introspect.opt_func_info`` reports it: AVX-512 on x86): then the pass takes its exact
    angles instead of OpenCV's approximate ones. False where numpy cannot tell (numpy before 2.0)."""
    try:
        from numpy.lib.introspect import opt_func_info
    except ImportError:
        return False
    loops = opt_func_info(func_name="^arctan2$", signature="float32").get("arctan2", {})
    return any(not str(loop.get("current", "baseline")).startswith("baseline") for loop in loops.values())


def _opposite_angles(cv2: Any | None) -> bool:
    """Whether angles are numpy's exact ones from the opposite cosine (:func:`_angle_into`'s ``opposite``) rather
    than OpenCV's: with OpenCV at hand, where numpy's are fast (without it numpy's plain path is exact anyway)."""
    return cv2 is not None and exact_angles_are_fast()


def _angle_into(
    cos_part: np.ndarray,
    sin_part: np.ndarray,
    out: np.ndarray,
    cv2: Any | None,
    below_two_pi: bool = True,
    finite: bool = False,
    opposite: bool = False,
) -> np.ndarray:
    """atan2(sin, cos) of float32 vectors into ``out`` in [0, 2 pi]; NaN stays NaN.

    ``below_two_pi`` moves 2 pi itself (float32 rounding of tiny negative angles) just below it,
    so that the angle is a wrapped phase in [0, 2 pi); a look-up index does not need it.
    ``finite``: the inputs hold no NaN (integer frames; see :func:`_bound_into`).
    ``opposite``: the cosine part given is -cos: pi - numpy's exact atan2(sin, -cos) is the angle in [0, 2 pi]
    in two passes (numpy's masked add of 2 pi to the negative angles costs ten times more). A sine of exactly
    +0 (a sum that cancels) gives 0 for a positive cosine, as atan2 does, not 2 pi.
    """
    if opposite:
        np.arctan2(sin_part, cos_part, out=out)
        np.subtract(_PI, out, out=out)
    elif cv2 is not None:
        cv2.phase(cos_part, sin_part, angle=out)
    else:
        np.arctan2(sin_part, cos_part, out=out)
        np.add(out, np.float32(TWO_PI), out=out, where=out < 0)
    return _bound_into(out, _TOP, cv2, finite, upper=True) if below_two_pi else out


def _bound_into(values: np.ndarray, bound: float, cv2: Any | None, finite: bool, upper: bool) -> np.ndarray:
    """min(values, bound) (``upper``) or max(values, bound) of a float32 vector in place, the bound in float32.

    ``finite``: no NaN in ``values``, so OpenCV's ``min``/``max`` may do it (15 us per 64k pixels against
    numpy's 35-50 us with a scalar; the same values, but OpenCV's would turn a NaN into the bound).
    """
    if cv2 is not None and finite:
        (cv2.min if upper else cv2.max)(values, float(np.float32(bound)), dst=values)
        return values
    return (np.minimum if upper else np.maximum)(values, np.float32(bound), out=values)


def _magnitude_into(cos_part: np.ndarray, sin_part: np.ndarray, out: np.ndarray, cv2: Any | None) -> np.ndarray:
    """sqrt(cos^2 + sin^2) of float32 vectors into ``out``."""
    if cv2 is not None:
        cv2.magnitude(cos_part, sin_part, magnitude=out)
        return out
    np.multiply(cos_part, cos_part, out=out)
    out += sin_part * sin_part
    return np.sqrt(out, out=out)


def wrapped_angle(cos_part: np.ndarray, sin_part: np.ndarray, opencv: bool = True) -> np.ndarray:
    """The fast angle of the pass: atan2(sin_part, cos_part) in [0, 2 pi) as float32.

    Parameters
    ----------
    cos_part, sin_part : arrays of one shape
        B cos phi and B sin phi (any real dtype; computed in float32).
    opencv : bool
        Use ``cv2.phase`` when OpenCV is installed (error at most :data:`ANGLE_TOLERANCE`
        radians), numpy's where :func:`exact_angles_are_fast`; else numpy's arctan2 in float32.

    Returns
    -------
    angle : float32 array of the inputs' shape, in [0, 2 pi); NaN where an input is NaN.
    """
    c = np.ascontiguousarray(_validate.real_array(cos_part, "cos_part"), dtype=np.float32)
    s = np.ascontiguousarray(_validate.real_array(sin_part, "sin_part"), dtype=np.float32)
    _validate.same_shape(s, c.shape, "sin_part")
    out = np.empty(c.size, dtype=np.float32)
    if _opposite_angles(_backend(opencv)):
        _angle_into(-c.reshape(-1), s.reshape(-1), out, None, opposite=True)
    else:
        _angle_into(c.reshape(-1), s.reshape(-1), out, _backend(opencv))
    return out.reshape(c.shape)


@dataclass
class FringePass:
    """Output of :func:`fringe_pass`; maps are (H, W).

    Attributes
    ----------
    frequencies : list of float
        Frequency of each group, as given (lowest first).
    method : str or None
        The temporal method applied, None for wrapped phases only.
    phase : float32 map or None
        Absolute phase at ``phase_frequency`` (= 2 pi (orders + wrapped / 2 pi)), NaN where not
        ``modulated``; where the method's test failed it is kept (untrusted: ``valid`` is False),
        for callers that re-examine those pixels. None without a method.
    orders : int32 map or None
        Fringe orders of ``phase_frequency`` (wrapped phase taken in [0, 2 pi)).
    modulated : bool map
        Lit and modulated in every group (:func:`processing.phase.shifting.shadow_mask`'s test with
        ``thresholds``).
    valid : bool map
        ``modulated`` and, with a method, consistent for it (see processing.unwrap.temporal).
    kept : list of int
        Groups whose ``wrapped``, ``modulation`` and ``background`` (or ``brightness``) maps were
        kept (in order).
    wrapped, modulation, background : lists of float32 maps, one per kept group
        Wrapped phase in [0, 2 pi), fringe amplitude B and mean intensity A (these two empty when
        ``brightness`` was asked for).
    thresholds : list of float
        Minimum modulation of each group's mask.
    phase_frequency : float
        The frequency of ``phase`` (the highest one the method reads).
    sigma : float32 map or None
        With ``fuse_noise``: the predicted standard deviation (rad) of the fused ``phase``.
    disagreeing : int
        With ``fuse_noise``: pixels where a lower frequency disagreed with the highest and was
        left out (:func:`processing.phase.frequency_fusion.fuse_frequencies`).
    """

    frequencies: list[float]
    method: str | None
    phase: np.ndarray | None
    orders: np.ndarray | None
    modulated: np.ndarray
    valid: np.ndarray
    kept: list[int]
    wrapped: list[np.ndarray]
    modulation: list[np.ndarray]
    background: list[np.ndarray]
    thresholds: list[float]
    phase_frequency: float
    brightness: list[np.ndarray] = field(default_factory=list)  # A + B per kept group, when asked for
    sigma: np.ndarray | None = None
    disagreeing: int = 0


@dataclass(frozen=True)
class _Group:
    rows: slice | np.ndarray  # frame indices into the flat stack
    weights: np.ndarray  # (3, N) float32


def _rows(indices: Sequence[int]) -> slice | np.ndarray:
    """Frame indices as a slice when they are evenly spaced (a view, not a copy, per block)."""
    if len(indices) > 1:
        step = indices[1] - indices[0]
        if step > 0 and all(b - a == step for a, b in itertools.pairwise(indices)):
            return slice(indices[0], indices[-1] + 1, step)
    return np.asarray(indices, dtype=np.intp)


def _check_groups(groups: Sequence[Sequence[int]], frames: int) -> list[list[int]]:
    try:
        lists = [[_validate.positive_int(i, "groups", minimum=0) for i in g] for g in groups]
    except TypeError:
        raise ValueError("groups: expected a sequence of frame index sequences") from None
    if not lists:
        raise ValueError("groups: expected at least one group of frames")
    for k, indices in enumerate(lists):
        if len(indices) < 3:
            raise ValueError(f"groups[{k}]: expected at least 3 phase-shifted frames, found {len(indices)}")
        if max(indices) >= frames:
            raise ValueError(f"groups[{k}]: frame index {max(indices)} outside the stack of {frames} frames")
    return lists


@dataclass(frozen=True)
class _DingTables:
    """Ding's look-up for (f1, f2) as 256-entry tables of 2 pi k, k and reachability (OpenCV path)."""

    f1: int
    f2: int
    phase: np.ndarray
    orders: np.ndarray
    reach: np.ndarray


def _ding_tables(frequencies: Sequence[int], used: Sequence[int]) -> _DingTables | None:
    """The tables of the pair that ``used`` picks, or None when m + f1 can reach the last 8-bit index.

    The last index marks unmodulated pixels: NaN phase, not reachable.
    """
    f1, f2 = (int(frequencies[i]) for i in used)
    if f1 + f2 >= _LUT_SIZE - 1:
        return None
    table = pair_table(f1, f2)
    size = table.kb.shape[0]
    phase = np.full(_LUT_SIZE, np.nan, dtype=np.float32)
    phase[:size] = table.kb * TWO_PI
    orders = np.zeros(_LUT_SIZE, dtype=np.int32)
    orders[:size] = table.kb
    reach = np.zeros(_LUT_SIZE, dtype=np.uint8)
    reach[:size] = table.reachable
    return _DingTables(f1, f2, phase, orders, reach)


def fringe_pass(
    frames: np.ndarray,
    groups: Sequence[Sequence[int]],
    frequencies: Sequence[float],
    method: str | None = None,
    shifts: Sequence[np.ndarray | None] | None = None,
    min_ratio: float = 0.2,
    max_residual: float = np.pi / 2,
    keep_all: bool = False,
    opencv: bool = True,
    threads: int = 1,
    orders: bool = True,
    brightness: bool = False,
    fuse_noise: float | None = None,
    thresholds: Sequence[float] | None = None,
) -> FringePass:
    """Wrapped phases, modulation mask and (optionally) temporal unwrapping in one pass.

    Parameters
    ----------
    frames : (N, H, W) array, any integer or float dtype
        Every frame of the capture; computed in float32 (exact for 8- and 16-bit images).
    groups : sequence of sequences of int
        Frame indices of each frequency's phase-shifted set (>= 3 each), lowest frequency first.
    frequencies : sequence of float
        Fringes across the projector of each group (whole numbers for a temporal method).
    method : str, optional
        One of :data:`processing.unwrap.temporal.TEMPORAL_METHODS`; the two- and three-frequency
        methods read the two / three highest frequencies (see
        :func:`processing.unwrap.temporal.turn_kernel`). None: wrapped phases and mask only.
    shifts : sequence of (N_i,) arrays or None, optional
        Phase shifts of each group in radians (including the patterns' ``phase_rad``); None
        for 2 pi k / N_i.
    min_ratio : float in (0, 1]
        Modulation mask of each group as :func:`processing.phase.shifting.shadow_mask` with its
        automatic threshold: B >= min_ratio x 99th percentile of B, B >= min_ratio x A, A > 0.
    max_residual : float
        Residual bound of the hierarchical and heterodyne methods (radians).
    keep_all : bool
        Keep the wrapped phase, modulation and background of every group; default only the
        highest frequency's (what height, texture and corrections read).
    opencv : bool
        Use OpenCV's angle, magnitude and look-up kernels when installed (angles within
        :data:`ANGLE_TOLERANCE` of exact); False: numpy only.
    threads : int
        Threads sharing the blocks (numpy and OpenCV release the GIL in their loops).
    orders : bool
        Keep the fringe-order map (False: ``orders`` is None, for callers that read only the
        phase; it follows from ``phase`` and the wrapped phase).
    brightness : bool
        Keep A + B of each kept group (a texture: the brightest the pixel gets) instead of A and
        B apart: one full-size map instead of two.
    fuse_noise : float, optional
        Camera noise sigma_I (grey levels): with a method, the phase becomes the noise-weighted
        combination of every group's (:mod:`processing.phase.frequency_fusion`), ``sigma`` its
        predicted standard deviation. None: the highest frequency's phase alone.
    thresholds : sequence of float, optional
        :func:`modulation_thresholds` of the same frames, groups, shifts and ratio; None: derived here.

    Returns
    -------
    FringePass
        Within ``ANGLE_TOLERANCE`` (OpenCV) or float32 rounding (numpy) of the float64 stage functions;
        fringe orders equal theirs except where the unwrapping index sits on a rounding boundary.
    """
    stack = _validate.real_array(frames, "frames", ndim=3)
    count, height, width = stack.shape
    lists, freqs, ratio = _checked_groups(groups, count, frequencies, shifts, min_ratio)
    threads = _validate.positive_int(threads, "threads")
    cv2 = _backend(opencv)
    kernel, used, tables = _temporal_kernel(method, freqs, max_residual, cv2)
    flat = stack.reshape(count, -1)
    specs, thresholds = _group_specs(flat, lists, shifts, ratio, (height, width), cv2, thresholds)
    kept = list(range(len(lists))) if keep_all else [len(lists) - 1]
    fusion = None if fuse_noise is None or method is None or len(lists) < 2 else _Fusion(freqs, lists, fuse_noise)
    out = _Outputs.allocate(flat.shape[1], len(kept), method is not None, orders, brightness, fusion is not None)
    nonnegative = np.issubdtype(stack.dtype, np.unsignedinteger) and all((s.weights[0] >= 0).all() for s in specs)
    plan = _Plan(flat, specs, thresholds, ratio, kept, kernel, used, tables, cv2, nonnegative, fusion)
    _run_blocks(plan, out, flat.shape[1], threads)
    return _result(out, freqs, method, kept, thresholds, used, (height, width), fusion)


def modulation_thresholds(
    frames: np.ndarray,
    groups: Sequence[Sequence[int]],
    shifts: Sequence[np.ndarray | None] | None = None,
    min_ratio: float = 0.2,
    opencv: bool = True,
) -> list[float]:
    """Each group's modulation-mask threshold as :func:`fringe_pass` derives it (its ``thresholds``).

    ``min_ratio`` x the 99th percentile of the modulation B over a regular subsample of about 16k
    pixels (the tiniest float32 at least). Arguments as :func:`fringe_pass`'s. Computed apart so
    that a caller can run it beside other work that the pass waits for.
    """
    stack = _validate.real_array(frames, "frames", ndim=3)
    count, height, width = stack.shape
    lists = _check_groups(groups, count)
    _check_shifts(shifts, len(lists))
    ratio = _checked_ratio(min_ratio)
    flat = stack.reshape(count, -1)
    return _group_specs(flat, lists, shifts, ratio, (height, width), _backend(opencv))[1]


def _group_specs(
    flat: np.ndarray,
    lists: list[list[int]],
    shifts: Sequence[np.ndarray | None] | None,
    ratio: float,
    shape: tuple[int, int],
    cv2: Any | None,
    thresholds: Sequence[float] | None = None,
) -> tuple[list[_Group], list[float]]:
    """Each group's frame rows and float32 weights, and its modulation mask's threshold (from the subsample).

    ``thresholds``: the thresholds when the caller has them (checked, not derived again).
    """
    specs = [
        _Group(_rows(g), shift_weights(len(g), None if shifts is None else shifts[k]).astype(np.float32))
        for k, g in enumerate(lists)
    ]
    if thresholds is not None:
        if len(thresholds) != len(specs):
            raise ValueError(f"thresholds: expected {len(specs)} (one per group), found {len(thresholds)}")
        return specs, [_validate.finite_float(t, f"thresholds[{k}]", minimum=0.0) for k, t in enumerate(thresholds)]
    tiny = float(np.finfo(np.float32).tiny)
    return specs, [max(ratio * _sampled_high(flat, spec, shape, cv2), tiny) for spec in specs]


def _result(
    out: _Outputs,
    freqs: list[float],
    method: str | None,
    kept: list[int],
    thresholds: list[float],
    used: list[int],
    shape: tuple[int, int],
    fusion: _Fusion | None,
) -> FringePass:
    """The pass's flat outputs as (H, W) maps, with the fusion's count of disagreeing pixels."""
    return FringePass(
        frequencies=freqs,
        method=method,
        phase=None if out.phase is None else out.phase.reshape(shape),
        orders=None if out.orders is None else out.orders.reshape(shape),
        modulated=out.valid.reshape(shape) if out.modulated is None else out.modulated.reshape(shape),
        valid=out.valid.reshape(shape),
        kept=kept,
        wrapped=[m.reshape(shape) for m in out.wrapped],
        modulation=[m.reshape(shape) for m in out.modulation],
        background=[m.reshape(shape) for m in out.background],
        thresholds=thresholds,
        phase_frequency=freqs[used[-1]] if used else freqs[-1],
        brightness=[m.reshape(shape) for m in out.brightness],
        sigma=None if out.sigma is None else out.sigma.reshape(shape),
        disagreeing=0 if fusion is None else sum(fusion.disagreeing),
    )


def _checked_groups(
    groups: Sequence[Sequence[int]],
    count: int,
    frequencies: Sequence[float],
    shifts: Sequence[np.ndarray | None] | None,
    min_ratio: float,
) -> tuple[list[list[int]], list[float], float]:
    """:func:`fringe_pass`'s groups, frequencies, shifts and ratio checked: (groups, frequencies, ratio)."""
    lists = _check_groups(groups, count)
    freqs = [
        _validate.finite_float(f, f"frequencies[{i}]", minimum=0.0, strict=True) for i, f in enumerate(frequencies)
    ]
    if len(freqs) != len(lists):
        raise ValueError(f"frequencies: expected {len(lists)} (one per group), found {len(freqs)}")
    _check_shifts(shifts, len(lists))
    return lists, freqs, _checked_ratio(min_ratio)


def _check_shifts(shifts: Sequence[np.ndarray | None] | None, groups: int) -> None:
    if shifts is not None and len(shifts) != groups:
        raise ValueError(f"shifts: expected {groups} entries (one per group, None for uniform), found {len(shifts)}")


def _checked_ratio(min_ratio: float) -> float:
    ratio = _validate.finite_float(min_ratio, "min_ratio", minimum=0.0, strict=True)
    if ratio > 1.0:
        raise ValueError(f"min_ratio: expected a fraction in (0, 1], found {min_ratio!r}")
    return ratio


def _temporal_kernel(
    method: str | None, freqs: list[float], max_residual: float, cv2: Any | None
) -> tuple[TurnKernel | None, list[int], _DingTables | None]:
    """The method's kernel on turns, the indices of the frequencies it reads, and OpenCV's Ding tables."""
    if method is None:
        return None, [], None
    if method not in TEMPORAL_METHODS:
        raise ValueError(f"method: expected one of {', '.join(TEMPORAL_METHODS)} or None, found {method!r}")
    whole = [f for f in freqs if float(f).is_integer()]
    if len(whole) != len(freqs):
        raise ValueError(f"frequencies: temporal unwrapping needs whole fringe counts, found {freqs}")
    kernel, used = turn_kernel(method, [int(f) for f in freqs], max_residual)
    tables = _ding_tables([int(f) for f in freqs], used) if method == "two-frequency" and cv2 is not None else None
    return kernel, used, tables


def _run_blocks(plan: _Plan, out: _Outputs, pixels: int, threads: int) -> None:
    """The plan over every pixel, on ``threads`` threads taking the next block in turn
    (:func:`processing.concurrency.on_blocks`)."""
    concurrency.on_blocks(lambda take: plan.run(out, take, pixels), pixels, BLOCK, threads)


def _sampled_high(flat: np.ndarray, spec: _Group, shape: tuple[int, int], cv2: Any | None) -> float:
    """99th percentile of a group's modulation over :func:`sample_stride`'s subsample (no full pass)."""
    stride = sample_stride(shape)
    sample = np.ascontiguousarray(flat[spec.rows, ::stride], dtype=np.float32)  # only the sampled columns copied
    coeffs = spec.weights @ sample
    modulation = _magnitude_into(coeffs[1], coeffs[2], aligned_empty(coeffs.shape[1]), cv2)
    if np.isfinite(modulation).any():
        return robust_high(modulation)
    everything = np.ascontiguousarray(flat[spec.rows], dtype=np.float32)  # rare: NaN throughout the subsample
    coeffs = spec.weights @ everything
    return robust_high(_magnitude_into(coeffs[1], coeffs[2], aligned_empty(coeffs.shape[1]), cv2))


@dataclass
class _Outputs:
    """Full-size flat outputs that the blocks write into."""

    phase: np.ndarray | None
    orders: np.ndarray | None
    valid: np.ndarray
    modulated: np.ndarray | None  # the mask before the method's test (None: the same as valid)
    wrapped: list[np.ndarray]
    modulation: list[np.ndarray]
    background: list[np.ndarray]
    brightness: list[np.ndarray]
    sigma: np.ndarray | None = None  # the fused phase's predicted sigma, when fusing

    @classmethod
    def allocate(
        cls,
        pixels: int,
        kept: int,
        unwrapping: bool,
        orders: bool = True,
        brightness: bool = False,
        fusing: bool = False,
    ) -> _Outputs:
        # One allocation for the float32 maps: large enough for numpy to ask for huge pages, and
        # a few big blocks instead of many 3 MiB ones keep the allocator from returning them to
        # the system between runs (fresh pages cost more to touch than the pass to compute).
        per_group = 2 if brightness else 3
        # Every row starts aligned (processing._aligned: OpenCV's magnitude writes into them; blocks of BLOCK
        # pixels keep the alignment), so rows are padded to whole 64-byte lines.
        count = per_group * kept + (1 if unwrapping else 0) + (1 if fusing else 0)
        maps = aligned_empty((count, -(-pixels // 16) * 16))[:, :pixels]
        rows = list(maps)
        sigma = rows.pop() if fusing else None
        return cls(
            phase=rows.pop() if unwrapping else None,
            orders=np.empty(pixels, dtype=np.int32) if unwrapping and orders else None,
            valid=np.empty(pixels, dtype=bool),
            modulated=np.empty(pixels, dtype=bool) if unwrapping else None,
            wrapped=rows[:kept],
            modulation=[] if brightness else rows[kept : 2 * kept],
            background=[] if brightness else rows[2 * kept :],
            brightness=rows[kept:] if brightness else [],
            sigma=sigma,
        )


class _Fusion:
    """What the blocks need to fuse every frequency into the absolute phase, and the disagreeing pixels they found."""

    def __init__(self, frequencies: list[float], groups: list[list[int]], noise: float) -> None:
        self.frequencies = frequencies
        self.steps = [len(g) for g in groups]
        self.noise = float(noise)
        self.disagreeing: list[int] = []  # one count per block (list.append is thread-safe)


@dataclass
class _Plan:
    """Everything a thread needs to run the pass over a range of pixels."""

    flat: np.ndarray
    specs: list[_Group]
    thresholds: list[float]
    ratio: float
    kept: list[int]
    kernel: TurnKernel | None
    used: list[int]
    tables: _DingTables | None
    cv2: Any | None
    background_nonnegative: bool  # unsigned frames and non-negative A weights
    fusion: _Fusion | None = None
    finite_frames: bool = field(init=False)  # integer frames: no NaN anywhere in the blocks' coefficients
    # numpy's exact angles (exact_angles_are_fast): the weights give -B cos phi (see _angle_into)
    opposite: bool = field(init=False)

    def __post_init__(self) -> None:
        self.finite_frames = bool(np.issubdtype(self.flat.dtype, np.integer))
        self.opposite = _opposite_angles(self.cv2)
        if self.opposite:
            flip = np.array([[1.0], [-1.0], [1.0]], dtype=np.float32)  # B's magnitude ignores the sign
            self.specs = [_Group(spec.rows, spec.weights * flip) for spec in self.specs]

    def run(self, out: _Outputs, take: Callable[[], int | None], pixels: int) -> None:
        """The blocks whose first pixels ``take`` hands out, until it gives None.

        Scratch buffers are this thread's own; each block writes its own slices of the outputs.
        """
        size = min(BLOCK, pixels)
        scratch = _Scratch.reused(self.specs, size)
        while (begin := take()) is not None:
            end = min(begin + BLOCK, pixels)
            self._block(out, begin, end, scratch if end - begin == size else _Scratch.allocate(self.specs, end - begin))

    def _block(self, out: _Outputs, begin: int, end: int, scratch: _Scratch) -> None:
        cv2 = self.cv2
        window = slice(begin, end)
        valid = out.valid[window]
        angles: list[np.ndarray] = []
        amplitudes: list[np.ndarray] = []
        for g, spec in enumerate(self.specs):
            frames = scratch.frames[: spec.weights.shape[1]]
            np.copyto(frames, self.flat[spec.rows, window], casting="unsafe")
            coeffs = scratch.coeffs
            np.matmul(spec.weights, frames, out=coeffs)
            slot = self.kept.index(g) if g in self.kept else -1
            angle = out.wrapped[slot][window] if slot >= 0 else scratch.angle[g]
            # pi - (-pi) is 2 pi, which the look-up index must not see either
            below = slot >= 0 or self.tables is None or self.opposite
            angles.append(
                _angle_into(
                    coeffs[1],
                    coeffs[2],
                    angle,
                    cv2,
                    below_two_pi=below,
                    finite=self.finite_frames,
                    opposite=self.opposite,
                )
            )
            modulation = out.modulation[slot][window] if slot >= 0 and out.modulation else scratch.modulation[g]
            amplitudes.append(_magnitude_into(coeffs[1], coeffs[2], modulation, cv2))
            if slot >= 0 and out.brightness:
                np.add(coeffs[0], modulation, out=out.brightness[slot][window])
            elif slot >= 0:
                np.copyto(out.background[slot][window], coeffs[0])
            self._mask(coeffs[0], modulation, self.thresholds[g], valid if g == 0 else scratch.test, scratch)
            if g:
                valid &= scratch.test
        if self.kernel is None:
            return
        assert out.phase is not None and out.modulated is not None
        np.copyto(out.modulated[window], valid)
        phase = out.phase[window]
        orders = None if out.orders is None else out.orders[window]
        if self.tables is not None:  # NaN outside the modulated pixels comes from the tables
            self._ding_opencv(angles[self.used[0]], angles[self.used[1]], phase, orders, valid, scratch)
        else:
            turns = [np.minimum(angles[i] * np.float32(1.0 / TWO_PI), _BELOW_ONE) for i in self.used]
            absolute, k, consistent = self.kernel(turns)
            np.copyto(phase, absolute, casting="same_kind")
            if orders is not None:
                np.copyto(orders, k, casting="unsafe")
            valid &= consistent
            np.logical_not(out.modulated[window], out=scratch.test)
            np.copyto(phase, np.float32(np.nan), where=scratch.test)
        fusion = self.fusion
        if fusion is not None:
            assert out.sigma is not None
            fused = fuse_frequencies(
                phase,
                angles,
                fusion.frequencies,
                amplitudes,
                fusion.steps,
                fusion.noise,
                out=phase,
                sigma_out=out.sigma[window],
            )
            fusion.disagreeing.append(fused.disagreeing)

    def _mask(
        self, background: np.ndarray, modulation: np.ndarray, threshold: float, out: np.ndarray, scratch: _Scratch
    ) -> None:
        """shadow_mask's test: B >= max(threshold, ratio A) and A > 0 (NaN compares False)."""
        level = np.multiply(background, np.float32(self.ratio), out=scratch.level)
        _bound_into(level, threshold, self.cv2, self.finite_frames, upper=False)
        np.greater_equal(modulation, level, out=out)
        if not self.background_nonnegative:  # else A = 0 only where every frame is 0, so B = 0 fails
            out &= np.greater(background, 0, out=scratch.positive)

    def _ding_opencv(
        self,
        low: np.ndarray,
        high: np.ndarray,
        phase: np.ndarray,
        orders: np.ndarray | None,
        valid: np.ndarray,
        scratch: _Scratch,
    ) -> None:
        """Ding's look-up as OpenCV tables: index m + f1 = round(f2 t1 - f1 t2 + f1), rounded by addWeighted.

        Pixels outside ``valid`` (the modulation mask on entry) get the last index, whose phase
        is NaN and which reaches nothing.
        """
        cv2, tables = self.cv2, self.tables
        assert cv2 is not None and tables is not None
        f1, f2 = tables.f1, tables.f2
        index = cv2.addWeighted(low, f2 / TWO_PI, high, -f1 / TWO_PI, float(f1), dtype=cv2.CV_8U)
        unmodulated = np.subtract(valid.view(np.uint8), np.uint8(1), out=scratch.reach)  # 255 outside, 0 inside
        np.bitwise_or(index, unmodulated, out=index)
        cv2.LUT(index, tables.phase, dst=phase)
        phase += high
        if orders is not None:
            cv2.LUT(index, tables.orders, dst=orders)
        valid &= cv2.LUT(index, tables.reach, dst=scratch.reach).view(bool)


_SCRATCH = threading.local()


@dataclass
class _Scratch:
    """Per-thread block buffers, reused from block to block.

    One frame buffer and one coefficient buffer serve every group in turn (a group's coefficients are
    read only before the next group's frames come in): the block's working set stays smaller, and
    the next group's frames are written into cache lines the last group's left warm.
    """

    frames: np.ndarray  # (most steps of a group, pixels)
    coeffs: np.ndarray  # (3, pixels)
    angle: list[np.ndarray]
    modulation: list[np.ndarray]
    level: np.ndarray
    test: np.ndarray
    positive: np.ndarray
    reach: np.ndarray

    @classmethod
    def reused(cls, specs: Sequence[_Group], size: int) -> _Scratch:
        """This thread's buffers for blocks of ``size`` pixels, kept from the last pass of the same layout.

        A pass allocates about 100 bytes of scratch per block pixel (6 MiB for two six-step
        frequencies); fresh pages cost more to fault in than the blocks take to compute.
        """
        layout = (size, tuple(s.weights.shape[1] for s in specs))
        kept = getattr(_SCRATCH, "kept", None)
        if kept is None or kept[0] != layout:
            kept = _SCRATCH.kept = (layout, cls.allocate(specs, size))
        return kept[1]

    @classmethod
    def allocate(cls, specs: Sequence[_Group], size: int) -> _Scratch:
        def vector(dtype: type = np.float32) -> np.ndarray:
            return aligned_empty(size, dtype)  # see processing._aligned

        return cls(
            frames=aligned_empty((max(s.weights.shape[1] for s in specs), size)),
            coeffs=aligned_empty((3, size)),
            angle=[vector() for _ in specs],
            modulation=[vector() for _ in specs],
            level=vector(),
            test=vector(np.bool_),
            positive=vector(np.bool_),
            reach=vector(np.uint8),
        )
