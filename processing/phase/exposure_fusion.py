"""Fringe frames taken at several exposures, fused per pixel into one stack before any phase is computed.

Each exposure k (time t_k) sees I_kj = t_k R_j + noise: the same radiance R_j per pattern j, scaled
by its exposure. Per pixel and per pattern group (a phase-shifted frequency: the weights must be
the same for all its steps), exposure k gets the inverse-variance weight of its radiance estimate
I_kj / t_k::

    w_k = t_k^2 / var_k(A_k)      (0 where any frame of the group saturates at that exposure)

with the camera's noise ``var(A) = read + shot * A`` at the group's mean level A_k
(:func:`noise_model`, estimated from the capture itself). The fused frames are the
inverse-variance mean of the radiances, scaled per pixel by sqrt(sum w)::

    F_j = sum_k (w_k / t_k) I_kj / sqrt(sum_k w_k)

Phase shifting is linear in the frames, so each group's phasor is the inverse-variance weighted
sum of the exposures' phasors: the phase, the modulation ratio B / A and every unwrapping and
correction method work on F as on one exposure. The per-pixel scale whitens the noise: every
pixel of F has noise of standard deviation 1 (grey level), so F's modulation B is the pixel's
fringe signal-to-noise ratio, and the phase's standard deviation sqrt(2 / J) / B follows from F
alone. Pixels saturated at every exposure get F = 0 (no modulation: invalid downstream).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from processing.phase.shifting import fit_residual_variance, sample_stride

QUANTISATION_VARIANCE = 1.0 / 12.0  # a grey level's rounding: the least noise an integer camera has


@dataclass(frozen=True)
class NoiseModel:
    """A camera's noise variance at mean level A (grey levels): ``read + shot * A``."""

    read: float
    shot: float

    def variance(self, level: np.ndarray) -> np.ndarray:
        """Noise variance (float32) at each mean level (grey levels)."""
        out = np.maximum(np.asarray(level, dtype=np.float32), np.float32(0.0))
        out *= np.float32(self.shot)
        out += np.float32(self.read)
        return out


@dataclass
class FusedExposures:
    """Frames fused over exposures and what each pixel drew on.

    frames : (N, H, W) float32, the fused stack, noise of standard deviation 1 at every pixel.
    dominant : (H, W) int8, per pixel the exposure with the largest weight in the ``primary``
        group (index into the exposures; -1 where every exposure saturates).
    used : (H, W) uint8, how many exposures contributed to the ``primary`` group.
    noise : the noise model used for the weights.
    """

    frames: np.ndarray
    dominant: np.ndarray
    used: np.ndarray
    noise: NoiseModel


def _as_index(indices: Sequence[int]) -> slice | list[int]:
    """A group's pattern indices as a slice when they run consecutively (views, not copies)."""
    items = list(indices)
    if items == list(range(items[0], items[-1] + 1)):
        return slice(items[0], items[-1] + 1)
    return items


def _group_weights(
    frames: np.ndarray, index: slice | list[int], scale: np.ndarray, noise: NoiseModel, saturation: float
) -> np.ndarray:
    """(E, H, W) float32 inverse-variance weights of one group: (t_k / t_max)^2 / var(A_k), 0 where saturated."""
    weights = np.empty((frames.shape[0], *frames.shape[2:]), dtype=np.float32)
    for k in range(frames.shape[0]):
        part = frames[k, index]
        variance = np.add.reduce(part, axis=0, dtype=np.float32)  # the sum, made var(mean) in place:
        if noise.shot > 0:
            np.maximum(variance, np.float32(0.0), out=variance)
        variance *= np.float32(noise.shot / len(part))
        variance += np.float32(noise.read)
        np.divide(np.float32(scale[k] ** 2), variance, out=weights[k])
        if np.isfinite(saturation):
            np.copyto(weights[k], np.float32(0.0), where=np.maximum.reduce(part, axis=0) >= saturation)
    return weights


def _dominant(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel the index of the largest weight (-1 where all are 0) and how many weights are positive."""
    dominant = np.full(weights.shape[1:], -1, dtype=np.int8)
    used = np.zeros(weights.shape[1:], dtype=np.uint8)
    best = np.zeros(weights.shape[1:], dtype=np.float32)
    for k, weight in enumerate(weights):
        np.copyto(dominant, np.int8(k), where=weight > best)
        np.maximum(best, weight, out=best)
        used += weight > 0
    return dominant, used


def _check_stack(stack: np.ndarray, exposures_us: Sequence[float]) -> tuple[np.ndarray, np.ndarray]:
    frames = np.asarray(stack)
    if frames.ndim != 4:
        raise ValueError(f"stack: expected (exposures, patterns, rows, cols), found shape {frames.shape}")
    times = np.asarray(exposures_us, dtype=np.float64)
    if times.shape != (frames.shape[0],):
        raise ValueError(f"exposures_us: expected {frames.shape[0]} exposure times, found {times.shape}")
    if not np.all(np.isfinite(times) & (times > 0)):
        raise ValueError(f"exposures_us: expected positive times, found {times.tolist()}")
    return frames, times


def noise_model(
    stack: np.ndarray,
    groups: Sequence[Sequence[int]],
    shifts: Sequence[np.ndarray],
    saturation: float = np.inf,
) -> NoiseModel:
    """The camera's noise ``read + shot * A`` from the sinusoid fits of every exposure.

    Parameters
    ----------
    stack : (E, N, H, W) array
        The frames of each exposure.
    groups : sequence of index lists
        The phase-shifted groups (pattern indices into N); groups of four steps or more are fitted.
    shifts : sequence of (J,) arrays
        Each group's phase shifts in radians.
    saturation : float
        Grey level at which a pixel clips; pixels reaching it in a group are left out.

    Returns
    -------
    NoiseModel
        A least-squares line through the fit residual variance against the mean level, over a
        regular subsample of unsaturated pixels of every exposure and group; with no group of
        four steps, the quantisation noise alone (``read`` = 1/12, ``shot`` = 0).
    """
    frames = np.asarray(stack)
    stride = sample_stride(frames.shape[2:])
    sample = frames.reshape(frames.shape[0], frames.shape[1], -1)[:, :, ::stride].astype(np.float64)  # (E, N, P)
    levels: list[np.ndarray] = []
    variances: list[np.ndarray] = []
    for indices, delta in zip(groups, shifts):
        if len(indices) < 4:
            continue
        for part in sample[:, list(indices)]:
            keep = np.all(part < saturation, axis=0)
            levels.append(part[:, keep].mean(axis=0))
            variances.append(fit_residual_variance(part[:, keep], np.asarray(delta, dtype=np.float64)))
    if not levels:
        return NoiseModel(QUANTISATION_VARIANCE, 0.0)
    level, variance = np.concatenate(levels), np.concatenate(variances)
    if level.size < 2 or np.ptp(level) == 0:
        return NoiseModel(max(float(np.mean(variance)) if level.size else 0.0, QUANTISATION_VARIANCE), 0.0)
    shot, read = np.polyfit(level, variance, 1)
    return NoiseModel(max(float(read), QUANTISATION_VARIANCE), max(float(shot), 0.0))


def fuse_exposures(
    stack: np.ndarray,
    exposures_us: Sequence[float],
    groups: Sequence[Sequence[int]],
    noise: NoiseModel,
    saturation: float = np.inf,
    primary: int = 0,
) -> FusedExposures:
    """Fuse the frames of several exposures into one stack with unit noise (see the module docstring).

    Parameters
    ----------
    stack : (E, N, H, W) array
        Frame j of exposure k at ``stack[k, j]`` (grey levels, not yet normalised by exposure).
    exposures_us : (E,) sequence of float
        Each exposure's time (any unit; only the ratios matter).
    groups : sequence of index lists
        Patterns that must share one weight per pixel (a phase-shifted group; Gray planes with their
        inverses); every pattern index 0 .. N-1 in exactly one group.
    noise : NoiseModel
        The camera's noise (:func:`noise_model`).
    saturation : float
        Grey level at which the camera clips (the bit depth's top value); inf for float frames.
    primary : int
        The group whose weights give ``dominant`` and ``used`` (the highest frequency: the phase's).

    Returns
    -------
    FusedExposures

    Examples
    --------
    Two exposures of a 4-step fringe; the longer one clips where the fringe peaks:

    >>> import numpy as np
    >>> phi = np.full((1, 2), 0.5)
    >>> steps = [50 + 40 * np.cos(phi + 2 * np.pi * j / 4) for j in range(4)]
    >>> stack = np.stack([np.stack(steps), np.minimum(4 * np.stack(steps), 255)])
    >>> fused = fuse_exposures(stack, [1000, 4000], [[0, 1, 2, 3]], NoiseModel(1.0, 0.0), saturation=255)
    >>> int(fused.dominant[0, 0]), int(fused.used[0, 0])
    (0, 1)
    """
    frames, times = _check_stack(stack, exposures_us)
    count = frames.shape[1]
    members = sorted(i for indices in groups for i in indices)
    if members != list(range(count)):
        raise ValueError(f"groups: expected every pattern index 0 .. {count - 1} in exactly one group")
    if not 0 <= primary < len(groups):
        raise ValueError(f"primary: expected a group index 0 .. {len(groups) - 1}, found {primary}")
    shape = frames.shape[2:]
    fused = np.empty((count, *shape), dtype=np.float32)
    dominant = np.full(shape, -1, dtype=np.int8)
    used = np.zeros(shape, dtype=np.uint8)
    scale = times / times.max()  # relative times: the weights stay in float32 range
    product = np.empty(shape, dtype=np.float32)
    for g, indices in enumerate(groups):
        index = _as_index(indices)
        patterns = np.arange(count)[index]
        weights = _group_weights(frames, index, scale, noise, saturation)
        if g == primary:
            dominant, used = _dominant(weights)
        norm = weights.sum(axis=0)
        positive = norm > 0
        np.sqrt(norm, out=norm)
        np.divide(np.float32(1.0), norm, out=norm, where=positive)
        norm[~positive] = 0.0
        for k, coefficient in enumerate(weights):  # each weight becomes its coefficient, in place
            coefficient *= norm
            coefficient *= np.float32(1.0 / scale[k])
            for j in patterns:
                if k == 0:
                    np.multiply(frames[k, j], coefficient, out=fused[j])
                else:
                    np.multiply(frames[k, j], coefficient, out=product)
                    fused[j] += product
    return FusedExposures(fused, dominant, used, noise)
