"""The processing options a page offers, from the pipeline's own lists (never written in HTML)."""

from __future__ import annotations

from typing import Any

from rig.pipeline.corrections import REGISTRY as CORRECTIONS
from rig.pipeline.plan import DEFAULT_CORRECTION, UNWRAP_METHODS
from rig.pipeline.stages import DENOISERS


def process_choices() -> dict[str, Any]:
    """Unwrapping methods, denoisers and corrections by name, and the default correction."""
    return {
        "unwrap": list(UNWRAP_METHODS),
        "denoise": list(DENOISERS),
        "correction": list(CORRECTIONS),
        "default_correction": DEFAULT_CORRECTION,
    }
