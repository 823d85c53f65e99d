"""Refuse a capture whose images follow another phase convention than its patterns say.

The evidence (Gray-code positions, heterodyne beats) and its maths are in
:mod:`processing.phase.convention`; this module turns a suspicious offset into one line naming what
is likely wrong and the import option that fixes it. ``--param phase_convention_check=false``
processes anyway.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from rig.errors import ProcessingError

if TYPE_CHECKING:
    from processing.phase.convention import OffsetEstimate
    from rig.pipeline.plan import ProcessOptions


def enabled(options: ProcessOptions) -> bool:
    """Whether the check runs (``--param phase_convention_check=false`` turns it off)."""
    return options.params.get("phase_convention_check", True) is not False


def _angle_text(value: float) -> str:
    """An angle as the importer's spec writes it: 0, pi, pi/2, -pi/2 when close, else radians."""
    value = math.remainder(value, 2 * math.pi)
    quarter = round(value / (math.pi / 2))
    if abs(value - quarter * math.pi / 2) < 0.3:
        return {0: "0", 1: "pi/2", 2: "pi", -2: "pi", -1: "-pi/2"}[quarter]
    return f"{value:.2f}"


def _spec_with_phase(spec: str, phase: str) -> str:
    """The import spec with ``phase=`` of every ``sin`` group set to ``phase``."""
    groups = []
    for group in spec.split(";"):
        kind, _, rest = group.strip().partition(":")
        if kind.strip() == "sin":
            keys = [item for item in rest.split(",") if item.strip() and not item.strip().startswith("phase=")]
            group = f"sin:{','.join(keys + [f'phase={phase}'])}"
        groups.append(group.strip())
    return "; ".join(groups)


def check(estimate: OffsetEstimate, evidence: str, capture: Any, patterns: list[dict[str, Any]], where: str) -> None:
    """Raise ProcessingError when ``estimate`` shows the images' phase convention differs from the capture's."""
    if not estimate.suspicious():
        return
    sinusoids = [p for p in patterns if p.get("kind") == "sinusoid"]
    current = float(sinusoids[0].get("phase_rad", 0.0)) if sinusoids else 0.0
    wanted = _angle_text(current + estimate.offset)
    provenance = capture.manifest.get("import")
    if isinstance(provenance, dict):
        spec = provenance.get("spec")
        example = f" ({_spec_with_phase(spec, wanted)!r})" if isinstance(spec, str) and not spec.startswith("@") else ""
        fix = f"re-import with phase={wanted} in the sin group of --patterns{example}"
    else:
        fix = (
            f"the projector's patterns differ from capture.json's phase_rad; set each sinusoid's phase_rad to {wanted}"
        )
    raise ProcessingError(
        f"{where}: phase convention: {evidence}: every phase is offset by {estimate.offset:+.2f} rad from what "
        f"the patterns say; likely cause: the images follow another phase convention (pattern phase "
        f"{wanted} instead of {_angle_text(current)}); fix: {fix}; --param phase_convention_check=false processes anyway"
    )
