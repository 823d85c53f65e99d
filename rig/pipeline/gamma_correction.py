"""`rig process --correction gamma-table`: remove the projector-gamma phase ripple in processing.

For captures whose projector could not be pre-corrected (see :mod:`calibration.gamma`): the
calibration's ``phase_error`` table (learnt by ``rig calibrate`` on the reference plane: mean
wrapped-phase error per phase bin against a smooth fit) is subtracted from the absolute phase of
the object and of the reference, both at the table's frequency.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from calibration.errors import CalibrationError
from calibration.gamma import compensate_phase, table_from_fields

NAME = "gamma-table"


def correct_gamma_ripple(state: Any, options: Any) -> None:
    """A ``rig.pipeline`` correction: ``state.unwrapped.phase`` minus the tabulated ripple."""
    calibration = state.calibration
    if calibration is None:
        raise CalibrationError(f"--correction {NAME}: needs --calibration (its phase_error table)")
    fields = calibration.extra.get("phase_error")
    if not isinstance(fields, dict):
        raise CalibrationError(f"{calibration.where}: phase_error: missing (recalibrate with rig calibrate, or --from)")
    table = table_from_fields(fields)
    frequency = float(fields.get("frequency", state.unwrapped.frequency))
    if frequency != state.unwrapped.frequency:
        raise CalibrationError(
            f"{calibration.where}: phase_error: learnt at {frequency:g} fringes, the capture's phase is at {state.unwrapped.frequency:g}"
        )
    phase = state.unwrapped.phase
    state.unwrapped.phase = np.where(np.isfinite(phase), compensate_phase(phase, table), np.nan)
    state.info["gamma_table_rms_rad"] = float(np.sqrt(np.mean(table.error**2)))


def register(corrections: dict) -> None:
    """Add the correction to a pipeline's correction registry."""
    corrections[NAME] = correct_gamma_ripple
