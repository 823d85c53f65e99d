"""A capture looked at before (or instead of) processing: its raw frames, and for each phase-shifted
group of patterns the wrapped phase and the fringe modulation, so that an operator can see why a
result looks as it does (a dark frame, saturation, fringes too faint for the modulation threshold).

The groups are the pipeline's own (:func:`rig.pipeline.plan.group_patterns`), and the wrapped phase
and modulation come from :func:`processing.phase.shifting.phase_shift` with each group's shifts,
as the phase stage computes them (without lens undistortion, denoising or corrections).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from processing.phase.shifting import phase_shift
from rig.errors import CaptureError
from rig.pipeline.plan import SinusoidGroup, group_patterns
from rig.store.capture import Capture


def describe_frames(capture: Capture) -> dict[str, Any]:
    """The frames (index, kind, a one-line description) and the phase-shifted groups of a capture."""
    held = capture.frame_index()
    frames = [
        {"index": i, "kind": p.get("kind", "?"), "what": _pattern_line(p), "held": i in held}
        for i, p in enumerate(capture.patterns)
    ]
    groups = [
        {"group": g, "axis": s.axis, "frequency": s.frequency, "steps": s.steps, "indices": s.indices}
        for g, s in enumerate(_groups(capture))
    ]
    return {"frames": frames, "groups": groups, "bit_depth": capture.bit_depth}


def _pattern_line(pattern: dict[str, Any]) -> str:
    keys = ("axis", "frequency", "steps", "step", "bit", "level", "inverted")
    return ", ".join(f"{k} {pattern[k]}" for k in keys if k in pattern) or str(pattern.get("kind", ""))


def _groups(capture: Capture) -> list[SinusoidGroup]:
    return [g for g in group_patterns(capture.patterns, where=str(capture.manifest_path)).sinusoids if g.steps >= 3]


def frame_8bit(capture: Capture, index: int) -> np.ndarray:
    """Frame ``index`` scaled to 8 bits (the capture's full scale to 0..255), for display."""
    if not 0 <= index < len(capture.patterns):
        raise CaptureError(f"frame: expected 0 .. {len(capture.patterns) - 1}, found {index}")
    image = capture.load_frame(index)
    shift = max(capture.bit_depth - 8, 0)
    return np.asarray(image >> shift if shift else image, dtype=np.uint8)


def wrapped_phase(capture: Capture, group: int) -> tuple[np.ndarray, np.ndarray]:
    """Wrapped phase (rad, [-pi, pi)) and modulation (grey levels of the capture) of a phase-shifted group."""
    groups = _groups(capture)
    if not 0 <= group < len(groups):
        raise CaptureError(
            f"group: expected 0 .. {len(groups) - 1} (the capture's phase-shifted groups), found {group}"
        )
    chosen = groups[group]
    result = phase_shift(capture.load_frames(chosen.indices), shifts=np.asarray(chosen.shifts))
    return result.phase.astype(np.float32), result.modulation.astype(np.float32)
