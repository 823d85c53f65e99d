"""What one capture carries through the stages: its frames, wrapped and unwrapped phase, timings and report."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from calibration.store import Calibration
from rig.pipeline.plan import PatternGroups
from rig.store.capture import Capture
from rig.store.exposures import ExposureSets


@dataclass
class WrappedPhase:
    """Wrapped phase per frequency (any 2 pi representation), with the modulation and background of each.

    The fused pass keeps these maps only for the highest frequency (what height, texture and
    corrections read) unless the capture has no calibration (wrapped.npy has them all); the
    other entries are then None.
    """

    frequencies: list[float]
    phase: list[np.ndarray | None]
    modulation: list[np.ndarray | None]
    background: list[np.ndarray | None]
    valid: np.ndarray
    # A + B per frequency instead of the two apart (the fused pass: the texture is all that reads them)
    brightness: list[np.ndarray | None] | None = None


@dataclass
class UnwrappedPhase:
    """Absolute phase 2 pi f u / W at ``frequency`` (NaN where invalid); ``absolute`` False for spatial."""

    phase: np.ndarray
    valid: np.ndarray
    frequency: float
    method: str
    absolute: bool = True
    orders: np.ndarray | None = None
    fused: bool = False  # every frequency went into the phase (processing.phase.frequency_fusion)


@dataclass
class SceneState:
    """One capture on its way through the stages."""

    name: str
    capture: Capture
    groups: PatternGroups
    axis: str
    frames: np.ndarray | None = None
    wrapped: WrappedPhase | None = None
    unwrapped: UnwrappedPhase | None = None
    reference: SceneState | None = None
    timings: dict[str, float] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    info: dict[str, Any] = field(default_factory=dict)
    calibration: Calibration | None = None
    # valid pixels whose fringe orders the correction could not settle (``auto``), else None
    unresolved: np.ndarray | None = None
    # predicted phase standard deviation (rad) per pixel at the unwrapped frequency (processing.geometry.uncertainty)
    phase_sigma: np.ndarray | None = None
    single_shot_reference: Any = None  # processing.unwrap.single_shot.SingleShotReference of a reference capture
    exposures: ExposureSets | None = None  # a capture taken at several exposures (fused in the load stage)
    # per pixel the exposure (us) that weighed most in the fused phase; NaN where none was usable
    exposure_map: np.ndarray | None = None
