"""A capture taken at several exposures becomes one fused stack of its base patterns, in the load stage.

Everything after the load stage (undistortion, denoising, phase, unwrapping, corrections, heights)
then runs on the fused frames as on one exposure (:mod:`processing.phase.exposure_fusion` has the
rule). The weights come per pattern group (each phase-shifted frequency; the Gray planes; the
rest); the highest frequency along the fringe axis gives each pixel's dominant exposure, kept as
``state.exposure_map`` for the result's ``exposure.npy``.
"""

from __future__ import annotations

import time

import numpy as np

from processing.phase.exposure_fusion import fuse_exposures, noise_model
from rig.errors import ProcessingError
from rig.pipeline.plan import PatternGroups
from rig.pipeline.state import SceneState

# the fused frames' noise: unit standard deviation at every pixel (the phase sigma reads it)
FUSED_NOISE_SIGMA = 1.0


def fusion_groups(groups: PatternGroups, count: int, axis: str) -> tuple[list[list[int]], int]:
    """Pattern groups sharing one weight per pixel, and the index of the phase's (highest) frequency.

    Each sinusoid group (phase-shifted or single-shot) is one; Gray planes and every other pattern
    form the last.
    """
    out = [list(g.indices) for g in groups.sinusoids + groups.single_shot]
    along = groups.along(axis) or groups.single_shot
    primary = out.index(list(along[-1].indices)) if along else 0
    grouped = {i for indices in out for i in indices}
    rest = [i for i in range(count) if i not in grouped]
    if rest:
        out.append(rest)
    return out, primary


def saturation_level(frames: np.ndarray) -> float:
    """The grey level at which integer frames clip (their dtype's top value); inf for float frames."""
    if np.issubdtype(frames.dtype, np.integer):
        return float(np.iinfo(frames.dtype).max)
    return float("inf")


def fuse_state_exposures(state: SceneState) -> None:
    """Replace the state's (E x N) frames by the fused (N) stack; note the exposures and noise in the report."""
    sets = state.exposures
    if sets is None or not sets.multiple or state.frames is None:
        return
    started = time.perf_counter()
    frames = state.frames
    # (E, N, H, W), exposure k's full sequence at stack[k]: capture order makes it a view of the frames
    stack = frames.reshape(len(sets.exposures_us), len(sets.base), *frames.shape[1:])
    groups, primary = fusion_groups(state.groups, len(sets.base), state.axis)
    saturation = saturation_level(frames)
    phase_shifted = [g for g in state.groups.sinusoids if g.steps >= 3]
    try:
        noise = noise_model(
            stack, [g.indices for g in phase_shifted], [np.asarray(g.shifts) for g in phase_shifted], saturation
        )
        fused = fuse_exposures(stack, sets.exposures_us, groups, noise, saturation, primary)
    except ValueError as exc:
        raise ProcessingError(f"{state.capture.manifest_path}: exposures: {exc}") from None
    state.frames = fused.frames
    times = np.asarray(sets.exposures_us, dtype=np.float32)
    state.exposure_map = np.where(fused.dominant >= 0, times[np.maximum(fused.dominant, 0)], np.float32(np.nan))
    counts = np.bincount(fused.dominant.ravel() + 1, minlength=len(times) + 1)
    state.info["exposures"] = {
        "exposures_us": list(sets.exposures_us),
        "rule": "inverse-variance weights per pixel and pattern group; saturated frames weigh 0",
        "noise_model": {"read_grey2": round(noise.read, 4), "shot_grey": round(noise.shot, 5)},
        "dominant_fraction": [round(float(c) / fused.dominant.size, 4) for c in counts[1:]],
        "saturated_everywhere_fraction": round(float(counts[0]) / fused.dominant.size, 4),
        "noise_sigma_grey": FUSED_NOISE_SIGMA,
        "seconds": round(time.perf_counter() - started, 4),
    }
