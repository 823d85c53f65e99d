"""What a verification measures: how many positions of each artefact, the declared MPE, how scans are processed.

Also the check of the artefacts' sizes against the guideline's rules relative to L0 (a rule not
met is a note in the report, not a refusal: the user may have no better artefact).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from rig.verify import guideline
from rig.verify.artefacts import Artefacts
from rig.verify.guideline import Volume

if TYPE_CHECKING:
    from rig.pipeline.plan import ProcessOptions

# MPE (mm) of the built-in simulated rig: what it meets with margin (docs/verification.md).
SIMULATED_MPE_MM = {"PF": 0.5, "PS": 0.15, "SD": 0.1, "F": 0.4}


@dataclass
class VerificationPlan:
    """How many positions of each artefact, the declared MPE, and how scans are processed."""

    sphere_positions: int = guideline.SPHERE_POSITIONS
    ball_bar_positions: int = guideline.BALL_BAR_POSITIONS
    plane_positions: int = guideline.PLANE_POSITIONS
    mpe_mm: dict[str, float] = field(default_factory=lambda: dict(SIMULATED_MPE_MM))
    options: ProcessOptions | None = None  # None: what `rig process` does without flags

    def notes(self) -> list[str]:
        """Where this plan departs from the guideline (a reduced procedure is said so in the report)."""
        out = []
        counts = (
            ("sphere", self.sphere_positions, guideline.SPHERE_POSITIONS, "at least "),
            ("ball bar", self.ball_bar_positions, guideline.BALL_BAR_POSITIONS, ""),
            ("plane", self.plane_positions, guideline.PLANE_POSITIONS, ""),
        )
        for name, count, required, least in counts:
            if count < required:
                out.append(f"reduced procedure: {name} at {count} positions, the guideline asks {least}{required}")
        return out


def size_notes(volume: Volume, artefacts: Artefacts) -> list[str]:
    """The guideline's size rules relative to L0 that these artefacts do not meet (none: all met)."""
    l0 = volume.l0_mm
    lo, hi = guideline.SPHERE_DIAMETER_L0
    out = []
    if not lo * l0 <= artefacts.sphere_diameter_mm <= hi * l0:
        out.append(
            f"sphere diameter {artefacts.sphere_diameter_mm:g} mm outside {lo:g}..{hi:g} L0 ({lo * l0:.0f}..{hi * l0:.0f} mm)"
        )
    if artefacts.ball_bar_length_mm < guideline.BALL_BAR_MIN_L0 * l0:
        out.append(
            f"ball bar {artefacts.ball_bar_length_mm:g} mm shorter than {guideline.BALL_BAR_MIN_L0:g} L0 ({guideline.BALL_BAR_MIN_L0 * l0:.0f} mm)"
        )
    if artefacts.plane_length_mm < guideline.PLANE_MIN_L0 * l0:
        out.append(
            f"plane {artefacts.plane_length_mm:g} mm shorter than {guideline.PLANE_MIN_L0:g} L0 ({guideline.PLANE_MIN_L0 * l0:.0f} mm)"
        )
    return out
